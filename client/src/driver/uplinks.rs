//! The uplinks' way out: what the haptic loop queues in its ring is sent on the session's connection by an
//! [`Outlet`], drained either by a thread of the client's own ([`send_uplinks`], unparked by the loop after
//! each push) or, for the many clients of one process, by the shared network's pump (woken once a round by
//! the shared clock). Either way the loop never blocks: it pushes into a bounded ring and takes its buffers
//! from a ring of free ones.
//!
//! When the drainer falls behind, only the newest [`BACKLOG`] queued uplinks are sent and the older ones
//! dropped (counted as superseded): a server uses the newest state of a hand, and a burst of old ones would
//! only fill QUIC's send buffer, whose own overflow drops the oldest too, but uncounted.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use kinloop_protocol::quic::DatagramSender;
use kinloop_protocol::{Datagram, Uplink};

use super::rt_loop::LoopShared;
use super::session::NetShared;

/// Most uplinks an outlet sends at once (a few milliseconds of a 1 kHz loop); older ones are superseded.
pub const BACKLOG: usize = 8;

/// One client's uplinks on their way out: the loop's ring, the free buffers' ring back to the loop, and the
/// connection's sender (replaced when the session is, empty between sessions).
pub(super) struct Outlet {
    pub(super) uplinks: rtrb::Consumer<Uplink>,
    pub(super) free: rtrb::Producer<Uplink>,
    pub(super) sender: Arc<Mutex<Option<DatagramSender>>>,
    pub(super) shared: Arc<LoopShared>,
    pub(super) net: Arc<NetShared>,
}

impl Outlet {
    /// Sends what is queued through the session's sender; true once the loop has stopped and nothing is left.
    pub(super) fn drain(&mut self) -> bool {
        // One lock for the whole drain, not one a datagram: the pump drains every user each round.
        let sender = self.sender.clone();
        let guard = sender.lock().ok();
        let connection = guard.as_ref().and_then(|g| g.as_ref());
        self.drain_with(&mut |message| connection.is_some_and(|s| s.send(message).is_ok()))
    }

    /// [`Outlet::drain`] with `send` (true: handed to QUIC) in place of the connection.
    fn drain_with(&mut self, send: &mut dyn FnMut(&Datagram) -> bool) -> bool {
        let stale = self.uplinks.slots().saturating_sub(BACKLOG);
        for _ in 0..stale {
            if let Ok(uplink) = self.uplinks.pop() {
                self.net.uplinks_superseded.fetch_add(1, Ordering::Relaxed);
                let _ = self.free.push(uplink);
            }
        }
        while let Ok(uplink) = self.uplinks.pop() {
            let message = Datagram::Uplink(uplink);
            if send(&message) {
                self.net.uplinks_sent.fetch_add(1, Ordering::Relaxed);
            }
            if let Datagram::Uplink(buffer) = message {
                // Back to the loop for reuse: it never allocates a buffer of its own.
                let _ = self.free.push(buffer);
            }
        }
        self.shared.stop.load(Ordering::Relaxed) && self.uplinks.is_empty()
    }
}

/// A client's own uplink thread: parked until the loop pushes, drains the outlet, until the loop stops.
pub(super) fn send_uplinks(mut outlet: Outlet) {
    while !outlet.drain() {
        std::thread::park_timeout(Duration::from_millis(10));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outlet(queued: u64) -> (Outlet, rtrb::Consumer<Uplink>) {
        let (mut tx, uplinks) = rtrb::RingBuffer::new(64);
        for seq in 0..queued {
            tx.push(Uplink::at_rest(seq, 3, 3)).unwrap();
        }
        let (free, returned) = rtrb::RingBuffer::new(64);
        let shared = Arc::new(LoopShared::default());
        let outlet = Outlet { uplinks, free, sender: Arc::default(), shared, net: Arc::default() };
        (outlet, returned)
    }

    #[test]
    fn a_drainer_behind_sends_the_newest_and_counts_the_older_as_superseded() {
        let (mut outlet, mut returned) = outlet(20);
        let mut sent = Vec::new();
        let done = outlet.drain_with(&mut |m| {
            let Datagram::Uplink(u) = m else { panic!("not an uplink") };
            sent.push(u.seq);
            true
        });
        assert!(!done, "the loop has not stopped");
        assert_eq!(sent, (12..20).collect::<Vec<_>>(), "the newest {BACKLOG}, in order");
        assert_eq!(outlet.net.uplinks_superseded.load(Ordering::Relaxed), 12);
        assert_eq!(outlet.net.uplinks_sent.load(Ordering::Relaxed), 8);
        let back: Vec<u64> = std::iter::from_fn(|| returned.pop().ok()).map(|u| u.seq).collect();
        assert_eq!(back, (0..20).collect::<Vec<_>>(), "every buffer goes back to the loop");
    }

    #[test]
    fn a_drainer_in_time_sends_everything_and_ends_with_the_loop() {
        let (mut outlet, _returned) = outlet(3);
        let mut sent = 0;
        assert!(!outlet.drain_with(&mut |_| {
            sent += 1;
            true
        }));
        assert_eq!((sent, outlet.net.uplinks_superseded.load(Ordering::Relaxed)), (3, 0));
        outlet.shared.stop.store(true, Ordering::Relaxed);
        assert!(outlet.drain_with(&mut |_| true), "stopped and empty: the outlet is done");
    }

    #[test]
    fn uplinks_refused_by_the_connection_are_not_counted_sent() {
        let (mut outlet, _returned) = outlet(4);
        outlet.drain();
        assert_eq!(outlet.net.uplinks_sent.load(Ordering::Relaxed), 0, "no session: nothing sent");
    }
}
