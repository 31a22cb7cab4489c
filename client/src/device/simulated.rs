//! A simulated haptic device: a rigid handle with mass and inertia per axis, viscous damping, smooth Coulomb
//! friction, stiff workspace walls, motor saturation, encoder quantization and a filtered velocity estimate.
//!
//! The plant is continuous; the haptic loop is discrete. [`SimulatedDevice::advance`] integrates the plant
//! over one haptic period in substeps of at most `1 / plant_rate_hz` (≥ 10 kHz: ten substeps per 1 kHz
//! tick) by semi-implicit Euler, holding the commanded wrench constant (zero-order hold), so a controller's
//! stability is judged against a plant that moves between its samples, as a real one does.
//!
//! Coordinates are the operational axes (linear first). Walls and encoder quantization act on the linear
//! position and on the rotation vector of the handle's orientation (exact for planar θ; for spatial
//! handles a per-component approximation that holds for the moderate rotations of gimbals).

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};

use kinloop_protocol::wrench_limits::{limit_wrench, WrenchLimits};

use super::DeviceSpec;

/// Plant parameters beyond the [`DeviceSpec`], per operational axis.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimulatedDeviceParams {
    /// Viscous damping (N s/m, N m s/rad).
    pub damping: Vec<f64>,
    /// Coulomb friction level (N, N m), smoothed as `F_c tanh(v / coulomb_velocity)`.
    pub coulomb: Vec<f64>,
    /// Velocity over which Coulomb friction reaches 76 % of its level (tanh(1)), m/s or rad/s.
    pub coulomb_velocity: f64,
    /// Encoder resolution (m, rad); 0 reads the exact pose.
    pub encoder_resolution: Vec<f64>,
    /// Workspace wall stiffness (N/m, N m/rad).
    pub wall_stiffness: Vec<f64>,
    /// Workspace wall damping while in contact with a wall.
    pub wall_damping: Vec<f64>,
    /// Plant integration rate (Hz), at least 10 kHz.
    pub plant_rate_hz: f64,
    /// Cut-off (Hz) of the first-order filter on the finite-difference velocity; 0 disables the filter.
    pub velocity_filter_hz: f64,
}

impl SimulatedDeviceParams {
    /// A frictionless, undamped, exactly measured plant with no walls in reach: for closed-form checks.
    pub fn ideal(op_dim: usize) -> Self {
        SimulatedDeviceParams {
            damping: vec![0.0; op_dim],
            coulomb: vec![0.0; op_dim],
            coulomb_velocity: 1e-3,
            encoder_resolution: vec![0.0; op_dim],
            wall_stiffness: vec![0.0; op_dim],
            wall_damping: vec![0.0; op_dim],
            plant_rate_hz: 10_000.0,
            velocity_filter_hz: 0.0,
        }
    }
}

/// Why a simulated device could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimulatedDeviceError {
    /// A per-axis list has the wrong length for the space.
    #[error("device {device}: {field} has {got} values, the {kind:?} operational space has {expected} axes")]
    WrongAxes {
        /// Device name.
        device: String,
        /// Which list.
        field: &'static str,
        /// Its length.
        got: usize,
        /// Axes of the space.
        expected: usize,
        /// The space.
        kind: kinloop_linkage::math::space::SceneKind,
    },
    /// A value that makes no physical sense (non-positive mass, plant slower than 10 kHz...).
    #[error("device {device}: {what}")]
    Invalid {
        /// Device name.
        device: String,
        /// What is wrong.
        what: String,
    },
}

/// Slowest plant integration rate accepted: ten substeps per 1 kHz tick.
pub const MIN_PLANT_RATE_HZ: f64 = 10_000.0;

/// The most substeps one `advance` takes (a stalled loop integrates a long gap in coarser steps).
const MAX_SUBSTEPS: usize = 10_000;

/// The simulated device (see the module documentation). Sans-IO: time enters only as `advance(dt, ..)`.
#[derive(Clone, Debug)]
pub struct SimulatedDevice<S: Space> {
    spec: DeviceSpec,
    limits: WrenchLimits,
    mass: S::OpVec,
    /// Mass a hand adds to the handle (see `attach_mass`).
    attached: S::OpVec,
    inverse_mass: S::OpVec,
    damping: S::OpVec,
    coulomb: S::OpVec,
    coulomb_velocity: f64,
    resolution: S::OpVec,
    wall_stiffness: S::OpVec,
    wall_damping: S::OpVec,
    workspace_min: S::OpVec,
    workspace_max: S::OpVec,
    /// Axes with equal workspace bounds: held still, read as their bound.
    locked: [bool; 6],
    /// Axes without walls (angular axes whose bounds reach beyond ±π).
    unbounded: [bool; 6],
    substep_s: f64,
    velocity_filter_hz: f64,
    pose: OpPose<S>,
    twist: S::OpVec,
    command: S::OpVec,
    applied_command: S::OpVec,
    measured: OpPose<S>,
    velocity_estimate: S::OpVec,
    since_sample_s: f64,
}

impl<S: Space> SimulatedDevice<S> {
    /// A device at rest at `start`, no command.
    pub fn new(
        spec: DeviceSpec,
        params: &SimulatedDeviceParams,
        start: OpPose<S>,
    ) -> Result<Self, SimulatedDeviceError> {
        let k = S::DIM;
        let axes = |field: &'static str, v: &[f64]| -> Result<S::OpVec, SimulatedDeviceError> {
            if v.len() != k {
                return Err(SimulatedDeviceError::WrongAxes {
                    device: spec.name.clone(),
                    field,
                    got: v.len(),
                    expected: k,
                    kind: S::KIND,
                });
            }
            Ok(S::OpVec::from_slice(v))
        };
        let invalid = |what: String| SimulatedDeviceError::Invalid { device: spec.name.clone(), what };
        let mass = axes("mass", &spec.mass)?;
        let workspace_min = axes("workspace_min", &spec.workspace_min)?;
        let workspace_max = axes("workspace_max", &spec.workspace_max)?;
        let damping = axes("damping", &params.damping)?;
        let coulomb = axes("coulomb", &params.coulomb)?;
        let resolution = axes("encoder_resolution", &params.encoder_resolution)?;
        let wall_stiffness = axes("wall_stiffness", &params.wall_stiffness)?;
        let wall_damping = axes("wall_damping", &params.wall_damping)?;
        if mass.as_slice().iter().any(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(invalid(format!("masses and inertias must be positive, got {:?}", spec.mass)));
        }
        if !(params.plant_rate_hz.is_finite() && params.plant_rate_hz >= MIN_PLANT_RATE_HZ) {
            return Err(invalid(format!(
                "plant rate {} Hz is below the {MIN_PLANT_RATE_HZ} Hz needed for an honest continuous plant",
                params.plant_rate_hz
            )));
        }
        let all = [&damping, &coulomb, &resolution, &wall_stiffness, &wall_damping];
        if all.iter().any(|v| v.as_slice().iter().any(|x| !(x.is_finite() && *x >= 0.0))) {
            return Err(invalid("damping, friction, resolution and wall gains must be finite and ≥ 0".into()));
        }
        if (0..k).any(|i| workspace_min[i].partial_cmp(&workspace_max[i]).is_none_or(|o| o.is_gt())) {
            return Err(invalid("every workspace_min must be ≤ its workspace_max".into()));
        }
        let linear = <S::Point as VecOps>::LEN;
        let mut locked = [false; 6];
        let mut unbounded = [false; 6];
        let mut inverse_mass = S::OpVec::zero();
        for i in 0..k {
            locked[i] = workspace_min[i] == workspace_max[i];
            unbounded[i] =
                i >= linear && workspace_min[i] < -std::f64::consts::PI && workspace_max[i] > std::f64::consts::PI;
            inverse_mass[i] = 1.0 / mass[i];
        }
        let limits = spec.wrench_limits();
        let mut device = SimulatedDevice {
            spec,
            limits,
            mass,
            attached: S::OpVec::zero(),
            inverse_mass,
            damping,
            coulomb,
            coulomb_velocity: params.coulomb_velocity.max(1e-9),
            resolution,
            wall_stiffness,
            wall_damping,
            workspace_min,
            workspace_max,
            locked,
            unbounded,
            substep_s: 1.0 / params.plant_rate_hz,
            velocity_filter_hz: params.velocity_filter_hz.max(0.0),
            pose: start,
            twist: S::OpVec::zero(),
            command: S::OpVec::zero(),
            applied_command: S::OpVec::zero(),
            measured: start,
            velocity_estimate: S::OpVec::zero(),
            since_sample_s: 0.0,
        };
        device.hold_locked_axes();
        device.measured = device.quantized_pose();
        Ok(device)
    }

    /// A hand holding the handle adds `mass` per axis (kg, kg m²) to the plant; zero when it lets go.
    /// Negative or non-finite values count as zero.
    pub fn attach_mass(&mut self, mass: &S::OpVec) {
        if *mass == self.attached {
            return;
        }
        self.attached = *mass;
        for i in 0..S::DIM {
            let extra = mass[i];
            let extra = if extra.is_finite() && extra > 0.0 { extra } else { 0.0 };
            self.inverse_mass[i] = 1.0 / (self.mass[i] + extra);
        }
    }

    /// The spec this device was built from.
    pub fn spec(&self) -> &DeviceSpec {
        &self.spec
    }

    /// Sets the wrench the motors produce from now on (saturated to the motors' limits, direction kept).
    pub fn set_command(&mut self, wrench: &S::OpVec) {
        self.command = *wrench;
        self.applied_command =
            if wrench.is_finite() { limit_wrench::<S>(wrench, &self.limits).0 } else { S::OpVec::zero() };
    }

    /// The wrench the motors actually produce (after saturation).
    pub fn applied_command(&self) -> S::OpVec {
        self.applied_command
    }

    /// The last commanded wrench, before saturation.
    pub fn commanded(&self) -> S::OpVec {
        self.command
    }

    /// The exact (unquantized) handle pose.
    pub fn true_pose(&self) -> OpPose<S> {
        self.pose
    }

    /// The exact handle twist.
    pub fn true_twist(&self) -> S::OpVec {
        self.twist
    }

    /// Integrates the plant for `dt_s` seconds under the held command and a constant `hand_wrench`.
    pub fn advance(&mut self, dt_s: f64, hand_wrench: &S::OpVec) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let hand = if hand_wrench.is_finite() { *hand_wrench } else { S::OpVec::zero() };
        let substeps = ((dt_s / self.substep_s).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let h = dt_s / substeps as f64;
        for _ in 0..substeps {
            let force = self.applied_command + hand + self.passive_wrench();
            for i in 0..S::DIM {
                self.twist[i] += force[i] * self.inverse_mass[i] * h;
            }
            self.hold_locked_axes();
            self.pose.integrate(&self.twist, h);
        }
        self.since_sample_s += dt_s;
    }

    /// Reads the encoders: the quantized pose and the filtered finite-difference twist since the last read.
    pub fn sample(&mut self) -> (OpPose<S>, S::OpVec) {
        let measured = self.quantized_pose();
        if self.since_sample_s > 0.0 {
            let raw = measured.difference(&self.measured) * (1.0 / self.since_sample_s);
            let alpha = if self.velocity_filter_hz > 0.0 {
                1.0 - (-2.0 * std::f64::consts::PI * self.velocity_filter_hz * self.since_sample_s).exp()
            } else {
                1.0
            };
            self.velocity_estimate += (raw - self.velocity_estimate) * alpha;
        }
        self.measured = measured;
        self.since_sample_s = 0.0;
        (measured, self.velocity_estimate)
    }

    /// Damping, friction and wall wrenches at the current state.
    fn passive_wrench(&self) -> S::OpVec {
        let coordinates = self.coordinates();
        let mut w = S::OpVec::zero();
        for i in 0..S::DIM {
            let v = self.twist[i];
            w[i] = -self.damping[i] * v - self.coulomb[i] * (v / self.coulomb_velocity).tanh();
            if self.unbounded[i] {
                continue;
            }
            let x = coordinates[i];
            // A penalty wall: a stiff spring, damped only while pressing into it (no sticky pull-back).
            let beyond = if x > self.workspace_max[i] {
                x - self.workspace_max[i]
            } else if x < self.workspace_min[i] {
                x - self.workspace_min[i]
            } else {
                0.0
            };
            if beyond != 0.0 {
                let into = if beyond * v > 0.0 { v } else { 0.0 };
                w[i] += -self.wall_stiffness[i] * beyond - self.wall_damping[i] * into;
            }
        }
        w
    }

    /// The pose as operational coordinates: position and rotation vector.
    fn coordinates(&self) -> S::OpVec {
        S::op(self.pose.position, S::rot_log(&self.pose.rotation))
    }

    fn hold_locked_axes(&mut self) {
        if !self.locked.iter().any(|l| *l) {
            return;
        }
        let mut c = self.coordinates();
        for i in 0..S::DIM {
            if self.locked[i] {
                self.twist[i] = 0.0;
                c[i] = self.workspace_min[i];
            }
        }
        self.pose = OpPose { position: S::op_lin(&c), rotation: S::rot_from_vector(&S::op_ang(&c)) };
    }

    fn quantized_pose(&self) -> OpPose<S> {
        let mut c = self.coordinates();
        for i in 0..S::DIM {
            let r = self.resolution[i];
            if r > 0.0 {
                c[i] = (c[i] / r).round() * r;
            }
        }
        OpPose { position: S::op_lin(&c), rotation: S::rot_from_vector(&S::op_ang(&c)) }
    }
}
