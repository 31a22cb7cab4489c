//! An OpenHaptics device: opened (`hdInitDevice`), its spec read from the device (`hdGetDoublev`), and the
//! [`HapticDevice`] the vendor's servo thread drives: each `read` begins an HD frame (`hdBeginFrame`, then
//! position, velocity and buttons), each `command` sets the frame's force and ends it (`hdEndFrame`); the
//! errors each raised are read with `hdGetError` and reported with their code and text.
//!
//! Safety as with the DHD devices: `HD_FORCE_OUTPUT` is enabled at open, but zero is commanded until the
//! core's first non-zero command (it commands nothing before its first snapshot), and forces ramp in from
//! there over [`RAMP_IN`]; a gap between frames longer than [`STALL`] (a scheduler that stalled) zeroes the
//! output and ramps in again; every command is clamped to the device's nominal peak; an HD error in a frame
//! (`HD_COMM_ERROR` and its kin) or a non-finite reading ends the device with zero force; `hdDisableDevice`
//! runs on every way out (the lease's `Drop`). Button 1 is a clutch, as button 0 is on a DHD device.

use std::ffi::c_uint;
use std::marker::PhantomData;
use std::time::Duration;

use kinloop_linkage::math::space::{SceneKind, Space, VecOps};

use super::library::{constants, parse_version, HdError, HdLibrary, OLDEST_VERSION};
use super::units;
use crate::device::presets::DevicePreset;
use crate::device::{DeviceError, DeviceSpec, DeviceState, HapticDevice, HdRequest};

/// Time over which forces ramp from zero to full after the first command or a stall (s).
pub const RAMP_IN: Duration = Duration::from_millis(500);
/// A gap between frames longer than this is a stalled scheduler: zero, then ramp in again.
pub const STALL: Duration = Duration::from_millis(10);
/// The name `hdInitDevice` gets when none is asked for: `HD_DEFAULT_DEVICE`'s.
pub const DEFAULT_NAME: &str = "Default Device";

/// The figures the device reports, in SI (see [`units`]).
#[derive(Clone, Debug, PartialEq)]
pub struct HdSpec {
    /// `HD_DEVICE_MODEL_TYPE`.
    pub model: String,
    /// `HD_USABLE_WORKSPACE_DIMENSIONS` (m).
    pub workspace_min: [f64; 3],
    /// See `workspace_min`.
    pub workspace_max: [f64; 3],
    /// `HD_NOMINAL_MAX_FORCE` (N).
    pub max_force_n: f64,
    /// `HD_NOMINAL_MAX_CONTINUOUS_FORCE` (N).
    pub continuous_force_n: f64,
    /// `HD_NOMINAL_MAX_STIFFNESS` (N/m).
    pub max_stiffness: f64,
    /// `HD_NOMINAL_MAX_DAMPING` (N s/m).
    pub max_damping: f64,
}

impl HdSpec {
    /// The [`DeviceSpec`] kinloop designs for in a scene of `kind`: what the device reports, and what no
    /// device reports (apparent mass at the tip, mechanism damping) from the `sim:touch` preset; the
    /// angular axes locked (equal bounds: read as 0, never commanded), as the Touch outputs no torque.
    pub fn device_spec(&self, kind: SceneKind) -> DeviceSpec {
        let base = DevicePreset::Touch.spec(kind).ok();
        let linear = kind.point_dim();
        let per_axis = |lin: &[f64; 3]| (0..kind.op_dim()).map(|i| if i < linear { lin[i] } else { 0.0 }).collect();
        let mass = base.as_ref().map_or_else(|| vec![0.045; kind.op_dim()], |b| b.mass.clone());
        let damping = base.as_ref().map_or_else(|| vec![0.0; kind.op_dim()], |b| b.damping.clone());
        DeviceSpec {
            name: format!("{} (OpenHaptics)", self.model),
            dof: 3,
            kind,
            workspace_min: per_axis(&self.workspace_min),
            workspace_max: per_axis(&self.workspace_max),
            max_force_n: self.max_force_n,
            continuous_force_n: self.continuous_force_n,
            max_torque_nm: 0.0,
            max_stiffness: self.max_stiffness,
            max_damping: self.max_damping,
            max_angular_stiffness: 0.0,
            max_angular_damping: 0.0,
            damping,
            native_rate_hz: 1000.0,
            has_force_sensor: false,
            has_presence_sensor: false,
            mass,
        }
    }

    /// What is wrong with figures that cannot describe a device, if anything.
    fn garbage(&self) -> Option<String> {
        let positive = [self.max_force_n, self.continuous_force_n, self.max_stiffness, self.max_damping];
        if !positive.iter().all(|x| x.is_finite() && *x >= 0.0) || self.max_force_n <= 0.0 {
            return Some(format!(
                "nominal force {} N, continuous {} N, stiffness {} N/m, damping {} N s/m",
                self.max_force_n, self.continuous_force_n, self.max_stiffness, self.max_damping
            ));
        }
        let spans = (0..3).all(|i| {
            let (lo, hi) = (self.workspace_min[i], self.workspace_max[i]);
            lo.is_finite() && hi.is_finite() && hi > lo
        });
        (!spans).then(|| format!("workspace {:?} to {:?} m", self.workspace_min, self.workspace_max))
    }
}

/// The library's HDAPI version against [`OLDEST_VERSION`] (`hdGetString(HD_VERSION)` answers once a device
/// is initialised).
fn check_version(library: &HdLibrary) -> Result<(), HdError> {
    let text = library.version();
    let _ = library.error();
    match text.as_deref().map(|t| (t, parse_version(t))) {
        Some((_, Some(version))) if version >= OLDEST_VERSION => Ok(()),
        found => Err(HdError::Old {
            library: library.path().display().to_string(),
            found: found
                .map_or_else(|| "unknown (hdGetString(HD_VERSION) answers nothing)".into(), |f| format!("{:?}", f.0)),
        }),
    }
}

/// An initialised device: forces off and the device disabled when dropped.
struct Lease {
    library: &'static HdLibrary,
    handle: c_uint,
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.library.set_capability(constants::FORCE_OUTPUT, false);
        self.library.disable_device(self.handle);
        let _ = self.library.error();
    }
}

/// A device initialised and described, before a scene says which axes it uses.
pub struct OpenedHd {
    lease: Lease,
    name: String,
    spec: HdSpec,
}

impl OpenedHd {
    /// Initialises the device `request` names and reads its figures, a first error check and its
    /// calibration state (`hdCheckCalibration`, when the library has it); force output stays off. For
    /// `kinloop devices`, and the first half of [`OpenedHd::open`].
    pub fn describe(library: &'static HdLibrary, request: &HdRequest) -> Result<(OpenedHd, Option<bool>), HdError> {
        let lib_name = library.path().display().to_string();
        let name = request.name.clone().unwrap_or_else(|| DEFAULT_NAME.to_owned());
        let handle = library.init_device(request.name.as_deref()).map_err(|e| HdError::Init {
            library: lib_name.clone(),
            name: name.clone(),
            reason: library.describe(e),
        })?;
        let lease = Lease { library, handle };
        library.make_current(handle);
        check_version(library)?;
        let one = |pname| {
            let mut v = [f64::NAN];
            library.get_doubles(pname, &mut v);
            v[0]
        };
        let mut dims = [f64::NAN; 6];
        library.get_doubles(constants::USABLE_WORKSPACE_DIMENSIONS, &mut dims);
        let (workspace_min, workspace_max) = units::workspace(dims);
        let spec = HdSpec {
            model: library.model_name().unwrap_or_else(|| "OpenHaptics device".into()),
            workspace_min,
            workspace_max,
            max_force_n: one(constants::NOMINAL_MAX_FORCE),
            continuous_force_n: one(constants::NOMINAL_MAX_CONTINUOUS_FORCE),
            max_stiffness: units::per_mm_to_per_m(one(constants::NOMINAL_MAX_STIFFNESS)),
            max_damping: units::per_mm_to_per_m(one(constants::NOMINAL_MAX_DAMPING)),
        };
        let garbage = |what: String| HdError::Garbage { library: lib_name.clone(), name: name.clone(), what };
        if let Some(e) = library.error() {
            return Err(garbage(format!("reading its figures raised {}", library.describe(e))));
        }
        if let Some(what) = spec.garbage() {
            return Err(garbage(what));
        }
        let calibrated = library.check_calibration().map(|c| c != constants::CALIBRATION_NEEDS_UPDATE);
        Ok((OpenedHd { lease, name, spec }, calibrated))
    }

    /// Opens the device `request` names for rendering: as [`OpenedHd::describe`], calibrated (running
    /// `hdUpdateCalibration` only when asked), and force output enabled (zero is commanded until the
    /// session's first force).
    pub fn open(library: &'static HdLibrary, request: &HdRequest) -> Result<OpenedHd, HdError> {
        let (opened, calibrated) = OpenedHd::describe(library, request)?;
        let lib_name = || library.path().display().to_string();
        if calibrated == Some(false) {
            if !request.calibrate {
                return Err(HdError::NotCalibrated { library: lib_name(), name: opened.name.clone() });
            }
            library.update_calibration(constants::CALIBRATION_INKWELL);
        }
        library.set_capability(constants::FORCE_OUTPUT, true);
        if let Some(e) = library.error() {
            return Err(HdError::Init { library: lib_name(), name: opened.name.clone(), reason: library.describe(e) });
        }
        Ok(opened)
    }

    /// The name it was initialised by.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The figures the device reported.
    pub fn spec(&self) -> &HdSpec {
        &self.spec
    }

    /// The library it was opened through.
    pub fn library(&self) -> &'static HdLibrary {
        self.lease.library
    }

    /// The handle `hdInitDevice` gave.
    pub fn handle(&self) -> c_uint {
        self.lease.handle
    }

    /// The device for a scene of space `S`.
    pub fn into_device<S: Space>(self) -> HdDevice<S> {
        let spec = self.spec.device_spec(S::KIND);
        let label = format!("{} (HD device {:?}, {})", self.spec.model, self.name, self.lease.library.path().display());
        HdDevice {
            lease: self.lease,
            spec,
            label,
            in_frame: false,
            started: false,
            ramp_from: None,
            last_read: None,
            #[cfg(feature = "fault-injection")]
            panic_at: fault_injection::panic_at(),
            #[cfg(feature = "fault-injection")]
            frames: 0,
            _space: PhantomData,
        }
    }
}

/// The [`HapticDevice`] the vendor's servo thread drives, one frame per tick.
pub struct HdDevice<S: Space> {
    lease: Lease,
    spec: DeviceSpec,
    label: String,
    in_frame: bool,
    /// The first non-zero command came.
    started: bool,
    ramp_from: Option<Duration>,
    last_read: Option<Duration>,
    /// The frame whose read panics (see [`fault_injection`]).
    #[cfg(feature = "fault-injection")]
    panic_at: Option<u64>,
    /// Frames begun.
    #[cfg(feature = "fault-injection")]
    frames: u64,
    _space: PhantomData<S>,
}

impl<S: Space> HdDevice<S> {
    /// Zero force in the open frame (or one of its own) and end it: after a fault, a panic in the callback,
    /// and at the end. Raises nothing kinloop reads.
    pub fn zero_now(&mut self) {
        let library = self.lease.library;
        if !self.in_frame {
            library.begin_frame(self.lease.handle);
        }
        library.set_force(&[0.0; 3]);
        library.end_frame(self.lease.handle);
        self.in_frame = false;
        self.ramp_from = None;
        let _ = library.error();
    }

    /// Zero force and a fatal device error saying `why`.
    fn lost(&mut self, why: String) -> DeviceError {
        self.zero_now();
        DeviceError::Communication { device: self.label.clone(), reason: why }
    }

    fn check(&mut self, call: &str) -> Result<(), DeviceError> {
        match self.lease.library.error() {
            None => Ok(()),
            Some(e) => {
                let why = format!("{call} raised {}", self.lease.library.describe(e));
                Err(self.lost(why))
            }
        }
    }
}

impl<S: Space> HapticDevice<S> for HdDevice<S> {
    fn spec(&self) -> &DeviceSpec {
        &self.spec
    }

    fn read(&mut self, now: Duration) -> Result<DeviceState<S>, DeviceError> {
        let library = self.lease.library;
        if self.last_read.is_some_and(|last| now.saturating_sub(last) > STALL) {
            // A stalled scheduler: what was commanded is stale; ramp in again from the next command.
            self.ramp_from = None;
        }
        self.last_read = Some(now);
        library.begin_frame(self.lease.handle);
        self.in_frame = true;
        self.check("hdBeginFrame")?;
        #[cfg(feature = "fault-injection")]
        {
            self.frames += 1;
            fault_injection::maybe_panic(self.panic_at, self.frames);
        }
        let (mut p, mut v) = ([f64::NAN; 3], [f64::NAN; 3]);
        library.get_doubles(constants::CURRENT_POSITION, &mut p);
        library.get_doubles(constants::CURRENT_VELOCITY, &mut v);
        let buttons = library.get_int(constants::CURRENT_BUTTONS);
        self.check("hdGetDoublev")?;
        if !p.iter().chain(&v).all(|x| x.is_finite()) {
            return Err(
                self.lost(format!("non-finite reading from the HD library: position {p:?} mm, velocity {v:?} mm/s"))
            );
        }
        // Button 1 (bit 0) is the clutch: held, the hand counts as not grasping.
        Ok(DeviceState::linear(units::mm_to_m(p), units::mm_to_m(v), Some(buttons & 1 == 0)))
    }

    fn command(&mut self, now: Duration, wrench: &S::OpVec) -> Result<(), DeviceError> {
        let linear = S::KIND.point_dim();
        let force = &wrench.as_slice()[..linear];
        if !force.iter().all(|f| f.is_finite()) {
            self.zero_now();
            return Err(DeviceError::Force { device: self.label.clone(), reason: "non-finite wrench refused".into() });
        }
        self.started |= force.iter().any(|&f| f != 0.0);
        let gain = if self.started {
            let from = *self.ramp_from.get_or_insert(now);
            (now.saturating_sub(from).as_secs_f64() / RAMP_IN.as_secs_f64()).min(1.0)
        } else {
            0.0
        };
        let norm = force.iter().map(|f| f * f).sum::<f64>().sqrt();
        let clamp = if norm > self.spec.max_force_n { self.spec.max_force_n / norm } else { 1.0 };
        let mut scaled = [0.0; 3];
        for (out, f) in scaled.iter_mut().zip(force) {
            *out = f * clamp * gain;
        }
        let library = self.lease.library;
        if !self.in_frame {
            library.begin_frame(self.lease.handle);
        }
        library.set_force(&units::force_to_device(&scaled, linear));
        library.end_frame(self.lease.handle);
        self.in_frame = false;
        self.check("hdEndFrame")
    }
}

/// A panic inside the servo callback on demand, for the tests that check it is caught (kinloop's own code
/// has no panic a test could reach through the library): built only with the `fault-injection` feature,
/// which the workspace's tests turn on and no shipped build does.
#[cfg(feature = "fault-injection")]
pub mod fault_injection {
    /// The variable naming the frame (counted from 1) whose read panics, mid-frame.
    pub const PANIC_AT_FRAME: &str = "KINLOOP_FAULT_HD_PANIC_AT_FRAME";

    /// The frame `PANIC_AT_FRAME` names, if any.
    pub fn panic_at() -> Option<u64> {
        std::env::var(PANIC_AT_FRAME).ok()?.parse().ok()
    }

    /// Panics when `frame` is the one asked for.
    pub fn maybe_panic(at: Option<u64>, frame: u64) {
        if at == Some(frame) {
            panic!("{PANIC_AT_FRAME}: a panic injected at frame {frame}");
        }
    }
}
