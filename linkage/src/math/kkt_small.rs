//! The loop-closure part of the KKT solve of eq 4 (`Z = U⁻¹ Wᵀ`, `S = Zᵀ Z`, then q̈ and λ) and the
//! projection's chord correction, for models of at most 8 joints, with n a constant
//! ([`by_size`](crate::math::dense)). `kkt` and `integrator` dispatch here; nothing else calls these.
//!
//! **Why.** On the paper's testbed (n = 4, m = 2) these three do about 150 floating-point operations a
//! step, but their general forms (`kkt::z_and_schur_general`, `kkt::solve_general`,
//! `integrator::correct_general`) are chains of small calls over run-time lengths: a support per column,
//! groups of columns, a Schur solve on a vector moved out of the workspace and back, many times the
//! instructions of the arithmetic. Here each is one function whose columns are `[f64; N]`
//! arrays held in registers; only m, the closure rows, is still a loop bound.
//!
//! **Same results.** The same operations in the same order as the general forms, which for n ≤ 8 also
//! take whole columns (`ltl_small`, `dense::dot_fixed`); a test in `integrator` (the top of the stack that
//! dispatches here) compares the two on every test scene.

use crate::math::dense::{self, dot, dot_fixed, mul_add};
use crate::math::kkt_factors::KktWorkspace;
use crate::math::ltl_small::{self, column};

/// `x ← x - Σ_c r_c a_c` over the columns of `a` (Z), in column order.
#[inline(always)]
fn sub_columns_times<const N: usize>(a: &[f64], r: &[f64], x: &mut [f64; N]) {
    for (c, rc) in r.iter().enumerate() {
        for (x, a) in x.iter_mut().zip(column::<N>(a, c)) {
            *x = mul_add(-rc, *a, *x);
        }
    }
}

/// `Z = U⁻¹ Wᵀ` from the closure Jacobian `wt` (n×m), and `S = Zᵀ Z` (both triangles). Needs U.
pub(crate) fn z_and_schur<const N: usize>(kkt: &mut KktWorkspace, wt: &[f64], m: usize) {
    let (u, inv) = (kkt.factor.as_slice(), &kkt.factor_inv_diag.as_slice()[..N]);
    let z = &mut kkt.z.as_mut_slice()[..N * m];
    for (c, out) in z.chunks_exact_mut(N).enumerate() {
        let mut col = *column::<N>(wt, c);
        ltl_small::solve_u_columns::<N>(u, inv, &mut col);
        out.copy_from_slice(&col);
    }
    let s = kkt.schur.as_mut_slice();
    for j in 0..m {
        for i in 0..=j {
            let v = dot_fixed::<N>(column::<N>(z, i), column::<N>(z, j));
            s[j * m + i] = v;
            s[i * m + j] = v;
        }
    }
}

/// The solve of eq 4 (see `kkt::solve`) from `tau`: `y = U⁻¹ τ`, `λ = S⁺ (Zᵀ y + w_stab)`,
/// `q̈ = U⁻ᵀ (y - Z λ)`. Needs the factors of `kkt::factorize`; `lambda` and `w_stab` have m entries.
pub(crate) fn solve<const N: usize>(kkt: &KktWorkspace, tau: [f64; N], w_stab: &[f64], lambda: &mut [f64]) -> [f64; N] {
    let (u, inv) = (kkt.factor.as_slice(), &kkt.factor_inv_diag.as_slice()[..N]);
    let mut x = tau;
    ltl_small::solve_u_columns::<N>(u, inv, &mut x);
    if !lambda.is_empty() {
        let z = kkt.z.as_slice();
        for (c, (rhs, w)) in lambda.iter_mut().zip(w_stab).enumerate() {
            *rhs = dot_fixed::<N>(column::<N>(z, c), &x) + w;
        }
        schur_solve::<N>(kkt, lambda);
        sub_columns_times::<N>(z, lambda, &mut x);
    }
    ltl_small::solve_ut_columns::<N>(u, inv, &mut x);
    x
}

/// `S x = r` in place with the pivoted factor (dependent rows get 0). The factor's rank is at most
/// `Model::closure_rank`, the rank of the n×m matrix Wᵀ, so at most n = N: the scratch fits on the stack.
#[inline(always)]
fn schur_solve<const N: usize>(kkt: &KktWorkspace, r: &mut [f64]) {
    let (l, m, mut y) = (kkt.schur_factor.as_slice(), r.len(), [0.0; N]);
    let (inv, perm, rank) = (kkt.schur_inv_diag.as_slice(), &kkt.schur_perm, kkt.schur_rank.min(N));
    dense::pivoted_solve_slices(l, m, inv, perm, rank, r, &mut y);
}

/// One chord correction of the projection (see `integrator::project`) for the pairs `(r_q, q)` and
/// `(r_v, q̇)`: `δ = -U⁻ᵀ Z S⁺ r`, `x ← x + δ`, `r ← r + W(q) δ`, W(q) from `wt` (n×m). `s` is scratch of
/// m entries.
pub(crate) fn correct<const N: usize>(
    kkt: &KktWorkspace,
    wt: &[f64],
    [r_q, r_v]: [&mut [f64]; 2],
    [q, qd]: [&mut [f64]; 2],
    s: &mut [f64],
) {
    let (u, inv) = (kkt.factor.as_slice(), &kkt.factor_inv_diag.as_slice()[..N]);
    let z = kkt.z.as_slice();
    for (r, x) in [(r_q, q), (r_v, qd)] {
        // S⁺ r on a copy: r is updated below.
        dense::copy(s, r);
        schur_solve::<N>(kkt, s);
        let mut t = [0.0; N];
        sub_columns_times::<N>(z, s, &mut t);
        ltl_small::solve_ut_columns::<N>(u, inv, &mut t);
        let x: &mut [f64; N] = (&mut x[..N]).try_into().expect("n entries");
        for (x, t) in x.iter_mut().zip(&t) {
            *x += t;
        }
        for (c, r) in r.iter_mut().enumerate() {
            *r += dot(column::<N>(wt, c), &t);
        }
    }
}
