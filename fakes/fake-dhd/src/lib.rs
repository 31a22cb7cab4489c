//! A fake Force Dimension DHD library: the C symbols of `dhdc.h` (SDK 3.x) that kinloop loads, with the
//! same signatures and calling convention (`__stdcall` on Windows, hence `extern "system"`), behind a plant
//! of its own. Written for kinloop's tests and tools only; it shares no code with kinloop's simulated
//! devices, and speaks the vendor's units (metres, newtons, seconds) in the device's own frame (x towards
//! the user, y to the right, z up, origin at the workspace centre).
//!
//! Configured by environment variables, read when the library opens a device:
//! - `FAKE_DHD_SYSTEM`: the system type `dhdGetSystemType` answers (default 33, omega.3);
//! - `FAKE_DHD_VERSION`: `MAJOR.MINOR.RELEASE` for `dhdGetSDKVersion` (default 3.17.6);
//! - `FAKE_DHD_HAND`: `soft`, `firm` or `none`: the grasp of the hand holding the handle (default soft;
//!   see [`hand`] for the impedances);
//! - `FAKE_DHD_TOUR`: the waypoints the hand tours, `X,Y,Z;X,Y,Z;...` in metres in the device's frame; the
//!   handle starts at the first, and the hand sets off when the device is first read at a haptic loop's
//!   pace (default: a circle in the y-z plane from the centre, a smoke-test motion);
//! - `FAKE_DHD_BUTTON`: `FROM:UNTIL`, seconds after the hand set off: button 0 is held over that span;
//! - `FAKE_DHD_CALIBRATED`: `0` makes `drdIsInitialized` false until `drdAutoInit` runs (default calibrated);
//! - `FAKE_DHD_FAULT`: `open` (`dhdOpen` fails), `lost:N` (every read from the N-th on fails: the device is
//!   gone), `nan:N` (the N-th position read is NaN), `stall:N:MS` (the N-th read takes MS milliseconds, as a
//!   stalled process would), `watchdog:N` (the device's watchdog expires at the N-th read: it switches its
//!   forces off, ignores every force after, and `dhdGetStatus` says forces are off because of the
//!   watchdog, `DHD_FORCEOFF_WATCHDOG`);
//! - `FAKE_DHD_RECORD`: a file that receives one line per call that changes the output: `F T FX FY FZ`
//!   for every force commanded (T seconds since open), `E 0|1` for force enabling, `W TICKS` for the
//!   watchdog, `B 0|1` when button 0 changes, `A` for `drdAutoInit`, `X lost|nan|stall|watchdog` when a
//!   fault strikes, `O watchdog` when the armed watchdog (`dhdSetWatchdog`, units of 125 µs) expires because
//!   no command came in time (the device then switches its forces off, as a real one does), `C` at close.
//!
//! Where the hand, tour or button value does not parse, `dhdOpen` fails: a test's typo is never a silent
//! default.

mod hand;
mod plant;

use std::ffi::{c_char, c_int, c_uchar};
use std::io::Write;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use hand::{Grip, Intent};
use plant::{Hand, Plant};

/// `DHD_DEVICE_OMEGA3` in `dhdc.h`.
const OMEGA3: c_int = 33;

/// Reads closer together than this are a haptic loop's: the hand sets off on its intended motion at the
/// first of them (a session has started; one read at open is a check, not a session).
const LOOP_PACE: Duration = Duration::from_millis(10);

/// What a fault does, and when.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    None,
    Open,
    Lost(u64),
    NotANumber(u64),
    Stall(u64, Duration),
    Watchdog(u64),
}

fn fault_from(text: &str) -> Fault {
    let mut parts = text.split(':');
    let kind = parts.next().unwrap_or("");
    let n = parts.next().and_then(|n| n.parse().ok()).unwrap_or(1);
    match kind {
        "open" => Fault::Open,
        "lost" => Fault::Lost(n),
        "nan" => Fault::NotANumber(n),
        "stall" => Fault::Stall(n, Duration::from_millis(parts.next().and_then(|m| m.parse().ok()).unwrap_or(100))),
        "watchdog" => Fault::Watchdog(n),
        _ => Fault::None,
    }
}

/// The one device this library serves.
struct Device {
    system: c_int,
    fault: Fault,
    plant: Plant,
    opened: Instant,
    last_step: Instant,
    reads: u64,
    forces_enabled: bool,
    /// `DHD_FORCEOFF_*`: why the device last switched its forces off by itself (0: it did not).
    force_off_cause: c_int,
    force: [f64; 3],
    /// The watchdog `dhdSetWatchdog` armed (none: off), and when the last command fed it.
    watchdog: Option<Duration>,
    last_command: Instant,
    /// Button 0 held over this span of the hand's motion (s).
    button_span: Option<(f64, f64)>,
    button: bool,
    calibrated: bool,
    record: Option<std::io::BufWriter<std::fs::File>>,
}

static DEVICE: Mutex<Option<Device>> = Mutex::new(None);
static LAST_ERROR: &[u8] = b"fake DHD: no device\0";

fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

impl Device {
    fn open() -> Option<Device> {
        let fault = env("FAKE_DHD_FAULT").map_or(Fault::None, |f| fault_from(&f));
        if fault == Fault::Open {
            return None;
        }
        let system = env("FAKE_DHD_SYSTEM").and_then(|s| s.parse().ok()).unwrap_or(OMEGA3);
        let intent = match env("FAKE_DHD_TOUR") {
            Some(text) => Intent::tour(&Intent::parse_waypoints(&text)?),
            None => Intent::Circle,
        };
        let hand = match env("FAKE_DHD_HAND").as_deref() {
            Some("none") => Hand::Absent,
            Some("firm") => Hand::Holding(Grip::FIRM, intent),
            Some("soft") | None => Hand::Holding(Grip::SOFT, intent),
            Some(_) => return None,
        };
        let button_span = match env("FAKE_DHD_BUTTON") {
            Some(text) => {
                let (from, until) = text.split_once(':')?;
                Some((from.parse().ok()?, until.parse().ok()?))
            }
            None => None,
        };
        let record = env("FAKE_DHD_RECORD")
            .and_then(|path| std::fs::File::create(path).ok())
            .map(|f| std::io::BufWriter::with_capacity(1 << 16, f));
        let now = Instant::now();
        Some(Device {
            system,
            fault,
            plant: Plant::for_system(system, hand),
            opened: now,
            last_step: now,
            reads: 0,
            forces_enabled: false,
            force_off_cause: 0,
            force: [0.0; 3],
            watchdog: None,
            last_command: now,
            button_span,
            button: false,
            calibrated: env("FAKE_DHD_CALIBRATED").as_deref() != Some("0"),
            record,
        })
    }

    fn note(&mut self, line: std::fmt::Arguments) {
        if let Some(r) = &mut self.record {
            let _ = writeln!(r, "{line}");
        }
    }

    /// Advances the plant to now under the force the device outputs. An armed watchdog that no command fed
    /// in time switches the forces off at the instant it expired, as the device does
    /// (`DHD_FORCEOFF_WATCHDOG`); the record says `O watchdog`.
    fn step(&mut self) {
        let now = Instant::now();
        let mut applied = if self.forces_enabled { self.force } else { [0.0; 3] };
        let expiry = self.watchdog.filter(|_| self.forces_enabled).map(|w| self.last_command + w);
        if let Some(expired) = expiry.filter(|t| *t < now) {
            let until = expired.max(self.last_step);
            self.plant.advance(until.duration_since(self.last_step).as_secs_f64(), applied);
            self.last_step = until;
            self.forces_enabled = false;
            self.force_off_cause = FORCEOFF_WATCHDOG;
            self.note(format_args!("O watchdog"));
            applied = [0.0; 3];
        }
        self.plant.advance(now.duration_since(self.last_step).as_secs_f64(), applied);
        self.last_step = now;
    }

    /// Whether button 0 is held now (the scripted span of the hand's motion).
    fn button_held(&self) -> bool {
        let t = self.plant.moving_for();
        self.button_span.is_some_and(|(from, until)| t > 0.0 && t >= from && t < until)
    }
}

fn with_device<T>(missing: T, f: impl FnOnce(&mut Device) -> T) -> T {
    let mut guard = match DEVICE.lock() {
        Ok(g) => g,
        Err(poisoned) => poisoned.into_inner(),
    };
    match guard.as_mut() {
        Some(d) => f(d),
        None => missing,
    }
}

/// `void dhdGetSDKVersion(int *major, int *minor, int *release, int *revision)`.
///
/// # Safety
/// Each pointer is null or valid for a write.
#[no_mangle]
pub unsafe extern "system" fn dhdGetSDKVersion(
    major: *mut c_int,
    minor: *mut c_int,
    release: *mut c_int,
    revision: *mut c_int,
) {
    let text = env("FAKE_DHD_VERSION").unwrap_or_else(|| "3.17.6".into());
    let mut parts = text.split('.').map(|p| p.parse::<c_int>().unwrap_or(0));
    for out in [major, minor, release, revision] {
        let value = parts.next().unwrap_or(0);
        if !out.is_null() {
            // SAFETY: the caller passes valid pointers or null, as the header asks.
            unsafe { *out = value };
        }
    }
}

/// `int dhdGetDeviceCount(void)`.
#[no_mangle]
pub extern "system" fn dhdGetDeviceCount() -> c_int {
    if env("FAKE_DHD_FAULT").is_some_and(|f| f == "open") {
        0
    } else {
        1
    }
}

/// `int dhdOpen(void)`: the device ID, or -1.
#[no_mangle]
pub extern "system" fn dhdOpen() -> c_int {
    dhdOpenID(0)
}

/// `int dhdOpenID(char ID)`: the device ID, or -1.
#[no_mangle]
pub extern "system" fn dhdOpenID(id: c_char) -> c_int {
    if id != 0 {
        return -1;
    }
    let mut guard = match DEVICE.lock() {
        Ok(g) => g,
        Err(poisoned) => poisoned.into_inner(),
    };
    match Device::open() {
        Some(d) => {
            *guard = Some(d);
            0
        }
        None => -1,
    }
}

/// `int dhdClose(char ID)`.
#[no_mangle]
pub extern "system" fn dhdClose(_id: c_char) -> c_int {
    let mut guard = match DEVICE.lock() {
        Ok(g) => g,
        Err(poisoned) => poisoned.into_inner(),
    };
    match guard.take() {
        Some(mut d) => {
            d.note(format_args!("C"));
            if let Some(r) = &mut d.record {
                let _ = r.flush();
            }
            0
        }
        None => -1,
    }
}

/// `int dhdGetSystemType(char ID)`.
#[no_mangle]
pub extern "system" fn dhdGetSystemType(_id: c_char) -> c_int {
    with_device(-1, |d| d.system)
}

/// `int dhdGetPosition(double *px, double *py, double *pz, char ID)`.
///
/// # Safety
/// Each pointer is valid for a write.
#[no_mangle]
pub unsafe extern "system" fn dhdGetPosition(px: *mut f64, py: *mut f64, pz: *mut f64, _id: c_char) -> c_int {
    let read = with_device(None, |d| {
        d.reads += 1;
        match d.fault {
            Fault::Lost(n) if d.reads >= n => {
                if d.reads == n {
                    d.note(format_args!("X lost"));
                }
                return None;
            }
            Fault::Stall(n, pause) if d.reads == n => {
                std::thread::sleep(pause);
                d.note(format_args!("X stall"));
            }
            Fault::Watchdog(n) if d.reads == n => {
                d.forces_enabled = false;
                d.force_off_cause = FORCEOFF_WATCHDOG;
                d.note(format_args!("X watchdog"));
            }
            _ => {}
        }
        let since = d.last_step.elapsed();
        d.step();
        if d.reads > 1 && since < LOOP_PACE {
            // Reads at a haptic loop's pace: a session runs, and the hand sets off.
            d.plant.start_moving();
        }
        let p = d.plant.position();
        Some(match d.fault {
            Fault::NotANumber(n) if d.reads == n => {
                d.note(format_args!("X nan"));
                [f64::NAN, p[1], p[2]]
            }
            _ => p,
        })
    });
    let Some(p) = read else { return -1 };
    for (out, value) in [px, py, pz].into_iter().zip(p) {
        if !out.is_null() {
            // SAFETY: the caller passes valid pointers, as the header asks.
            unsafe { *out = value };
        }
    }
    0
}

/// `int dhdGetLinearVelocity(double *pvx, double *pvy, double *pvz, char ID)`.
///
/// # Safety
/// Each pointer is valid for a write.
#[no_mangle]
pub unsafe extern "system" fn dhdGetLinearVelocity(vx: *mut f64, vy: *mut f64, vz: *mut f64, _id: c_char) -> c_int {
    let Some(v) = with_device(None, |d| Some(d.plant.velocity())) else { return -1 };
    for (out, value) in [vx, vy, vz].into_iter().zip(v) {
        if !out.is_null() {
            // SAFETY: the caller passes valid pointers, as the header asks.
            unsafe { *out = value };
        }
    }
    0
}

/// `int dhdSetForce(double fx, double fy, double fz, char ID)`: 0, `DHD_MOTOR_SATURATED` (2) when the
/// force was limited, or -1.
#[no_mangle]
pub extern "system" fn dhdSetForce(fx: f64, fy: f64, fz: f64, _id: c_char) -> c_int {
    with_device(-1, |d| {
        let t = d.opened.elapsed().as_secs_f64();
        d.note(format_args!("F {t:.6} {fx:e} {fy:e} {fz:e}"));
        d.step();
        d.last_command = Instant::now();
        if matches!(d.fault, Fault::Lost(n) if d.reads >= n) {
            return -1;
        }
        let limit = d.plant.max_force();
        let norm = (fx * fx + fy * fy + fz * fz).sqrt();
        if !norm.is_finite() {
            d.force = [0.0; 3];
            return -1;
        }
        let k = if norm > limit { limit / norm } else { 1.0 };
        d.force = [fx * k, fy * k, fz * k];
        if k < 1.0 {
            2
        } else {
            0
        }
    })
}

/// `int dhdEnableForce(unsigned char val, char ID)`.
#[no_mangle]
pub extern "system" fn dhdEnableForce(val: c_uchar, _id: c_char) -> c_int {
    with_device(-1, |d| {
        d.forces_enabled = val != 0;
        if d.forces_enabled {
            d.force_off_cause = 0;
            d.last_command = Instant::now();
        }
        d.note(format_args!("E {}", u8::from(d.forces_enabled)));
        0
    })
}

/// `int dhdGetButton(int index, char ID)`: 1 pressed, 0 released, -1 on error. Button 0 follows
/// `FAKE_DHD_BUTTON`; the others are never pressed.
#[no_mangle]
pub extern "system" fn dhdGetButton(index: c_int, _id: c_char) -> c_int {
    with_device(-1, |d| {
        let held = index == 0 && d.button_held();
        if index == 0 && held != d.button {
            d.button = held;
            d.note(format_args!("B {}", u8::from(held)));
        }
        c_int::from(held)
    })
}

/// `DHD_MAX_STATUS` of the SDK 3.6 headers: the entries the fake writes (later SDKs have more; a caller
/// passes at least its own SDK's count).
const MAX_STATUS: usize = 15;
/// `DHD_STATUS_POWER`, `_CONNECTED`, `_STARTED`, `_FORCE` and `_FORCEOFFCAUSE` indices in `dhdc.h`.
const STATUS_POWER: usize = 0;
const STATUS_CONNECTED: usize = 1;
const STATUS_STARTED: usize = 2;
const STATUS_FORCE: usize = 5;
const STATUS_FORCEOFFCAUSE: usize = 14;
/// `DHD_FORCEOFF_WATCHDOG` in `dhdc.h`.
const FORCEOFF_WATCHDOG: c_int = 3;

/// `int dhdGetStatus(int status[DHD_MAX_STATUS], char ID)`.
///
/// # Safety
/// `status` is null or valid for [`MAX_STATUS`] writes.
#[no_mangle]
pub unsafe extern "system" fn dhdGetStatus(status: *mut c_int, _id: c_char) -> c_int {
    let Some(values) = with_device(None, |d| {
        let mut v = [0; MAX_STATUS];
        v[STATUS_POWER] = 1;
        v[STATUS_CONNECTED] = 1;
        v[STATUS_STARTED] = 1;
        v[STATUS_FORCE] = c_int::from(d.forces_enabled);
        v[STATUS_FORCEOFFCAUSE] = d.force_off_cause;
        Some(v)
    }) else {
        return -1;
    };
    if status.is_null() {
        return -1;
    }
    for (i, value) in values.into_iter().enumerate() {
        // SAFETY: the caller passes room for the SDK's status count, at least MAX_STATUS.
        unsafe { *status.add(i) = value };
    }
    0
}

/// `bool drdIsInitialized(char ID)` (DRD): whether the device knows where it is.
#[no_mangle]
pub extern "system" fn drdIsInitialized(_id: c_char) -> bool {
    with_device(false, |d| d.calibrated)
}

/// `int drdAutoInit(char ID)` (DRD): on a real device, moves the handle to find its references; the fake
/// records `A` and is calibrated after.
#[no_mangle]
pub extern "system" fn drdAutoInit(_id: c_char) -> c_int {
    with_device(-1, |d| {
        d.calibrated = true;
        d.note(format_args!("A"));
        0
    })
}

/// `int dhdSetWatchdog(unsigned char val, char ID)`: `val` in units of 125 µs.
#[no_mangle]
pub extern "system" fn dhdSetWatchdog(val: c_uchar, _id: c_char) -> c_int {
    with_device(-1, |d| {
        d.watchdog = (val > 0).then(|| Duration::from_micros(125 * u64::from(val)));
        d.note(format_args!("W {val}"));
        0
    })
}

/// `const char *dhdErrorGetLastStr(void)`.
#[no_mangle]
pub extern "system" fn dhdErrorGetLastStr() -> *const c_char {
    LAST_ERROR.as_ptr().cast()
}
