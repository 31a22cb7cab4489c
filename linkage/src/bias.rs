//! B(q, q̇), the Coriolis and centripetal generalized forces of eq 1, by the recursive Newton-Euler
//! algorithm in the world frame with q̈ = 0 and no gravity.

use crate::data::Data;
use crate::model::{Model, NO_PARENT};
use crate::space::{Space, VecOps};

/// Fills `data.bias`. Needs `forward_kinematics` and `forward_velocity`.
pub fn bias_forces<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let n = model.nq();
    let kin = &data.kin;
    for i in 0..n {
        let inertia = &kin.body_inertia[i];
        let v = &kin.body_velocity[i];
        // f_i = I_i a_i + v_i ×* I_i v_i: the force the body needs to follow its velocity-product motion.
        data.body_force[i] =
            S::inertia_mul(inertia, &kin.bias_acceleration[i]) + S::cross_force(v, &S::inertia_mul(inertia, v));
    }
    subtree_force_projections(model, &kin.motion_subspace, &mut data.body_force, data.bias.as_mut_slice());
}

/// The backward pass shared by B and G: `out_i = S_iᵀ F_i` with `F_i` the sum of the per-body `forces`
/// over body i's subtree (the spatial force joint i transmits). `forces` is scratch: on return an entry may
/// hold a partial sum.
#[inline]
pub(crate) fn subtree_force_projections<S: Space>(
    model: &Model<S>,
    motion_subspace: &[S::Spatial],
    forces: &mut [S::Spatial],
    out: &mut [f64],
) {
    // Joint i + 1's subtree force reaches its parent i in registers (see `articulated::factor`: the same
    // sums in the same order, without a store-to-load wait on the recursion's path).
    let mut from_next = None;
    for i in (0..model.nq()).rev() {
        let mut f = forces[i];
        if let Some(child) = from_next.take() {
            f += child;
        }
        out[i] = motion_subspace[i].dot(&f);
        let parent = model.joints[i].parent;
        // (A root at 0 also passes the first test, NO_PARENT + 1 wrapping to 0; the loop then ends.)
        if parent.wrapping_add(1) == i {
            from_next = Some(f);
        } else if parent != NO_PARENT {
            forces[parent] += f;
        }
    }
}
