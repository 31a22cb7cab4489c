//! The VE thread: wakes at absolute deadlines `epoch + k·period` (spin_sleep's hybrid sleep, SCHED_FIFO
//! when granted), moves uplinks in and snapshots out through lock-free rings, and runs the core.
//!
//! It never blocks, never allocates for a fixed set of users, and never logs per tick: events go to a ring
//! that a tokio task turns into log lines, statistics are copied out every 100 ms. Joins and leaves arrive
//! as commands (they allocate and free per-user buffers, once per user).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_process::realtime::try_realtime_priority;
use kinloop_protocol::codec;
use rtrb::{Consumer, Producer};

use crate::core::{UserId, VeCore, VeEvent};
use crate::fleet::Heartbeat;
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
    /// Advanced every tick, for a fleet manager's health pings (`crate::fleet`), if one listens.
    pub heartbeat: Option<Heartbeat>,
    /// A test knob: milliseconds to stall the loop for at its next tick (then reset to 0).
    pub stall_ms: Arc<AtomicU64>,
}

/// Runs the VE loop until `io.stop` is set; returns the final statistics.
pub fn run<S: Space>(mut core: VeCore<S>, mut io: VeThreadIo, realtime: bool) -> VeLoopStats {
    let granted = if realtime {
        try_realtime_priority().inspect_err(|why| tracing::warn!(%why, "the VE thread runs at normal priority")).is_ok()
    } else {
        false
    };
    let mut stats = VeLoopStats { realtime_priority: granted, ..Default::default() };
    let period = core.config().ve_period();
    let half_period = period / 2;
    let publish_every = (core.config().ve_rate_hz / 10.0).ceil().max(1.0) as u64;
    let room_every = (core.config().ve_rate_hz * ROOM_STATE_PERIOD.as_secs_f64()).round().max(1.0) as u64;
    let mut histogram = LatencyHistogram::default();
    let mut links: Vec<ActiveLink> = Vec::with_capacity(2 * core.config().max_users);
    let mut encoded = Vec::with_capacity(codec::limits::MAX_DATAGRAM_MESSAGE_BYTES);
    let sleeper = spin_sleep::SpinSleeper::default();
    let epoch = Instant::now();
    let mut iterations = 0u64;
    while !io.stop.load(Ordering::Relaxed) {
        let deadline = epoch + core.poll_timeout();
        sleeper.sleep_until(deadline);
        let woke = Instant::now();
        let lateness = woke.saturating_duration_since(deadline);
        stats.max_lateness_ns = stats.max_lateness_ns.max(lateness.as_nanos() as u64);
        if lateness > half_period {
            stats.deadline_misses += 1;
        }
        if let Some(heartbeat) = &io.heartbeat {
            heartbeat.beat();
        }
        let stall_ms = io.stall_ms.swap(0, Ordering::Relaxed);
        if stall_ms > 0 {
            std::thread::sleep(Duration::from_millis(stall_ms));
        }
        let now = woke - epoch;
        serve_commands(&mut core, &mut io.commands, &mut links, now);
        for l in &mut links {
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
            let sent = codec::encode_datagram_into(pending.datagram(), &mut encoded).is_ok()
                && push_frame(&mut l.link.snapshots, &encoded);
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
            if super::record::write_row(&core, record) {
                stats.record_rows += 1;
            } else {
                stats.record_rows_dropped += 1;
            }
        }
        if let Some(view) = io.view.as_mut() {
            view.after_tick(&core, &stats);
            stats.view_frames = view.published;
            stats.view_frames_dropped = view.dropped;
        }
        if let Some(room) = io.room.as_ref().filter(|_| iterations.is_multiple_of(room_every)) {
            room.publish(&core);
        }
        histogram.record(woke.elapsed().as_nanos() as u64);
        iterations += 1;
        if iterations.is_multiple_of(publish_every) {
            stats.step_time = histogram.summary();
            stats.core = core.metrics();
            let _ = io.stats.push(stats);
        }
    }
    stats.step_time = histogram.summary();
    stats.core = core.metrics();
    let _ = io.stats.push(stats);
    stats
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
