//! `ltl`'s factorization `D = U Uᵀ` and its triangular solves for models of at most 8 joints, on
//! fixed-size arrays. `ltl`'s public functions dispatch here by n ([`by_size`](crate::math::dense)); nothing else calls these.
//!
//! **Why.** The tree-sparse loops of `ltl` pay, per row, for what a small matrix does not need: walking the
//! parent array off the chain prefix, blocks of 16/8/4/2/1 rows, bounds checks on run-time lengths. With n a
//! constant the compiler unrolls the whole factorization and each solve into straight-line code (the
//! `ltl` benchmarks compare the two paths).
//!
//! **Same results, same zeros.** The arithmetic is the dense textbook form of the same recurrences, so
//! results agree with `ltl`'s to round-off (the tests of `ltl` run on both paths: the small scenes here,
//! `chain30` there). The tree's sparsity is kept exactly, not approximately: an entry `U_ik` between joints
//! on different branches is `D_ik` (a structural zero that `mass_matrix` writes) minus products
//! `U_ij U_kj` over j > k, and a joint j below both i and k would make one of them the other's ancestor, so
//! every product has an exact-zero factor. Likewise `U⁻¹ x` adds `U_ik x_k` to row i only from a nonzero
//! `x_k`, so a column supported on the joints of one body keeps its zeros.

use crate::error::DynamicsError;
use crate::math::dense::mul_add;

/// `U_kk = sqrt(pivot)` into place, failing on a pivot that is not positive; returns `1/U_kk`, computed as
/// `sqrt(p) · (1/p)`: the square root and the division run side by side instead of one after the other
/// (the factorization is a chain of such pivots), with the same two roundings as `1/sqrt(p)`. A pivot below
/// 1/f64::MAX (~5.6e-309) gives an infinite reciprocal, which the solves report as a non-finite result.
#[inline]
pub(crate) fn finish_pivot(col: &mut [f64], k: usize) -> Result<f64, DynamicsError> {
    let pivot = col[k];
    if pivot.is_nan() || pivot <= 0.0 {
        return Err(DynamicsError::MassNotPositive { joint: k, pivot });
    }
    let ukk = pivot.sqrt();
    col[k] = ukk;
    Ok(ukk * (1.0 / pivot))
}

/// Pivot and scaling of a column with contiguous rows `0..=k`; returns `1/U_kk`.
#[inline]
pub(crate) fn finish_contiguous(col: &mut [f64], k: usize) -> Result<f64, DynamicsError> {
    let inv = finish_pivot(col, k)?;
    for x in &mut col[..k] {
        *x *= inv;
    }
    Ok(inv)
}

/// Column k of a column-major matrix of N rows (N×N here, N×m in `kkt_small`).
#[inline(always)]
pub(crate) fn column<const N: usize>(a: &[f64], k: usize) -> &[f64; N] {
    a[k * N..(k + 1) * N].try_into().expect("an N-row column")
}

/// The columns of `x` (whole columns of N rows).
#[inline(always)]
fn columns_mut<const N: usize>(x: &mut [f64]) -> impl Iterator<Item = &mut [f64; N]> {
    x.chunks_exact_mut(N).map(|c| c.try_into().expect("a chunk of N"))
}

/// `U Uᵀ = D + extra` (see `ltl::factor_sum`): reads the upper triangles of `d` and `extra`, writes the
/// upper triangle of `u` and the reciprocals of U's diagonal. Column k, from the last: D's column k minus
/// `Σ_{j>k} U_kj U_{·j}`, then the pivot and the scaling of [`finish_contiguous`].
pub(crate) fn factor_sum<const N: usize>(
    d: &[f64],
    extra: Option<&[f64]>,
    u: &mut [f64],
    inv_diag: &mut [f64],
) -> Result<(), DynamicsError> {
    let mut a: [[f64; N]; N] = std::array::from_fn(|k| *column::<N>(d, k));
    if let Some(extra) = extra {
        for (k, col) in a.iter_mut().enumerate() {
            for (x, e) in col.iter_mut().zip(column::<N>(extra, k)) {
                *x += e;
            }
        }
    }
    for k in (0..N).rev() {
        let mut col = a[k];
        for done in &a[k + 1..] {
            let ukj = done[k];
            for i in 0..=k {
                col[i] = mul_add(-ukj, done[i], col[i]);
            }
        }
        inv_diag[k] = finish_contiguous(&mut col[..=k], k)?;
        a[k] = col;
        u[k * N..k * N + k + 1].copy_from_slice(&col[..=k]);
    }
    Ok(())
}

/// `X ← U⁻¹ X` for whole columns of N rows (see `ltl::solve_u_columns`; the support bound is not needed:
/// zeros stay zero, see the module documentation). `inv` holds `1/U_kk`.
pub(crate) fn solve_u_columns<const N: usize>(u: &[f64], inv: &[f64], x: &mut [f64]) {
    let inv = &inv[..N];
    for col in columns_mut::<N>(x) {
        for k in (0..N).rev() {
            let xk = col[k] * inv[k];
            col[k] = xk;
            let u_k = column::<N>(u, k);
            for i in 0..k {
                col[i] = mul_add(-u_k[i], xk, col[i]);
            }
        }
    }
}

/// `X ← U⁻ᵀ X` for whole columns of N rows (see `ltl::solve_ut_columns`).
pub(crate) fn solve_ut_columns<const N: usize>(u: &[f64], inv: &[f64], x: &mut [f64]) {
    let inv = &inv[..N];
    for col in columns_mut::<N>(x) {
        for k in 0..N {
            let (mut s, u_k) = (col[k], column::<N>(u, k));
            for i in 0..k {
                s = mul_add(-u_k[i], col[i], s);
            }
            col[k] = s * inv[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::math::dense::by_size;

    /// The fixed-size kernels serve exactly 1 to 8 joints, each with its own N.
    #[test]
    fn by_size_gives_n_itself_up_to_eight() {
        for n in 0..12 {
            let fixed: Option<usize> = by_size!(n, N => Some(N), _ => None);
            assert_eq!(fixed, (1..=8).contains(&n).then_some(n), "n = {n}");
        }
    }
}
