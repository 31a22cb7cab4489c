//! Linearly-implicit joint springs, dampers and PD actuators for the semi-implicit Euler step.
//!
//! A joint spring `-k (q - r)` and damper `-b q̇` evaluated at the start of the step are stable only while
//! `h sqrt(k / m) < 2` and `h b / m < 2`, with `m` the joint's effective inertia: a spring sized by one heavy
//! link on a joint that moves a light one (a ratio of 1000 in mass is within a generated linkage's range)
//! breaks that bound at a kilohertz and the state goes non-finite. Evaluated at the end of the step instead
//! (`q + h q̇⁺`, `q̇⁺ = q̇ + h q̈`), to first order the step solves
//! `(D + h b + h² k) q̈ = τ - h k q̇` on the joint's diagonal, stable for any `k, b ≥ 0` (the same form as the
//! couplings', see `Forces::add_implicit`). An actuator inside its effort limit is a spring-damper of `kp, kd`;
//! a saturated one is a constant effort and adds nothing.

use nalgebra::{DMatrix, DVector};

use crate::math::space::Space;
use crate::model::{JointKind, Model};

/// Adds `h b + h² k` to `implicit_mass`'s diagonal and `-h k q̇` to `tau` for every revolute or prismatic joint
/// with a spring, damping or an actuator inside its limit at `(q, q̇)`. Returns true when it added anything.
pub fn add_implicit_joint_terms<S: Space>(
    model: &Model<S>,
    dt: f64,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    implicit_mass: &mut DMatrix<f64>,
    tau: &mut DVector<f64>,
) -> bool {
    if !model.has_joint_forces && !model.has_springs {
        return false;
    }
    let mut added = false;
    for (i, joint) in model.joints.iter().enumerate() {
        if !matches!(joint.kind, JointKind::Revolute | JointKind::Prismatic) {
            continue;
        }
        let mut stiffness = joint.spring.map_or(0.0, |s| s.stiffness.max(0.0));
        let mut damping = joint.damping.max(0.0);
        if let Some(a) = joint.actuator {
            let effort = a.kp * (a.target - q[joint.q_index]) - a.kd * qd[i];
            if effort.abs() < a.max_effort {
                stiffness += a.kp.max(0.0);
                damping += a.kd.max(0.0);
            }
        }
        if stiffness == 0.0 && damping == 0.0 {
            continue;
        }
        implicit_mass[(i, i)] += dt * damping + dt * dt * stiffness;
        tau[i] -= dt * stiffness * qd[i];
        added = true;
    }
    added
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::integrator::{step, StepConfig};
    use crate::math::space::Planar;
    use crate::model::data::Data;
    use crate::model::scene::{Scene, SpringSpec};

    /// A 5 g pendulum of 1 cm on a spring sized for a 5 kg link (k = 3 m g L with m = 5 kg): its natural
    /// frequency sqrt(k / I) is about 2,700 rad/s, so a 1 ms explicit step (h ω ≈ 2.7 > 2) diverges.
    fn stiff_pendulum() -> Model<Planar> {
        let mut scene = Scene::from_toml_str(
            r#"
kind = "planar"
gravity = [0.0, 0.0]

[[body]]
name = "link"
mass = 0.005
com = [0.005, 0.0]
inertia = 4e-8

[[joint]]
name = "pivot"
kind = "revolute"
parent = "ground"
child = "link"
q0 = 0.3
"#,
            "stiff.toml",
        )
        .expect("the test scene parses");
        scene.joints[0].spring = Some(SpringSpec { stiffness: 3.0 * 5.0 * 9.81 * 0.01, rest: 0.0 });
        Model::compile(&scene, "stiff").expect("the test scene compiles")
    }

    /// Runs one second at 1 kHz; returns the largest |q| seen, or None if a step failed.
    fn largest_angle(implicit: bool) -> Option<f64> {
        let model = stiff_pendulum();
        let mut data = Data::new(&model);
        let (mut q, mut qd) = (model.q0.clone(), DVector::zeros(model.nv()));
        let cfg = StepConfig { implicit_forces: implicit, ..StepConfig::euler(1e-3) };
        let mut largest: f64 = 0.0;
        for _ in 0..1000 {
            step(&model, &mut data, &mut q, &mut qd, &mut (), &cfg).ok()?;
            largest = largest.max(q[0].abs());
        }
        Some(largest)
    }

    #[test]
    fn a_stiff_joint_spring_stays_bounded_when_implicit() {
        let largest = largest_angle(true).expect("the implicit steps succeed");
        // A passive spring released at rest from 0.3 rad never passes 0.3 rad (the implicit step only loses energy).
        assert!(largest <= 0.3 + 1e-12, "largest angle {largest}");
    }

    #[test]
    fn the_same_spring_explicit_diverges() {
        // The independent check that the test above exercises the stiff case: the explicit step blows up.
        assert!(largest_angle(false).is_none_or(|a| a > 10.0));
    }
}
