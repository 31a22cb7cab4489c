//! A fake OpenHaptics HD library (`libHD`): the C symbols of `HD/hdDevice.h` and `HD/hdScheduler.h`
//! (OpenHaptics 3.x) that kinloop loads, with the same signatures and calling convention (`HDAPIENTRY` and
//! `HDCALLBACK` are `__stdcall` on Windows, hence `extern "system"`), behind a servo thread and a plant of
//! its own ([`plant`], in the vendor's millimetres). Written for kinloop's tests and tools only; it shares
//! no code with kinloop's simulated devices.
//!
//! As the vendor's library does, it owns the clock: `hdStartScheduler` starts a servo thread that, every
//! millisecond, advances the plant and calls each callback `hdScheduleAsynchronous` registered, until the
//! callback returns `HD_CALLBACK_DONE` or `hdUnschedule` removes it. The servo thread is paced as the
//! device's is (OpenHaptics' scheduler runs its servo loop in a high-priority thread at the device's own
//! 1 kHz): it asks for real-time priority (SCHED_FIFO, where the system grants it; otherwise it runs at
//! normal priority), and a tick it missed is lost, never made up by a burst of late ticks (a device's
//! servo exchange cannot happen in the past; see [`next_tick`]). A force set in a frame
//! (`hdSetDoublev(HD_CURRENT_FORCE)` between `hdBeginFrame` and `hdEndFrame`) is output from the frame's end.
//! A stalled servo loop: OpenHaptics' headers do not say what the device does when no frame ends; the fake
//! takes the conservative reading, that the amplifiers hold a force for [`FORCE_HOLD`] after the last frame
//! and output zero after it (the record says `O hold`).
//!
//! Configured by environment variables, read by `hdInitDevice`:
//! - `FAKE_HD_HAND`: `soft`, `firm` or `none` (default soft; see [`plant::Grasp`]);
//! - `FAKE_HD_TOUR`: waypoints `X,Y,Z;X,Y,Z;...` in millimetres, the device's frame (x right, y up, z
//!   towards the user); the stylus starts at the first, and the hand sets off at the first frame;
//! - `FAKE_HD_BUTTON`: `FROM:UNTIL`, seconds after the first frame: button 1 is held over that span;
//! - `FAKE_HD_VERSION`: what `hdGetString(HD_VERSION)` answers (default `3.4.0`; `none`: a null string);
//! - `FAKE_HD_CALIBRATION`: `update` makes `hdCheckCalibration` answer `HD_CALIBRATION_NEEDS_UPDATE` until
//!   `hdUpdateCalibration` runs;
//! - `FAKE_HD_FAULT`: `init` (`hdInitDevice` fails with `HD_COMM_ERROR`), `lost:N` (from the N-th frame on,
//!   every frame fails with `HD_COMM_ERROR` and no force is output: the device is gone), `nan:N` (the N-th
//!   frame's position is NaN), `stall:N:MS` (the servo thread stops for MS milliseconds at its N-th tick);
//! - `FAKE_HD_RECORD`: a file that receives a line per event: `F T FX FY FZ` for each force a frame
//!   outputs (T seconds since init), `E 0|1` for `HD_FORCE_OUTPUT`, `B 0|1` when button 1 changes, `A` for
//!   `hdUpdateCalibration`, `X lost|nan|stall` when a fault strikes, `O hold` when a held force runs out,
//!   `D` when the device is disabled.
//!
//! A value that does not parse makes `hdInitDevice` fail: a test's typo is never a silent default.

pub mod plant;

use std::ffi::{c_char, c_int, c_uint, c_ulong, c_ushort, c_void, CStr, CString};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use plant::{Grasp, Plant};

/// `HHD`, `HDenum`, `HDerror` are `unsigned int`; `HDSchedulerHandle` is `unsigned long` (`hdDefines.h`,
/// `hdScheduler.h`).
type Hhd = c_uint;
/// `HDCallbackCode (HDCALLBACK *HDSchedulerCallback)(void *pUserData)`.
type Callback = unsafe extern "system" fn(*mut c_void) -> c_uint;

/// `HDErrorInfo`: `{ HDerror errorCode; int internalErrorCode; HHD hHD; }`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ErrorInfo {
    /// `HD_*` error code.
    pub error_code: c_uint,
    /// The device's own code.
    pub internal_error_code: c_int,
    /// The device.
    pub hhd: Hhd,
}

// Constants of `hdDefines.h` (OpenHaptics 3.x).
const HD_SUCCESS: c_uint = 0x0000;
const HD_INVALID_ENUM: c_uint = 0x0100;
const HD_BAD_HANDLE: c_uint = 0x0104;
const HD_EXCEEDED_MAX_FORCE: c_uint = 0x0201;
const HD_COMM_ERROR: c_uint = 0x0302;
const HD_COMM_CONFIG_ERROR: c_uint = 0x0303;
const HD_ILLEGAL_BEGIN: c_uint = 0x0400;
const HD_ILLEGAL_END: c_uint = 0x0401;
const HD_CURRENT_BUTTONS: c_uint = 0x2000;
const HD_CURRENT_INKWELL_SWITCH: c_uint = 0x2002;
const HD_CURRENT_POSITION: c_uint = 0x2050;
const HD_CURRENT_VELOCITY: c_uint = 0x2051;
const HD_VERSION: c_uint = 0x2500;
const HD_DEVICE_MODEL_TYPE: c_uint = 0x2501;
const HD_USABLE_WORKSPACE_DIMENSIONS: c_uint = 0x2551;
const HD_OUTPUT_DOF: c_uint = 0x2554;
const HD_UPDATE_RATE: c_uint = 0x2600;
const HD_NOMINAL_MAX_STIFFNESS: c_uint = 0x2602;
const HD_NOMINAL_MAX_FORCE: c_uint = 0x2603;
const HD_NOMINAL_MAX_CONTINUOUS_FORCE: c_uint = 0x2604;
const HD_NOMINAL_MAX_DAMPING: c_uint = 0x2609;
const HD_CURRENT_FORCE: c_uint = 0x2700;
const HD_FORCE_OUTPUT: c_uint = 0x4000;
const HD_CALIBRATION_OK: c_uint = 0x5000;
const HD_CALIBRATION_NEEDS_UPDATE: c_uint = 0x5001;
const HD_INVALID_HANDLE: Hhd = 0xFFFF_FFFF;
const HD_CALLBACK_DONE: c_uint = 0;

/// The handle of the one device this library serves.
const HANDLE: Hhd = 0;
/// The servo period (1 kHz, the Touch's).
const SERVO_PERIOD: Duration = Duration::from_millis(1);
/// How long the amplifiers hold a force after the last frame ended (see the module documentation).
pub const FORCE_HOLD: Duration = Duration::from_millis(5);
/// The servo thread's SCHED_FIFO priority, when granted (below kinloop's own loop's 80: the servo thread is
/// the vendor's, not kinloop's).
const SERVO_PRIORITY: u8 = 70;

/// The Touch's figures as the device reports them (`shared/haptics-facts.md`): 3.3 N peak, 0.88 N
/// continuous (OpenHaptics' figure), 0.4 N/mm and 0.004 N s/mm rendered stably, a usable workspace of
/// 160 x 120 x 70 mm about its centre.
const MAX_FORCE_N: f64 = 3.3;
const CONTINUOUS_FORCE_N: f64 = 0.88;
const STIFFNESS_N_PER_MM: f64 = 0.4;
const DAMPING_N_S_PER_MM: f64 = 0.004;
const HALF_EXTENT_MM: [f64; 3] = [80.0, 60.0, 35.0];
static MODEL: &[u8] = b"Touch (fake)\0";

#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    None,
    Init,
    Lost(u64),
    NotANumber(u64),
    Stall(u64, Duration),
}

fn fault_from(text: &str) -> Option<Fault> {
    let mut parts = text.split(':');
    let kind = parts.next()?;
    let mut number = || parts.next().map(|n| n.parse::<u64>().ok());
    Some(match kind {
        "init" => Fault::Init,
        "lost" => Fault::Lost(number()??),
        "nan" => Fault::NotANumber(number()??),
        "stall" => {
            let n = number()??;
            Fault::Stall(n, Duration::from_millis(number()??))
        }
        _ => return None,
    })
}

/// The device.
struct Device {
    fault: Fault,
    plant: Plant,
    opened: Instant,
    last_step: Instant,
    frames: u64,
    in_frame: bool,
    forces_enabled: bool,
    /// The force set in the current frame, and the one the amplifiers output.
    pending: [f64; 3],
    output: [f64; 3],
    /// When the last frame ended (the output holds for FORCE_HOLD after).
    last_end: Instant,
    held_out: bool,
    lost: bool,
    button_span: Option<(f64, f64)>,
    button: bool,
    calibrated: bool,
    /// `hdGetString(HD_VERSION)`'s answer (None: null).
    version: Option<CString>,
    record: Option<std::io::BufWriter<std::fs::File>>,
}

static DEVICE: Mutex<Option<Device>> = Mutex::new(None);
static ERRORS: Mutex<Vec<ErrorInfo>> = Mutex::new(Vec::new());

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

fn push_error(code: c_uint) {
    lock(&ERRORS).push(ErrorInfo { error_code: code, internal_error_code: 0, hhd: HANDLE });
}

fn parse_waypoints(text: &str) -> Option<Vec<[f64; 3]>> {
    text.split(';')
        .map(|p| {
            let v: Vec<f64> = p.split(',').map(|x| x.trim().parse().ok()).collect::<Option<_>>()?;
            (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| [v[0], v[1], v[2]])
        })
        .collect()
}

impl Device {
    fn init() -> Result<Device, c_uint> {
        let fault = match env("FAKE_HD_FAULT") {
            Some(text) => fault_from(&text).ok_or(HD_COMM_CONFIG_ERROR)?,
            None => Fault::None,
        };
        if fault == Fault::Init {
            return Err(HD_COMM_ERROR);
        }
        let tour = match env("FAKE_HD_TOUR") {
            Some(text) => parse_waypoints(&text).ok_or(HD_COMM_CONFIG_ERROR)?,
            None => vec![[0.0; 3]],
        };
        let hand = match env("FAKE_HD_HAND").as_deref() {
            Some("none") => None,
            Some("firm") => Some((Grasp::FIRM, tour)),
            Some("soft") | None => Some((Grasp::SOFT, tour)),
            Some(_) => return Err(HD_COMM_CONFIG_ERROR),
        };
        let button_span = match env("FAKE_HD_BUTTON") {
            Some(text) => {
                let (from, until) = text.split_once(':').ok_or(HD_COMM_CONFIG_ERROR)?;
                Some((
                    from.parse().map_err(|_| HD_COMM_CONFIG_ERROR)?,
                    until.parse().map_err(|_| HD_COMM_CONFIG_ERROR)?,
                ))
            }
            None => None,
        };
        let version = match env("FAKE_HD_VERSION").as_deref() {
            Some("none") => None,
            Some(text) => Some(CString::new(text).map_err(|_| HD_COMM_CONFIG_ERROR)?),
            None => Some(CString::from(c"3.4.0")),
        };
        let record = env("FAKE_HD_RECORD")
            .and_then(|path| std::fs::File::create(path).ok())
            .map(|f| std::io::BufWriter::with_capacity(1 << 16, f));
        let now = Instant::now();
        Ok(Device {
            fault,
            plant: Plant::new(HALF_EXTENT_MM, hand),
            opened: now,
            last_step: now,
            frames: 0,
            in_frame: false,
            forces_enabled: false,
            pending: [0.0; 3],
            output: [0.0; 3],
            last_end: now,
            held_out: false,
            lost: false,
            button_span,
            button: false,
            calibrated: env("FAKE_HD_CALIBRATION").as_deref() != Some("update"),
            version,
            record,
        })
    }

    fn note(&mut self, line: std::fmt::Arguments) {
        if let Some(r) = &mut self.record {
            let _ = writeln!(r, "{line}");
        }
    }

    /// Advances the plant to now; a force held past [`FORCE_HOLD`] without a frame ending drops to zero
    /// at the instant it ran out.
    fn step(&mut self) {
        let now = Instant::now();
        let applied = if self.forces_enabled { self.output } else { [0.0; 3] };
        let runs_out = self.last_end + FORCE_HOLD;
        if !self.held_out && runs_out < now && applied != [0.0; 3] {
            let until = runs_out.max(self.last_step);
            self.plant.advance(until.duration_since(self.last_step).as_secs_f64(), applied);
            self.last_step = until;
            self.output = [0.0; 3];
            self.held_out = true;
            self.note(format_args!("O hold"));
        }
        let applied = if self.forces_enabled { self.output } else { [0.0; 3] };
        self.plant.advance(now.duration_since(self.last_step).as_secs_f64(), applied);
        self.last_step = now;
    }
}

fn with_device<T>(missing: T, f: impl FnOnce(&mut Device) -> T) -> T {
    match lock(&DEVICE).as_mut() {
        Some(d) => f(d),
        None => {
            push_error(HD_BAD_HANDLE);
            missing
        }
    }
}

/// `HHD hdInitDevice(HDstring pConfigName)`: `HD_DEFAULT_DEVICE` (null) or `"Default Device"` names the
/// one device; another name fails with `HD_COMM_CONFIG_ERROR`, as an unknown configuration does.
///
/// # Safety
/// `name` is null or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "system" fn hdInitDevice(name: *const c_char) -> Hhd {
    if !name.is_null() {
        // SAFETY: non-null and NUL-terminated, as the header asks.
        let name = unsafe { CStr::from_ptr(name) }.to_string_lossy();
        if name != "Default Device" {
            push_error(HD_COMM_CONFIG_ERROR);
            return HD_INVALID_HANDLE;
        }
    }
    match Device::init() {
        Ok(d) => {
            *lock(&DEVICE) = Some(d);
            HANDLE
        }
        Err(code) => {
            push_error(code);
            HD_INVALID_HANDLE
        }
    }
}

/// `void hdMakeCurrentDevice(HHD hHD)`.
#[no_mangle]
pub extern "system" fn hdMakeCurrentDevice(hhd: Hhd) {
    if hhd != HANDLE {
        push_error(HD_BAD_HANDLE);
    }
}

/// `HHD hdGetCurrentDevice()`.
#[no_mangle]
pub extern "system" fn hdGetCurrentDevice() -> Hhd {
    HANDLE
}

/// `void hdDisableDevice(HHD hHD)`: forces off, the record closed with `D`.
#[no_mangle]
pub extern "system" fn hdDisableDevice(_hhd: Hhd) {
    if let Some(mut d) = lock(&DEVICE).take() {
        d.note(format_args!("D"));
        if let Some(r) = &mut d.record {
            let _ = r.flush();
        }
    }
}

/// `HDErrorInfo hdGetError()`: the most recent error first, `HD_SUCCESS` when none is left.
#[no_mangle]
pub extern "system" fn hdGetError() -> ErrorInfo {
    lock(&ERRORS).pop().unwrap_or(ErrorInfo { error_code: HD_SUCCESS, internal_error_code: 0, hhd: HANDLE })
}

/// `HDstring hdGetErrorString(HDerror errorCode)`.
#[no_mangle]
pub extern "system" fn hdGetErrorString(code: c_uint) -> *const c_char {
    let text: &'static [u8] = match code {
        HD_SUCCESS => b"no error\0",
        HD_COMM_ERROR => b"communication error (fake)\0",
        HD_COMM_CONFIG_ERROR => b"communication configuration error (fake)\0",
        HD_BAD_HANDLE => b"bad handle (fake)\0",
        HD_EXCEEDED_MAX_FORCE => b"exceeded max force (fake)\0",
        HD_ILLEGAL_BEGIN | HD_ILLEGAL_END => b"illegal begin or end of frame (fake)\0",
        _ => b"error (fake)\0",
    };
    text.as_ptr().cast()
}

/// `void hdEnable(HDenum cap)`.
#[no_mangle]
pub extern "system" fn hdEnable(cap: c_uint) {
    set_capability(cap, true);
}

/// `void hdDisable(HDenum cap)`.
#[no_mangle]
pub extern "system" fn hdDisable(cap: c_uint) {
    set_capability(cap, false);
}

fn set_capability(cap: c_uint, on: bool) {
    if cap != HD_FORCE_OUTPUT {
        push_error(HD_INVALID_ENUM);
        return;
    }
    with_device((), |d| {
        d.forces_enabled = on;
        d.note(format_args!("E {}", u8::from(on)));
    });
}

/// `void hdBeginFrame(HHD hHD)`: the state of this servo tick; fails with `HD_COMM_ERROR` once the device
/// is lost.
#[no_mangle]
pub extern "system" fn hdBeginFrame(_hhd: Hhd) {
    with_device((), |d| {
        d.frames += 1;
        if matches!(d.fault, Fault::Lost(n) if d.frames >= n) {
            if !d.lost {
                d.lost = true;
                d.note(format_args!("X lost"));
            }
            push_error(HD_COMM_ERROR);
            return;
        }
        if d.in_frame {
            push_error(HD_ILLEGAL_BEGIN);
        }
        d.in_frame = true;
        d.plant.start_moving();
        d.step();
        let t = d.frames as f64 * SERVO_PERIOD.as_secs_f64();
        let held = d.button_span.is_some_and(|(from, until)| t >= from && t < until);
        if held != d.button {
            d.button = held;
            d.note(format_args!("B {}", u8::from(held)));
        }
    });
}

/// `void hdEndFrame(HHD hHD)`: the frame's force goes out (clamped to the nominal peak, with
/// `HD_EXCEEDED_MAX_FORCE`, as `HD_MAX_FORCE_CLAMPING` does).
#[no_mangle]
pub extern "system" fn hdEndFrame(_hhd: Hhd) {
    with_device((), |d| {
        if d.lost {
            push_error(HD_COMM_ERROR);
            return;
        }
        if !d.in_frame {
            push_error(HD_ILLEGAL_END);
            return;
        }
        d.in_frame = false;
        d.step();
        let f = d.pending;
        let t = d.opened.elapsed().as_secs_f64();
        d.note(format_args!("F {t:.6} {:e} {:e} {:e}", f[0], f[1], f[2]));
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let k = if norm > MAX_FORCE_N {
            push_error(HD_EXCEEDED_MAX_FORCE);
            MAX_FORCE_N / norm
        } else {
            1.0
        };
        d.output = f.map(|x| x * k);
        d.last_end = Instant::now();
        d.held_out = false;
    });
}

/// Writes `values` to `params`.
///
/// # Safety
/// `params` is valid for `values.len()` writes.
unsafe fn write<T: Copy>(params: *mut T, values: &[T]) {
    if params.is_null() {
        return;
    }
    for (i, v) in values.iter().enumerate() {
        // SAFETY: the caller passes room for the parameter's values, as the header asks.
        unsafe { *params.add(i) = *v };
    }
}

/// `void hdGetDoublev(HDenum pname, HDdouble *params)`.
///
/// # Safety
/// `params` has room for the parameter's values (3 for a position, 6 for the workspace, 1 otherwise).
#[no_mangle]
pub unsafe extern "system" fn hdGetDoublev(pname: c_uint, params: *mut f64) {
    let values: Option<Vec<f64>> = match pname {
        HD_NOMINAL_MAX_FORCE => Some(vec![MAX_FORCE_N]),
        HD_NOMINAL_MAX_CONTINUOUS_FORCE => Some(vec![CONTINUOUS_FORCE_N]),
        HD_NOMINAL_MAX_STIFFNESS => Some(vec![STIFFNESS_N_PER_MM]),
        HD_NOMINAL_MAX_DAMPING => Some(vec![DAMPING_N_S_PER_MM]),
        HD_UPDATE_RATE => Some(vec![1.0 / SERVO_PERIOD.as_secs_f64()]),
        HD_USABLE_WORKSPACE_DIMENSIONS => {
            let [x, y, z] = HALF_EXTENT_MM;
            Some(vec![-x, -y, -z, x, y, z])
        }
        HD_CURRENT_POSITION => with_device(None, |d| {
            let p = d.plant.position();
            if matches!(d.fault, Fault::NotANumber(n) if d.frames == n) {
                d.note(format_args!("X nan"));
                return Some(vec![f64::NAN, p[1], p[2]]);
            }
            Some(p.to_vec())
        }),
        HD_CURRENT_VELOCITY => with_device(None, |d| Some(d.plant.velocity().to_vec())),
        _ => {
            push_error(HD_INVALID_ENUM);
            None
        }
    };
    if let Some(values) = values {
        // SAFETY: as this function's contract.
        unsafe { write(params, &values) };
    }
}

/// `void hdGetIntegerv(HDenum pname, HDint *params)`: the buttons (bit 0: button 1), the inkwell switch,
/// the output DOF.
///
/// # Safety
/// `params` has room for one value.
#[no_mangle]
pub unsafe extern "system" fn hdGetIntegerv(pname: c_uint, params: *mut c_int) {
    let value = match pname {
        HD_CURRENT_BUTTONS => with_device(None, |d| Some(c_int::from(d.button))),
        HD_CURRENT_INKWELL_SWITCH => Some(0),
        HD_OUTPUT_DOF => Some(3),
        _ => {
            push_error(HD_INVALID_ENUM);
            None
        }
    };
    if let Some(v) = value {
        // SAFETY: as this function's contract.
        unsafe { write(params, &[v]) };
    }
}

/// `HDstring hdGetString(HDenum pname)`: the model, and the HDAPI's version (the device's, which lives
/// until `hdDisableDevice`).
#[no_mangle]
pub extern "system" fn hdGetString(pname: c_uint) -> *const c_char {
    if pname == HD_DEVICE_MODEL_TYPE {
        MODEL.as_ptr().cast()
    } else if pname == HD_VERSION {
        with_device(std::ptr::null(), |d| d.version.as_ref().map_or(std::ptr::null(), |v| v.as_ptr()))
    } else {
        push_error(HD_INVALID_ENUM);
        std::ptr::null()
    }
}

/// `void hdSetDoublev(HDenum pname, const HDdouble *params)`: `HD_CURRENT_FORCE` (3 values, N) inside a
/// frame.
///
/// # Safety
/// `params` holds 3 values.
#[no_mangle]
pub unsafe extern "system" fn hdSetDoublev(pname: c_uint, params: *const f64) {
    if pname != HD_CURRENT_FORCE || params.is_null() {
        push_error(HD_INVALID_ENUM);
        return;
    }
    // SAFETY: three values, as this function's contract.
    let f = unsafe { [*params, *params.add(1), *params.add(2)] };
    with_device((), |d| {
        if f.iter().all(|x| x.is_finite()) {
            d.pending = f;
        } else {
            d.pending = [0.0; 3];
            push_error(HD_EXCEEDED_MAX_FORCE);
        }
    });
}

/// `HDenum hdCheckCalibration()`.
#[no_mangle]
pub extern "system" fn hdCheckCalibration() -> c_uint {
    with_device(
        HD_CALIBRATION_NEEDS_UPDATE,
        |d| if d.calibrated { HD_CALIBRATION_OK } else { HD_CALIBRATION_NEEDS_UPDATE },
    )
}

/// `void hdUpdateCalibration(HDenum style)`.
#[no_mangle]
pub extern "system" fn hdUpdateCalibration(_style: c_uint) {
    with_device((), |d| {
        d.calibrated = true;
        d.note(format_args!("A"));
    });
}

/// A callback the servo thread calls, with its user data (an address, passed back as given).
#[derive(Clone, Copy)]
struct Scheduled {
    handle: c_ulong,
    callback: Callback,
    data: usize,
}

struct Scheduler {
    callbacks: Vec<Scheduled>,
    next: c_ulong,
    running: Option<(Arc<AtomicBool>, JoinHandle<()>)>,
}

static SCHEDULER: Mutex<Scheduler> = Mutex::new(Scheduler { callbacks: Vec::new(), next: 1, running: None });

/// `HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback pCallback, void *pUserData, HDushort
/// nPriority)`.
#[no_mangle]
pub extern "system" fn hdScheduleAsynchronous(callback: Callback, data: *mut c_void, _priority: c_ushort) -> c_ulong {
    let mut s = lock(&SCHEDULER);
    let handle = s.next;
    s.next += 1;
    s.callbacks.push(Scheduled { handle, callback, data: data as usize });
    handle
}

/// `void hdUnschedule(HDSchedulerHandle hHandle)`.
#[no_mangle]
pub extern "system" fn hdUnschedule(handle: c_ulong) {
    lock(&SCHEDULER).callbacks.retain(|c| c.handle != handle);
}

/// `void hdStartScheduler()`: the servo thread, calling every scheduled callback each millisecond.
#[no_mangle]
pub extern "system" fn hdStartScheduler() {
    let mut s = lock(&SCHEDULER);
    if s.running.is_some() {
        return;
    }
    let running = Arc::new(AtomicBool::new(true));
    let flag = running.clone();
    let stall = with_device(None, |d| match d.fault {
        Fault::Stall(n, pause) => Some((n, pause)),
        _ => None,
    });
    let thread = std::thread::Builder::new().name("fake-hd-servo".into()).spawn(move || servo(&flag, stall));
    match thread {
        Ok(t) => s.running = Some((running, t)),
        Err(_) => push_error(HD_COMM_ERROR),
    }
}

/// `void hdStopScheduler()`: returns once the servo thread has stopped (no callback runs after).
#[no_mangle]
pub extern "system" fn hdStopScheduler() {
    let running = lock(&SCHEDULER).running.take();
    if let Some((flag, thread)) = running {
        flag.store(false, Ordering::Relaxed);
        let _ = thread.join();
    }
}

/// The tick after `tick` whose deadline (`start + tick · period`) is still to come at `elapsed` since the
/// start: the next one, or, when the servo thread fell behind, the first one not yet due; the ticks in
/// between are lost.
pub fn next_tick(tick: u64, elapsed: Duration, period: Duration) -> u64 {
    let due = (elapsed.as_nanos() / period.as_nanos().max(1)) as u64;
    (tick + 1).max(due + 1)
}

/// Real-time priority for the calling thread, where the system grants it (see the module documentation).
fn servo_priority() {
    #[cfg(unix)]
    {
        use thread_priority::unix::{
            set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy, ThreadSchedulePolicy,
        };
        use thread_priority::{ThreadPriority, ThreadPriorityValue};
        if let Ok(value) = ThreadPriorityValue::try_from(SERVO_PRIORITY) {
            let fifo = ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo);
            let _ = set_thread_priority_and_policy(thread_native_id(), ThreadPriority::Crossplatform(value), fifo);
        }
    }
}

/// The servo loop: absolute deadlines every [`SERVO_PERIOD`], missed ones skipped ([`next_tick`]); the
/// scheduled callbacks called in order of scheduling, outside the scheduler's lock (they call back into the
/// library). Fault ticks (`stall:N:MS`) count servo ticks run.
fn servo(running: &AtomicBool, stall: Option<(u64, Duration)>) {
    servo_priority();
    let start = Instant::now();
    let (mut tick, mut ran): (u64, u64) = (0, 0);
    while running.load(Ordering::Relaxed) {
        ran += 1;
        if let Some((_, pause)) = stall.filter(|(n, _)| *n == ran) {
            with_device((), |d| d.note(format_args!("X stall")));
            std::thread::sleep(pause);
            with_device((), Device::step);
        }
        let callbacks = lock(&SCHEDULER).callbacks.clone();
        for c in callbacks {
            // SAFETY: the callback and its data are what the caller scheduled, with the header's signature.
            let code = unsafe { (c.callback)(c.data as *mut c_void) };
            if code == HD_CALLBACK_DONE {
                hdUnschedule(c.handle);
            }
        }
        // The plant moves between frames too (a callback that ended leaves the device to its hand).
        if lock(&SCHEDULER).callbacks.is_empty() {
            with_device((), Device::step);
        }
        tick = next_tick(tick, start.elapsed(), SERVO_PERIOD);
        let deadline = start + SERVO_PERIOD * u32::try_from(tick).unwrap_or(u32::MAX);
        if let Some(wait) = deadline.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_servo_thread_that_fell_behind_skips_the_ticks_it_missed() {
        let ms = Duration::from_millis;
        // On time: the next tick.
        assert_eq!(next_tick(1, Duration::from_micros(1_200), ms(1)), 2);
        assert_eq!(next_tick(0, Duration::ZERO, ms(1)), 1);
        // Tick 1 ran 5.3 ms in: ticks 2 to 5 are lost, the next is due at 6 ms, never a burst of late ones.
        assert_eq!(next_tick(1, Duration::from_micros(5_300), ms(1)), 6);
        // Exactly at a deadline that has come: that one is gone too.
        assert_eq!(next_tick(3, ms(7), ms(1)), 8);
    }
}
