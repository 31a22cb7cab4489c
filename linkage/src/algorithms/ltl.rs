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
//!
//! Models of at most 8 joints take fixed-size dense kernels with the same results and zeros (`ltl_small`).
//! Above that, the hot paths use [`factor_sum`] (left-looking, two columns per pass, FMA) and the blocked
//! multi-column solves [`solve_u_columns`] / [`solve_ut_columns`] with the reciprocals of U's diagonal; [`solve_u`] and
//! [`solve_ut`] are the plain reference forms.

use nalgebra::DMatrix;

use crate::error::DynamicsError;
use crate::math::dense::{by_size, dot, mul_add, sub_scaled};
use crate::math::ltl_small::{self, finish_contiguous, finish_pivot};
use crate::math::simd::F64x4;
use crate::math::space::Space;
use crate::model::{Model, NO_PARENT};

/// Factors `u` in place: on entry its upper triangle holds D (as written by `mass_matrix`), on exit U.
/// The strict lower triangle is neither read nor written.
pub fn factor<S: Space>(model: &Model<S>, u: &mut DMatrix<f64>) -> Result<(), DynamicsError> {
    let n = u.nrows();
    factor_columns(model, u.as_mut_slice(), n, |_, _| {}, None)
}

/// Factors `D + extra` into `u` (`U Uᵀ = D + extra`), reading only the upper triangles of `d` and `extra`
/// and writing only the upper triangle of `u` (the copy of each column is fused into its factorization),
/// and writes the reciprocals of U's diagonal into `inv_diag` (what [`inverse_diagonal`] computes, here
/// for free: the factorization scales by them).
pub fn factor_sum<S: Space>(
    model: &Model<S>,
    d: &DMatrix<f64>,
    extra: Option<&DMatrix<f64>>,
    u: &mut DMatrix<f64>,
    inv_diag: &mut [f64],
) -> Result<(), DynamicsError> {
    let n = u.nrows();
    let (d, extra) = (d.as_slice(), extra.map(|e| e.as_slice()));
    by_size!(n, N => return ltl_small::factor_sum::<N>(d, extra, u.as_mut_slice(), inv_diag), _ => ());
    let init = |k: usize, col: &mut [f64]| {
        col.copy_from_slice(&d[k * n..k * n + col.len()]);
        if let Some(e) = extra {
            for (c, e) in col.iter_mut().zip(&e[k * n..]) {
                *c += e;
            }
        }
    };
    factor_columns(model, u.as_mut_slice(), n, init, Some(&mut inv_diag[..n]))
}

/// The factorization proper, column by column from the last, in the left-looking ("dot-product") order:
/// column k of U is D's column k minus `Σ_{j>k} U_kj U_{·j}` over the finished columns j > k, then scaled
/// by `1/U_kk`. Each entry is accumulated in registers over all j and stored once, where the right-looking
/// order (Featherstone's listing) reads and writes the whole remaining triangle for every k; the
/// arithmetic, and so the result up to round-off, is the same. `init(k, col)` fills rows `0..=k` of
/// column k with D's entries (nothing to do in place); the reciprocals `1/U_kk` go to `inv_diag`.
fn factor_columns<S: Space>(
    model: &Model<S>,
    a: &mut [f64],
    n: usize,
    mut init: impl FnMut(usize, &mut [f64]),
    mut inv_diag: Option<&mut [f64]>,
) -> Result<(), DynamicsError> {
    let mut record = |k: usize, inv: f64| {
        if let Some(out) = inv_diag.as_deref_mut() {
            out[k] = inv;
        }
    };
    let mut k = n;
    while k > 0 {
        k -= 1;
        if k >= 1 && model.chain_prefix[k] {
            // Columns k and k - 1 together (k - 1 is then on the chain prefix too): one pass over the
            // finished columns serves both, halving the loads and the loop overhead per multiply-add.
            let (head, done) = a.split_at_mut((k + 1) * n);
            let (head, col_k) = head.split_at_mut(k * n);
            let col_k = &mut col_k[..k + 1];
            let col_p = &mut head[(k - 1) * n..k * n][..k];
            init(k, col_k);
            init(k - 1, col_p);
            update_pair(col_k, col_p, done, n, k);
            record(k, finish_contiguous(col_k, k)?);
            // The one finished column the pass could not include: k itself.
            sub_scaled(col_p, col_k[k - 1], &col_k[..k]);
            record(k - 1, finish_contiguous(col_p, k - 1)?);
            k -= 1;
            continue;
        }
        let (head, done) = a.split_at_mut((k + 1) * n);
        let col = &mut head[k * n..k * n + k + 1];
        init(k, col);
        if k == 0 {
            // The root column (single row); every other column on the chain prefix went in a pair.
            update_pair_block::<1, false>(col, &mut [], done, n, k, 0);
            record(k, finish_contiguous(col, k)?);
        } else {
            update_ancestors(model, col, done, n, k);
            let inv = finish_pivot(col, k)?;
            let mut i = model.joints[k].parent;
            while i != NO_PARENT {
                col[i] *= inv;
                i = model.joints[i].parent;
            }
            record(k, inv);
        }
    }
    Ok(())
}

/// `col_k[0..=k] -= Σ_j U_kj U_{0..=k, j}` and `col_p[0..k] -= Σ_j U_{k-1,j} U_{0..k, j}` over the finished
/// columns j > k, for a body k whose supporting joints are `0..k`: every column j that k supports has all of
/// rows `0..=k` filled, so the rows are contiguous. Rows go in blocks of 16, 8, 4, 2, 1 held in registers
/// across the sum over j. (Columns j that k does not support, possible in a branched tree, have zero
/// multipliers and contribute nothing.)
fn update_pair(col_k: &mut [f64], col_p: &mut [f64], done: &[f64], n: usize, k: usize) {
    let len = k;
    let mut r = 0;
    while r + 16 <= len {
        update_pair_block::<16, true>(col_k, col_p, done, n, k, r);
        r += 16;
    }
    if len - r >= 8 {
        update_pair_block::<8, true>(col_k, col_p, done, n, k, r);
        r += 8;
    }
    if len - r >= 4 {
        update_pair_block::<4, true>(col_k, col_p, done, n, k, r);
        r += 4;
    }
    if len - r >= 2 {
        update_pair_block::<2, true>(col_k, col_p, done, n, k, r);
        r += 2;
    }
    if len - r >= 1 {
        update_pair_block::<1, true>(col_k, col_p, done, n, k, r);
    }
    // Row k belongs to column k only.
    update_pair_block::<1, false>(col_k, &mut [], done, n, k, k);
}

/// Rows `r..r + B` of column k (and, when `PAIR`, of column k - 1).
#[inline(always)]
fn update_pair_block<const B: usize, const PAIR: bool>(
    col_k: &mut [f64],
    col_p: &mut [f64],
    done: &[f64],
    n: usize,
    k: usize,
    r: usize,
) {
    let mut acc_k: [f64; B] = col_k[r..r + B].try_into().expect("block inside the column");
    let mut acc_p = [0.0; B];
    if PAIR {
        acc_p.copy_from_slice(&col_p[r..r + B]);
    }
    for cj in done.chunks_exact(n) {
        let src: &[f64; B] = cj[r..r + B].try_into().expect("block inside the column");
        let u_k = cj[k];
        for t in 0..B {
            acc_k[t] = mul_add(-u_k, src[t], acc_k[t]);
        }
        if PAIR {
            let u_p = cj[k - 1];
            for t in 0..B {
                acc_p[t] = mul_add(-u_p, src[t], acc_p[t]);
            }
        }
    }
    col_k[r..r + B].copy_from_slice(&acc_k);
    if PAIR {
        col_p[r..r + B].copy_from_slice(&acc_p);
    }
}

/// As [`update_contiguous`] for a body off the chain prefix: only k and its ancestors (the nonzeros of
/// column k), walked through the parent array.
fn update_ancestors<S: Space>(model: &Model<S>, col: &mut [f64], done: &[f64], n: usize, k: usize) {
    for cj in done.chunks_exact(n) {
        let ukj = cj[k];
        if ukj == 0.0 {
            continue;
        }
        col[k] = mul_add(-ukj, ukj, col[k]);
        let mut i = model.joints[k].parent;
        while i != NO_PARENT {
            col[i] = mul_add(-ukj, cj[i], col[i]);
            i = model.joints[i].parent;
        }
    }
}

/// `x ← U⁻¹ x` (back substitution, dividing by the diagonal). Entries outside the support of x's nonzeros
/// stay zero and are skipped. The hot paths use [`solve_u_columns`]; this is the plain reference form.
pub fn solve_u<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    let x = &mut x[..n];
    for k in (0..n).rev() {
        if x[k] == 0.0 {
            continue;
        }
        let col_k = &a[k * n..k * n + k + 1];
        let xk = x[k] / col_k[k];
        x[k] = xk;
        if model.chain_prefix[k] {
            sub_scaled(&mut x[..k], xk, &col_k[..k]);
        } else {
            sub_scaled_ancestors(model, x, xk, col_k, k);
        }
    }
}

/// `x ← U⁻ᵀ x` (forward substitution, dividing by the diagonal); the reference form of
/// [`solve_ut_columns`].
pub fn solve_ut<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    let x = &mut x[..n];
    for k in 0..n {
        let col_k = &a[k * n..k * n + k + 1];
        x[k] = forward_row(model, x, col_k, k) / col_k[k];
    }
}

/// `x ← D⁻¹ x = U⁻ᵀ U⁻¹ x`.
pub fn solve<S: Space>(model: &Model<S>, u: &DMatrix<f64>, x: &mut [f64]) {
    solve_u(model, u, x);
    solve_ut(model, u, x);
}

/// `x[i] -= U_ik x_k` for the ancestors i of body k (column k off the chain prefix).
#[inline]
fn sub_scaled_ancestors<S: Space>(model: &Model<S>, x: &mut [f64], xk: f64, col_k: &[f64], k: usize) {
    let mut i = model.joints[k].parent;
    while i != NO_PARENT {
        x[i] = mul_add(-col_k[i], xk, x[i]);
        i = model.joints[i].parent;
    }
}

/// `x_k - Σ_{i<k} U_ik x_i`: row k of the forward substitution before its division.
#[inline]
fn forward_row<S: Space>(model: &Model<S>, x: &[f64], col_k: &[f64], k: usize) -> f64 {
    if model.chain_prefix[k] {
        return x[k] - dot(&col_k[..k], &x[..k]);
    }
    let mut s = x[k];
    let mut i = model.joints[k].parent;
    while i != NO_PARENT {
        s = mul_add(-col_k[i], x[i], s);
        i = model.joints[i].parent;
    }
    s
}

/// Reciprocals of U's diagonal, for [`solve_u_columns`] and [`solve_ut_columns`]: each row of a triangular
/// solve waits for the one before it, and a multiplication takes a quarter of a division's latency.
pub fn inverse_diagonal(u: &DMatrix<f64>, inv: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    for (k, v) in inv[..n].iter_mut().enumerate() {
        *v = 1.0 / a[k * n + k];
    }
}

/// Solves `U X = B` in place (`X ← U⁻¹ X`) for the columns of `x` (column-major, n rows each), all of whose
/// nonzeros lie in rows `0..len` — true of `Wᵀ` and `Jᵀ` columns, nonzero only on the supporting joints of
/// a body below `len`, and kept by U⁻¹ (see the module documentation). `inv` is [`inverse_diagonal`].
///
/// Up to four columns go through the rows together, and the chain-prefix rows go in blocks of four: the
/// 4x4 diagonal block is solved, then the rows above it are updated by all four U columns at once (one
/// pass over x per four columns instead of one per column). Same operations as [`solve_u`] up to round-off.
pub fn solve_u_columns<S: Space>(model: &Model<S>, u: &DMatrix<f64>, inv: &[f64], x: &mut [f64], len: usize) {
    let n = u.nrows();
    let a = u.as_slice();
    by_size!(n, N => return ltl_small::solve_u_columns::<N>(a, inv, x), _ => ());
    for group in x.chunks_mut(4 * n) {
        match group.len() / n {
            1 => solve_u_group::<S, 1>(model, a, n, inv, group, len),
            2 => solve_u_group::<S, 2>(model, a, n, inv, group, len),
            3 => solve_u_group::<S, 3>(model, a, n, inv, group, len),
            _ => solve_u_group::<S, 4>(model, a, n, inv, group, len),
        }
    }
}

/// `W` columns of `x` as separate mutable slices.
#[inline(always)]
fn columns<const W: usize>(x: &mut [f64], n: usize) -> [&mut [f64]; W] {
    let mut it = x.chunks_exact_mut(n);
    std::array::from_fn(|_| it.next().expect("W columns of n rows"))
}

/// Columns `k0..k0 + 4` of U, rows `0..=k0 + c` of column `k0 + c` (the upper triangle).
#[inline(always)]
fn four_columns(a: &[f64], n: usize, k0: usize) -> [&[f64]; 4] {
    std::array::from_fn(|c| &a[(k0 + c) * n..(k0 + c) * n + k0 + c + 1])
}

// Not inlined: each width keeps its own (small) set-up instead of the dispatcher computing every width's
// loop invariants on entry.
#[inline(never)]
fn solve_u_group<S: Space, const W: usize>(
    model: &Model<S>,
    a: &[f64],
    n: usize,
    inv: &[f64],
    x: &mut [f64],
    len: usize,
) {
    let mut cols = columns::<W>(x, n);
    let prefix = model.chain_prefix_len.min(len);
    // Rows off the chain prefix: one at a time through the parent array (Featherstone's sparse form).
    for k in (prefix..len).rev() {
        let col_k = &a[k * n..k * n + k + 1];
        for x in cols.iter_mut() {
            if x[k] != 0.0 {
                let xk = x[k] * inv[k];
                x[k] = xk;
                sub_scaled_ancestors(model, x, xk, col_k, k);
            }
        }
    }
    // Chain-prefix rows: one at a time down to a multiple of four, then four at a time (aligned blocks keep
    // every row update in whole vectors).
    let mut k = prefix;
    while !k.is_multiple_of(4) {
        k -= 1;
        let col_k = &a[k * n..k * n + k + 1];
        for x in cols.iter_mut() {
            let xk = x[k] * inv[k];
            x[k] = xk;
            sub_scaled(&mut x[..k], xk, &col_k[..k]);
        }
    }
    while k >= 4 {
        let k0 = k - 4;
        let u = four_columns(a, n, k0);
        let mut vals = [[0.0; 4]; W];
        for (x, v) in cols.iter_mut().zip(vals.iter_mut()) {
            let x3 = x[k0 + 3] * inv[k0 + 3];
            let x2 = mul_add(-u[3][k0 + 2], x3, x[k0 + 2]) * inv[k0 + 2];
            let x1 = mul_add(-u[2][k0 + 1], x2, mul_add(-u[3][k0 + 1], x3, x[k0 + 1])) * inv[k0 + 1];
            let x0 = mul_add(-u[1][k0], x1, mul_add(-u[2][k0], x2, mul_add(-u[3][k0], x3, x[k0]))) * inv[k0];
            *v = [x0, x1, x2, x3];
            x[k0..k].copy_from_slice(v);
        }
        // The four rows just above first: the next block waits for them, not for the rest.
        if k0 > 0 {
            update_rows(&u, &vals, &mut cols, k0 - 4, k0);
        }
        if k0 > 4 {
            update_rows(&u, &vals, &mut cols, 0, k0 - 4);
        }
        k = k0;
    }
}

/// Rows `lo..hi` (multiples of four) of every column: `x_i -= Σ_c U_{i,k0+c} x_{k0+c}`, the four U columns
/// of a block at once, four rows per step.
#[inline(always)]
fn update_rows<const W: usize>(
    u: &[&[f64]; 4],
    vals: &[[f64; 4]; W],
    cols: &mut [&mut [f64]; W],
    lo: usize,
    hi: usize,
) {
    let [u0, u1, u2, u3] = u.map(|c| c[lo..hi].chunks_exact(4));
    for (x, v) in cols.iter_mut().zip(vals) {
        let [v0, v1, v2, v3] = v.map(F64x4::splat);
        let rows = x[lo..hi].chunks_exact_mut(4).zip(u0.clone().zip(u1.clone())).zip(u2.clone().zip(u3.clone()));
        for ((x, (a0, a1)), (a2, a3)) in rows {
            let xi = F64x4::load(x).sub_mul(F64x4::load(a3), v3).sub_mul(F64x4::load(a2), v2);
            xi.sub_mul(F64x4::load(a1), v1).sub_mul(F64x4::load(a0), v0).store(x);
        }
    }
}

/// Solves `Uᵀ X = B` in place (`X ← U⁻ᵀ X`) for the columns of `x` (column-major, n rows each); `inv` is
/// [`inverse_diagonal`]. The chain-prefix rows go in blocks of four: the four dot products of a block with
/// the rows before it share one pass over x, then the 4x4 diagonal block is solved. Same operations as
/// [`solve_ut`] up to round-off.
pub fn solve_ut_columns<S: Space>(model: &Model<S>, u: &DMatrix<f64>, inv: &[f64], x: &mut [f64]) {
    let n = u.nrows();
    let a = u.as_slice();
    by_size!(n, N => return ltl_small::solve_ut_columns::<N>(a, inv, x), _ => ());
    for group in x.chunks_mut(4 * n) {
        match group.len() / n {
            1 => solve_ut_group::<S, 1>(model, a, n, inv, group),
            2 => solve_ut_group::<S, 2>(model, a, n, inv, group),
            3 => solve_ut_group::<S, 3>(model, a, n, inv, group),
            _ => solve_ut_group::<S, 4>(model, a, n, inv, group),
        }
    }
}

#[inline(never)]
fn solve_ut_group<S: Space, const W: usize>(model: &Model<S>, a: &[f64], n: usize, inv: &[f64], x: &mut [f64]) {
    let mut cols = columns::<W>(x, n);
    let prefix = model.chain_prefix_len;
    let mut k0 = 0;
    while k0 + 4 <= prefix {
        let u = four_columns(a, n, k0);
        for x in cols.iter_mut() {
            let d = if k0 > 0 { dot4(&u, &x[..k0]) } else { [0.0; 4] };
            let x0 = (x[k0] - d[0]) * inv[k0];
            let x1 = mul_add(-u[1][k0], x0, x[k0 + 1] - d[1]) * inv[k0 + 1];
            let x2 = mul_add(-u[2][k0 + 1], x1, mul_add(-u[2][k0], x0, x[k0 + 2] - d[2])) * inv[k0 + 2];
            let x3 = mul_add(-u[3][k0 + 2], x2, mul_add(-u[3][k0 + 1], x1, mul_add(-u[3][k0], x0, x[k0 + 3] - d[3])))
                * inv[k0 + 3];
            x[k0..k0 + 4].copy_from_slice(&[x0, x1, x2, x3]);
        }
        k0 += 4;
    }
    for k in k0..n {
        let col_k = &a[k * n..k * n + k + 1];
        for x in cols.iter_mut() {
            x[k] = forward_row(model, x, col_k, k) * inv[k];
        }
    }
}

/// The four dot products `u[c][..len] · x` (len = x.len(), a multiple of four), in four lanes each.
#[inline(always)]
fn dot4(u: &[&[f64]; 4], x: &[f64]) -> [f64; 4] {
    debug_assert!(x.len().is_multiple_of(4));
    let len = x.len();
    let [u0, u1, u2, u3] = u.map(|c| c[..len].chunks_exact(4));
    let mut acc = [F64x4::zero(); 4];
    for (xi, ((a0, a1), (a2, a3))) in x.chunks_exact(4).zip(u0.zip(u1).zip(u2.zip(u3))) {
        let xi = F64x4::load(xi);
        acc[0] = acc[0].add_mul(F64x4::load(a0), xi);
        acc[1] = acc[1].add_mul(F64x4::load(a1), xi);
        acc[2] = acc[2].add_mul(F64x4::load(a2), xi);
        acc[3] = acc[3].add_mul(F64x4::load(a3), xi);
    }
    acc.map(F64x4::sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::{kinematics::forward_kinematics, mass_matrix::mass_matrix};
    use crate::model::data::Data;
    use crate::testing::{for_each_model, random_state};
    use nalgebra::DVector;

    /// U Uᵀ reproduces D (plus an extra term), U keeps the tree's sparsity, and the solves invert U, Uᵀ
    /// and D, for every test scene (chains, branched trees, spatial).
    #[test]
    fn factor_reproduces_the_mass_matrix_and_solves_invert_it() {
        for_each_model!(name, model => { check(name, model) });
        check(
            "chain30_loops3",
            &crate::testing::compile::<crate::math::space::Planar>(&crate::model::builtin::chain(30, 3)),
        );
    }

    fn check<S: Space>(name: &str, model: &Model<S>) {
        let n = model.nv();
        let mut data = Data::new(model);
        let (q, _) = random_state(model, 3);
        forward_kinematics(model, &mut data, &q);
        mass_matrix(model, &mut data);
        let d = data.mass_matrix.clone();
        // A symmetric positive semi-definite extra term on the supporting joints of the last body.
        let mut extra = DMatrix::zeros(n, n);
        for i in crate::algorithms::jacobian::support(model, Some(n - 1)) {
            for j in crate::algorithms::jacobian::support(model, Some(n - 1)) {
                extra[(i, j)] = 0.01 * (1.0 + (i * j) as f64 * 0.1);
            }
        }
        for (extra, total) in [(None, d.clone()), (Some(&extra), &d + &extra)] {
            let mut u = DMatrix::from_element(n, n, f64::NAN);
            let mut inv = vec![f64::NAN; n];
            factor_sum(model, &d, extra, &mut u, &mut inv).unwrap();
            let mut inv_ref = vec![0.0; n];
            inverse_diagonal(&u, &mut inv_ref);
            // sqrt(p)·(1/p) and 1/sqrt(p) both round twice: they agree to a few ulps.
            for (a, b) in inv.iter().zip(&inv_ref) {
                assert!((a - b).abs() <= 4.0 * f64::EPSILON * b.abs(), "{name}: reciprocal {a} vs {b}");
            }
            let upper = u.upper_triangle();
            let rebuilt = &upper * upper.transpose();
            assert!((&rebuilt - &total).amax() < 1e-13 * total.amax(), "{name}: U Uᵀ ≠ D");
            for j in 0..n {
                for i in 0..j {
                    if !model.supports(i, j) {
                        assert_eq!(u[(i, j)], 0.0, "{name}: U[{i},{j}] outside the tree's sparsity");
                    }
                }
            }
            let mut in_place = total.clone();
            factor(model, &mut in_place).unwrap();
            assert!((in_place.upper_triangle() - &upper).amax() < 1e-14 * upper.amax(), "{name}: in place");
            let b = DVector::from_fn(n, |i, _| (i as f64 * 0.7).sin() + 0.3);
            let mut x = b.clone();
            solve(model, &u, x.as_mut_slice());
            assert!((&total * &x - &b).amax() < 1e-11 * (1.0 + x.amax()), "{name}: D⁻¹ b");
            let mut x = b.clone();
            solve_u(model, &u, x.as_mut_slice());
            assert!((&upper * &x - &b).amax() < 1e-12 * (1.0 + x.amax()), "{name}: U⁻¹ b");
            let mut x = b.clone();
            solve_ut(model, &u, x.as_mut_slice());
            assert!((upper.transpose() * &x - &b).amax() < 1e-12 * (1.0 + x.amax()), "{name}: U⁻ᵀ b");
            check_columns(name, model, &u);
        }
    }

    /// The blocked multi-column solves agree with the reference solves, for 1 to 7 columns and supports
    /// ending at every body.
    fn check_columns<S: Space>(name: &str, model: &Model<S>, u: &DMatrix<f64>) {
        let n = model.nv();
        let mut inv = vec![0.0; n];
        inverse_diagonal(u, &mut inv);
        for cols in 1..=7 {
            for body in 0..n {
                // Columns supported on the joints that move `body` (so rows 0..=body).
                let b = DMatrix::from_fn(n, cols, |i, c| {
                    if model.supports(i, body) {
                        ((i * 3 + c * 5) as f64 * 0.37).cos()
                    } else {
                        0.0
                    }
                });
                let mut x = b.clone();
                solve_u_columns(model, u, &inv, x.as_mut_slice(), body + 1);
                let mut y = b.clone();
                solve_ut_columns(model, u, &inv, y.as_mut_slice());
                for c in 0..cols {
                    let mut xr = b.column(c).clone_owned();
                    solve_u(model, u, xr.as_mut_slice());
                    let mut yr = b.column(c).clone_owned();
                    solve_ut(model, u, yr.as_mut_slice());
                    let tol = 1e-12 * (1.0 + xr.amax() + yr.amax());
                    assert!((x.column(c) - &xr).amax() < tol, "{name}: U⁻¹ columns ({cols}, body {body})");
                    assert!((y.column(c) - &yr).amax() < tol, "{name}: U⁻ᵀ columns ({cols}, body {body})");
                    for i in 0..n {
                        if b[(i, c)] == 0.0 {
                            assert_eq!(x[(i, c)], 0.0, "{name}: U⁻¹ keeps the support");
                        }
                    }
                }
            }
        }
    }
}
