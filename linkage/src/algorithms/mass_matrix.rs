//! D(q), the joint-space mass matrix of eq 1, by the composite-rigid-body algorithm in the world frame.
//!
//! With every quantity at the world origin, a subtree's composite inertia is the plain sum of its bodies'
//! spatial inertias and `D_ji = S_jᵀ I^c_i S_i` for each joint j supporting body i: no transforms at all.
//! A joint's armature (a rotor's reflected inertia, as MJCF's) adds to its diagonal entry, `D_ii += a_i`.

use crate::algorithms::jacobian::support;
use crate::algorithms::tree::subtree_sums;
use crate::math::dense::by_size;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// Fills `data.mass_matrix` unless it already belongs to the current kinematics. Needs `forward_kinematics`.
pub fn ensure<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    if !data.mass_matrix_fresh {
        mass_matrix(model, data);
    }
}

/// Fills `data.mass_matrix` (symmetric, n×n). Needs `forward_kinematics`.
pub fn mass_matrix<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let n = model.nv();
    let composite = &mut data.composite_inertia;
    composite.copy_from_slice(&data.kin.body_inertia);
    subtree_sums(model, composite, |_, _| ());
    let d = &mut data.mass_matrix;
    if !model.is_chain() {
        // Entries between joints on different branches are structural zeros, never written below.
        d.as_mut_slice().fill(0.0);
    }
    let s = &data.kin.motion_subspace;
    let a = d.as_mut_slice();
    // For a small chain the loop bounds are constants and each entry is mirrored as it is made: no bounds
    // checks, no second pass (the same dot products, so the same D bit for bit).
    if model.is_chain() {
        by_size!(n, N => {
            chain_small::<S, N>(&s[..N], &composite[..N], &mut a[..N * N]);
            add_armature(model, a);
            data.mass_matrix_fresh = true;
            return;
        }, _ => ());
    }
    for i in 0..n {
        let f = S::inertia_mul(&data.composite_inertia[i], &s[i]);
        // Column i above the diagonal (contiguous), then mirrored below.
        if model.chain_prefix[i] {
            for (j, dst) in a[i * n..i * n + i + 1].iter_mut().enumerate() {
                *dst = s[j].dot(&f);
            }
        } else {
            for j in support(model, Some(i)) {
                a[i * n + j] = s[j].dot(&f);
            }
        }
    }
    // Mirror: column c below the diagonal is row c right of it (a strided read of the later columns).
    for c in 0..n.saturating_sub(1) {
        let (left, right) = a.split_at_mut((c + 1) * n);
        for (dst, col) in left[c * n + c + 1..].iter_mut().zip(right.chunks_exact(n)) {
            *dst = col[c];
        }
    }
    add_armature(model, a);
    data.mass_matrix_fresh = true;
}

/// `D_ii += a_i` for every joint with an armature (`a`: D column-major, n×n).
fn add_armature<S: Space>(model: &Model<S>, a: &mut [f64]) {
    let n = model.nv();
    for (i, joint) in model.joints.iter().enumerate().filter(|(_, j)| j.armature != 0.0) {
        a[i * n + i] += joint.armature;
    }
}

/// D of a chain of N joints from the composite inertias (see [`mass_matrix`]), both triangles.
#[inline(always)]
fn chain_small<S: Space, const N: usize>(s: &[S::Spatial], composite: &[S::Inertia], a: &mut [f64]) {
    for i in 0..N {
        let f = S::inertia_mul(&composite[i], &s[i]);
        for j in 0..=i {
            let v = s[j].dot(&f);
            a[i * N + j] = v;
            a[j * N + i] = v;
        }
    }
}
