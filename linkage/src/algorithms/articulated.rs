//! The factor U of `D = U Uᵀ` (the tree-sparse factor of `ltl`, same storage and zeros) computed straight
//! from the bodies' spatial inertias, without forming D: the articulated-body inertias of Featherstone's
//! ABA, accumulated from the leaves in the world frame, give column k of U as
//! ```text
//! U_kk = √(S_kᵀ I^A_k S_k),   U_ik = S_iᵀ I^A_k S_k / U_kk   for every joint i supporting body k,
//! I^A_k = I_k + Σ_{children c} (I^A_c - I^A_c S_c S_cᵀ I^A_c / U_cc²).
//! ```
//!
//! **Why it is the same factor.** In the world frame `D_ij = S_iᵀ I^c_k S_j`, with k the deeper of bodies i
//! and j and `I^c_k` the sum of the inertias of k's subtree (see `mass_matrix`). The LTL order eliminates
//! the joints from the leaves. Eliminating joint c subtracts `D_·c D_cᵀ / D_cc` from the rows and columns of
//! c's supporting joints, which all see body c through the same `I^c_c S_c`: the matrix that remains is
//! again a mass matrix of the same form, in which body c's inertia has become its articulated inertia minus
//! `I S_c S_cᵀ I / (S_cᵀ I S_c)` — ABA's recursion, folded into the parent. When it is joint k's turn,
//! column k of what remains is `S_iᵀ I^A_k S_k`, and LTL divides it by the square root of its diagonal.
//!
//! **Armature.** A joint's armature `a_k` adds to `D_kk` only, so it adds to the pivot, `U_kk² = S_kᵀ I^A_k S_k
//! plus a_k`, and the parent carries `I^A_k - I^A_k S_k S_kᵀ I^A_k / U_kk²` (ABA's `D_i = S_iᵀ I^A_i S_i + a_i`,
//! as in MuJoCo and Pinocchio's rotor inertia).
//!
//! **Why faster.** D costs one dot product per nonzero of U plus the composite inertias, and factoring it
//! `O(Σ_k depth_k²)` more. Here the factorization *is* the dot products, plus one `DIM×DIM` update per body
//! (the step benchmarks show what it saves, most on long chains). D itself is then
//! computed only where it is read ([`crate::algorithms::mass_matrix::ensure`], called by
//! [`crate::algorithms::local_model::ConfigSpaceTerms::fill_from`]), for `implicit_mass`, which is added to D, and for
//! callers that set `Data::keep_mass_matrix`.

use crate::algorithms::jacobian::support;
use crate::algorithms::tree::follows_parent;
use crate::error::DynamicsError;
use crate::math::space::{MatOps, Space, VecOps};
use crate::model::data::Data;
use crate::model::{Model, NO_PARENT};

/// Fills `data.kkt.factor` (upper triangle: U) and `data.kkt.factor_inv_diag` (`1/U_kk`) for D(q).
/// Needs `forward_kinematics` (body inertias and motion subspaces). Errors when a pivot is not positive
/// (a body without inertia along its joint's motion), as `ltl::factor_sum` does.
pub fn factor<S: Space>(model: &Model<S>, data: &mut Data<S>) -> Result<(), DynamicsError> {
    let n = model.nv();
    let kin = &data.kin;
    let articulated = &mut data.articulated_inertia;
    articulated.copy_from_slice(&kin.body_inertia);
    let u = data.kkt.factor.as_mut_slice();
    if !model.is_chain() {
        // Entries between joints on different branches are structural zeros, never written below.
        u.fill(0.0);
    }
    let inv_diag = data.kkt.factor_inv_diag.as_mut_slice();
    let s = &kin.motion_subspace;
    // What joint k + 1 hands to its parent k, kept in registers (see `model::follows_parent`; as in
    // `model::subtree_sums`, adding it last keeps the order of the sums: the factor is bit for bit what
    // accumulating in memory gives). Through memory, the next joint's loads of its inertia straddled the
    // stores just made (a 3x3 or 6x6 matrix is not written in the shape it is read).
    let mut from_next: Option<S::Inertia> = None;
    for k in (0..n).rev() {
        let mut inertia = articulated[k];
        if let Some(carried) = from_next.take() {
            inertia += carried;
        }
        let f = S::inertia_mul(&inertia, &s[k]);
        let pivot = s[k].dot(&f) + model.joints[k].armature;
        if pivot.is_nan() || pivot <= 0.0 {
            return Err(DynamicsError::MassNotPositive { joint: k, pivot });
        }
        // sqrt(p) and 1/p side by side rather than 1/sqrt(p) in sequence (as in `ltl`). What the parent
        // carries needs only 1/p (f fᵀ/p below), not the square root: the recursion from leaf to root, a
        // chain of dependent operations, waits for one division per joint, and sqrt runs beside it.
        let inv_pivot = 1.0 / pivot;
        let ukk = pivot.sqrt();
        let inv = ukk * inv_pivot;
        inv_diag[k] = inv;
        let g = f * inv;
        let column = &mut u[k * n..k * n + k + 1];
        column[k] = ukk;
        if model.chain_prefix[k] {
            for (dst, sj) in column[..k].iter_mut().zip(s) {
                *dst = sj.dot(&g);
            }
        } else {
            for j in support(model, Some(k)).skip(1) {
                column[j] = s[j].dot(&g);
            }
        }
        let parent = model.joints[k].parent;
        if parent != NO_PARENT {
            // I^A_k - I^A_k S_k S_kᵀ I^A_k / U_kk² = I^A_k - (f fᵀ)/p, what the parent carries of body k
            // (f_r f_c, then 1/p: bit-for-bit symmetric).
            let mut carried = inertia;
            let (f, m) = (f.as_slice(), carried.as_mut_slice());
            for (c, fc) in f.iter().enumerate() {
                for (r, fr) in f.iter().enumerate() {
                    m[c * f.len() + r] -= fr * fc * inv_pivot;
                }
            }
            if follows_parent(parent, k) {
                from_next = Some(carried);
            } else {
                articulated[parent] += carried;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::kinematics::forward_kinematics;
    use crate::algorithms::mass_matrix::mass_matrix;
    use crate::testing::{for_each_model, random_state};

    /// U Uᵀ reproduces D from `mass_matrix`, U equals `ltl`'s factor of that D to round-off with the same
    /// structural zeros, on every built-in scene (chains, branches, planar and spatial), as written and with
    /// an armature on every joint (which adds to D's diagonal and nowhere else).
    #[test]
    fn factor_is_ltl_of_the_mass_matrix() {
        fn check<S: Space>(name: &str, model: &Model<S>) {
            let n = model.nv();
            let mut data = Data::new(model);
            for seed in 0..5 {
                let (q, _) = random_state(model, seed);
                forward_kinematics(model, &mut data, &q);
                mass_matrix(model, &mut data);
                let d = data.mass_matrix.clone();
                let mut ltl_u = d.clone();
                crate::algorithms::ltl::factor(model, &mut ltl_u).unwrap();
                data.kkt.factor.fill(f64::NAN);
                factor(model, &mut data).unwrap();
                let u = data.kkt.factor.upper_triangle();
                let scale = d.amax();
                assert!((&u * u.transpose() - &d).amax() <= 1e-12 * scale, "{name}: U Uᵀ ≠ D");
                for k in 0..n {
                    assert!((data.kkt.factor_inv_diag[k] * u[(k, k)] - 1.0).abs() < 1e-14, "{name}: 1/U_{k}{k}");
                    for i in 0..=k {
                        let (a, b) = (u[(i, k)], ltl_u[(i, k)]);
                        // Structural zeros come from the tree (U_ik ≠ 0 needs i to support k); an entry that is
                        // zero by the geometry (the RSSR's Hooke joint: perpendicular axes, a rod whose axis is a
                        // principal axis) may be exactly 0 in one factor and round-off in the other.
                        if !model.supports(i, k) {
                            assert_eq!((a, b), (0.0, 0.0), "{name}: U_{i}{k} must be a structural zero");
                        }
                        assert!((a - b).abs() <= 1e-12 * scale.sqrt(), "{name}: U_{i}{k} {a} vs {b}");
                    }
                }
            }
        }
        fn with_armature<S: Space>(name: &str, model: &Model<S>) {
            let mut geared = model.clone();
            for (i, j) in geared.joints.iter_mut().enumerate() {
                j.armature = 1e-3 * (1 + i % 3) as f64;
            }
            check(name, &geared);
            let (q, _) = random_state(model, 9);
            let (mut plain, mut data) = (Data::new(model), Data::new(&geared));
            forward_kinematics(model, &mut plain, &q);
            mass_matrix(model, &mut plain);
            forward_kinematics(&geared, &mut data, &q);
            mass_matrix(&geared, &mut data);
            let added = &data.mass_matrix - &plain.mass_matrix;
            let expected = nalgebra::DMatrix::from_fn(model.nv(), model.nv(), |r, c| {
                if r == c {
                    geared.joints[r].armature
                } else {
                    0.0
                }
            });
            let scale = plain.mass_matrix.amax().max(1e-3);
            assert!((added - expected).amax() <= 1e-14 * scale, "{name}: the armature is not D's diagonal alone");
        }
        let mut branched = false;
        for_each_model!(name, model => {
            branched |= !model.is_chain();
            check(name, model);
            with_armature(name, model);
        });
        assert!(branched, "the test scenes should include a branched tree");
    }
}
