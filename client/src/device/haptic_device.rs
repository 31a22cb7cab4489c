//! The device interface the haptic core drives: its spec, its state and its commands.

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{SceneKind, Space, VecOps};
use kinloop_protocol::wrench_limits::WrenchLimits;
use kinloop_protocol::DeviceCaps;

/// What a device can do, per operational axis (linear axes first, as everywhere in kinloop).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DeviceSpec {
    /// Human-readable model name.
    pub name: String,
    /// Actuated degrees of freedom.
    pub dof: u8,
    /// Planar `(x, y, θ)` or spatial `(v, ω)` operational axes.
    pub kind: SceneKind,
    /// Lower workspace bound per axis (m, rad). An axis whose bounds are equal is locked (neither sensed
    /// nor moving); an angular axis whose bounds reach beyond ±π turns without limit.
    pub workspace_min: Vec<f64>,
    /// Upper workspace bound per axis (m, rad).
    pub workspace_max: Vec<f64>,
    /// Peak force (N); 0 means no force actuation.
    pub max_force_n: f64,
    /// Force the device holds indefinitely (N), at most the peak: what scales are fitted to.
    pub continuous_force_n: f64,
    /// Peak torque (N m); 0 means the angular axes are sensed but not actuated.
    pub max_torque_nm: f64,
    /// Highest stiffness the device renders stably (N/m).
    pub max_stiffness: f64,
    /// Highest damping the device renders stably (N s/m).
    pub max_damping: f64,
    /// Highest stiffness the device renders stably on its angular axes (N m/rad; 0 without torque).
    pub max_angular_stiffness: f64,
    /// Highest damping the device renders stably on its angular axes (N m s/rad).
    pub max_angular_damping: f64,
    /// The mechanism's own viscous damping per axis (N s/m, N m s/rad): passivity bounds are made of it.
    pub damping: Vec<f64>,
    /// The device's own servo rate (Hz).
    pub native_rate_hz: f64,
    /// True when the device measures the hand wrench.
    pub has_force_sensor: bool,
    /// True when the handle senses whether a hand holds it (a presence or dead-man switch).
    #[serde(default)]
    pub has_presence_sensor: bool,
    /// Moving mass per linear axis (kg) and inertia per angular axis (kg m²) at the handle.
    pub mass: Vec<f64>,
}

impl DeviceSpec {
    /// The peaks the device renders (non-finite or negative peaks read as 0: refuse to render rather than
    /// guess).
    pub fn wrench_limits(&self) -> WrenchLimits {
        WrenchLimits::rated(self.max_force_n, self.max_torque_nm)
    }

    /// The capabilities sent in the `Join`.
    pub fn caps(&self) -> DeviceCaps {
        DeviceCaps {
            name: self.name.clone(),
            dof: self.dof,
            workspace_min: self.workspace_min.clone(),
            workspace_max: self.workspace_max.clone(),
            max_force_n: self.max_force_n,
            continuous_force_n: self.continuous_force_n,
            max_torque_nm: self.max_torque_nm,
            max_stiffness_n_per_m: self.max_stiffness,
            max_damping_ns_per_m: self.max_damping,
            max_angular_stiffness_nm_per_rad: self.max_angular_stiffness,
            max_angular_damping_nms_per_rad: self.max_angular_damping,
            damping: self.damping.clone(),
            mass: self.mass.clone(),
            native_rate_hz: self.native_rate_hz,
            has_force_sensor: self.has_force_sensor,
        }
    }

    /// Mass of the linear axes (the first one), kg: what the paper's per-kilogram gains multiply.
    pub fn linear_mass(&self) -> f64 {
        self.mass.first().copied().unwrap_or(1.0)
    }
}

/// One reading of a device, in the device's own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceState<S: Space> {
    /// Handle pose (quantized by the encoders).
    pub pose: OpPose<S>,
    /// Handle twist (linear, angular), as the device estimates it.
    pub twist: S::OpVec,
    /// Wrench the hand applies to the handle, when the device has a force sensor.
    pub hand_wrench: Option<S::OpVec>,
    /// Whether a hand holds the handle, when the device has a presence sensor (a dead-man switch in the
    /// handle, as on Haption's Virtuose): `Some(false)` fades the output and lets go of the VE's OP.
    pub grasped: Option<bool>,
}

impl<S: Space> DeviceState<S> {
    /// A 3-DOF device's reading in kinloop's axes (position m, velocity m/s): the scene's linear axes from
    /// it, its angular axes at rest (locked), no force sensor; `grasped` from the device's clutch button.
    pub fn linear(position: [f64; 3], velocity: [f64; 3], grasped: Option<bool>) -> Self {
        let mut point = <S::Point as VecOps>::zero();
        let mut twist = S::OpVec::zero();
        for (i, x) in point.as_mut_slice().iter_mut().enumerate() {
            *x = position[i];
            twist[i] = velocity[i];
        }
        DeviceState { pose: OpPose { position: point, rotation: S::rot_identity() }, twist, hand_wrench: None, grasped }
    }
}

/// Why a device call failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeviceError {
    /// The device refused or limited this command (over-force, over-temperature...); the next may work.
    #[error("device {device}: force error: {reason}")]
    Force {
        /// Which device.
        device: String,
        /// What it said.
        reason: String,
    },
    /// The device is unreachable; nothing more can be done with it.
    #[error("device {device}: communication lost: {reason}")]
    Communication {
        /// Which device.
        device: String,
        /// What failed.
        reason: String,
    },
}

impl DeviceError {
    /// True when the device cannot be used any more.
    pub fn is_fatal(&self) -> bool {
        matches!(self, DeviceError::Communication { .. })
    }
}

/// A haptic device the real-time loop drives: read, compute, command, once per tick.
pub trait HapticDevice<S: Space>: Send {
    /// What it can do.
    fn spec(&self) -> &DeviceSpec;
    /// Reads the device at `now` (time since the loop's epoch).
    fn read(&mut self, now: Duration) -> Result<DeviceState<S>, DeviceError>;
    /// Commands `wrench` (held until the next command).
    fn command(&mut self, now: Duration, wrench: &S::OpVec) -> Result<(), DeviceError>;
}

/// A boxed device is a device: the loop drives a simulated rig or a real device through one type.
impl<S: Space> HapticDevice<S> for Box<dyn HapticDevice<S>> {
    fn spec(&self) -> &DeviceSpec {
        (**self).spec()
    }

    fn read(&mut self, now: Duration) -> Result<DeviceState<S>, DeviceError> {
        (**self).read(now)
    }

    fn command(&mut self, now: Duration, wrench: &S::OpVec) -> Result<(), DeviceError> {
        (**self).command(now, wrench)
    }
}
