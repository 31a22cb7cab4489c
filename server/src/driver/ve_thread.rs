//! The VE thread: wakes at absolute deadlines `epoch + k·period` (a native sleep, then a warm-up and a spin
//! to the deadline: `super::rehearsal`; SCHED_FIFO when granted), moves uplinks in and snapshots out through
//! lock-free rings, and runs the core.
//!
//! It never blocks, never allocates for a fixed set of users, and never logs per tick: events go to a ring
//! that a tokio task turns into log lines, statistics are copied out every 100 ms. Joins and leaves arrive
//! as commands (they allocate and free per-user buffers, once per user).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_process::cpu::thread_cpu_time;
use kinloop_process::realtime::{try_realtime_priority, StallRuns};
use kinloop_protocol::codec;
use rtrb::{Consumer, Producer};

use crate::core::prefetch::prefetch;
use crate::core::{UserId, VeCore, VeEvent};
use crate::gateway::{
    prefetch_next_frame, push_frame, Command, LatencyHistogram, StageHistograms, UserLink, VeLoopStats,
};
use crate::view::ViewTap;

use super::rehearsal::{wait_warmed, Rehearsal};
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
    while !ve.stopped() {
        wait_warmed(ve.next_deadline(), granted, || ve.warm());
        ve.tick();
    }
    ve.finish()
}

/// One VE's loop state, stepped by whoever owns it: [`run`] on a thread of its own, or a thread of the
/// rooms' executor among other rooms (`super::rooms::executor`). [`VeLoop::tick`] is one iteration.
///
/// Each iteration runs its stages in turn and times each (`StageHistograms`): intake, step, snapshot terms,
/// then the round's snapshots encoded together, pushed together and their tasks woken together (a stage at a
/// time over all users keeps each stage's code and data hot across users), events and the recorder, the
/// view's tap, and the loop's own statistics.
pub struct VeLoop<S: Space> {
    core: VeCore<S>,
    io: VeThreadIo,
    /// Statistics so far (also published every 100 ms).
    pub stats: VeLoopStats,
    half_period: Duration,
    publish_every: u64,
    room_every: u64,
    histogram: LatencyHistogram,
    stages: StageHistograms,
    links: Vec<ActiveLink>,
    round: Round,
    epoch: Instant,
    /// CPU time of the thread that made the loop (a room's executor thread is shared with other rooms).
    cpu_at_start: Option<Duration>,
    /// The one-user VE whose tick warms the caches before a deadline ([`Self::warm`]).
    rehearsal: Option<Rehearsal<S>>,
    iterations: u64,
    /// The runs of late wake-ups (`VeLoopStats::deadline_stalls`).
    stalls: StallRuns,
}

impl<S: Space> VeLoop<S> {
    /// A loop for `core` whose time starts at `epoch`.
    pub fn new(core: VeCore<S>, io: VeThreadIo, epoch: Instant) -> Self {
        let period = core.config().ve_period();
        let publish_every = (core.config().ve_rate_hz / 10.0).ceil().max(1.0) as u64;
        let room_every = (core.config().ve_rate_hz * ROOM_STATE_PERIOD.as_secs_f64()).round().max(1.0) as u64;
        let links = Vec::with_capacity(2 * core.config().max_users);
        let round = Round::with_capacity(2 * core.config().max_users);
        let rehearsal = Rehearsal::new(core.model(), core.config());
        VeLoop {
            core,
            io,
            stats: VeLoopStats::default(),
            half_period: period / 2,
            publish_every,
            room_every,
            histogram: LatencyHistogram::default(),
            stages: StageHistograms::default(),
            links,
            round,
            epoch,
            cpu_at_start: thread_cpu_time(),
            rehearsal,
            iterations: 0,
            stalls: StallRuns::default(),
        }
    }

    /// Warms the caches for the coming tick (`super::rehearsal`): called shortly before its deadline, after
    /// the thread's sleep.
    pub fn warm(&mut self) {
        if let Some(rehearsal) = self.rehearsal.as_mut() {
            rehearsal.rehearse();
        }
        self.core.prefetch();
        prefetch(&self.links);
        let frame_len = self.round.frame_len();
        for l in &mut self.links {
            // The uplink waiting at the head of each ring, as the intake will read it, and the snapshot
            // ring's slots the round's frame will fill.
            if let Ok(sample) = l.link.uplinks.peek() {
                prefetch(std::slice::from_ref(sample));
            }
            prefetch_next_frame(&mut l.link.snapshots, frame_len);
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
        let stats = &mut self.stats;
        let lateness = woke.saturating_duration_since(deadline);
        stats.max_lateness_ns = stats.max_lateness_ns.max(lateness.as_nanos() as u64);
        let missed = lateness > self.half_period;
        if missed {
            stats.deadline_misses += 1;
        }
        stats.deadline_stalls += u64::from(self.stalls.begins_stall(missed));
        let now = woke - self.epoch;
        self.round(woke, now);
    }

    /// One iteration run at once, as if it were due now: what `kinloop bench`'s `server/ve_loop_users_N`
    /// times back to back (`crate::bench::LoopBench`), the same work as [`Self::tick`] less its deadline's
    /// bookkeeping. The VE's time advances one period however late the call comes, so a quarantined room
    /// runs it in slow motion (`super::rooms::quarantine`).
    pub fn tick_back_to_back(&mut self) {
        let now = self.core.poll_timeout();
        self.round(Instant::now(), now);
    }

    /// Forgets the loop's timing so far (the step's and the stages' histograms), keeping its counters: a
    /// benchmark's warm-up is not what it times.
    pub fn restart_timing(&mut self) {
        self.histogram = LatencyHistogram::default();
        self.stages = StageHistograms::default();
    }

    /// The iteration's work after its wake-up at `woke`, VE time `now`: every stage, timed, and the loop's
    /// statistics.
    fn round(&mut self, woke: Instant, now: Duration) {
        let (core, io, stats, links, round, stages) =
            (&mut self.core, &mut self.io, &mut self.stats, &mut self.links, &mut self.round, &mut self.stages);
        let mut clock = StageClock { last: woke };
        serve_commands(core, &mut io.commands, links, now);
        for l in links.iter_mut() {
            while let Ok(arrived) = l.link.uplinks.pop() {
                // Rejections are counted (and reported once per burst) by the core.
                let _ = core.handle_uplink_sample(now, l.user, &arrived.taken_in(woke));
            }
        }
        clock.lap(&mut stages.intake);
        let round_due = core.run_due_ticks(now);
        clock.lap(&mut stages.step);
        if round_due {
            core.build_due_snapshots();
        }
        clock.lap(&mut stages.snapshot_terms);
        round.clear();
        let mut view_ns = 0;
        while let Some(pending) = core.poll_snapshot() {
            if let Some(view) = io.view.as_mut() {
                let before = Instant::now();
                view.note_snapshot(pending.snapshot());
                view_ns += before.elapsed().as_nanos() as u64;
            }
            // Links are kept in join order, and ids are handed out increasing (`VeCore::join`): a search.
            let Ok(at) = links.binary_search_by_key(&pending.user_id(), |l| l.user) else { continue };
            if !round.encode(at, pending.datagram()) {
                stats.snapshots_dropped += 1;
            }
        }
        clock.lap_less(&mut stages.encode, view_ns);
        stats.snapshots_dropped += round.push(links);
        clock.lap(&mut stages.ring_push);
        for (at, _) in round.frames().filter(|(at, _)| round.pushed[*at]) {
            links[at].link.notify.notify_one();
        }
        clock.lap(&mut stages.wake);
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
        clock.lap(&mut stages.events_record);
        if let Some(view) = io.view.as_mut() {
            view.after_tick(core, stats);
            stats.view_frames = view.published;
            stats.view_frames_dropped = view.dropped;
        }
        clock.lap_plus(&mut stages.view, view_ns);
        if let Some(room) = io.room.as_ref().filter(|_| self.iterations.is_multiple_of(self.room_every)) {
            room.publish(core);
        }
        self.histogram.record(woke.elapsed().as_nanos() as u64);
        clock.lap(&mut stages.stats);
        self.iterations += 1;
        if self.iterations.is_multiple_of(self.publish_every) {
            self.publish();
        }
    }

    /// Users in the VE now.
    pub fn users(&self) -> usize {
        self.links.len()
    }

    /// Copies the histograms' summaries, the core's counters and the thread's CPU use into the statistics,
    /// and pushes them out.
    fn publish(&mut self) {
        let stats = &mut self.stats;
        stats.step_time = self.histogram.summary();
        stats.stages = self.stages.summary();
        stats.core = self.core.metrics();
        let since_epoch = self.epoch.elapsed();
        stats.wall_s = since_epoch.as_secs_f64();
        let unix = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        stats.epoch_unix_s = unix.saturating_sub(since_epoch).as_secs_f64();
        stats.cpu_s = self.cpu_at_start.zip(thread_cpu_time()).map(|(a, b)| b.saturating_sub(a).as_secs_f64());
        let _ = self.io.stats.push(*stats);
    }

    /// Publishes the final statistics and returns them.
    pub fn finish(mut self) -> VeLoopStats {
        self.publish();
        self.stats
    }
}

/// Times consecutive stages: each lap records the time since the last.
struct StageClock {
    last: Instant,
}

impl StageClock {
    fn lap(&mut self, into: &mut LatencyHistogram) {
        self.lap_plus(into, 0);
    }

    /// A lap with `extra_ns` added (time another stage spent inside it, see `lap_less`).
    fn lap_plus(&mut self, into: &mut LatencyHistogram, extra_ns: u64) {
        let now = Instant::now();
        into.record(now.saturating_duration_since(self.last).as_nanos() as u64 + extra_ns);
        self.last = now;
    }

    /// A lap less `inner_ns` spent inside it on another stage's work.
    fn lap_less(&mut self, into: &mut LatencyHistogram, inner_ns: u64) {
        let now = Instant::now();
        into.record((now.saturating_duration_since(self.last).as_nanos() as u64).saturating_sub(inner_ns));
        self.last = now;
    }
}

/// One round's encoded snapshots, back to back in one buffer, with the link each is for: encoded in one pass,
/// pushed in the next, woken in a third. Its buffers grow to a round's size once and are reused.
struct Round {
    bytes: Vec<u8>,
    /// `(link index, end of its frame in bytes)`, in encoding order.
    ends: Vec<(usize, usize)>,
    /// Per link index: its frame went into its ring this round.
    pushed: Vec<bool>,
    /// One snapshot's encoding (as long as the largest datagram).
    scratch: Box<[u8]>,
}

impl Round {
    fn with_capacity(links: usize) -> Self {
        Round {
            bytes: Vec::new(),
            ends: Vec::with_capacity(links),
            pushed: Vec::with_capacity(links),
            scratch: vec![0; codec::limits::MAX_DATAGRAM_MESSAGE_BYTES].into_boxed_slice(),
        }
    }

    fn clear(&mut self) {
        self.bytes.clear();
        self.ends.clear();
    }

    /// Encodes a snapshot for link `at`; false when the codec refused it.
    fn encode(&mut self, at: usize, datagram: &kinloop_protocol::Datagram) -> bool {
        let Ok(len) = codec::encode_datagram_into_slice(datagram, &mut self.scratch) else { return false };
        self.bytes.extend_from_slice(&self.scratch[..len]);
        self.ends.push((at, self.bytes.len()));
        if self.pushed.len() <= at {
            self.pushed.resize(at + 1, false);
        }
        self.pushed[at] = true;
        true
    }

    /// Pushes each encoded frame into its link's ring; returns how many found their ring full (those links
    /// are not woken).
    fn push(&mut self, links: &mut [ActiveLink]) -> u64 {
        let mut dropped = 0;
        let mut start = 0;
        for &(at, end) in &self.ends {
            if !push_frame(&mut links[at].link.snapshots, &self.bytes[start..end]) {
                self.pushed[at] = false;
                dropped += 1;
            }
            start = end;
        }
        dropped
    }

    /// The mean length of the last round's frames (zero before the first).
    fn frame_len(&self) -> usize {
        self.bytes.len() / self.ends.len().max(1)
    }

    /// Each encoded frame with its link index.
    fn frames(&self) -> impl Iterator<Item = (usize, &[u8])> + '_ {
        let starts = std::iter::once(0).chain(self.ends.iter().map(|(_, end)| *end));
        self.ends.iter().zip(starts).map(|((at, end), start)| (*at, &self.bytes[start..*end]))
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
            Command::Join { request, round_trip, link, reply } => {
                let decision = core.join_measured(now, request, round_trip);
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
