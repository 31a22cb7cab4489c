//! The VE thread: wakes at absolute deadlines `epoch + k·period` (spin_sleep's hybrid sleep, SCHED_FIFO
//! when granted), moves uplinks in and snapshots out through lock-free rings, and runs the core.
//!
//! It never blocks, never allocates for a fixed set of users, and never logs per tick: events go to a ring
//! that a tokio task turns into log lines, statistics are copied out every 100 ms. Joins and leaves arrive
//! as commands (they allocate and free per-user buffers, once per user).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_process::realtime::try_realtime_priority;
use kinloop_protocol::codec;
use rtrb::{Consumer, Producer};

use crate::core::{UserId, VeCore, VeEvent};
use crate::gateway::{push_frame, Command, LatencyHistogram, UserLink, VeLoopStats};
use crate::view::ViewTap;

use super::room::{Room, ROOM_STATE_PERIOD};

struct ActiveLink {
    user: UserId,
    link: UserLink,
}

/// The VE thread's ends of the shared rings.
pub struct VeThreadIo {
    /// Joins and leaves.
    pub commands: Consumer<Command>,
    /// Events for the log.
    pub events: Producer<VeEvent>,
    /// Statistics, a few times per second.
    pub stats: Producer<VeLoopStats>,
    /// Recorded rows (see `record`), when recording.
    pub record: Option<Producer<f64>>,
    /// Frames for the view's hub (see `crate::view::tap`), when a view is served.
    pub view: Option<ViewTap>,
    /// The room whose state the loop publishes (`--room-key`), if any.
    pub room: Option<Arc<Room>>,
    /// Set to stop the loop.
    pub stop: Arc<AtomicBool>,
}

/// Runs the VE loop on the calling thread until `io.stop` is set; returns the final statistics.
pub fn run<S: Space>(core: VeCore<S>, io: VeThreadIo, realtime: bool) -> VeLoopStats {
    let granted = if realtime {
        try_realtime_priority().inspect_err(|why| tracing::warn!(%why, "the VE thread runs at normal priority")).is_ok()
    } else {
        false
    };
    let mut ve = VeLoop::new(core, io, Instant::now());
    ve.stats.realtime_priority = granted;
    let sleeper = spin_sleep::SpinSleeper::default();
    while !ve.stopped() {
        sleeper.sleep_until(ve.next_deadline());
        ve.tick();
    }
    ve.finish()
}

/// One VE's loop state, stepped by whoever owns it: [`run`] on a thread of its own, or a thread of the
/// rooms' executor among other rooms (`super::rooms::executor`). [`VeLoop::tick`] is one iteration.
pub struct VeLoop<S: Space> {
    core: VeCore<S>,
    io: VeThreadIo,
    /// Statistics so far (also published every 100 ms).
    pub stats: VeLoopStats,
    half_period: Duration,
    publish_every: u64,
    room_every: u64,
    histogram: LatencyHistogram,
    links: Vec<ActiveLink>,
    encoded: Vec<u8>,
    epoch: Instant,
    iterations: u64,
}

impl<S: Space> VeLoop<S> {
    /// A loop for `core` whose time starts at `epoch`.
    pub fn new(core: VeCore<S>, io: VeThreadIo, epoch: Instant) -> Self {
        let period = core.config().ve_period();
        let publish_every = (core.config().ve_rate_hz / 10.0).ceil().max(1.0) as u64;
        let room_every = (core.config().ve_rate_hz * ROOM_STATE_PERIOD.as_secs_f64()).round().max(1.0) as u64;
        let links = Vec::with_capacity(2 * core.config().max_users);
        VeLoop {
            core,
            io,
            stats: VeLoopStats::default(),
            half_period: period / 2,
            publish_every,
            room_every,
            histogram: LatencyHistogram::default(),
            links,
            encoded: Vec::with_capacity(codec::limits::MAX_DATAGRAM_MESSAGE_BYTES),
            epoch,
            iterations: 0,
        }
    }

    /// When the next tick is due.
    pub fn next_deadline(&self) -> Instant {
        self.epoch + self.core.poll_timeout()
    }

    /// Whether the loop was told to stop.
    pub fn stopped(&self) -> bool {
        self.io.stop.load(Ordering::Relaxed)
    }

    /// One iteration, at the deadline it was due (now or a little later).
    pub fn tick(&mut self) {
        let deadline = self.next_deadline();
        let woke = Instant::now();
        let (core, io, stats, links, encoded) =
            (&mut self.core, &mut self.io, &mut self.stats, &mut self.links, &mut self.encoded);
        let lateness = woke.saturating_duration_since(deadline);
        stats.max_lateness_ns = stats.max_lateness_ns.max(lateness.as_nanos() as u64);
        if lateness > self.half_period {
            stats.deadline_misses += 1;
        }
        let now = woke - self.epoch;
        serve_commands(core, &mut io.commands, links, now);
        for l in links.iter_mut() {
            while let Ok(sample) = l.link.uplinks.pop() {
                // Rejections are counted (and reported once per burst) by the core.
                let _ = core.handle_uplink_sample(now, l.user, &sample);
            }
        }
        core.handle_timeout(now);
        while let Some(pending) = core.poll_snapshot() {
            let user = pending.user_id();
            if let Some(view) = io.view.as_mut() {
                view.note_snapshot(pending.snapshot());
            }
            let Some(l) = links.iter_mut().find(|l| l.user == user) else { continue };
            let sent = codec::encode_datagram_into(pending.datagram(), encoded).is_ok()
                && push_frame(&mut l.link.snapshots, encoded);
            if sent {
                l.link.notify.notify_one();
            } else {
                stats.snapshots_dropped += 1;
            }
        }
        while let Some(event) = core.poll_event() {
            // A full event ring drops the event; the core's counters still count what happened.
            let _ = io.events.push(event);
        }
        if let Some(record) = io.record.as_mut() {
            if super::record::write_row(core, record) {
                stats.record_rows += 1;
            } else {
                stats.record_rows_dropped += 1;
            }
        }
        if let Some(view) = io.view.as_mut() {
            view.after_tick(core, stats);
            stats.view_frames = view.published;
            stats.view_frames_dropped = view.dropped;
        }
        if let Some(room) = io.room.as_ref().filter(|_| self.iterations.is_multiple_of(self.room_every)) {
            room.publish(core);
        }
        self.histogram.record(woke.elapsed().as_nanos() as u64);
        self.iterations += 1;
        if self.iterations.is_multiple_of(self.publish_every) {
            self.publish();
        }
    }

    /// Users in the VE now.
    pub fn users(&self) -> usize {
        self.links.len()
    }

    fn publish(&mut self) {
        self.stats.step_time = self.histogram.summary();
        self.stats.core = self.core.metrics();
        let _ = self.io.stats.push(self.stats);
    }

    /// Publishes the final statistics and returns them.
    pub fn finish(mut self) -> VeLoopStats {
        self.publish();
        self.stats
    }
}

fn serve_commands<S: Space>(
    core: &mut VeCore<S>,
    commands: &mut Consumer<Command>,
    links: &mut Vec<ActiveLink>,
    now: Duration,
) {
    while let Ok(command) = commands.pop() {
        match command {
            Command::Join { request, link, reply } => {
                let decision = core.join(now, request);
                if let Ok(joined) = &decision {
                    links.push(ActiveLink { user: joined.user_id, link });
                }
                // The session may have given up waiting; then the user leaves on its own.
                if let Err(Ok(joined)) = reply.send(decision) {
                    let _ = core.leave(now, joined.user_id);
                    links.retain(|l| l.user != joined.user_id);
                }
            }
            Command::Resume { q, qd, reply } => {
                let _ = reply.send(core.handle_resume_offer(now, &q, &qd));
            }
            Command::Leave { user } => {
                let _ = core.leave(now, user);
                links.retain(|l| l.user != user);
            }
        }
    }
}

/// An upper bound of a user's encoded snapshot (bytes) for a scene with `n` coordinates, `m` closure rows
/// and operational dimension `k`: every number as 8 bytes plus generous framing.
pub fn snapshot_size_bound<S: Space>(n: usize, m: usize) -> usize {
    let k = S::DIM;
    let point = <S::Point as VecOps>::LEN;
    let fixed = 7 + k + k * (k + 1) / 2 + 3 * k + k * k;
    let contact = 2 * point + k + 6;
    let other = point + k;
    let config = 3 * n + n * (n + 1) / 2 + m * n + m + k * n + k;
    let numbers = fixed
        + kinloop_linkage::algorithms::local_model::MAX_LOCAL_CONTACTS * contact
        + kinloop_protocol::codec::limits::MAX_LIST_ENTRIES * other
        + config;
    (numbers * 8 + 1024).min(codec::limits::MAX_DATAGRAM_MESSAGE_BYTES)
}
