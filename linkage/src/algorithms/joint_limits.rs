//! Ranges of tree joints and cut freedoms: penalty walls at both ends, generalized forces on the right-hand
//! side of eq 1 beside the joint damping.
//!
//! A wall is a penalty spring-damper, the law the obstacle contacts use (`penalty::penalty_force`), not a
//! unilateral constraint: eq 4's KKT system holds equalities only, and a penalty force needs no
//! complementarity solve, keeps every step's cost fixed, and reaches a client the way contacts' and
//! springs' forces do, through the snapshot's bias. The price is a penetration of about `load / k` at rest
//! against the wall. The stiffness and damping come from the scene's `contact` parameters, multiplied by
//! `length_scale²` for an angle so that a wall turns the same way whatever unit the lengths are written in.
//! The clamp in the penalty law makes the wall push only, so it never gives back more than its spring took.

use nalgebra::DVector;

use crate::algorithms::cut_forces::{apply_along, freedom_state};
use crate::algorithms::penalty::penalty_force;
use crate::math::space::Space;
use crate::model::data::Kinematics;
use crate::model::{Model, Range};

/// The walls' generalized force on a coordinate at `position` moving at `rate` (positive pushes up): the
/// lower wall pushes up when `position < lo`, the upper one down when `position > hi`.
pub fn wall_force(range: &Range, position: f64, rate: f64) -> f64 {
    penalty_force(range.stiffness, range.damping, position - range.lo, rate)
        - penalty_force(range.stiffness, range.damping, range.hi - position, -rate)
}

/// Energy held by the walls' springs at `position`: `½ k d²` for a penetration `d`.
pub fn wall_energy(range: &Range, position: f64) -> f64 {
    let depth = (range.lo - position).max(position - range.hi).max(0.0);
    0.5 * range.stiffness * depth * depth
}

/// Adds every range wall's force to the joint forces `tau`, at `(q, q̇)` whose kinematics (positions and
/// velocities) are in `kin`.
pub fn add_limit_walls<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    tau: &mut DVector<f64>,
) {
    for (i, joint) in model.joints.iter().enumerate() {
        if let Some(range) = &joint.range {
            tau[i] += wall_force(range, q[joint.q_index], qd[i]);
        }
    }
    for cut in &model.cuts {
        if let (Some(range), Some(s)) = (&cut.range, cut.range.and_then(|_| freedom_state(&cut.freedom, kin))) {
            let f = wall_force(range, s.position, s.rate);
            if f != 0.0 {
                apply_along(model, kin, &cut.freedom, f, tau);
            }
        }
    }
}

/// Energy held by every range wall at `q`, whose positions are in `kin`.
pub fn limit_wall_energy<S: Space>(model: &Model<S>, kin: &Kinematics<S>, q: &DVector<f64>) -> f64 {
    let joints: f64 = model.joints.iter().filter_map(|j| j.range.as_ref().map(|r| wall_energy(r, q[j.q_index]))).sum();
    let cuts: f64 = model
        .cuts
        .iter()
        .filter_map(|c| Some(wall_energy(c.range.as_ref()?, freedom_state(&c.freedom, kin)?.position)))
        .sum();
    joints + cuts
}
