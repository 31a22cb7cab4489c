//! Finding and loading OpenHaptics' HD library at run time, and the calls kinloop makes through it.
//!
//! Signatures from the public OpenHaptics 3.x headers (`HD/hdDevice.h`, `HD/hdScheduler.h`,
//! `HD/hdDefines.h`; `../shared/integration-facts.md`): `HDAPIENTRY` and `HDCALLBACK` are `__stdcall` on
//! Windows and nothing elsewhere, hence `extern "system"`; `HHD`, `HDenum` and `HDerror` are `unsigned int`,
//! `HDSchedulerHandle` is `unsigned long` (`c_ulong`: 64-bit on Linux, 32 on Windows), `HDushort` is
//! `unsigned short`; `hdGetError` returns `HDErrorInfo` by value (`{ HDerror errorCode; int
//! internalErrorCode; HHD hHD; }`, most recent error first, `HD_SUCCESS` when none is left).
//!
//! The library is loaded once per process and never unloaded: the vendor's driver fails when it is loaded
//! a second time in one process, so kinloop keeps it for the process's life.

use std::ffi::{c_char, c_int, c_uint, c_ulong, c_ushort, c_void, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use crate::device::vendor_search;

/// The variable naming the library file, before any search.
pub const LIBRARY_VARIABLE: &str = "KINLOOP_HD_LIB";
/// The OpenHaptics install folder, as 3D Systems' installers set it.
pub const SDK_VARIABLE: &str = "OH_SDK_BASE";

/// `hdDefines.h` constants kinloop uses.
pub mod constants {
    use std::ffi::c_uint;
    /// `HD_SUCCESS`.
    pub const SUCCESS: c_uint = 0x0000;
    /// `HD_COMM_ERROR`.
    pub const COMM_ERROR: c_uint = 0x0302;
    /// `HD_CURRENT_BUTTONS` (an int, bit 0 = button 1).
    pub const CURRENT_BUTTONS: c_uint = 0x2000;
    /// `HD_CURRENT_POSITION` (3 doubles, mm).
    pub const CURRENT_POSITION: c_uint = 0x2050;
    /// `HD_CURRENT_VELOCITY` (3 doubles, mm/s).
    pub const CURRENT_VELOCITY: c_uint = 0x2051;
    /// `HD_VERSION` (`hdGetString`: the HDAPI's version, e.g. `3.4.0`).
    pub const VERSION: c_uint = 0x2500;
    /// `HD_DEVICE_MODEL_TYPE` (`hdGetString`).
    pub const DEVICE_MODEL_TYPE: c_uint = 0x2501;
    /// `HD_USABLE_WORKSPACE_DIMENSIONS` (6 doubles, mm).
    pub const USABLE_WORKSPACE_DIMENSIONS: c_uint = 0x2551;
    /// `HD_NOMINAL_MAX_STIFFNESS` (N/mm).
    pub const NOMINAL_MAX_STIFFNESS: c_uint = 0x2602;
    /// `HD_NOMINAL_MAX_FORCE` (N).
    pub const NOMINAL_MAX_FORCE: c_uint = 0x2603;
    /// `HD_NOMINAL_MAX_CONTINUOUS_FORCE` (N).
    pub const NOMINAL_MAX_CONTINUOUS_FORCE: c_uint = 0x2604;
    /// `HD_NOMINAL_MAX_DAMPING` (N s/mm).
    pub const NOMINAL_MAX_DAMPING: c_uint = 0x2609;
    /// `HD_CURRENT_FORCE` (3 doubles, N).
    pub const CURRENT_FORCE: c_uint = 0x2700;
    /// `HD_FORCE_OUTPUT`.
    pub const FORCE_OUTPUT: c_uint = 0x4000;
    /// `HD_CALIBRATION_OK`, `_NEEDS_UPDATE`, `_NEEDS_MANUAL_INPUT`.
    pub const CALIBRATION_OK: c_uint = 0x5000;
    /// See [`CALIBRATION_OK`].
    pub const CALIBRATION_NEEDS_UPDATE: c_uint = 0x5001;
    /// `HD_CALIBRATION_INKWELL` style.
    pub const CALIBRATION_INKWELL: c_uint = 1 << 2;
    /// `HD_INVALID_HANDLE`.
    pub const INVALID_HANDLE: c_uint = 0xFFFF_FFFF;
    /// `HD_CALLBACK_DONE`, `HD_CALLBACK_CONTINUE`.
    pub const CALLBACK_DONE: c_uint = 0;
    /// See [`CALLBACK_DONE`].
    pub const CALLBACK_CONTINUE: c_uint = 1;
    /// `HD_MAX_SCHEDULER_PRIORITY` (`USHRT_MAX`).
    pub const MAX_SCHEDULER_PRIORITY: u16 = u16::MAX;
}

/// `HDErrorInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorInfo {
    /// The `HD_*` code.
    pub error_code: c_uint,
    /// The device's own code.
    pub internal_error_code: c_int,
    /// The device it concerns.
    pub hhd: c_uint,
}

/// `HDCallbackCode (HDCALLBACK *HDSchedulerCallback)(void *pUserData)`.
pub type SchedulerCallback = unsafe extern "system" fn(*mut c_void) -> c_uint;

type InitDevice = unsafe extern "system" fn(*const c_char) -> c_uint;
type ByHandle = unsafe extern "system" fn(c_uint);
type NoArgs = unsafe extern "system" fn();
type GetError = unsafe extern "system" fn() -> ErrorInfo;
type ErrorString = unsafe extern "system" fn(c_uint) -> *const c_char;
type Capability = unsafe extern "system" fn(c_uint);
type GetDoubles = unsafe extern "system" fn(c_uint, *mut f64);
type GetInts = unsafe extern "system" fn(c_uint, *mut c_int);
type SetDoubles = unsafe extern "system" fn(c_uint, *const f64);
type GetString = unsafe extern "system" fn(c_uint) -> *const c_char;
type Schedule = unsafe extern "system" fn(SchedulerCallback, *mut c_void, c_ushort) -> c_ulong;
type Unschedule = unsafe extern "system" fn(c_ulong);
type CheckCalibration = unsafe extern "system" fn() -> c_uint;
type UpdateCalibration = unsafe extern "system" fn(c_uint);

/// The required symbols, by name.
pub const REQUIRED: [&str; 16] = [
    "hdInitDevice",
    "hdDisableDevice",
    "hdMakeCurrentDevice",
    "hdGetError",
    "hdGetErrorString",
    "hdEnable",
    "hdDisable",
    "hdBeginFrame",
    "hdEndFrame",
    "hdGetDoublev",
    "hdGetIntegerv",
    "hdSetDoublev",
    "hdScheduleAsynchronous",
    "hdUnschedule",
    "hdStartScheduler",
    "hdStopScheduler",
];

/// The calls kinloop makes, resolved once from a library that stays loaded for the process's life.
pub struct HdLibrary {
    path: PathBuf,
    init_device: InitDevice,
    disable_device: ByHandle,
    make_current: ByHandle,
    get_error: GetError,
    error_string: ErrorString,
    enable: Capability,
    disable: Capability,
    begin_frame: ByHandle,
    end_frame: ByHandle,
    get_doubles: GetDoubles,
    get_ints: GetInts,
    set_doubles: SetDoubles,
    schedule: Schedule,
    unschedule: Unschedule,
    start_scheduler: NoArgs,
    stop_scheduler: NoArgs,
    get_string: Option<GetString>,
    check_calibration: Option<CheckCalibration>,
    update_calibration: Option<UpdateCalibration>,
}

/// The library file names.
pub fn library_names() -> &'static [&'static str] {
    if cfg!(windows) {
        &["HD.dll"]
    } else if cfg!(target_os = "macos") {
        &["libHD.dylib"]
    } else {
        &["libHD.so"]
    }
}

/// Where kinloop looks, in order: `KINLOOP_HD_LIB`; `$OH_SDK_BASE/lib`; `/usr/lib` and `/usr/local/lib`
/// (where the Linux installer puts `libHD.so`); then the name through the system loader's search path.
pub fn candidates() -> Vec<PathBuf> {
    vendor_search::candidates(LIBRARY_VARIABLE, SDK_VARIABLE, &["/usr/lib", "/usr/local/lib"], library_names())
}

/// The one library this process loaded, by path (never unloaded, never loaded twice).
static LOADED: OnceLock<Mutex<Vec<&'static HdLibrary>>> = OnceLock::new();

impl HdLibrary {
    /// The first candidate that loads (see [`candidates`]), with every required symbol. A candidate that
    /// exists but is refused is the error; when none exists, the error lists where kinloop looked.
    pub fn find() -> Result<&'static HdLibrary, HdError> {
        let candidates = candidates();
        let not_loadable = |e: &HdError| matches!(e, HdError::Load { .. });
        vendor_search::first_loadable(&candidates, HdLibrary::load, not_loadable)
            .unwrap_or(Err(HdError::NotFound { looked: candidates }))
    }

    /// Loads the library at `path` (once per process) and resolves its symbols.
    pub fn load(path: &Path) -> Result<&'static HdLibrary, HdError> {
        let loaded = LOADED.get_or_init(|| Mutex::new(Vec::new()));
        let mut loaded = loaded.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(library) = loaded.iter().find(|l| l.path == path) {
            return Ok(library);
        }
        let library = path.display().to_string();
        // SAFETY: loading runs the library's initialisers: the vendor's, trusted as any driver the user
        // installed, or the fake's, which do nothing.
        let handle = unsafe { libloading::Library::new(path) }
            .map_err(|e| HdError::Load { library: library.clone(), reason: e.to_string() })?;
        // Never unloaded (see the module documentation): the symbols below stay valid for the process.
        let handle: &'static libloading::Library = Box::leak(Box::new(handle));
        let mut missing = Vec::new();
        // SAFETY: each type is the signature the OpenHaptics headers declare for that name.
        macro_rules! required {
            ($name:literal) => {
                unsafe { vendor_search::required(handle, $name, &mut missing) }
            };
        }
        macro_rules! optional {
            ($name:literal) => {
                unsafe { vendor_search::optional(handle, $name) }
            };
        }
        let parts = (
            required!("hdInitDevice"),
            required!("hdDisableDevice"),
            required!("hdMakeCurrentDevice"),
            required!("hdGetError"),
            required!("hdGetErrorString"),
            required!("hdEnable"),
            required!("hdDisable"),
            required!("hdBeginFrame"),
            required!("hdEndFrame"),
            required!("hdGetDoublev"),
            required!("hdGetIntegerv"),
            required!("hdSetDoublev"),
            required!("hdScheduleAsynchronous"),
            required!("hdUnschedule"),
            required!("hdStartScheduler"),
            required!("hdStopScheduler"),
        );
        let (
            Some(init_device),
            Some(disable_device),
            Some(make_current),
            Some(get_error),
            Some(error_string),
            Some(enable),
            Some(disable),
            Some(begin_frame),
            Some(end_frame),
            Some(get_doubles),
            Some(get_ints),
            Some(set_doubles),
            Some(schedule),
            Some(unschedule),
            Some(start_scheduler),
            Some(stop_scheduler),
        ) = parts
        else {
            return Err(HdError::MissingSymbols { library, symbols: missing.join(", ") });
        };
        let ours: &'static HdLibrary = Box::leak(Box::new(HdLibrary {
            path: path.to_owned(),
            init_device,
            disable_device,
            make_current,
            get_error,
            error_string,
            enable,
            disable,
            begin_frame,
            end_frame,
            get_doubles,
            get_ints,
            set_doubles,
            schedule,
            unschedule,
            start_scheduler,
            stop_scheduler,
            get_string: optional!("hdGetString"),
            check_calibration: optional!("hdCheckCalibration"),
            update_calibration: optional!("hdUpdateCalibration"),
        }));
        loaded.push(ours);
        Ok(ours)
    }

    /// Where it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The most recent error, if any (`hdGetError`, one entry off the stack; the rest cleared).
    pub fn error(&self) -> Option<ErrorInfo> {
        // SAFETY: no arguments; returns the struct by value.
        let first = unsafe { (self.get_error)() };
        if first.error_code == constants::SUCCESS {
            return None;
        }
        // Older errors of the same call are not news: drop them (bounded, in case a library never empties).
        for _ in 0..16 {
            // SAFETY: as above.
            if unsafe { (self.get_error)() }.error_code == constants::SUCCESS {
                break;
            }
        }
        Some(first)
    }

    /// `hdGetErrorString(code)`.
    pub fn error_text(&self, code: c_uint) -> String {
        // SAFETY: returns null or a NUL-terminated static string.
        let text = unsafe { (self.error_string)(code) };
        if text.is_null() {
            return "no description".into();
        }
        // SAFETY: non-null and NUL-terminated, as above.
        unsafe { CStr::from_ptr(text) }.to_string_lossy().into_owned()
    }

    /// An error as a message: code in hex, the library's text, the device's own code.
    pub fn describe(&self, e: ErrorInfo) -> String {
        format!(
            "HD error 0x{:04X} ({}), device code {}",
            e.error_code,
            self.error_text(e.error_code),
            e.internal_error_code
        )
    }

    /// `hdInitDevice(name)` (None: `HD_DEFAULT_DEVICE`): the handle, or the error it raised.
    pub fn init_device(&self, name: Option<&str>) -> Result<c_uint, ErrorInfo> {
        let unknown = ErrorInfo { error_code: constants::COMM_ERROR, internal_error_code: 0, hhd: 0 };
        let owned = match name.map(CString::new).transpose() {
            Ok(owned) => owned,
            Err(_) => return Err(unknown),
        };
        let pointer = owned.as_ref().map_or(std::ptr::null(), |c| c.as_ptr());
        // SAFETY: null or a NUL-terminated string alive for the call.
        let handle = unsafe { (self.init_device)(pointer) };
        match self.error() {
            Some(e) => Err(e),
            None if handle == constants::INVALID_HANDLE => Err(unknown),
            None => Ok(handle),
        }
    }

    /// `hdDisableDevice(handle)`.
    pub fn disable_device(&self, handle: c_uint) {
        // SAFETY: plain values.
        unsafe { (self.disable_device)(handle) }
    }

    /// `hdMakeCurrentDevice(handle)`.
    pub fn make_current(&self, handle: c_uint) {
        // SAFETY: plain values.
        unsafe { (self.make_current)(handle) }
    }

    /// `hdEnable` / `hdDisable`.
    pub fn set_capability(&self, cap: c_uint, on: bool) {
        // SAFETY: plain values.
        unsafe {
            if on {
                (self.enable)(cap)
            } else {
                (self.disable)(cap)
            }
        }
    }

    /// `hdBeginFrame(handle)`.
    pub fn begin_frame(&self, handle: c_uint) {
        // SAFETY: plain values.
        unsafe { (self.begin_frame)(handle) }
    }

    /// `hdEndFrame(handle)`.
    pub fn end_frame(&self, handle: c_uint) {
        // SAFETY: plain values.
        unsafe { (self.end_frame)(handle) }
    }

    /// `hdGetDoublev(pname, out)`: `out` must have room for the parameter's values.
    pub fn get_doubles(&self, pname: c_uint, out: &mut [f64]) {
        // SAFETY: `out` is as long as the parameter's values (the callers pass 1, 3 or 6 as the header says).
        unsafe { (self.get_doubles)(pname, out.as_mut_ptr()) }
    }

    /// `hdGetIntegerv(pname)` for a one-value parameter.
    pub fn get_int(&self, pname: c_uint) -> c_int {
        // Room beyond one value, so a library that writes more for some parameter stays inside it.
        let mut out = [0; 4];
        // SAFETY: room for the parameter's value.
        unsafe { (self.get_ints)(pname, out.as_mut_ptr()) };
        out[0]
    }

    /// `hdSetDoublev(HD_CURRENT_FORCE, force)` (N).
    pub fn set_force(&self, force: &[f64; 3]) {
        // SAFETY: three values, as HD_CURRENT_FORCE takes.
        unsafe { (self.set_doubles)(constants::CURRENT_FORCE, force.as_ptr()) }
    }

    /// `hdGetString(HD_DEVICE_MODEL_TYPE)`, when the library has it.
    pub fn model_name(&self) -> Option<String> {
        self.string(constants::DEVICE_MODEL_TYPE)
    }

    /// `hdGetString(HD_VERSION)`, when the library has it and answers.
    pub fn version(&self) -> Option<String> {
        self.string(constants::VERSION)
    }

    /// `hdGetString(pname)`, when the library has it and answers.
    fn string(&self, pname: c_uint) -> Option<String> {
        let call = self.get_string?;
        // SAFETY: returns null or a NUL-terminated string owned by the library.
        let text = unsafe { call(pname) };
        // SAFETY: non-null and NUL-terminated, as above.
        (!text.is_null()).then(|| unsafe { CStr::from_ptr(text) }.to_string_lossy().into_owned())
    }

    /// `hdCheckCalibration()`, when the library has it.
    pub fn check_calibration(&self) -> Option<c_uint> {
        // SAFETY: no arguments.
        self.check_calibration.map(|call| unsafe { call() })
    }

    /// `hdUpdateCalibration(style)`, when the library has it.
    pub fn update_calibration(&self, style: c_uint) -> bool {
        // SAFETY: plain values.
        self.update_calibration.map(|call| unsafe { call(style) }).is_some()
    }

    /// `hdScheduleAsynchronous(callback, data, priority)`.
    ///
    /// # Safety
    /// `data` must stay valid, and be used by nothing else, until [`Self::unschedule`] of the handle
    /// returned (or [`Self::stop_scheduler`]) has returned.
    pub unsafe fn schedule(&self, callback: SchedulerCallback, data: *mut c_void, priority: u16) -> c_ulong {
        // SAFETY: the caller keeps `data` valid as this function's contract says.
        unsafe { (self.schedule)(callback, data, priority) }
    }

    /// `hdUnschedule(handle)`.
    pub fn unschedule(&self, handle: c_ulong) {
        // SAFETY: plain values.
        unsafe { (self.unschedule)(handle) }
    }

    /// `hdStartScheduler()`.
    pub fn start_scheduler(&self) {
        // SAFETY: no arguments.
        unsafe { (self.start_scheduler)() }
    }

    /// `hdStopScheduler()`: returns once no scheduled callback runs any more (required: kinloop frees a
    /// callback's data only after it).
    pub fn stop_scheduler(&self) {
        // SAFETY: no arguments.
        unsafe { (self.stop_scheduler)() }
    }
}

/// The oldest HDAPI kinloop drives: the 3.x headers its signatures come from (`HDErrorInfo` by value,
/// `hdScheduleAsynchronous` with a priority).
pub const OLDEST_VERSION: (u32, u32) = (3, 0);

/// The (major, minor) of an `HD_VERSION` string (`3.4.0`, `3.00.66`), if it starts with one.
pub fn parse_version(text: &str) -> Option<(u32, u32)> {
    let mut parts = text.trim().split('.');
    let major = parts.next()?.parse().ok()?;
    let minor = parts.next().map_or(Some(0), |m| m.parse().ok())?;
    Some((major, minor))
}

/// Why the HD library or a device behind it cannot be used. Each message names the library.
#[derive(Debug, thiserror::Error)]
pub enum HdError {
    /// No candidate exists.
    #[error(
        "no OpenHaptics HD library found (looked for {}); install OpenHaptics and the Touch device driver, or set \
         {} to the library's path (or OH_SDK_BASE to the SDK's folder)",
        looked.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        LIBRARY_VARIABLE
    )]
    NotFound {
        /// Where kinloop looked.
        looked: Vec<PathBuf>,
    },
    /// The file is not a loadable library.
    #[error("HD library {library}: cannot be loaded: {reason}")]
    Load {
        /// The library.
        library: String,
        /// The loader's reason.
        reason: String,
    },
    /// Required calls are absent.
    #[error("HD library {library}: lacks required symbols {symbols}; it is not OpenHaptics' HD library")]
    MissingSymbols {
        /// The library.
        library: String,
        /// The missing names, comma-separated.
        symbols: String,
    },
    /// The library is older than [`OLDEST_VERSION`], or will not say its version.
    #[error(
        "HD library {library}: HDAPI version {found}, kinloop needs OpenHaptics {}.{} or newer (check which \
         OpenHaptics is installed, and that {} or OH_SDK_BASE points at it rather than an older copy)",
        OLDEST_VERSION.0,
        OLDEST_VERSION.1,
        LIBRARY_VARIABLE
    )]
    Old {
        /// The library.
        library: String,
        /// What `hdGetString(HD_VERSION)` said, quoted, or that it said nothing.
        found: String,
    },
    /// `hdInitDevice` failed.
    #[error(
        "HD library {library}: cannot initialise device {name:?}: {reason} (check that the device is plugged in and \
         powered, that its name is one Touch Setup lists (\"Default Device\" unless renamed), and that this user \
         may open its port)"
    )]
    Init {
        /// The library.
        library: String,
        /// The device name asked for.
        name: String,
        /// The HD error, with its code.
        reason: String,
    },
    /// The device needs calibrating first.
    #[error(
        "HD library {library}: device {name:?} needs calibrating (hdCheckCalibration says so): put the stylus in its \
         inkwell, or run Touch Diagnostic; or pass --hd-calibrate to let kinloop run hdUpdateCalibration"
    )]
    NotCalibrated {
        /// The library.
        library: String,
        /// The device name.
        name: String,
    },
    /// A reading or figure that cannot describe a device.
    #[error("HD library {library}: device {name:?} reads garbage ({what}); no force will be sent to it")]
    Garbage {
        /// The library.
        library: String,
        /// The device name.
        name: String,
        /// What was wrong.
        what: String,
    },
    /// The scheduler would not start.
    #[error("HD library {library}: the servo scheduler did not start: {reason}")]
    Scheduler {
        /// The library.
        library: String,
        /// The HD error.
        reason: String,
    },
}
