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
