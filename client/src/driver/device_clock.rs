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
//! from the one before.

use std::ffi::{c_uint, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;

use super::rt_loop::{Flow, LoopBody, LoopRings, LoopSettings, LoopShared};
use crate::core::{CoreStats, HapticCore};
use crate::device::hd::library::constants;
use crate::device::hd::{HdDevice, OpenedHd};
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

/// The callback's own state, used only by the servo thread while scheduled.
struct Clocked<S: Space> {
    body: LoopBody<S, HdDevice<S>>,
    start: Instant,
    period_ns: u64,
    previous_ns: Option<u64>,
    beat: Arc<Beat>,
    shared: Arc<LoopShared>,
    /// The device error that ended the body, for the waiting thread to say.
    error: Option<DeviceError>,
}

impl<S: Space> Clocked<S> {
    fn tick(&mut self) -> c_uint {
        let now = self.start.elapsed();
        let ns = now.as_nanos() as u64;
        if let Some(previous) = self.previous_ns {
            self.shared.lateness.record(ns.saturating_sub(previous + self.period_ns));
        }
        self.previous_ns = Some(ns);
        self.beat.last_ns.store(ns, Ordering::Relaxed);
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
    let period_ns = (1e9 / settings.rate_hz) as u64;
    let mut clocked = Box::new(Clocked {
        body: LoopBody::new(device, core, rings, shared.clone(), settings),
        start: Instant::now(),
        period_ns,
        previous_ns: None,
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
    let now = clocked.start.elapsed();
    let Clocked { body, .. } = *clocked;
    body.finish(now)
}
