//! B(q, q̇), the Coriolis and centripetal generalized forces of eq 1, by the recursive Newton-Euler
//! algorithm in the world frame with q̈ = 0 and no gravity.

use crate::algorithms::tree::subtree_sums;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// Fills `data.bias`. Needs `forward_kinematics` and `forward_velocity`.
pub fn bias_forces<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let n = model.nv();
    let kin = &data.kin;
    for i in 0..n {
        let inertia = &kin.body_inertia[i];
        let v = &kin.body_velocity[i];
        // f_i = I_i a_i + v_i ×* I_i v_i: the force the body needs to follow its velocity-product motion.
        data.body_force[i] =
            S::inertia_mul(inertia, &kin.bias_acceleration[i]) + S::cross_force(v, &S::inertia_mul(inertia, v));
    }
    let bias = data.bias.as_mut_slice();
    subtree_sums(model, &mut data.body_force, |i, f| bias[i] = kin.motion_subspace[i].dot(f));
}
