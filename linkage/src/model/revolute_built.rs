//! A scene's ball and universal joints rewritten as revolute joints around gimbal bodies: the version a
//! user had to write before the multi-rate joints existed (a ball as three revolutes about x, y, z with two
//! gimbals; a universal as two revolutes with a cross-piece). The tests compare the two versions' motion and
//! the benchmarks their step times.
//!
//! The gimbals are small balls of `gimbal_mass` (a scene body needs a positive mass): with a mass far below
//! the links' the two versions have the same dynamics, to that ratio. The three revolutes start at zero,
//! where the x-y-z sequence is far from its singularity (the middle angle at ±90°).

use crate::model::scene::{BodySpec, GeometrySpec, JointKindSpec, JointSpec, Numbers, Scene};

/// Radius of a gimbal ball, m (drawn, and giving it a rotational inertia).
const GIMBAL_RADIUS: f64 = 0.005;

/// `scene` with every ball and universal joint replaced by revolutes and gimbals of `gimbal_mass` kg each.
pub fn revolute_built(scene: &Scene, gimbal_mass: f64) -> Scene {
    let mut out = scene.clone();
    out.name = format!("{} (revolute-built)", scene.name);
    out.joints.clear();
    for j in &scene.joints {
        let axes: Vec<Vec<f64>> = match j.kind {
            JointKindSpec::Ball => vec![vec![1.0, 0.0, 0.0], vec![0.0, 1.0, 0.0], vec![0.0, 0.0, 1.0]],
            JointKindSpec::Universal => j.axes.clone().unwrap_or_default(),
            _ => {
                out.joints.push(j.clone());
                continue;
            }
        };
        let mut parent = j.parent.clone();
        for (k, axis) in axes.iter().enumerate() {
            let last = k + 1 == axes.len();
            let child = if last { j.child.clone() } else { format!("{}-gimbal{}", j.name, k + 1) };
            if !last {
                out.bodies.push(gimbal(&child, gimbal_mass));
            }
            out.joints.push(JointSpec {
                name: format!("{}-{}", j.name, ["x", "y", "z"][k]),
                kind: JointKindSpec::Revolute,
                parent: parent.clone(),
                child: child.clone(),
                origin: if k == 0 { j.origin.clone() } else { Vec::new() },
                rotation: if k == 0 { j.rotation.clone() } else { None },
                axis: Some(axis.clone()),
                axes: None,
                q0: 0.0,
                qd0: 0.0,
                spring: None,
                damping: j.damping,
                armature: j.armature,
                actuator: None,
                range: None,
            });
            parent = child;
        }
    }
    out
}

fn gimbal(name: &str, mass: f64) -> BodySpec {
    let i = 0.4 * mass * GIMBAL_RADIUS * GIMBAL_RADIUS;
    BodySpec {
        name: name.to_string(),
        mass,
        com: vec![0.0; 3],
        inertia: Numbers::Many(vec![i, i, i]),
        geometry: vec![GeometrySpec::Ball { center: vec![0.0; 3], radius: GIMBAL_RADIUS }],
    }
}
