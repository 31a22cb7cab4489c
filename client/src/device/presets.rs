//! Simulated devices with published characteristics. Where a datasheet is silent (moving mass, friction,
//! encoder resolution of a paper's custom device) the value chosen is written next to it with the reason.

use std::f64::consts::PI;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{SceneKind, Space, VecOps};

use super::simulated::{SimulatedDevice, SimulatedDeviceError, SimulatedDeviceParams};
use super::DeviceSpec;

/// A simulated device model, as named on the command line (`--device sim:paper`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DevicePreset {
    /// The paper's planar impedance device with a wrist force sensor (section VI).
    Paper,
    /// Novint Falcon: 3 translational DOF, about 8.9 N.
    Falcon,
    /// 3D Systems Touch: 6 DOF sensed, 3 translational actuated, about 3.3 N.
    Touch,
}

/// A device name that is not one of ours, or a device that cannot serve a scene's space.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PresetError {
    /// Unknown `--device` value.
    #[error("unknown device {0:?}; expected sim:paper, sim:falcon or sim:touch")]
    Unknown(String),
    /// The device has no such operational space.
    #[error("device {device} is planar only (axes x, y, θ) and cannot render a {kind:?} scene")]
    Unsupported {
        /// The preset.
        device: &'static str,
        /// The scene's space.
        kind: SceneKind,
    },
}

impl std::str::FromStr for DevicePreset {
    type Err = PresetError;

    /// `sim:paper`, `sim:falcon` or `sim:touch` (the `sim:` prefix may be omitted).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.strip_prefix("sim:").unwrap_or(s) {
            "paper" => Ok(DevicePreset::Paper),
            "falcon" => Ok(DevicePreset::Falcon),
            "touch" => Ok(DevicePreset::Touch),
            _ => Err(PresetError::Unknown(s.to_owned())),
        }
    }
}

/// Builds a per-axis list: `lin` on the linear axes, `ang` on the angular ones.
fn per_axis(kind: SceneKind, lin: f64, ang: f64) -> Vec<f64> {
    let linear = kind.point_dim();
    (0..kind.op_dim()).map(|i| if i < linear { lin } else { ang }).collect()
}

/// Per-axis list from explicit linear values (x, y[, z]) and one angular value for every angular axis.
fn axes(kind: SceneKind, linear: [f64; 3], ang: f64) -> Vec<f64> {
    let n = kind.point_dim();
    (0..kind.op_dim()).map(|i| if i < n { linear[i] } else { ang }).collect()
}

impl DevicePreset {
    /// The device a scene's space gets when none is asked for: the paper's planar device for planar
    /// scenes, a Touch (3 translations actuated, the stylus's rotations sensed) for spatial ones.
    pub fn for_kind(kind: SceneKind) -> Self {
        match kind {
            SceneKind::Planar => DevicePreset::Paper,
            SceneKind::Spatial => DevicePreset::Touch,
        }
    }

    /// Name as written on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DevicePreset::Paper => "sim:paper",
            DevicePreset::Falcon => "sim:falcon",
            DevicePreset::Touch => "sim:touch",
        }
    }

    /// The device's spec for a scene of `kind`.
    pub fn spec(self, kind: SceneKind) -> Result<DeviceSpec, PresetError> {
        let spec = match self {
            // The paper names no device; its experiment is planar, its user a constant wrench through a
            // force-sensed handle. Chosen: a 1 kg handle per linear axis (so the paper's per-kg gains read as
            // N/m), 0.005 kg m² in θ (a 10 cm handle bar), ±15 cm x-y travel (the testbed OP moves within
            // ±6 cm) and continuous rotation (the testbed's link 2 turns past ±π), 10 N and 0.2 N m peak,
            // 2000 N/m and 200 N s/m stable rendering (direct-drive linear motors).
            DevicePreset::Paper => {
                if kind != SceneKind::Planar {
                    return Err(PresetError::Unsupported { device: self.name(), kind });
                }
                DeviceSpec {
                    name: "paper planar impedance device (simulated)".into(),
                    dof: 3,
                    kind,
                    workspace_min: vec![-0.15, -0.15, -2.0 * PI],
                    workspace_max: vec![0.15, 0.15, 2.0 * PI],
                    max_force_n: 10.0,
                    // Linear motors hold about half their peak without overheating.
                    continuous_force_n: 5.0,
                    max_torque_nm: 0.2,
                    max_stiffness: 2000.0,
                    max_damping: 200.0,
                    // The linear figures through the handle's 5 cm lever (K r², B r²).
                    max_angular_stiffness: 5.0,
                    max_angular_damping: 0.5,
                    damping: self.damping(kind),
                    native_rate_hz: 1000.0,
                    has_force_sensor: true,
                    // An instrumented research handle: a presence switch beside the force sensor.
                    has_presence_sensor: true,
                    mass: vec![1.0, 1.0, 0.005],
                }
            }
            // Novint Falcon: 4" (10.16 cm) cube workspace, > 2 lbf (8.9 N), ~3000 N/m, 1 kHz, no rotation and no
            // force sensor. Effective grip mass ≈ 0.15 kg (parallel delta arms; not published). Its angular
            // axes are locked (equal bounds): nothing to sense, nothing to render.
            DevicePreset::Falcon => DeviceSpec {
                name: "Novint Falcon (simulated)".into(),
                dof: 3,
                kind,
                workspace_min: axes(kind, [-0.0508, -0.0508, -0.0508], 0.0),
                workspace_max: axes(kind, [0.0508, 0.0508, 0.0508], 0.0),
                max_force_n: 8.9,
                // Not published; the peak is a short-term figure for its small motors: taken as 45 %.
                continuous_force_n: 4.0,
                max_torque_nm: 0.0,
                max_stiffness: 3000.0,
                max_damping: 20.0,
                max_angular_stiffness: 0.0,
                max_angular_damping: 0.0,
                damping: self.damping(kind),
                native_rate_hz: 1000.0,
                has_force_sensor: false,
                has_presence_sensor: false,
                mass: per_axis(kind, 0.15, 1e-3),
            },
            // 3D Systems Touch: 160 x 120 x 70 mm, 3.3 N peak, ~400 N/m (x axis 1.26 N/mm peak is for short
            // contacts; 0.4 N/mm is the continuous figure used here), 1 kHz; gimbal sensed, not actuated;
            // apparent mass 45 g at the tip; stylus inertia ≈ 2e-5 kg m² (a 12 cm pen of 30 g).
            // Planar scenes use its x-y plane and the stylus roll as θ.
            DevicePreset::Touch => DeviceSpec {
                name: "3D Systems Touch (simulated)".into(),
                dof: 3,
                kind,
                workspace_min: axes(kind, [-0.08, -0.06, -0.035], -2.0),
                workspace_max: axes(kind, [0.08, 0.06, 0.035], 2.0),
                max_force_n: 3.3,
                // OpenHaptics' continuous figure (CHAI3D's device file, shared/haptics-facts.md).
                continuous_force_n: 0.88,
                max_torque_nm: 0.0,
                max_stiffness: 400.0,
                max_damping: 4.0,
                max_angular_stiffness: 0.0,
                max_angular_damping: 0.0,
                damping: self.damping(kind),
                native_rate_hz: 1000.0,
                has_force_sensor: false,
                has_presence_sensor: false,
                mass: per_axis(kind, 0.045, 2e-5),
            },
        };
        Ok(spec)
    }

    /// The mechanism's own viscous damping per axis (the spec advertises it, the plant has it).
    pub fn damping(self, kind: SceneKind) -> Vec<f64> {
        match self {
            DevicePreset::Paper => per_axis(kind, 0.02, 2e-5),
            DevicePreset::Falcon => per_axis(kind, 0.5, 0.0),
            DevicePreset::Touch => per_axis(kind, 0.05, 1e-5),
        }
    }

    /// Plant parameters of the simulation.
    pub fn params(self, kind: SceneKind) -> SimulatedDeviceParams {
        // Velocity from encoder differences is filtered as vendor SDKs do: one count per millisecond is
        // 1 mm/s on the paper's 1 µm encoder and 60 mm/s on the Falcon's, noise the damping gains would
        // turn into force ripple.
        let damping = self.damping(kind);
        let common = |coulomb: (f64, f64), resolution: (f64, f64), wall: (f64, f64), velocity_filter_hz: f64| {
            SimulatedDeviceParams {
                damping: damping.clone(),
                coulomb: per_axis(kind, coulomb.0, coulomb.1),
                coulomb_velocity: 2e-3,
                encoder_resolution: per_axis(kind, resolution.0, resolution.1),
                wall_stiffness: per_axis(kind, wall.0, wall.1),
                wall_damping: per_axis(kind, wall.0 / 100.0, wall.1 / 100.0),
                plant_rate_hz: 10_000.0,
                velocity_filter_hz,
            }
        };
        match self {
            // Direct-drive linear motors with 1 µm optical encoders: little friction (an impedance device whose
            // friction would otherwise mask the linkage's inertia, the very thing the experiment renders).
            DevicePreset::Paper => common((0.002, 1e-5), (1e-6, 1e-5), (5000.0, 5.0), 50.0),
            // 400 dpi encoders through the delta arms ≈ 60 µm; capstan friction ≈ 0.05 N.
            DevicePreset::Falcon => common((0.05, 0.0), (6e-5, 0.0), (3000.0, 1.0), 30.0),
            // 450 dpi ≈ 55 µm; gimbal pots ≈ 2 mrad.
            DevicePreset::Touch => common((0.03, 1e-5), (5.5e-5, 2e-3), (2000.0, 0.5), 30.0),
        }
    }

    /// A simulated device at the centre of its workspace, handle orientation at identity.
    pub fn build<S: Space>(self) -> Result<SimulatedDevice<S>, SimulatedDeviceBuildError> {
        let spec = self.spec(S::KIND)?;
        let mut centre = S::OpVec::zero();
        let linear = <S::Point as VecOps>::LEN;
        for i in 0..linear {
            centre[i] = 0.5 * (spec.workspace_min[i] + spec.workspace_max[i]);
        }
        self.build_at(S::op_lin(&centre))
    }

    /// A simulated device with its handle at `position` (clamped into the workspace), orientation identity.
    pub fn build_at<S: Space>(self, position: S::Point) -> Result<SimulatedDevice<S>, SimulatedDeviceBuildError> {
        let spec = self.spec(S::KIND)?;
        let params = self.params(S::KIND);
        let mut position = position;
        for (i, x) in position.as_mut_slice().iter_mut().enumerate() {
            *x = if x.is_finite() { x.clamp(spec.workspace_min[i], spec.workspace_max[i]) } else { 0.0 };
        }
        let start = OpPose { position, rotation: S::rot_identity() };
        Ok(SimulatedDevice::new(spec, &params, start)?)
    }
}

/// Why a preset device could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimulatedDeviceBuildError {
    /// The preset does not fit the space.
    #[error(transparent)]
    Preset(#[from] PresetError),
    /// The parameters were refused.
    #[error(transparent)]
    Device(#[from] SimulatedDeviceError),
}
