//! Published specs per DHD system type (`dhdGetSystemType`; the constants are `dhdc.h`'s `DHD_DEVICE_*`).
//!
//! Workspace, force, DOF and gripper are the vendor's published figures (Force Dimension's product pages and
//! datasheets; Novint's Falcon specification). The translational workspace is the box inscribed in the
//! published cylinder (diameter d, height h: ±d/(2√2) across, ±h/2 up). The stiffness and damping a 1 kHz
//! loop over USB renders stably are no datasheet's: they are CHAI3D's for the same models (its Force
//! Dimension driver, `CDeltaDevices.cpp`), well below the published closed-loop stiffness, which is a
//! mechanical figure, not a rendering one. What nobody publishes (moving mass at the handle, mechanism
//! damping) is chosen, and the reason written beside it.

use std::f64::consts::SQRT_2;

use kinloop_linkage::math::space::SceneKind;

use crate::device::DeviceSpec;

/// A model's figures, linear axes in kinloop's order (right, up, towards the user; see [`super::frames`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelSpec {
    /// `dhdGetSystemType`'s value.
    pub system: i32,
    /// The product's name.
    pub name: &'static str,
    /// Half the workspace per kinloop axis (m).
    pub half_extent: [f64; 3],
    /// Peak force (N).
    pub max_force_n: f64,
    /// Continuous force (N).
    pub continuous_force_n: f64,
    /// Stiffness rendered stably (N/m), chosen.
    pub max_stiffness: f64,
    /// Damping rendered stably (N s/m), chosen.
    pub max_damping: f64,
    /// Apparent moving mass at the handle (kg), chosen.
    pub mass: f64,
    /// Mechanism damping (N s/m), chosen.
    pub damping: f64,
    /// Actuated DOF (translations; rotations of the 6- and 7-DOF models are sensed or actuated by the SDK's
    /// wrist calls, which kinloop does not use yet).
    pub dof: u8,
    /// Whether it has a gripper.
    pub gripper: bool,
    /// Where the published figures come from.
    pub source: &'static str,
}

/// The inscribed box of a cylinder of diameter `d` and height `h` (m): right, up, towards the user.
const fn cylinder(d: f64, h: f64) -> [f64; 3] {
    [d / (2.0 * SQRT_2), h / 2.0, d / (2.0 * SQRT_2)]
}

// Rendering limits of the omega family as CHAI3D's Force Dimension driver sets them for a 1 kHz loop
// (chai3d/chai3d, src/devices/CDeltaDevices.cpp, omega.3/6/7: 12 N, 5000 N/m, 30 N s/m), about a third
// of the published 14.5 N/mm closed-loop stiffness, a mechanical figure. Force Dimension publishes one
// force for the omega.3, 12.0 N continuous, which is also the most its controller outputs: peak and
// continuous are the same figure. The handle's apparent mass ≈ 0.2 kg is chosen (not published).
const OMEGA: ModelSpec = ModelSpec {
    system: 33,
    name: "Force Dimension omega.3",
    half_extent: cylinder(0.160, 0.110),
    max_force_n: 12.0,
    continuous_force_n: 12.0,
    max_stiffness: 5000.0,
    max_damping: 30.0,
    mass: 0.2,
    damping: 0.5,
    dof: 3,
    gripper: false,
    source: "forcedimension.com omega.3 specifications: workspace ⌀160 x 110 mm, continuous force 12.0 N; \
             rendering limits: CHAI3D CDeltaDevices.cpp",
};

/// Every model kinloop knows.
pub const MODELS: [ModelSpec; 7] = [
    OMEGA,
    ModelSpec {
        system: 34,
        name: "Force Dimension omega.6",
        dof: 3,
        source: "forcedimension.com omega.6 specifications: translation as omega.3, rotations sensed",
        ..OMEGA
    },
    ModelSpec {
        system: 35,
        name: "Force Dimension omega.7",
        gripper: true,
        source: "forcedimension.com omega.7 specifications: translation as omega.3, active gripper",
        ..OMEGA
    },
    DELTA3,
    ModelSpec {
        system: 64,
        name: "Force Dimension delta.6",
        mass: 0.6,
        source: "forcedimension.com delta.6 specifications: translation as delta.3",
        ..DELTA3
    },
    ModelSpec {
        system: 104,
        name: "Force Dimension sigma.7",
        half_extent: cylinder(0.190, 0.130),
        max_force_n: 20.0,
        continuous_force_n: 20.0,
        // CHAI3D's driver renders the sigma.7 at most 4000 N/m (CDeltaDevices.cpp).
        max_stiffness: 4000.0,
        gripper: true,
        source: "forcedimension.com sigma.7 specifications: workspace ⌀190 x 130 mm, continuous force 20.0 N",
        ..OMEGA
    },
    // Novint Falcon: a 4" (101.6 mm) cube, more than 2 lbf (8.9 N); its small motors' continuous force is
    // not published: taken as 45 %. The stiffness and damping a 1 kHz loop renders on it as kinloop's
    // sim:falcon preset takes them.
    ModelSpec {
        system: 60,
        name: "Novint Falcon (DHD)",
        half_extent: [0.0508, 0.0508, 0.0508],
        max_force_n: 8.9,
        continuous_force_n: 4.0,
        max_stiffness: 3000.0,
        max_damping: 20.0,
        mass: 0.15,
        damping: 0.5,
        dof: 3,
        gripper: false,
        source: "Novint Falcon specification: 4 in cube workspace, > 2 lbf force, 400 dpi",
    },
];

const DELTA3: ModelSpec = ModelSpec {
    system: 63,
    name: "Force Dimension delta.3",
    half_extent: cylinder(0.400, 0.260),
    max_force_n: 20.0,
    continuous_force_n: 20.0,
    mass: 0.5,
    source: "forcedimension.com delta.3 specifications: workspace ⌀400 x 260 mm, continuous force 20.0 N",
    ..OMEGA
};

/// The model of system type `system`.
pub fn model(system: i32) -> Option<&'static ModelSpec> {
    MODELS.iter().find(|m| m.system == system)
}

/// The known system types, for messages.
pub fn known() -> String {
    MODELS.iter().map(|m| format!("{} ({})", m.system, m.name)).collect::<Vec<_>>().join(", ")
}

impl ModelSpec {
    /// The [`DeviceSpec`] kinloop designs for, in a scene of `kind`: the linear axes the scene uses (x, y
    /// planar; x, y, z spatial), every angular axis locked (equal bounds: read as 0, never commanded).
    pub fn device_spec(&self, kind: SceneKind) -> DeviceSpec {
        let linear = kind.point_dim();
        let per_axis = |lin: &dyn Fn(usize) -> f64, ang: f64| -> Vec<f64> {
            (0..kind.op_dim()).map(|i| if i < linear { lin(i) } else { ang }).collect()
        };
        DeviceSpec {
            name: self.name.into(),
            dof: self.dof,
            kind,
            workspace_min: per_axis(&|i| -self.half_extent[i], 0.0),
            workspace_max: per_axis(&|i| self.half_extent[i], 0.0),
            max_force_n: self.max_force_n,
            continuous_force_n: self.continuous_force_n,
            max_torque_nm: 0.0,
            max_stiffness: self.max_stiffness,
            max_damping: self.max_damping,
            max_angular_stiffness: 0.0,
            max_angular_damping: 0.0,
            damping: per_axis(&|_| self.damping, 0.0),
            native_rate_hz: 1000.0,
            has_force_sensor: false,
            has_presence_sensor: false,
            mass: per_axis(&|_| self.mass, 1e-3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_model_is_known_once_and_gives_a_consistent_spec() {
        for (i, m) in MODELS.iter().enumerate() {
            assert!(MODELS.iter().skip(i + 1).all(|o| o.system != m.system), "{} twice", m.system);
            assert!(!m.source.is_empty() && m.continuous_force_n <= m.max_force_n, "{}", m.name);
            for kind in [SceneKind::Planar, SceneKind::Spatial] {
                let spec = m.device_spec(kind);
                assert_eq!(spec.workspace_min.len(), kind.op_dim());
                // The angular axes are locked: equal bounds.
                for axis in kind.point_dim()..kind.op_dim() {
                    assert_eq!(spec.workspace_min[axis], spec.workspace_max[axis]);
                }
            }
        }
        // The omega.3's published cylinder, ⌀160 x 110 mm: the inscribed box is 113 mm across, 110 mm up.
        let omega = model(33).expect("omega.3");
        assert!(
            (2.0 * omega.half_extent[0] - 0.1131).abs() < 1e-4 && (2.0 * omega.half_extent[1] - 0.110).abs() < 1e-12
        );
        assert_eq!(model(60).expect("Falcon").max_force_n, 8.9);
        assert!(model(999).is_none());
    }
}
