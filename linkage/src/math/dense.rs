//! Small dense linear algebra on preallocated matrices, for the parts that have no tree structure to
//! exploit (the client's configuration-space local model, the Schur complement).

use nalgebra::{DMatrix, DVector};

pub use crate::math::simd::mul_add;
use crate::math::simd::F64x4;

/// Evaluates `$fixed` with the constant `$N` equal to `$n` when `1 ≤ n ≤ 8`, else `$general`. Eight covers
/// every built-in closed-loop scene; the `chainN` benchmarks take `ltl`'s tree-sparse path.
macro_rules! by_size {
    ($n:expr, $N:ident => $fixed:expr, _ => $general:expr) => {
        by_size!(@arms $n, $N, $fixed, $general, [1 2 3 4 5 6 7 8])
    };
    (@arms $n:expr, $N:ident, $fixed:expr, $general:expr, [$($size:literal)*]) => {
        match $n {
            $($size => {
                const $N: usize = $size;
                $fixed
            })*
            _ => $general,
        }
    };
}
pub(crate) use by_size;

/// `Σ a_i b_i` over the common length, in eight interleaved partial sums: a serial sum is one long chain of
/// dependent additions (Rust keeps the written order of floating-point operations), this vectorizes. Short
/// vectors (Jacobian columns of a body near the base, the testbed's four joints) take a plain loop.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let len = a.len().min(b.len());
    let (a, b) = (&a[..len], &b[..len]);
    if len < 8 {
        let mut s = 0.0;
        for (x, y) in a.iter().zip(b) {
            s = mul_add(*x, *y, s);
        }
        return s;
    }
    let (mut acc0, mut acc1) = (F64x4::zero(), F64x4::zero());
    let (mut ca, mut cb) = (a.chunks_exact(8), b.chunks_exact(8));
    for (x, y) in (&mut ca).zip(&mut cb) {
        acc0 = acc0.add_mul(F64x4::load(&x[..4]), F64x4::load(&y[..4]));
        acc1 = acc1.add_mul(F64x4::load(&x[4..]), F64x4::load(&y[4..]));
    }
    let (mut ra, mut rb) = (ca.remainder(), cb.remainder());
    if ra.len() >= 4 {
        acc0 = acc0.add_mul(F64x4::load(ra), F64x4::load(rb));
        (ra, rb) = (&ra[4..], &rb[4..]);
    }
    let mut s = acc0.add(acc1).sum();
    for (x, y) in ra.iter().zip(rb) {
        s = mul_add(*x, *y, s);
    }
    s
}

/// `Σ_{i<N} a_i b_i` over the first N entries, N a constant (the loop unrolls): the same sum, in the same
/// order, as [`dot`] gives for fewer than 8 terms.
#[inline(always)]
pub fn dot_fixed<const N: usize>(a: &[f64], b: &[f64]) -> f64 {
    let (a, b): (&[f64; N], &[f64; N]) = (a[..N].try_into().expect("N entries"), b[..N].try_into().expect("N entries"));
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        s = mul_add(*x, *y, s);
    }
    s
}

/// `dst ← src` (the same length). Up to 8 numbers (the workspaces of small linkages: q, a closure's
/// residual, Wᵀ of a planar pin) the copy has a constant length and is done inline, where `copy_from_slice`
/// of a length known only at run time calls `memcpy`, whose entry costs more than copying a few numbers.
#[inline(always)]
pub fn copy(dst: &mut [f64], src: &[f64]) {
    by_size!(dst.len(), N => dst[..N].copy_from_slice(&src[..N]), _ => dst.copy_from_slice(src))
}

/// `x ← 0`, inline up to 8 numbers as [`copy`].
#[inline(always)]
pub fn zero(x: &mut [f64]) {
    by_size!(x.len(), N => x[..N].fill(0.0), _ => x.fill(0.0))
}

/// `y ← y - alpha x` over the common length.
#[inline]
pub fn sub_scaled(y: &mut [f64], alpha: f64, x: &[f64]) {
    let len = y.len().min(x.len());
    let (y, x) = (&mut y[..len], &x[..len]);
    let a = F64x4::splat(alpha);
    let (mut cy, mut cx) = (y.chunks_exact_mut(4), x.chunks_exact(4));
    for (y, x) in (&mut cy).zip(&mut cx) {
        F64x4::load(y).sub_mul(a, F64x4::load(x)).store(y);
    }
    for (y, x) in cy.into_remainder().iter_mut().zip(cx.remainder()) {
        *y = mul_add(-alpha, *x, *y);
    }
}

/// A closure row whose diagonal of S, in the scene's units, is below this fraction of the largest counts as
/// vanishing (see [`pivoted_cholesky`]): a tenth of the largest row's norm.
pub const VANISHING_ROW: f64 = 1e-2;

/// Diagonal-pivoted, rank-revealing Cholesky of the symmetric positive semi-definite `s` into the lower
/// triangle of `l`, in pivoted order (`perm[k]` = row eliminated at step k). A row is dependent when its
/// remaining pivot falls below `tolerance` times its own original diagonal, which makes the decision
/// independent of each row's units. At most `max_rank` rows are kept. Returns the numerical rank. `scale`
/// is scratch of length m; `inv_diag[k]` receives `1 / l_kk` for the kept rows, so that the solves
/// multiply instead of dividing (a solve with two rows is a chain of four dependent divisions otherwise).
///
/// **Rows that vanish.** Relative to its own diagonal every row starts at 1, so without more the first row
/// kept is row 0 however small it has become. With `weights`, which put the rows in common units
/// (`Model::closure_row_weights`: 1/L² for a length row), a row's own diagonal is floored at
/// [`VANISHING_ROW`] times the largest weighted diagonal (divided by its weight): a row that has all but
/// vanished at the current state (a Bennett linkage's cut at its fold, where one of its point rows tends to
/// zero) then counts as small, and is kept only after the rows that still hold the loop. Rows of comparable
/// size are chosen and judged as without weights. The choice matters only where rows are dropped
/// (`max_rank` or a singular state); the kept rows' solution is the same.
#[allow(clippy::too_many_arguments)] // scratch and outputs are the caller's, preallocated
pub fn pivoted_cholesky(
    s: &DMatrix<f64>,
    l: &mut DMatrix<f64>,
    perm: &mut [usize],
    scale: &mut DVector<f64>,
    inv_diag: &mut [f64],
    tolerance: f64,
    max_rank: usize,
    weights: Option<&[f64]>,
) -> usize {
    // The sizes of a few closure rows get their own copy with m a constant, so the loops unroll (their
    // bookkeeping otherwise outweighs a 2x2 factorization several times).
    match s.nrows() {
        1 => pivoted_cholesky_m(1, s, l, perm, scale, inv_diag, tolerance, max_rank, weights),
        2 => pivoted_cholesky_2(s, l, perm, inv_diag, tolerance, max_rank, weights),
        3 => pivoted_cholesky_m(3, s, l, perm, scale, inv_diag, tolerance, max_rank, weights),
        m => pivoted_cholesky_m(m, s, l, perm, scale, inv_diag, tolerance, max_rank, weights),
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)] // the sizes are arguments so that each copy gets them as constants
fn pivoted_cholesky_m(
    m: usize,
    s: &DMatrix<f64>,
    l: &mut DMatrix<f64>,
    perm: &mut [usize],
    scale: &mut DVector<f64>,
    inv_diag: &mut [f64],
    tolerance: f64,
    max_rank: usize,
    weights: Option<&[f64]>,
) -> usize {
    let a = &mut l.as_mut_slice()[..m * m];
    a.copy_from_slice(&s.as_slice()[..m * m]);
    let scale = &mut scale.as_mut_slice()[..m];
    let perm = &mut perm[..m];
    let floor = weights.map_or(0.0, |w| VANISHING_ROW * (0..m).map(|i| a[i * m + i] * w[i]).fold(0.0, f64::max));
    for (i, (p, sc)) in perm.iter_mut().zip(scale.iter_mut()).enumerate() {
        *p = i;
        let own = weights.map_or(a[i * m + i], |w| a[i * m + i].max(floor / w[i]));
        *sc = own.max(f64::MIN_POSITIVE);
    }
    let cap = m.min(max_rank);
    for k in 0..cap {
        let mut best = k;
        let mut best_ratio = -1.0;
        for p in k..m {
            let ratio = a[p * m + p] / scale[perm[p]];
            if ratio > best_ratio {
                best_ratio = ratio;
                best = p;
            }
        }
        if best_ratio.is_nan() || best_ratio <= tolerance {
            return k;
        }
        if best != k {
            // Symmetric swap of rows and columns k and best (k < best).
            for c in 0..m {
                a.swap(c * m + k, c * m + best);
            }
            let (left, right) = a.split_at_mut(best * m);
            left[k * m..(k + 1) * m].swap_with_slice(&mut right[..m]);
            perm.swap(k, best);
        }
        let (head, trailing) = a.split_at_mut((k + 1) * m);
        let col_k = &mut head[k * m..];
        // sqrt(p) and 1/p side by side rather than 1/sqrt(p) in sequence (as in `ltl`).
        let pivot = col_k[k];
        let lkk = pivot.sqrt();
        col_k[k] = lkk;
        let inv = lkk * (1.0 / pivot);
        inv_diag[k] = inv;
        for x in &mut col_k[k + 1..] {
            *x *= inv;
        }
        // Update the whole trailing block, both triangles: the symmetric row/column swaps of later pivots
        // read entries from either side of the diagonal.
        for (col_j, ljk) in trailing.chunks_exact_mut(m).zip(&col_k[k + 1..]) {
            sub_scaled(&mut col_j[k + 1..], *ljk, &col_k[k + 1..]);
        }
    }
    cap
}

/// [`pivoted_cholesky_m`] for m = 2 (a planar pin joint's closure, the commonest cut) written out: the same
/// operations in the same order, so the same bits (a test compares the two), without the general loops'
/// swaps, scale array and trailing-block bookkeeping, which cost three times the arithmetic.
fn pivoted_cholesky_2(
    s: &DMatrix<f64>,
    l: &mut DMatrix<f64>,
    perm: &mut [usize],
    inv_diag: &mut [f64],
    tolerance: f64,
    max_rank: usize,
    weights: Option<&[f64]>,
) -> usize {
    let [s00, s10, _, s11]: [f64; 4] = s.as_slice()[..4].try_into().expect("a 2x2 matrix");
    let out: &mut [f64; 4] = (&mut l.as_mut_slice()[..4]).try_into().expect("a 2x2 factor");
    *out = [s00, s10, s10, s11];
    perm[..2].copy_from_slice(&[0, 1]);
    let floor = weights.map_or(0.0, |w| VANISHING_ROW * 0.0f64.max(s00 * w[0]).max(s11 * w[1]));
    let own = weights.map_or([s00, s11], |w| [s00.max(floor / w[0]), s11.max(floor / w[1])]);
    let scale = [own[0].max(f64::MIN_POSITIVE), own[1].max(f64::MIN_POSITIVE)];
    let cap = max_rank.min(2);
    if cap == 0 {
        return 0;
    }
    // First pivot: the larger of the two relative diagonals (the first on a tie), NaN never chosen.
    let (r0, r1) = (s00 / scale[0], s11 / scale[1]);
    let mut best_ratio = -1.0;
    let mut best = 0;
    if r0 > best_ratio {
        best_ratio = r0;
    }
    if r1 > best_ratio {
        best_ratio = r1;
        best = 1;
    }
    if best_ratio.is_nan() || best_ratio <= tolerance {
        return 0;
    }
    // In pivoted order: (a, b; b, c) with a the chosen diagonal.
    let (a, c) = if best == 1 { (s11, s00) } else { (s00, s11) };
    if best == 1 {
        perm[..2].copy_from_slice(&[1, 0]);
        out[0] = s11;
        out[3] = s00;
    }
    let l00 = a.sqrt();
    let inv0 = l00 * (1.0 / a);
    let l10 = s10 * inv0;
    let c = mul_add(-l10, l10, c);
    out[0] = l00;
    out[1] = l10;
    out[3] = c;
    inv_diag[0] = inv0;
    if cap == 1 {
        return 1;
    }
    let ratio = c / scale[perm[1]];
    if ratio.is_nan() || ratio <= -1.0 || ratio <= tolerance {
        return 1;
    }
    let l11 = c.sqrt();
    out[3] = l11;
    inv_diag[1] = l11 * (1.0 / c);
    2
}

/// Solves `S x = r` in place with a factor (and its `inv_diag`) from [`pivoted_cholesky`]; rows beyond the
/// rank get `x = 0`. `y` is scratch of length m.
pub fn pivoted_solve(
    l: &DMatrix<f64>,
    inv_diag: &[f64],
    perm: &[usize],
    rank: usize,
    r: &mut DVector<f64>,
    y: &mut DVector<f64>,
) {
    pivoted_solve_slices(l.as_slice(), l.nrows(), inv_diag, perm, rank, r.as_mut_slice(), y.as_mut_slice());
}

/// [`pivoted_solve`] on slices: `l` is the m×m factor (column-major), `r` has m entries.
#[inline]
pub fn pivoted_solve_slices(
    l: &[f64],
    m: usize,
    inv_diag: &[f64],
    perm: &[usize],
    rank: usize,
    r: &mut [f64],
    y: &mut [f64],
) {
    match (m, rank) {
        (2, 2) => pivoted_solve_2(l, inv_diag, perm, r),
        (3, 3) => pivoted_solve_m(3, 3, l, inv_diag, perm, r, y),
        (m, rank) => pivoted_solve_m(m, rank, l, inv_diag, perm, r, y),
    }
}

/// [`pivoted_solve_m`] for a 2x2 factor of rank 2 written out, the same operations in the same order.
#[inline(always)]
fn pivoted_solve_2(l: &[f64], inv_diag: &[f64], perm: &[usize], r: &mut [f64]) {
    let (l10, inv0, inv1) = (l[1], inv_diag[0], inv_diag[1]);
    let (p0, p1) = (perm[0], perm[1]);
    let (r0, r1) = (r[p0], r[p1]);
    let y0 = r0 * inv0;
    let y1 = mul_add(-l10, y0, r1) * inv1;
    // The general loop's back substitution: an empty dot product (0.0) for the last row.
    let y1 = (y1 - 0.0) * inv1;
    let y0 = (y0 - mul_add(l10, y1, 0.0)) * inv0;
    r[..2].fill(0.0);
    r[p0] = y0;
    r[p1] = y1;
}

/// [`pivoted_solve`] with the sizes as arguments, copied with constants for the common small cases.
#[inline(always)]
fn pivoted_solve_m(m: usize, rank: usize, l: &[f64], inv_diag: &[f64], perm: &[usize], r: &mut [f64], y: &mut [f64]) {
    let a = &l[..m * m];
    let r = &mut r[..m];
    let y = &mut y[..rank];
    for k in 0..rank {
        let mut s = r[perm[k]];
        for (j, yj) in y[..k].iter().enumerate() {
            s = mul_add(-a[j * m + k], *yj, s);
        }
        y[k] = s * inv_diag[k];
    }
    for k in (0..rank).rev() {
        let col = &a[k * m..k * m + rank];
        y[k] = (y[k] - dot(&col[k + 1..], &y[k + 1..])) * inv_diag[k];
    }
    r.fill(0.0);
    for (p, yk) in perm.iter().zip(y.iter()) {
        r[*p] = *yk;
    }
}

/// In-place Cholesky `A = L Lᵀ` of a symmetric positive definite matrix (lower triangle of `a` becomes L).
/// Returns false if a pivot is not positive.
pub fn cholesky_in_place(a: &mut DMatrix<f64>) -> bool {
    let n = a.nrows();
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let ljj = d.sqrt();
        a[(j, j)] = ljj;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / ljj;
        }
    }
    true
}

/// `x ← L⁻¹ x` for the lower-triangular L of [`cholesky_in_place`].
pub fn solve_lower(l: &DMatrix<f64>, x: &mut [f64]) {
    let n = l.nrows();
    for i in 0..n {
        let mut s = x[i];
        for k in 0..i {
            s -= l[(i, k)] * x[k];
        }
        x[i] = s / l[(i, i)];
    }
}

/// `x ← L⁻ᵀ x`.
pub fn solve_lower_t(l: &DMatrix<f64>, x: &mut [f64]) {
    let n = l.nrows();
    for i in (0..n).rev() {
        let mut s = x[i];
        for k in i + 1..n {
            s -= l[(k, i)] * x[k];
        }
        x[i] = s / l[(i, i)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::TestRng;

    /// The written-out 2x2 pivoted factorization and solve give the general loops' bits: rank, order, factor,
    /// reciprocals and solutions, on random positive-definite, nearly and exactly singular, indefinite and non-finite
    /// matrices, for every rank cap and a few tolerances.
    #[test]
    fn pivoted_cholesky_2_is_the_general_one() {
        let mut rng = TestRng(5);
        let mut cases: Vec<[f64; 3]> = (0..2000)
            .map(|i| {
                let (x, y, z) = (rng.signed(), rng.signed(), rng.signed());
                match i % 5 {
                    // A Gram matrix of two random columns: positive (semi-)definite.
                    0 | 1 => [x * x + z * z, x * y + z * y * 0.5, y * y + 0.25 * y * y],
                    // Rank one, up to round-off.
                    2 => [x * x, x * y, y * y * (1.0 + 1e-13 * z)],
                    // Scaled very differently (units).
                    3 => [1e6 * (x * x + 1.0), 1e3 * x * y, 1e-2 * (y * y + 1.0)],
                    _ => [x, y, z],
                }
            })
            .collect();
        cases.extend([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [f64::NAN, 0.0, 1.0], [1.0, f64::NAN, 1.0]]);
        cases.extend([[1.0, 0.0, f64::INFINITY], [-1.0, 0.5, 2.0], [2.0, 2.0, 2.0]]);
        for [a, b, c] in cases {
            let s = DMatrix::from_column_slice(2, 2, &[a, b, b, c]);
            let weightings: [Option<[f64; 2]>; 4] = [None, Some([1.0, 1.0]), Some([1e4, 1.0]), Some([1.0, 1e-6])];
            for (max_rank, weighting) in (0..=2).flat_map(|r| weightings.map(|w| (r, w))) {
                let weights = weighting.as_ref().map(|w| &w[..]);
                for tolerance in [0.0, 1e-10, 0.5] {
                    let (mut l1, mut l2) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 2));
                    let (mut p1, mut p2) = ([9; 2], [9; 2]);
                    let (mut d1, mut d2) = ([0.0; 2], [0.0; 2]);
                    let mut scale = DVector::zeros(2);
                    let m = std::hint::black_box(2);
                    let r1 =
                        pivoted_cholesky_m(m, &s, &mut l1, &mut p1, &mut scale, &mut d1, tolerance, max_rank, weights);
                    let r2 = pivoted_cholesky_2(&s, &mut l2, &mut p2, &mut d2, tolerance, max_rank, weights);
                    let case = format!(
                        "S = [{a}, {b}; {b}, {c}], cap {max_rank}, tolerance {tolerance}, weights {weighting:?}"
                    );
                    assert_eq!(r1, r2, "{case}: rank");
                    assert_eq!(p1, p2, "{case}: order");
                    let bits = |x: f64| x.to_bits();
                    for k in 0..r1 {
                        assert_eq!(bits(d1[k]), bits(d2[k]), "{case}: 1/L_{k}{k}");
                        for r in k..2 {
                            assert_eq!(bits(l1[(r, k)]), bits(l2[(r, k)]), "{case}: L_{r}{k}");
                        }
                    }
                    if r1 == 2 {
                        // And the written-out solve gives the general one's bits.
                        let rhs = [rng.signed(), 1e3 * rng.signed()];
                        let (mut x1, mut x2) = (DVector::from_column_slice(&rhs), DVector::from_column_slice(&rhs));
                        let mut y = DVector::zeros(2);
                        let (m, rank) = (std::hint::black_box(2), std::hint::black_box(2));
                        pivoted_solve_m(m, rank, l1.as_slice(), &d1, &p1, x1.as_mut_slice(), y.as_mut_slice());
                        pivoted_solve(&l2, &d2, &p2, r2, &mut x2, &mut y);
                        assert_eq!(x1.map(bits), x2.map(bits), "{case}: solve of {rhs:?}");
                    }
                }
            }
        }
    }
}
