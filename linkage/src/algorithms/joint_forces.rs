//! Joint damping and PD actuators: generalized forces on the right-hand side of eq 1. Actuators make the
//! linkage active (the paper's future work).

use nalgebra::DVector;

use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::Model;

/// Fills `data.joint_force` with `-b q̇ + clamp(kp (target - q) - kd q̇)` for every joint.
pub fn joint_forces<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>) {
    if !model.has_joint_forces {
        data.joint_force.as_mut_slice().fill(0.0);
        return;
    }
    for (i, joint) in model.joints.iter().enumerate() {
        let mut tau = -joint.damping * qd[i];
        if let Some(a) = joint.actuator {
            tau += (a.kp * (a.target - q[i]) - a.kd * qd[i]).clamp(-a.max_effort, a.max_effort);
        }
        data.joint_force[i] = tau;
    }
}
