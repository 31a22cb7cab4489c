//! A DHD device as the loop's [`HapticDevice`], with the vendor's safety practice: forces enabled only at the
//! first non-zero command (the core commands nothing before its first snapshot) and ramped in; the device's
//! own watchdog armed where the SDK has it (`dhdSetWatchdog`), and the same rule in software (a read after
//! a stalled loop commands zero and ramps in again); every command clamped to the model's peak force; a
//! failing call or a non-finite reading commands zero and ends the device; so does the device switching
//! its forces off by itself (`dhdGetStatus`: its force button, its velocity limit), with the cause said,
//! except for its watchdog expiring, which is a stalled loop: zero at once, then forces enabled and ramped
//! in again as after a stall the software rule sees; `dhdClose` on every way out (the lease's `Drop` runs on return, on error and on a
//! panic's unwinding).
//!
//! Button 0 (`dhdGetButton`) is a clutch: while it is held the hand counts as not grasping (`grasped`
//! false): the output fades to zero and the VE lets go of the OP, so the user can move the handle freely;
//! released, the coupling takes hold again and forces fade back in.
//!
//! Calibration: a DRD library says whether the device knows where it is (`drdIsInitialized`). An
//! uncalibrated device is refused with what to do, unless the user asked kinloop to run `drdAutoInit`
//! (`--dhd-auto-init`): the device then moves on its own, which kinloop never starts unasked.

use std::ffi::c_char;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use kinloop_linkage::math::space::{SceneKind, Space, VecOps};

use super::frames;
use super::library::{self, DhdError, DhdLibrary};
use super::specs::{self, ModelSpec};
use crate::device::{DeviceError, DeviceSpec, DeviceState, DhdRequest, HapticDevice};

/// Time over which forces ramp from zero to full after they are enabled or after a stall (s).
pub const RAMP_IN: Duration = Duration::from_millis(500);
/// A gap between reads longer than this is a stalled loop: zero force, then ramp in again.
pub const STALL: Duration = Duration::from_millis(10);
/// The device's own watchdog, in `dhdSetWatchdog`'s units of 125 µs: 80 = 10 ms, as [`STALL`].
pub const WATCHDOG_TICKS: u8 = 80;

/// An open device: zeroes its force, disables forces and closes it when dropped.
struct Lease {
    library: Arc<DhdLibrary>,
    id: c_char,
}

impl Lease {
    fn zero(&self) {
        let _ = self.library.set_force([0.0; 3], self.id);
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.zero();
        let _ = self.library.enable_force(false, self.id);
        let _ = self.library.close(self.id);
    }
}

/// A device opened and identified, forces off, before a scene says which axes it uses.
pub struct OpenedDhd {
    lease: Lease,
    index: u8,
    model: &'static ModelSpec,
    calibrated: Option<bool>,
}

impl OpenedDhd {
    /// Opens device `index` of `library` (`dhdOpenID`), maps its system type to a model and checks a first
    /// reading is finite; forces stay off.
    pub fn open(library: Arc<DhdLibrary>, index: u8) -> Result<OpenedDhd, DhdError> {
        let name = library.path().display().to_string();
        let id = library.open(index);
        if id < 0 {
            return Err(DhdError::Open { library: name, index, reason: library.last_error() });
        }
        let lease = Lease { library, id: id as c_char };
        let system = lease.library.system_type(lease.id);
        let Some(model) = specs::model(system) else {
            return Err(DhdError::UnknownSystem { library: name, index, system, known: specs::known() });
        };
        let _ = lease.library.enable_force(false, lease.id);
        match lease.library.position(lease.id) {
            Ok(p) if p.iter().all(|x| x.is_finite()) => {}
            Ok(p) => return Err(DhdError::Garbage { library: name, index, what: format!("position {p:?} m") }),
            Err(status) => {
                let what = format!("dhdGetPosition returned {status}: {}", lease.library.last_error());
                return Err(DhdError::Garbage { library: name, index, what });
            }
        }
        let calibrated = lease.library.is_initialized(lease.id);
        Ok(OpenedDhd { lease, index, model, calibrated })
    }

    /// Opens the device `request` names for rendering: as [`OpenedDhd::open`], and calibrated. An
    /// uncalibrated device is refused unless the request asks for `drdAutoInit`, which then runs once.
    pub fn open_for_rendering(library: Arc<DhdLibrary>, request: &DhdRequest) -> Result<OpenedDhd, DhdError> {
        let mut opened = OpenedDhd::open(library, request.index)?;
        if opened.calibrated != Some(false) {
            return Ok(opened);
        }
        let name = opened.library().path().display().to_string();
        let index = request.index;
        if !request.auto_init {
            return Err(DhdError::NotCalibrated { library: name, index });
        }
        let lease = &opened.lease;
        let reason = match lease.library.auto_init(lease.id) {
            None => "the library has no drdAutoInit (it is not Force Dimension's DRD library)".to_owned(),
            Some(status) if status < 0 => format!("returned {status}: {}", lease.library.last_error()),
            Some(_) => match lease.library.is_initialized(lease.id) {
                Some(false) => "the device still reports itself uncalibrated".to_owned(),
                _ => {
                    opened.calibrated = Some(true);
                    return Ok(opened);
                }
            },
        };
        Err(DhdError::AutoInit { library: name, index, reason })
    }

    /// The model's published figures.
    pub fn model(&self) -> &'static ModelSpec {
        self.model
    }

    /// `drdIsInitialized`, when the library is DRD: false means the device wants `drdAutoInit`, which
    /// kinloop never runs unasked.
    pub fn calibrated(&self) -> Option<bool> {
        self.calibrated
    }

    /// The library it was opened through.
    pub fn library(&self) -> &DhdLibrary {
        &self.lease.library
    }

    /// A position read now (m, device frame), forces off.
    pub fn position(&self) -> Result<[f64; 3], String> {
        self.lease
            .library
            .position(self.lease.id)
            .map_err(|s| format!("returned {s}: {}", self.lease.library.last_error()))
    }

    /// The spec a scene of `kind` is designed for.
    pub fn spec(&self, kind: SceneKind) -> DeviceSpec {
        self.model.device_spec(kind)
    }

    /// The device for a scene of space `S`.
    pub fn into_device<S: Space>(self) -> DhdDevice<S> {
        let spec = self.spec(S::KIND);
        let label = format!("{} (DHD device {}, {})", self.model.name, self.index, self.lease.library.path().display());
        DhdDevice {
            lease: self.lease,
            spec,
            label,
            enabled: false,
            ramp_from: None,
            last_read: None,
            last_position: None,
            _space: PhantomData,
        }
    }
}

/// The [`HapticDevice`] the loop drives.
pub struct DhdDevice<S: Space> {
    lease: Lease,
    spec: DeviceSpec,
    label: String,
    enabled: bool,
    ramp_from: Option<Duration>,
    last_read: Option<Duration>,
    last_position: Option<([f64; 3], Duration)>,
    _space: PhantomData<S>,
}

impl<S: Space> DhdDevice<S> {
    /// Zero force now and a device error saying `why`: fatal, the device is not used again.
    fn lost(&mut self, why: String) -> DeviceError {
        self.lease.zero();
        DeviceError::Communication { device: self.label.clone(), reason: why }
    }

    /// The fraction of the commanded force let through at `now` while forces ramp in.
    fn ramp(&self, now: Duration) -> f64 {
        match self.ramp_from {
            Some(from) => (now.saturating_sub(from).as_secs_f64() / RAMP_IN.as_secs_f64()).min(1.0),
            None => 0.0,
        }
    }
}

impl<S: Space> HapticDevice<S> for DhdDevice<S> {
    fn spec(&self) -> &DeviceSpec {
        &self.spec
    }

    fn read(&mut self, now: Duration) -> Result<DeviceState<S>, DeviceError> {
        if self.last_read.is_some_and(|last| now.saturating_sub(last) > STALL) && self.enabled {
            // A stalled loop: whatever was commanded is stale. Zero now, ramp in again from the next command.
            self.lease.zero();
            self.ramp_from = None;
        }
        self.last_read = Some(now);
        let library = &self.lease.library;
        let position = match library.position(self.lease.id) {
            Ok(p) if p.iter().all(|x| x.is_finite()) => p,
            Ok(p) => return Err(self.lost(format!("non-finite position {p:?} m from the DHD library"))),
            Err(status) => {
                let why = format!("dhdGetPosition returned {status}: {}", library.last_error());
                return Err(self.lost(why));
            }
        };
        if self.enabled {
            if let Some(Ok(status)) = library.status(self.lease.id) {
                if status[library::STATUS_FORCE] == 0 {
                    let cause = status[library::STATUS_FORCE_OFF_CAUSE];
                    let said = library::force_off_cause(cause);
                    if cause != library::FORCE_OFF_WATCHDOG {
                        return Err(self.lost(format!("the device switched its forces off: {said}")));
                    }
                    // Its watchdog saw a stalled loop, as the software rule does: zero now, and the next
                    // command enables forces again and ramps them in from zero.
                    tracing::warn!("{}: the device switched its forces off: {said}; ramping in again", self.label);
                    self.lease.zero();
                    self.enabled = false;
                    self.ramp_from = None;
                }
            }
        }
        // Button 0 is the clutch (see the module documentation); a failing button read leaves it alone.
        let grasped = match library.button(0, self.lease.id) {
            1 => Some(false),
            0 => Some(true),
            _ => None,
        };
        let velocity = match library.velocity(self.lease.id) {
            Some(Ok(v)) if v.iter().all(|x| x.is_finite()) => v,
            Some(Ok(v)) => return Err(self.lost(format!("non-finite velocity {v:?} m/s from the DHD library"))),
            Some(Err(status)) => {
                let why = format!("dhdGetLinearVelocity returned {status}: {}", library.last_error());
                return Err(self.lost(why));
            }
            // Without the SDK's estimate: the difference of the last two reads.
            None => match self.last_position {
                Some((p0, t0)) if now > t0 => {
                    let dt = (now - t0).as_secs_f64();
                    [0, 1, 2].map(|i| (position[i] - p0[i]) / dt)
                }
                _ => [0.0; 3],
            },
        };
        self.last_position = Some((position, now));
        Ok(DeviceState::linear(frames::to_kinloop(position), frames::to_kinloop(velocity), grasped))
    }

    fn command(&mut self, now: Duration, wrench: &S::OpVec) -> Result<(), DeviceError> {
        let linear = S::KIND.point_dim();
        let force = &wrench.as_slice()[..linear];
        if !force.iter().all(|f| f.is_finite()) {
            self.lease.zero();
            return Err(DeviceError::Force { device: self.label.clone(), reason: "non-finite wrench refused".into() });
        }
        if !self.enabled {
            if force.iter().all(|&f| f == 0.0) {
                return Ok(());
            }
            // The first force: arm the device's watchdog, then enable forces, starting the ramp at zero.
            let _ = self.lease.library.set_watchdog(WATCHDOG_TICKS, self.lease.id);
            self.lease.zero();
            if self.lease.library.enable_force(true, self.lease.id) < 0 {
                let why = format!("dhdEnableForce failed: {}", self.lease.library.last_error());
                return Err(self.lost(why));
            }
            self.enabled = true;
        }
        self.ramp_from.get_or_insert(now);
        let norm = force.iter().map(|f| f * f).sum::<f64>().sqrt();
        let clamp = if norm > self.spec.max_force_n { self.spec.max_force_n / norm } else { 1.0 };
        let scale = clamp * self.ramp(now);
        let mut scaled = [0.0; 3];
        for (out, f) in scaled.iter_mut().zip(force) {
            *out = f * scale;
        }
        let status = self.lease.library.set_force(frames::to_device(&scaled, linear), self.lease.id);
        if status < 0 {
            let why = format!("dhdSetForce returned {status}: {}", self.lease.library.last_error());
            return Err(self.lost(why));
        }
        Ok(())
    }
}
