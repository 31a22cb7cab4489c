//! Finding and loading the Force Dimension DHD library at run time, and the calls kinloop makes through it.
//!
//! Signatures from the public `dhdc.h` (SDK 3.x) and `drdc.h`: `__SDK` is `__stdcall` on Windows and nothing
//! elsewhere, hence `extern "system"`; the device ID is a C `char` (`c_char`, unsigned on aarch64 Linux), and
//! every call passes it (C has no default argument). Calls return 0 on success, a positive status that is not
//! an error (`DHD_TIMEGUARD` 1, `DHD_MOTOR_SATURATED` 2), or -1 on error. Required symbols must all be there;
//! optional ones (the expert SDK's watchdog, the velocity estimate, the status array, DRD's calibration
//! query and auto-initialisation) switch a feature off when absent, as CHAI3D's `CDeltaDevices.cpp` does
//! with one "available" flag per function.
//!
//! Checked against the SDK 3.6.0 headers as published in `psh117/dyros_jet`
//! (`dyros_jet_haptic/include/sdk-3.6.0/include/dhdc.h` and `dyros_jet_haptic/include/drdc.h`): every
//! signature below matches those declarations (`int dhdGetPosition(double *px, double *py, double *pz, char
//! ID = -1)`, `int dhdSetForce(double fx, double fy, double fz, char ID = -1)`, `int dhdEnableForce(uchar
//! val, char ID = -1)`, `int dhdGetButton(int index, char ID = -1)`, `int dhdGetStatus(int
//! status[DHD_MAX_STATUS], char ID = -1)`, `void dhdGetSDKVersion(int *, int *, int *, int *)`, `const
//! char *dhdErrorGetLastStr()`, `bool drdIsInitialized(char ID = -1)`, `int drdAutoInit(char ID = -1)`), as
//! do the constants used (`DHD_DEVICE_*`, `DHD_STATUS_FORCE` 5, `DHD_STATUS_FORCEOFFCAUSE` 14,
//! `DHD_FORCEOFF_*`, `DHD_MAX_STATUS` 15 there), and `int dhdSetWatchdog(unsigned char val, char ID = -1)`
//! in the expert SDK ("added in release 3.3.2"), hence optional. `bool` is C++'s one-byte `bool`, Rust's
//! `bool`.

use std::ffi::{c_char, c_int, c_uchar, CStr};
use std::path::{Path, PathBuf};

use crate::device::vendor_search;

/// The variable naming the library file, before any search.
pub const LIBRARY_VARIABLE: &str = "KINLOOP_DHD_LIB";
/// The SDK's install folder, as Force Dimension's installers and Python's `forcedimension_core` use it.
pub const SDK_VARIABLE: &str = "FORCEDIM_SDK";
/// Oldest SDK accepted: `forcedimension_core` (`runtime.py`) refuses anything older than 3.14.0 too.
pub const MINIMUM_VERSION: SdkVersion = SdkVersion { major: 3, minor: 14, release: 0, revision: 0 };

/// `dhdGetSDKVersion`'s four numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct SdkVersion {
    /// Major.
    pub major: i32,
    /// Minor.
    pub minor: i32,
    /// Release.
    pub release: i32,
    /// Revision.
    pub revision: i32,
}

impl std::fmt::Display for SdkVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}.{}-{}", self.major, self.minor, self.release, self.revision)
    }
}

/// The library file names, DRD first (it exports the DHD calls too), as CHAI3D loads `drd64.dll` before
/// `dhd64.dll`.
pub fn library_names() -> &'static [&'static str] {
    if cfg!(windows) {
        &["drd64.dll", "dhd64.dll", "drd.dll", "dhd.dll"]
    } else if cfg!(target_os = "macos") {
        &["libdrd.dylib", "libdhd.dylib"]
    } else {
        &["libdrd.so", "libdhd.so"]
    }
}

/// Where kinloop looks, in order: `KINLOOP_DHD_LIB`; `$FORCEDIM_SDK/lib`; `/usr/local/lib` and `/usr/lib`
/// (as `forcedimension_core`); then each name through the system loader's own search path.
pub fn candidates() -> Vec<PathBuf> {
    vendor_search::candidates(LIBRARY_VARIABLE, SDK_VARIABLE, &["/usr/local/lib", "/usr/lib"], library_names())
}

type GetVersion = unsafe extern "system" fn(*mut c_int, *mut c_int, *mut c_int, *mut c_int);
type OpenId = unsafe extern "system" fn(c_char) -> c_int;
type ById = unsafe extern "system" fn(c_char) -> c_int;
type GetTriple = unsafe extern "system" fn(*mut f64, *mut f64, *mut f64, c_char) -> c_int;
type SetForce = unsafe extern "system" fn(f64, f64, f64, c_char) -> c_int;
type SetFlag = unsafe extern "system" fn(c_uchar, c_char) -> c_int;
type GetButton = unsafe extern "system" fn(c_int, c_char) -> c_int;
type LastError = unsafe extern "system" fn() -> *const c_char;
type DeviceCount = unsafe extern "system" fn() -> c_int;
type IsInitialized = unsafe extern "system" fn(c_char) -> bool;
type GetStatus = unsafe extern "system" fn(*mut c_int, c_char) -> c_int;

/// Room for `dhdGetStatus`'s array: `DHD_MAX_STATUS` is 15 in SDK 3.6 and has grown since; twice that and
/// more, so a newer SDK never writes past it.
pub const STATUS_ROOM: usize = 32;
/// `DHD_STATUS_FORCE`: 1 while the device outputs forces.
pub const STATUS_FORCE: usize = 5;
/// `DHD_STATUS_FORCEOFFCAUSE`: why the device last switched its forces off (`DHD_FORCEOFF_*`).
pub const STATUS_FORCE_OFF_CAUSE: usize = 14;

/// `DHD_FORCEOFF_WATCHDOG`: the device's watchdog switched its forces off.
pub const FORCE_OFF_WATCHDOG: i32 = 3;

/// What a `DHD_FORCEOFF_*` value means, for messages.
pub fn force_off_cause(cause: i32) -> &'static str {
    match cause {
        1 => "its force button was pressed",
        2 => "the handle moved faster than its safety limit",
        3 => "its watchdog expired (no force command reached it in time)",
        4 => "software switched them off",
        5 => "its USB link was lost",
        6 => "its dead-man switch was released",
        _ => "no cause given",
    }
}

/// The calls kinloop makes, resolved once. Function pointers stay valid while `_library` is loaded, and it
/// is never unloaded before them (they live in the same value).
pub struct DhdLibrary {
    path: PathBuf,
    version: SdkVersion,
    open_id: OpenId,
    close: ById,
    system_type: ById,
    position: GetTriple,
    set_force: SetForce,
    enable_force: SetFlag,
    button: GetButton,
    last_error: LastError,
    velocity: Option<GetTriple>,
    watchdog: Option<SetFlag>,
    device_count: Option<DeviceCount>,
    status: Option<GetStatus>,
    is_initialized: Option<IsInitialized>,
    auto_init: Option<ById>,
    _library: libloading::Library,
}

/// The required symbols, by name.
pub const REQUIRED: [&str; 9] = [
    "dhdGetSDKVersion",
    "dhdOpenID",
    "dhdClose",
    "dhdGetSystemType",
    "dhdGetPosition",
    "dhdSetForce",
    "dhdEnableForce",
    "dhdGetButton",
    "dhdErrorGetLastStr",
];

impl DhdLibrary {
    /// The first candidate that loads (see [`candidates`]), checked: every required symbol present and the
    /// SDK at least [`MINIMUM_VERSION`]. A candidate that exists but is refused is the error; when none
    /// exists, the error lists where kinloop looked.
    pub fn find() -> Result<DhdLibrary, DhdError> {
        let candidates = candidates();
        let not_loadable = |e: &DhdError| matches!(e, DhdError::Load { .. });
        vendor_search::first_loadable(&candidates, DhdLibrary::load, not_loadable)
            .unwrap_or(Err(DhdError::NotFound { looked: candidates }))
    }

    /// Loads the library at `path` and checks it.
    pub fn load(path: &Path) -> Result<DhdLibrary, DhdError> {
        let library = path.display().to_string();
        // SAFETY: loading runs the library's initialisers; a DHD SDK's are the vendor's, trusted as any
        // driver the user installed, and the fake's do nothing.
        let loaded = unsafe { libloading::Library::new(path) }
            .map_err(|e| DhdError::Load { library: library.clone(), reason: e.to_string() })?;
        let mut missing = Vec::new();
        // SAFETY: each type below is the signature `dhdc.h` declares for that name.
        macro_rules! required {
            ($name:literal) => {
                unsafe { vendor_search::required(&loaded, $name, &mut missing) }
            };
        }
        macro_rules! optional {
            ($name:literal) => {
                unsafe { vendor_search::optional(&loaded, $name) }
            };
        }
        let get_version: Option<GetVersion> = required!("dhdGetSDKVersion");
        let open_id: Option<OpenId> = required!("dhdOpenID");
        let close: Option<ById> = required!("dhdClose");
        let system_type: Option<ById> = required!("dhdGetSystemType");
        let position: Option<GetTriple> = required!("dhdGetPosition");
        let set_force: Option<SetForce> = required!("dhdSetForce");
        let enable_force: Option<SetFlag> = required!("dhdEnableForce");
        let button: Option<GetButton> = required!("dhdGetButton");
        let last_error: Option<LastError> = required!("dhdErrorGetLastStr");
        let (
            Some(get_version),
            Some(open_id),
            Some(close),
            Some(system_type),
            Some(position),
            Some(set_force),
            Some(enable_force),
            Some(button),
            Some(last_error),
        ) = (get_version, open_id, close, system_type, position, set_force, enable_force, button, last_error)
        else {
            return Err(DhdError::MissingSymbols { library, symbols: missing.join(", ") });
        };
        let (mut major, mut minor, mut release, mut revision) = (0, 0, 0, 0);
        // SAFETY: four valid pointers, as the header asks.
        unsafe { get_version(&mut major, &mut minor, &mut release, &mut revision) };
        let version = SdkVersion { major, minor, release, revision };
        if version < MINIMUM_VERSION {
            return Err(DhdError::TooOld { library, found: version.to_string(), minimum: MINIMUM_VERSION.to_string() });
        }
        Ok(DhdLibrary {
            path: path.to_owned(),
            version,
            open_id,
            close,
            system_type,
            position,
            set_force,
            enable_force,
            button,
            last_error,
            velocity: optional!("dhdGetLinearVelocity"),
            watchdog: optional!("dhdSetWatchdog"),
            device_count: optional!("dhdGetDeviceCount"),
            status: optional!("dhdGetStatus"),
            is_initialized: optional!("drdIsInitialized"),
            auto_init: optional!("drdAutoInit"),
            _library: loaded,
        })
    }

    /// Where it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its SDK version.
    pub fn version(&self) -> SdkVersion {
        self.version
    }

    /// The SDK's last error, for messages.
    pub fn last_error(&self) -> String {
        // SAFETY: `dhdErrorGetLastStr` returns null or a NUL-terminated static string.
        let text = unsafe { (self.last_error)() };
        if text.is_null() {
            return "no reason given".into();
        }
        // SAFETY: non-null and NUL-terminated, as above.
        unsafe { CStr::from_ptr(text) }.to_string_lossy().into_owned()
    }

    /// `dhdGetDeviceCount`, when the library has it.
    pub fn device_count(&self) -> Option<i32> {
        // SAFETY: no arguments.
        self.device_count.map(|count| unsafe { count() })
    }

    /// `dhdOpenID(index)`: the device ID, or -1.
    pub fn open(&self, index: u8) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.open_id)(index as c_char) }
    }

    /// `dhdClose(id)`.
    pub fn close(&self, id: c_char) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.close)(id) }
    }

    /// `dhdGetSystemType(id)`.
    pub fn system_type(&self, id: c_char) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.system_type)(id) }
    }

    /// `dhdGetPosition`: metres in the device frame, or the failing return.
    pub fn position(&self, id: c_char) -> Result<[f64; 3], i32> {
        let mut p = [0.0; 3];
        let [x, y, z] = &mut p;
        // SAFETY: three valid pointers.
        let status = unsafe { (self.position)(x, y, z, id) };
        if status < 0 {
            Err(status)
        } else {
            Ok(p)
        }
    }

    /// `dhdGetLinearVelocity`, when the library has it: m/s in the device frame.
    pub fn velocity(&self, id: c_char) -> Option<Result<[f64; 3], i32>> {
        let call = self.velocity?;
        let mut v = [0.0; 3];
        let [x, y, z] = &mut v;
        // SAFETY: three valid pointers.
        let status = unsafe { call(x, y, z, id) };
        Some(if status < 0 { Err(status) } else { Ok(v) })
    }

    /// `dhdSetForce`: newtons in the device frame.
    pub fn set_force(&self, force: [f64; 3], id: c_char) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.set_force)(force[0], force[1], force[2], id) }
    }

    /// `dhdEnableForce`.
    pub fn enable_force(&self, on: bool, id: c_char) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.enable_force)(c_uchar::from(on), id) }
    }

    /// `dhdGetButton(index, id)`: 1 pressed, 0 released, -1 on error.
    pub fn button(&self, index: i32, id: c_char) -> i32 {
        // SAFETY: plain values.
        unsafe { (self.button)(index, id) }
    }

    /// `dhdSetWatchdog(ticks, id)` (ticks of 125 µs), when the library has it.
    pub fn set_watchdog(&self, ticks: u8, id: c_char) -> Option<i32> {
        // SAFETY: plain values.
        self.watchdog.map(|call| unsafe { call(ticks, id) })
    }

    /// `drdIsInitialized(id)`, when the library is DRD.
    pub fn is_initialized(&self, id: c_char) -> Option<bool> {
        // SAFETY: plain values.
        self.is_initialized.map(|call| unsafe { call(id) })
    }

    /// `drdAutoInit(id)`, when the library is DRD: the device moves on its own to find its references.
    pub fn auto_init(&self, id: c_char) -> Option<i32> {
        // SAFETY: plain values.
        self.auto_init.map(|call| unsafe { call(id) })
    }

    /// `dhdGetStatus(status, id)`, when the library has it: the status array, or the failing return.
    pub fn status(&self, id: c_char) -> Option<Result<[c_int; STATUS_ROOM], i32>> {
        let call = self.status?;
        let mut status = [0; STATUS_ROOM];
        // SAFETY: room for more entries than any SDK's DHD_MAX_STATUS.
        let result = unsafe { call(status.as_mut_ptr(), id) };
        Some(if result < 0 { Err(result) } else { Ok(status) })
    }
}

/// Why the DHD library or a device behind it cannot be used. Each message names the library.
#[derive(Debug, thiserror::Error)]
pub enum DhdError {
    /// No candidate exists.
    #[error(
        "no Force Dimension DHD library found (looked for {}); install the Force Dimension SDK, or set {} to the \
         library's path (or FORCEDIM_SDK to the SDK's folder)",
        looked.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        LIBRARY_VARIABLE
    )]
    NotFound {
        /// Where kinloop looked.
        looked: Vec<PathBuf>,
    },
    /// The file is not a loadable library.
    #[error("DHD library {library}: cannot be loaded: {reason}")]
    Load {
        /// The library.
        library: String,
        /// The loader's reason.
        reason: String,
    },
    /// Required calls are absent.
    #[error("DHD library {library}: lacks required symbols {symbols}; it is not a Force Dimension DHD/DRD library")]
    MissingSymbols {
        /// The library.
        library: String,
        /// The missing names, comma-separated.
        symbols: String,
    },
    /// The SDK is older than kinloop supports.
    #[error("DHD library {library}: SDK version {found} is older than {minimum}; install a newer Force Dimension SDK")]
    TooOld {
        /// The library.
        library: String,
        /// Its version.
        found: String,
        /// The oldest accepted.
        minimum: String,
    },
    /// `dhdOpenID` failed.
    #[error("DHD library {library}: cannot open device {index}: {reason} (is it plugged in and powered, and may this user open its USB device? see `kinloop devices`)")]
    Open {
        /// The library.
        library: String,
        /// The device index asked for.
        index: u8,
        /// The SDK's last error.
        reason: String,
    },
    /// The device is of a type kinloop has no spec for.
    #[error("DHD library {library}: device {index} reports system type {system}, which kinloop has no published spec for; known: {known}")]
    UnknownSystem {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
        /// What `dhdGetSystemType` said.
        system: i32,
        /// The known types.
        known: String,
    },
    /// The device does not know where it is, and the user did not ask kinloop to initialise it.
    #[error(
        "DHD library {library}: device {index} is not calibrated (drdIsInitialized is false), so its positions \
         cannot be trusted; calibrate it with the Force Dimension SDK's tools, or pass --dhd-auto-init to let \
         kinloop run drdAutoInit (the device moves on its own: let go of the handle and clear its workspace)"
    )]
    NotCalibrated {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
    },
    /// `drdAutoInit` was asked for and failed, or the library has no DRD calls.
    #[error("DHD library {library}: device {index}: drdAutoInit failed: {reason}")]
    AutoInit {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
        /// Why.
        reason: String,
    },
    /// The device's first reading is not usable.
    #[error("DHD library {library}: device {index} reads garbage ({what}); no force will be sent to it")]
    Garbage {
        /// The library.
        library: String,
        /// The device index.
        index: u8,
        /// What was wrong.
        what: String,
    },
}
