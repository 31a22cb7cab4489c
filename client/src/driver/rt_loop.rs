//! The haptic loop thread: absolute deadlines `start + k·period`, spin-sleep, SCHED_FIFO when permitted.
//! Each tick: read the device, take the snapshots waiting in the ring, tick the core, command the device,
//! hand the uplink and the record row to other threads through rings. No lock, no allocation, no IO, no
//! log line per tick; buffers that must be freed go back through return rings to be dropped elsewhere.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::Thread;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;
use kinloop_process::realtime::try_realtime_priority;
use kinloop_protocol::{Snapshot, Uplink};

use super::record::TickRecord;
use super::timing::{LatenessHistogram, LatenessSummary};
use crate::core::{CoreStats, HapticCore};
use crate::device::{DeviceError, HapticDevice};

/// State the loop shares with the rest of the client, all atomics.
#[derive(Debug, Default)]
pub struct LoopShared {
    /// Lateness histogram.
    pub lateness: LatenessHistogram,
    /// Set to stop the loop (by the handle, or by the loop itself at the end of its duration).
    pub stop: AtomicBool,
    /// One-way delay estimate (ns) from the network side's RTT measurements.
    pub one_way_delay_ns: AtomicU64,
    /// Largest force ratio over every session (f64 bits).
    pub max_force_ratio_bits: AtomicU64,
    /// Uplinks dropped because the network side fell behind.
    pub uplinks_dropped: AtomicU64,
    /// Record rows dropped because the writer fell behind.
    pub records_dropped: AtomicU64,
    /// Recoverable device errors.
    pub device_force_errors: AtomicU64,
    /// Set when the device failed for good.
    pub device_lost: AtomicBool,
    /// Nanoseconds since the loop started, at its last tick.
    pub elapsed_ns: AtomicU64,
    /// Set by the network side when it loses its server; cleared by the loop when the next session's core
    /// takes over (the record marks the ticks in between as session 0).
    pub between_servers: AtomicBool,
    /// The loop's time zero on the system clock (ns since the Unix epoch), set at its first tick (0 before):
    /// what a record's times count from, for a reader that lines them up with another program's.
    pub epoch_unix_ns: AtomicU64,
}

impl LoopShared {
    /// Takes a round trip measured by the network side: the loop's core predicts by half of it.
    pub fn set_round_trip(&self, rtt: Duration) {
        self.one_way_delay_ns.store(u64::try_from(rtt.as_nanos() / 2).unwrap_or(u64::MAX), Ordering::Relaxed);
    }

    /// Largest `|F| / F_max` commanded so far.
    pub fn max_force_ratio(&self) -> f64 {
        f64::from_bits(self.max_force_ratio_bits.load(Ordering::Relaxed))
    }
}

/// A periodic report to the logging side.
#[derive(Clone, Copy, Debug)]
pub struct LoopReport {
    /// Time since start.
    pub elapsed: Duration,
    /// The current session's core counters.
    pub core: CoreStats,
    /// Constrained directions now.
    pub constraint_count: usize,
    /// Output gain now.
    pub gain: f64,
    /// Age of the snapshot in use.
    pub snapshot_age: Option<Duration>,
}

/// The loop's ends of the rings.
pub struct LoopRings<S: Space> {
    /// Snapshots from the network, each with when it arrived.
    pub snapshots: rtrb::Consumer<(Instant, Snapshot)>,
    /// Used snapshots back to the network side, to be dropped there.
    pub spent_snapshots: rtrb::Producer<Snapshot>,
    /// Uplinks to send.
    pub uplinks: rtrb::Producer<Uplink>,
    /// Empty uplink buffers to fill.
    pub free_uplinks: rtrb::Consumer<Uplink>,
    /// A new core for a new session.
    pub cores: rtrb::Consumer<Box<HapticCore<S>>>,
    /// Replaced cores, to be dropped by the network side.
    pub spent_cores: rtrb::Producer<Box<HapticCore<S>>>,
    /// Rows for `--record`.
    pub records: Option<rtrb::Producer<TickRecord>>,
    /// Periodic reports.
    pub reports: rtrb::Producer<LoopReport>,
    /// The thread that sends uplinks (unparked after each push).
    pub uplink_sender: Option<Thread>,
}

/// Loop settings.
#[derive(Clone, Copy, Debug)]
pub struct LoopSettings {
    /// Tick rate (Hz).
    pub rate_hz: f64,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Try SCHED_FIFO.
    pub realtime_priority: bool,
    /// Spin for the last stretch before each deadline (spin_sleep's default); false sleeps only. A spinning
    /// loop keeps its deadlines to a microsecond but takes about an eighth of a core: many loops on one
    /// small machine (the demo's 16 users on 2 cores) would take all of it, and their network threads would
    /// starve.
    pub busy_wait: bool,
    /// Ticks between reports.
    pub report_every: u64,
}

/// Runs the loop until `shared.stop`, the duration, or a lost device; returns the last core's counters.
pub fn run<S: Space, D: HapticDevice<S>>(
    device: D,
    core: Box<HapticCore<S>>,
    rings: LoopRings<S>,
    shared: Arc<LoopShared>,
    settings: LoopSettings,
) -> CoreStats {
    if settings.realtime_priority {
        if let Err(why) = try_realtime_priority() {
            tracing::warn!(%why, "could not switch the haptic loop to SCHED_FIFO; running at normal priority");
        }
    }
    let mut ticker = Ticker::new(settings.rate_hz, settings.busy_wait);
    let mut body = LoopBody::new(device, core, rings, shared.clone(), settings);
    loop {
        let now = ticker.wait(&shared.lateness);
        match body.step(now) {
            Flow::Continue => {}
            Flow::Stop(None) => break,
            Flow::Stop(Some(e)) => {
                // Said once: the loop ends here.
                tracing::error!("{e}; the loop stops");
                break;
            }
        }
        ticker.advance();
    }
    body.finish(ticker.start.elapsed())
}

/// What a tick tells its clock.
pub enum Flow {
    /// Call again next tick.
    Continue,
    /// The loop ends: asked to, its duration is over, or the device failed (the error, for the clock's
    /// thread to say: a device-clocked tick never logs).
    Stop(Option<DeviceError>),
}

/// One tick's work, whichever clock calls it: kinloop's own loop ([`run`]) or the vendor's servo thread
/// (`super::device_clock`). Read the device, take the snapshots waiting in the ring, tick the core, command
/// the device, hand the uplink and the record row on; no lock, no allocation, no IO, no log line.
pub struct LoopBody<S: Space, D: HapticDevice<S>> {
    /// The device.
    pub device: D,
    core: Box<HapticCore<S>>,
    rings: LoopRings<S>,
    shared: Arc<LoopShared>,
    settings: LoopSettings,
    ticks: u64,
    /// The last tick's time (since the loop started).
    last_tick: Duration,
    /// The session whose core renders: 1 for the first, one more for each that took over.
    session: u32,
}

impl<S: Space, D: HapticDevice<S>> LoopBody<S, D> {
    /// A loop body for `device` and the session's `core`.
    pub fn new(
        device: D,
        core: Box<HapticCore<S>>,
        rings: LoopRings<S>,
        shared: Arc<LoopShared>,
        settings: LoopSettings,
    ) -> Self {
        LoopBody { device, core, rings, shared, settings, ticks: 0, last_tick: Duration::ZERO, session: 1 }
    }

    /// What the loop shares with the rest of its client.
    pub fn shared(&self) -> &LoopShared {
        &self.shared
    }

    /// One tick at `now` (time since the loop started).
    pub fn step(&mut self, now: Duration) -> Flow {
        let (rings, shared, core, session) = (&mut self.rings, &self.shared, &mut self.core, &mut self.session);
        shared.elapsed_ns.store(now.as_nanos() as u64, Ordering::Relaxed);
        if self.ticks == 0 && shared.epoch_unix_ns.load(Ordering::Relaxed) == 0 {
            shared.epoch_unix_ns.store(unix_ns_at(now), Ordering::Relaxed);
        }
        if shared.stop.load(Ordering::Relaxed) || self.settings.duration.is_some_and(|d| now >= d) {
            return Flow::Stop(None);
        }
        self.ticks += 1;
        let last_tick = std::mem::replace(&mut self.last_tick, now);
        // A new session's core replaces the old one, which goes back to be dropped off this thread; not before
        // the old one has faded out (a server that drains says so at once, and the old core may still push),
        // so the force never steps from the old session's to the new one's zero.
        while core.output_gain() == 0.0 {
            let Ok(next) = rings.cores.pop() else { break };
            *session += 1;
            shared.between_servers.store(false, Ordering::Relaxed);
            let old = std::mem::replace(core, next);
            if let Err(rtrb::PushError::Full(old)) = rings.spent_cores.push(old) {
                // The network side is not collecting: keep the old core alive rather than free it here.
                std::mem::forget(old);
            }
        }
        core.set_one_way_delay(Duration::from_nanos(shared.one_way_delay_ns.load(Ordering::Relaxed)));
        // While the next session's core waits for the old one to fade, the new server's snapshots wait for it.
        while rings.cores.is_empty() {
            let Ok((arrived, snapshot)) = rings.snapshots.pop() else { break };
            // Dated at its arrival, as in virtual time, so that the age the uplinks report leaves the network's
            // round trip to the VE without this loop's wait for its tick; it came after the last tick emptied
            // the ring. Refused snapshots are counted by the core.
            let received = now.saturating_sub(arrived.elapsed()).max(last_tick).min(now);
            let _ = core.handle_snapshot(received, &snapshot);
            if let Err(rtrb::PushError::Full(snapshot)) = rings.spent_snapshots.push(snapshot) {
                std::mem::forget(snapshot);
            }
        }
        let state = match self.device.read(now) {
            Ok(state) => state,
            Err(e) if e.is_fatal() => {
                shared.device_lost.store(true, Ordering::Relaxed);
                return Flow::Stop(Some(e));
            }
            Err(_) => {
                shared.device_force_errors.fetch_add(1, Ordering::Relaxed);
                return Flow::Continue;
            }
        };
        let out = core.tick(now, &state);
        if let Err(e) = self.device.command(now, &out.command) {
            if e.is_fatal() {
                shared.device_lost.store(true, Ordering::Relaxed);
                return Flow::Stop(Some(e));
            }
            shared.device_force_errors.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(uplink) = out.uplink {
            match rings.free_uplinks.pop() {
                Ok(mut buffer) => {
                    // Same lengths as the buffers were made with: clone_from copies without allocating.
                    buffer.clone_from(uplink);
                    if rings.uplinks.push(buffer).is_err() {
                        shared.uplinks_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    if let Some(sender) = &rings.uplink_sender {
                        sender.unpark();
                    }
                }
                Err(_) => {
                    shared.uplinks_dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if let Some(records) = rings.records.as_mut() {
            let mut row = super::record::tick_record(out.report);
            row.session = if shared.between_servers.load(Ordering::Relaxed) { 0 } else { *session };
            if records.push(row).is_err() {
                shared.records_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
        let stats = core.stats();
        shared.max_force_ratio_bits.fetch_max(stats.max_force_ratio.to_bits(), Ordering::Relaxed);
        if self.ticks.is_multiple_of(self.settings.report_every.max(1)) {
            let report = core.report();
            let _ = rings.reports.push(LoopReport {
                elapsed: now,
                core: stats,
                constraint_count: report.constraint_count,
                gain: report.gain,
                snapshot_age: report.snapshot_age,
            });
        }
        Flow::Continue
    }

    /// The end: zero commanded, the loop marked stopped; the last core's counters.
    pub fn finish(mut self, now: Duration) -> CoreStats {
        let _ = self.device.command(now, &zero::<S>());
        self.shared.stop.store(true, Ordering::Relaxed);
        self.core.stats()
    }
}

/// The loop's clock: absolute deadlines `start + k·period` (no drift), reached by spin_sleep (a native
/// sleep, then a spin for the last stretch), each tick's lateness recorded.
struct Ticker {
    sleeper: spin_sleep::SpinSleeper,
    start: Instant,
    period: Duration,
    /// Index of the current tick.
    tick: u64,
}

impl Ticker {
    fn new(rate_hz: f64, busy_wait: bool) -> Self {
        Ticker {
            sleeper: if busy_wait { spin_sleep::SpinSleeper::default() } else { spin_sleep::SpinSleeper::new(0) },
            start: Instant::now(),
            period: Duration::from_secs_f64(1.0 / rate_hz),
            tick: 0,
        }
    }

    /// Sleeps until the current tick's deadline, records how late it woke, and returns the time since the
    /// start.
    fn wait(&mut self, lateness: &LatenessHistogram) -> Duration {
        let deadline = self.start + Duration::from_nanos(self.period.as_nanos() as u64 * self.tick);
        self.sleeper.sleep_until(deadline);
        let woke = Instant::now();
        lateness.record(woke.saturating_duration_since(deadline).as_nanos() as u64);
        woke - self.start
    }

    /// On to the next tick, skipping deadlines already missed rather than running a burst of late ticks.
    fn advance(&mut self) {
        self.tick += 1;
        let behind = (Instant::now().saturating_duration_since(self.start).as_nanos() / self.period.as_nanos()) as u64;
        self.tick = self.tick.max(behind);
    }
}

/// The floor under the loop's timing on this machine: the same clock, priority and sleep as [`run`] with no
/// work in the ticks, for `duration` at `rate_hz`. What it measures is the operating system's and the
/// hypervisor's share of the lateness, which no change to the loop's work can remove. Returns the lateness
/// and whether SCHED_FIFO was granted.
pub fn timer_floor(rate_hz: f64, duration: Duration, realtime_priority: bool) -> (LatenessSummary, bool) {
    timer_floor_after(rate_hz, Duration::ZERO, duration, realtime_priority)
}

/// [`timer_floor`] counted after `warm_up` of the same loop, uncounted. The loop runs on a thread of its own
/// that ends with it: raised to SCHED_FIFO, the caller's thread would stay there, and every thread and
/// process it started afterwards would inherit the policy (a server's quarantine, a load process's every
/// thread), competing with the real-time loops the floor is measured for.
pub fn timer_floor_after(
    rate_hz: f64,
    warm_up: Duration,
    duration: Duration,
    realtime_priority: bool,
) -> (LatenessSummary, bool) {
    std::thread::scope(|scope| {
        scope
            .spawn(|| {
                let fifo = realtime_priority && try_realtime_priority().is_ok();
                if !warm_up.is_zero() {
                    paced(rate_hz, warm_up, |_| {});
                }
                (paced(rate_hz, duration, |_| {}), fifo)
            })
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// Calls `tick` (with the time since the start) at `rate_hz` for `duration` on the loop's own clock (absolute
/// deadlines, spin_sleep), as [`run`] paces the haptic loop; returns the ticks' lateness. For work outside a
/// session that must run at the loop's rate, such as `kinloop devices --check` reading a device.
pub fn paced(rate_hz: f64, duration: Duration, mut tick: impl FnMut(Duration)) -> LatenessSummary {
    let lateness = LatenessHistogram::default();
    let mut ticker = Ticker::new(rate_hz, true);
    loop {
        let now = ticker.wait(&lateness);
        if now >= duration {
            break;
        }
        tick(now);
        ticker.advance();
    }
    lateness.summary()
}

/// The system clock's reading (ns since the Unix epoch) `since` ago: a clock's time zero, read once (the
/// system clock is read through the vDSO, without blocking).
pub fn unix_ns_at(since: Duration) -> u64 {
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    u64::try_from(now.saturating_sub(since).as_nanos()).unwrap_or(u64::MAX)
}

fn zero<S: Space>() -> S::OpVec {
    <S::OpVec as kinloop_linkage::math::space::VecOps>::zero()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Measuring the floor at SCHED_FIFO leaves the caller's thread at the policy it had, and counts the
    /// ticks of the counted part only.
    #[test]
    fn the_timer_floor_leaves_its_callers_policy_as_it_was() {
        std::thread::spawn(|| {
            let before = kinloop_process::realtime::runs_realtime();
            let (lateness, _) = timer_floor_after(1000.0, Duration::from_millis(30), Duration::from_millis(50), true);
            assert_eq!(kinloop_process::realtime::runs_realtime(), before, "the caller's policy changed");
            assert!(!before, "a fresh thread starts at the normal policy");
            // The warm-up counted too would make about 80.
            assert!((1..=55).contains(&lateness.ticks), "{} ticks counted in 50 ms at 1 kHz", lateness.ticks);
        })
        .join()
        .expect("the probe thread");
    }
}
