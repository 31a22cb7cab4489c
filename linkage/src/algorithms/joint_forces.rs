//! Joint damping and PD actuators: generalized forces on the right-hand side of eq 1. Actuators make the
//! linkage active (the paper's future work). The cuts' dampers and the range walls join them here (their
//! own files say how).

use nalgebra::DVector;

use crate::algorithms::cut_forces::add_cut_dampers;
use crate::algorithms::joint_limits::add_limit_walls;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::Model;

/// Fills `data.joint_force` with `-b q̇ + clamp(kp (target - q) - kd q̇)` for every joint, plus the cuts'
/// dampers and the range walls. Needs `forward_kinematics` and `forward_velocity` at `(q, q̇)`.
pub fn joint_forces<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>) {
    if !model.has_joint_forces {
        data.joint_force.as_mut_slice().fill(0.0);
        return;
    }
    for (i, joint) in model.joints.iter().enumerate() {
        let mut tau = -joint.damping * qd[i];
        if let Some(a) = joint.actuator {
            tau += (a.kp * (a.target - q[joint.q_index]) - a.kd * qd[i]).clamp(-a.max_effort, a.max_effort);
        }
        data.joint_force[i] = tau;
    }
    add_cut_dampers(model, &data.kin, &mut data.joint_force);
    add_limit_walls(model, &data.kin, q, qd, &mut data.joint_force);
}
