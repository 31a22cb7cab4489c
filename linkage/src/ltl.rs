//! Sparse factorization of the mass matrix that keeps the tree's branch-induced sparsity
//! (Featherstone's LTL, "Efficient factorization of the joint-space inertia matrix for branched kinematic
//! trees", IJRR 2005), stored transposed: `D = U Uᵀ` with U upper triangular and `U_ik ≠ 0` only when
//! joint i supports body k.
//!
//! Why this order and not plain Cholesky (`D = L Lᵀ`): with `D = U Uᵀ`, the vector `U⁻¹ b` is zero outside
//! the support of b's nonzeros. A Jacobian column `Jᵀ` at a point on body k is nonzero only on k's
//! supporting joints, so `U⁻¹ Jᵀ` (and `U⁻¹ Wᵀ` for a loop closure near the base) costs O(depth²) instead of
//! O(n²). Column k of U holds exactly k's supporting joints, contiguous when they are `0..k` (a chain), so the
//! inner loops vectorize there.

use nalgebra::DMatrix;

use crate::error::DynamicsError;
use crate::model::{Model, NO_PARENT};
use crate::space::Space;

/// Factors `u` in place: on entry its upper triangle holds D (as written by `mass_matrix`), on exit U.
pub fn factor<S: Space>(model: &Model<S>, u: &mut DMatrix<f64>) -> Result<(), DynamicsError> {
    let n = u.nrows();
    let a = u.as_mut_slice();
    for k in (0..n).rev() {
        let pivot = a[k * n + k];
        if pivot.is_nan() || pivot <= 0.0 {
            return Err(DynamicsError::MassNotPositive { joint: k, pivot });
        }
        let ukk = pivot.sqrt();
        a[k * n + k] = ukk;
        let inv = 1.0 / ukk;
        let (left, right) = a.split_at_mut(k * n);
        let col_k = &mut right[..n];
        if model.chain_prefix[k] {
            for x in &mut col_k[..k] {
                *x *= inv;
            }
            for i in 0..k {
                let uik = col_k[i];
                let col_i = &mut left[i * n..i * n + i + 1];
                for (dst, src) in col_i.iter_mut().zip(&col_k[..=i]) {
                    *dst -= uik * src;
                }
            }
        } else {
            let mut i = model.joints[k].parent;
            while i != NO_PARENT {
                col_k[i] *= inv;
                i = model.joints[i].parent;
            }
            let mut i = model.joints[k].parent;
            while i != NO_PARENT {
                let uik = col_k[i];
                let mut j = i;
                while j != NO_PARENT {
                    left[i * n + j] -= uik * col_k[j];
                    j = model.joints[j].parent;
                }
                i = model.joints[i].parent;
            }
        }
    }
    Ok(())
}

/// `x ← U⁻¹ x` (back substitution). Entries outside the support of x's nonzeros stay zero and are skipped.
pub fn solve_u<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    for k in (0..n).rev() {
        if x[k] == 0.0 {
            continue;
        }
        let xk = x[k] / a[k * n + k];
        x[k] = xk;
        let col_k = &a[k * n..k * n + n];
        if model.chain_prefix[k] {
            for (xi, uik) in x[..k].iter_mut().zip(&col_k[..k]) {
                *xi -= uik * xk;
            }
        } else {
            let mut i = model.joints[k].parent;
            while i != NO_PARENT {
                x[i] -= col_k[i] * xk;
                i = model.joints[i].parent;
            }
        }
    }
}

/// `x ← U⁻ᵀ x` (forward substitution).
pub fn solve_ut<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    for k in 0..n {
        let col_k = &a[k * n..k * n + n];
        let mut s = x[k];
        if model.chain_prefix[k] {
            s -= col_k[..k].iter().zip(&x[..k]).map(|(u, x)| u * x).sum::<f64>();
        } else {
            let mut i = model.joints[k].parent;
            while i != NO_PARENT {
                s -= col_k[i] * x[i];
                i = model.joints[i].parent;
            }
        }
        x[k] = s / col_k[k];
    }
}

/// `x ← D⁻¹ x = U⁻ᵀ U⁻¹ x`.
pub fn solve<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    solve_u(model, u, x);
    solve_ut(model, u, x);
}
