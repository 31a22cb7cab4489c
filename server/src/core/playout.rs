//! A jitter buffer for each user's uplinks: the coupling follows the local model at a steady delay.
//!
//! The graphics controller pulls the user's OP toward the newest uplinked model pose. Over a link whose delay
//! jitters, packets leave a queue in bursts (a late one holds back those behind it), so the newest pose held
//! still through a gap and then jumped by the gap's worth of motion: on a jab, a step of several centimetres
//! in one tick, energy the PD put into the linkage that the hand never did (`kinloop experiment latency`'s
//! jittered points). Extrapolating the newest pose over the gap overshoots instead.
//!
//! So each uplink is held until the client time it was sent at, plus the stream's steady delay, has come:
//! the VE plays the stream out as it was sent, later by a buffer that covers the jitter, and never ahead of
//! what it has received. The steady delay is learnt from the stream itself (no synchronised clocks):
//! - `base`: the smallest `arrival − client time` seen (the clock offset plus the fastest path), allowed to
//!   creep up by [`BASE_CREEP`] so a route that got slower is followed;
//! - `buffer`: the [`LATENESS_QUANTILE`] quantile of each arrival's lateness `arrival − client time − base`,
//!   tracked by stochastic approximation, at most [`MAX_BUFFER_S`].
//!
//! The buffer holds uplinks only while it is at least [`ENGAGE_S`] (and until it falls below [`RELEASE_S`]):
//! below that every uplink is used on arrival, as without the buffer. A loaded host makes lateness of its own
//! (many clients' loops on few cores stamp uplinks well before they leave), and holding for it buys nothing:
//! it lengthens the loop through which users on one OP push each other through the VE (see `sharing`, which
//! counts the hold in the round trip). On a clean link every uplink arrives `base` after it was sent and the
//! buffer stays at zero. The played-out client time is what snapshots report as the uplink they answer
//! (`Snapshot::uplink_time_s`).

use std::collections::VecDeque;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::Space;

/// Uplinks kept waiting at most: 0.5 s of a 1 kHz stream, beyond the largest buffer.
pub const CAPACITY: usize = 512;
/// The quantile of the lateness the buffer covers: one uplink in fifty comes after its turn (and is used at
/// once, as the newest).
pub const LATENESS_QUANTILE: f64 = 0.98;
/// Step of the quantile's stochastic approximation (s): the buffer rises by 0.98 of this on a late arrival
/// and falls by 0.02 of it otherwise, so it settles in about a second of a 1 kHz stream.
const QUANTILE_STEP_S: f64 = 5e-4;
/// The buffer never holds uplinks longer than this (s): a client whose clock runs wild delays only its own
/// coupling, and by no more.
pub const MAX_BUFFER_S: f64 = 0.2;
/// How fast the learnt base delay may rise, seconds per second of arrivals.
pub const BASE_CREEP: f64 = 1e-3;
/// The buffer starts holding uplinks when it grows to this (s) ...
pub const ENGAGE_S: f64 = 0.025;
/// ... and stops when it falls below this (s).
pub const RELEASE_S: f64 = 0.015;

/// One uplink's reference for the coupling.
#[derive(Clone, Copy, Debug)]
pub struct Reference<S: Space> {
    /// Client clock when sent (s).
    pub client_time_s: f64,
    /// F_h.
    pub hand_wrench: S::OpVec,
    /// x_lm.
    pub pose: OpPose<S>,
    /// ẋ_lm.
    pub twist: S::OpVec,
}

/// One user's uplinks waiting for their turn (see the module documentation).
#[derive(Clone, Debug)]
pub struct Playout<S: Space> {
    waiting: VecDeque<Reference<S>>,
    /// Smallest `arrival − client time` (s), crept up since; `None` before the first uplink.
    base_s: Option<f64>,
    /// Client time of the newest uplink taken (s).
    newest_client_s: f64,
    /// The buffer (s): the tracked quantile of the lateness.
    buffer_s: f64,
    /// Holding uplinks (the buffer reached [`ENGAGE_S`] and has not fallen below [`RELEASE_S`] since).
    engaged: bool,
    last_arrival_s: f64,
}

impl<S: Space> Playout<S> {
    /// An empty buffer, its storage allocated once.
    pub fn new() -> Self {
        Playout {
            waiting: VecDeque::with_capacity(CAPACITY),
            base_s: None,
            newest_client_s: f64::NEG_INFINITY,
            buffer_s: 0.0,
            engaged: false,
            last_arrival_s: 0.0,
        }
    }

    /// The buffer learnt (s); uplinks are held for it only while [`Playout::holding`].
    pub fn buffer_s(&self) -> f64 {
        self.buffer_s
    }

    /// Whether uplinks are held (see [`ENGAGE_S`]).
    pub fn holding(&self) -> bool {
        self.engaged
    }

    /// Uplinks waiting.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// Takes an uplink that arrived at `arrival_s` (server clock). A client clock that went back (a restarted
    /// client) starts the stream afresh.
    pub fn push(&mut self, arrival_s: f64, reference: Reference<S>) {
        if reference.client_time_s < self.newest_client_s {
            self.waiting.clear();
            self.base_s = None;
        }
        self.newest_client_s = reference.client_time_s;
        let offset = arrival_s - reference.client_time_s;
        let base = match self.base_s {
            Some(base) => (base + BASE_CREEP * (arrival_s - self.last_arrival_s).max(0.0)).min(offset),
            None => {
                self.buffer_s = 0.0;
                offset
            }
        };
        self.base_s = Some(base);
        self.last_arrival_s = arrival_s;
        let lateness = offset - base;
        self.buffer_s = if lateness > self.buffer_s {
            self.buffer_s + QUANTILE_STEP_S * LATENESS_QUANTILE
        } else {
            self.buffer_s - QUANTILE_STEP_S * (1.0 - LATENESS_QUANTILE)
        }
        .clamp(0.0, MAX_BUFFER_S);
        self.engaged = if self.engaged { self.buffer_s >= RELEASE_S } else { self.buffer_s >= ENGAGE_S };
        if self.waiting.len() == CAPACITY {
            self.waiting.pop_front();
        }
        self.waiting.push_back(reference);
    }

    /// The newest uplink whose turn has come by `now_s` (server clock), if any came since the last call; the
    /// ones before it are dropped (they are older references).
    pub fn due(&mut self, now_s: f64) -> Option<Reference<S>> {
        let base = self.base_s?;
        // A microsecond of slack: on a clean link an uplink is due the instant it arrives, whatever the rounding.
        let turn = if self.engaged { now_s - base - self.buffer_s + 1e-6 } else { f64::INFINITY };
        let mut newest = None;
        while let Some(front) = self.waiting.front() {
            if front.client_time_s > turn {
                break;
            }
            newest = self.waiting.pop_front();
        }
        newest
    }
}

impl<S: Space> Default for Playout<S> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::{math::space::Planar, math::space::VecOps};

    type V = <Planar as Space>::OpVec;

    fn reference(client_time_s: f64, x: f64) -> Reference<Planar> {
        let mut pose = OpPose::<Planar>::identity();
        pose.position[0] = x;
        Reference { client_time_s, hand_wrench: V::zero(), pose, twist: V::zero() }
    }

    #[test]
    fn a_steady_stream_is_used_on_arrival() {
        // Sent every millisecond on a client clock 5 s behind, 80 ms on the way, every time.
        let mut p = Playout::<Planar>::new();
        for k in 0..2000 {
            let sent = k as f64 * 1e-3;
            let arrival = sent + 5.0 + 0.08;
            p.push(arrival, reference(sent, sent));
            let used = p.due(arrival).expect("due on arrival");
            assert_eq!(used.client_time_s, sent);
        }
        assert_eq!(p.buffer_s(), 0.0);
        assert_eq!(p.waiting(), 0);
    }

    #[test]
    fn a_millisecond_of_lateness_is_not_held_for() {
        // A loaded host's loopback: one uplink in ten comes 1.5 ms late. The buffer learns it, below the
        // threshold, and every uplink is still used on arrival.
        let mut p = Playout::<Planar>::new();
        for k in 0..5000 {
            let sent = k as f64 * 1e-3;
            let arrival = sent + 0.0002 + if k % 10 == 0 { 0.0015 } else { 0.0 };
            p.push(arrival, reference(sent, sent));
            assert_eq!(p.due(arrival).map(|r| r.client_time_s), Some(sent));
        }
        assert!(p.buffer_s() > 0.0 && p.buffer_s() < ENGAGE_S && !p.holding(), "buffer {}", p.buffer_s());
    }

    #[test]
    fn a_bursty_stream_is_played_out_at_a_steady_pace() {
        // A FIFO link whose delay jumps by 60 ms for one packet in two hundred: that packet and the ones queued
        // behind it arrive together. Without the buffer the reference holds through each gap and then
        // jumps by it; played out, it advances steadily once the buffer has learnt.
        let mut p = Playout::<Planar>::new();
        let mut arrivals = Vec::new();
        let mut free_at = 0.0f64;
        for k in 0..6000 {
            let sent = k as f64 * 1e-3;
            let delay = if k % 200 == 0 { 0.11 } else { 0.05 };
            // FIFO: no packet overtakes the one before it.
            free_at = free_at.max(sent + delay);
            arrivals.push((free_at, sent));
        }
        let (mut next, mut last_used, mut largest_step) = (0, None::<f64>, 0.0f64);
        for tick in 0..6100 {
            let now = tick as f64 * 1e-3;
            while next < arrivals.len() && arrivals[next].0 <= now + 1e-12 {
                p.push(arrivals[next].0, reference(arrivals[next].1, arrivals[next].1));
                next += 1;
            }
            if let Some(used) = p.due(now) {
                if let (Some(last), true) = (last_used, now > 3.0) {
                    largest_step = largest_step.max(used.client_time_s - last);
                }
                last_used = Some(used.client_time_s);
            }
        }
        // The buffer settles at the lateness's 98th percentile, computed here from the arrivals.
        let base = arrivals.iter().map(|(a, s)| a - s).fold(f64::INFINITY, f64::min);
        let mut lateness: Vec<f64> = arrivals[3000..].iter().map(|(a, s)| a - s - base).collect();
        lateness.sort_by(f64::total_cmp);
        let q98 = lateness[(0.98 * lateness.len() as f64) as usize];
        assert!((p.buffer_s() - q98).abs() < 5e-3, "buffer {} against the 98th percentile {q98}", p.buffer_s());
        assert!(p.holding());
        // Used on arrival instead, the reference holds through each gap and jumps by it.
        let (mut newest, mut on_arrival_step) = (None::<f64>, 0.0f64);
        let mut next = 0;
        for tick in 3000..6100 {
            let now = tick as f64 * 1e-3;
            let before = newest;
            while next < arrivals.len() && arrivals[next].0 <= now + 1e-12 {
                newest = Some(arrivals[next].1);
                next += 1;
            }
            if let (Some(a), Some(b)) = (before, newest) {
                on_arrival_step = on_arrival_step.max(b - a);
            }
        }
        assert!(on_arrival_step > 0.05, "on arrival the reference jumps {on_arrival_step} s");
        // Played out, it jumps only where an uplink came later than the buffer's percentile.
        assert!(
            largest_step <= on_arrival_step / 5.0,
            "played out, the reference jumped {largest_step} s of the stream in a tick ({on_arrival_step} on arrival)"
        );
    }

    #[test]
    fn a_client_clock_that_goes_back_restarts_the_stream_and_the_buffer_is_bounded() {
        let mut p = Playout::<Planar>::new();
        // A clock that runs at half speed: every arrival is later than the last by more; the buffer stops at
        // its bound.
        for k in 0..5000 {
            let now = k as f64 * 1e-3;
            p.push(now, reference(now / 2.0, 0.0));
            let _ = p.due(now);
        }
        assert!((p.buffer_s() - MAX_BUFFER_S).abs() < 1e-12);
        // The client restarts its clock at zero: the next uplink is due at once, not after 2.5 s.
        p.push(5.0, reference(0.0, 1.0));
        let used = p.due(5.0).expect("a restarted stream is used");
        assert_eq!(used.pose.position[0], 1.0);
        assert_eq!(p.buffer_s(), 0.0);
    }
}
