//! The device-clocked loop: the vendor's servo thread owns the clock and calls kinloop's tick once per
//! servo tick (OpenHaptics' `hdScheduleAsynchronous` + `hdStartScheduler`), running the same
//! [`LoopBody`] as kinloop's own loop ([`super::rt_loop::run`]), so nothing in the core knows which clock
//! it runs on.
//!
//! The callback never blocks, allocates or logs on its normal path (the body does not; an ending device's
//! message is formatted once, at the end). A panic inside it is caught (`catch_unwind`: unwinding out of an
//! `extern "system"` function aborts the process, which would skip `hdDisableDevice`) and ends in zero
//! force and the callback unscheduled. The thread that started the scheduler waits beside it: it stops the
//! scheduler when the body ends, when the client is stopped, or when the scheduler stops calling back
//! ([`SILENT_LIMIT`]: the device then holds no force of kinloop's, see `hd::device`), then says what
//! happened, and drops the device, which disables it.
//!
//! Lateness, for the same histogram kinloop's loop fills: how far each callback came after one period
//! from the one before ([`Beats`]). [`check`] measures it with no session: a callback that only reads the
//! device, forces off (`kinloop devices --check`).

use std::ffi::{c_uint, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;

use super::rt_loop::{Flow, LoopBody, LoopRings, LoopSettings, LoopShared};
use super::timing::{LatenessHistogram, LatenessSummary};
use crate::core::{CoreStats, HapticCore};
use crate::device::hd::library::constants;
use crate::device::hd::{HdDevice, HdLibrary, OpenedHd};
use crate::device::DeviceError;

/// A scheduler that has not called back for this long has stopped: the client ends.
pub const SILENT_LIMIT: Duration = Duration::from_millis(500);
/// How often the waiting thread looks.
const WATCH: Duration = Duration::from_millis(5);

/// What the callback and the waiting thread share (atomics only).
#[derive(Default)]
struct Beat {
    /// Nanoseconds since the start at the last callback.
    last_ns: AtomicU64,
    /// The body ended (asked, duration, or a device error).
    ended: AtomicBool,
    /// The callback panicked.
    panicked: AtomicBool,
}

/// The callbacks' clock: time since the first, and each callback's lateness after one period from the one
/// before.
struct Beats {
    start: Instant,
    period_ns: u64,
    previous_ns: Option<u64>,
}

impl Beats {
    fn new(rate_hz: f64) -> Beats {
        Beats { start: Instant::now(), period_ns: (1e9 / rate_hz) as u64, previous_ns: None }
    }

    /// A callback now: its time since the start, its lateness recorded in `lateness`.
    fn beat(&mut self, lateness: &LatenessHistogram) -> Duration {
        let now = self.start.elapsed();
        let ns = now.as_nanos() as u64;
        if let Some(previous) = self.previous_ns {
            lateness.record(ns.saturating_sub(previous + self.period_ns));
        }
        self.previous_ns = Some(ns);
        now
    }
}

/// The callback's own state, used only by the servo thread while scheduled.
struct Clocked<S: Space> {
    body: LoopBody<S, HdDevice<S>>,
    beats: Beats,
    beat: Arc<Beat>,
    shared: Arc<LoopShared>,
    /// The device error that ended the body, for the waiting thread to say.
    error: Option<DeviceError>,
}

impl<S: Space> Clocked<S> {
    fn tick(&mut self) -> c_uint {
        let now = self.beats.beat(&self.shared.lateness);
        self.beat.last_ns.store(now.as_nanos() as u64, Ordering::Relaxed);
        match self.body.step(now) {
            Flow::Continue => constants::CALLBACK_CONTINUE,
            Flow::Stop(error) => {
                self.error = error;
                self.body.device.zero_now();
                self.beat.ended.store(true, Ordering::Release);
                constants::CALLBACK_DONE
            }
        }
    }
}

/// The servo thread's entry: one tick, panics caught.
unsafe extern "system" fn servo_tick<S: Space>(data: *mut c_void) -> c_uint {
    // SAFETY: `data` is the `Clocked<S>` `run` scheduled and keeps alive, used by nothing else while the
    // scheduler may call this (see `run`).
    let clocked = unsafe { &mut *data.cast::<Clocked<S>>() };
    match catch_unwind(AssertUnwindSafe(|| clocked.tick())) {
        Ok(code) => code,
        Err(_) => {
            let beat = clocked.beat.clone();
            // Zero force even if the body is half-way through a tick; a second panic is caught too.
            let _ = catch_unwind(AssertUnwindSafe(|| clocked.body.device.zero_now()));
            beat.panicked.store(true, Ordering::Release);
            beat.ended.store(true, Ordering::Release);
            constants::CALLBACK_DONE
        }
    }
}

/// Runs the session's core in the vendor's servo thread until it ends (see the module documentation);
/// returns the last core's counters.
pub fn run<S: Space>(
    opened: OpenedHd,
    core: Box<HapticCore<S>>,
    rings: LoopRings<S>,
    shared: Arc<LoopShared>,
    settings: LoopSettings,
) -> CoreStats {
    let library = opened.library();
    let device = opened.into_device::<S>();
    let beat = Arc::new(Beat::default());
    let beats = Beats::new(settings.rate_hz);
    let mut clocked = Box::new(Clocked {
        body: LoopBody::new(device, core, rings, shared.clone(), settings),
        beats,
        beat: beat.clone(),
        shared: shared.clone(),
        error: None,
    });
    let data: *mut Clocked<S> = &mut *clocked;
    // SAFETY: `clocked` outlives the schedule: it is dropped only after hdStopScheduler and hdUnschedule
    // returned below, and this thread does not touch it until then (it watches `beat` alone).
    let handle = unsafe { library.schedule(servo_tick::<S>, data.cast(), constants::MAX_SCHEDULER_PRIORITY) };
    library.start_scheduler();
    if let Some(e) = library.error() {
        tracing::error!("the HD servo scheduler did not start: {}", library.describe(e));
        beat.ended.store(true, Ordering::Release);
    }
    let started = Instant::now();
    while !beat.ended.load(Ordering::Acquire) && !shared.stop.load(Ordering::Relaxed) {
        std::thread::sleep(WATCH);
        // This thread may wake long after the body ended (a loaded host): an ended body is no silence.
        if beat.ended.load(Ordering::Acquire) {
            break;
        }
        let last = Duration::from_nanos(beat.last_ns.load(Ordering::Relaxed));
        let since = started.elapsed().saturating_sub(last);
        if since > SILENT_LIMIT {
            tracing::error!(
                "the HD servo scheduler has not called kinloop for {} ms; the device holds no force of kinloop's, \
                 and the client stops",
                since.as_millis()
            );
            shared.device_lost.store(true, Ordering::Relaxed);
            break;
        }
    }
    library.stop_scheduler();
    library.unschedule(handle);
    let _ = library.error();
    if beat.panicked.load(Ordering::Acquire) {
        tracing::error!("kinloop's tick panicked inside the HD servo callback; force zeroed, the loop stops");
        shared.device_lost.store(true, Ordering::Relaxed);
    }
    if let Some(e) = clocked.error.take() {
        tracing::error!("{e}; the loop stops");
    }
    let now = clocked.beats.start.elapsed();
    let Clocked { body, .. } = *clocked;
    body.finish(now)
}

/// What [`check`] measured.
#[derive(Clone, Copy, Debug)]
pub struct ServoCheck {
    /// The callbacks' lateness, as a session's loop measures it.
    pub lateness: LatenessSummary,
    /// Frames whose position read back finite.
    pub reads: u64,
    /// Frames that raised an HD error or read a non-finite position.
    pub failed_reads: u64,
}

/// A reading callback's state (see [`check`]).
struct Probe {
    library: &'static HdLibrary,
    handle: c_uint,
    beats: Beats,
    lateness: LatenessHistogram,
    duration: Duration,
    reads: u64,
    failed_reads: u64,
    /// The callback returned `HD_CALLBACK_DONE` (read by the waiting thread).
    done: AtomicBool,
}

/// The servo thread's entry for [`check`]: a frame that reads the position and commands nothing.
unsafe extern "system" fn probe_tick(data: *mut c_void) -> c_uint {
    // SAFETY: `data` is the `Probe` `check` scheduled and keeps alive until the scheduler has stopped.
    let probe = unsafe { &mut *data.cast::<Probe>() };
    let now = probe.beats.beat(&probe.lateness);
    let mut p = [f64::NAN; 3];
    probe.library.begin_frame(probe.handle);
    probe.library.get_doubles(constants::CURRENT_POSITION, &mut p);
    probe.library.end_frame(probe.handle);
    if probe.library.error().is_none() && p.iter().all(|x| x.is_finite()) {
        probe.reads += 1;
    } else {
        probe.failed_reads += 1;
    }
    if now >= probe.duration {
        probe.done.store(true, Ordering::Release);
        constants::CALLBACK_DONE
    } else {
        constants::CALLBACK_CONTINUE
    }
}

/// Runs a callback on `opened`'s servo thread for `duration` (at most twice that, if the scheduler stops
/// calling back), with force output as it was (off, from [`OpenedHd::describe`]): each callback reads the
/// position in a frame, and its lateness is recorded as a session's loop records it at `rate_hz`.
pub fn check(opened: &OpenedHd, rate_hz: f64, duration: Duration) -> ServoCheck {
    let library = opened.library();
    let mut probe = Box::new(Probe {
        library,
        handle: opened.handle(),
        beats: Beats::new(rate_hz),
        lateness: LatenessHistogram::default(),
        duration,
        reads: 0,
        failed_reads: 0,
        done: AtomicBool::new(false),
    });
    let data: *mut Probe = &mut *probe;
    // SAFETY: `probe` outlives the schedule (dropped after hdStopScheduler and hdUnschedule below), and this
    // thread does not touch it until then.
    let handle = unsafe { library.schedule(probe_tick, data.cast(), constants::MAX_SCHEDULER_PRIORITY) };
    library.start_scheduler();
    let started = Instant::now();
    // SAFETY: `done` is an atomic, shared with the callback by design; nothing else of `probe` is read here.
    let done = unsafe { &(*data).done };
    while !done.load(Ordering::Acquire) && started.elapsed() < duration * 2 {
        std::thread::sleep(WATCH);
    }
    library.stop_scheduler();
    library.unschedule(handle);
    let _ = library.error();
    ServoCheck { lateness: probe.lateness.summary(), reads: probe.reads, failed_reads: probe.failed_reads }
}
