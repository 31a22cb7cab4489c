//! Small dense linear algebra on preallocated matrices, for the parts that have no tree structure to
//! exploit (the client's configuration-space local model, the Schur complement).

use nalgebra::{DMatrix, DVector};

use crate::simd::F64x4;

/// `a * b + c`: one fused instruction with one rounding where the target has FMA (x86-64-v3, as this
/// workspace builds, and every aarch64). Without FMA hardware `f64::mul_add` becomes a libm call that is
/// far slower than the rounding it saves, so it falls back to the unfused form. Rust never contracts
/// `a * b + c` by itself, hence this helper in every kernel.
#[inline(always)]
pub fn mul_add(a: f64, b: f64, c: f64) -> f64 {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}

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

/// Diagonal-pivoted, rank-revealing Cholesky of the symmetric positive semi-definite `s` into the lower
/// triangle of `l`, in pivoted order (`perm[k]` = row eliminated at step k). A row is dependent when its
/// remaining pivot falls below `tolerance` times its own original diagonal, which makes the decision
/// independent of each row's units. At most `max_rank` rows are kept. Returns the numerical rank. `scale`
/// is scratch of length m; `inv_diag[k]` receives `1 / l_kk` for the kept rows, so that the solves
/// multiply instead of dividing (a solve with two rows is a chain of four dependent divisions otherwise).
pub fn pivoted_cholesky(
    s: &DMatrix<f64>,
    l: &mut DMatrix<f64>,
    perm: &mut [usize],
    scale: &mut DVector<f64>,
    inv_diag: &mut [f64],
    tolerance: f64,
    max_rank: usize,
) -> usize {
    // The sizes of a few closure rows get their own copy with m a constant, so the loops unroll (their
    // bookkeeping otherwise outweighs a 2x2 factorization several times).
    match s.nrows() {
        1 => pivoted_cholesky_m(1, s, l, perm, scale, inv_diag, tolerance, max_rank),
        2 => pivoted_cholesky_m(2, s, l, perm, scale, inv_diag, tolerance, max_rank),
        3 => pivoted_cholesky_m(3, s, l, perm, scale, inv_diag, tolerance, max_rank),
        m => pivoted_cholesky_m(m, s, l, perm, scale, inv_diag, tolerance, max_rank),
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
) -> usize {
    let a = &mut l.as_mut_slice()[..m * m];
    a.copy_from_slice(&s.as_slice()[..m * m]);
    let scale = &mut scale.as_mut_slice()[..m];
    let perm = &mut perm[..m];
    for (i, (p, sc)) in perm.iter_mut().zip(scale.iter_mut()).enumerate() {
        *p = i;
        *sc = a[i * m + i].max(f64::MIN_POSITIVE);
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
    let (r, y) = (r.as_mut_slice(), y.as_mut_slice());
    match (l.nrows(), rank) {
        (2, 2) => pivoted_solve_m(2, 2, l, inv_diag, perm, r, y),
        (3, 3) => pivoted_solve_m(3, 3, l, inv_diag, perm, r, y),
        (m, rank) => pivoted_solve_m(m, rank, l, inv_diag, perm, r, y),
    }
}

/// [`pivoted_solve`] with the sizes as arguments, copied with constants for the common small cases.
#[inline(always)]
fn pivoted_solve_m(
    m: usize,
    rank: usize,
    l: &DMatrix<f64>,
    inv_diag: &[f64],
    perm: &[usize],
    r: &mut [f64],
    y: &mut [f64],
) {
    let a = &l.as_slice()[..m * m];
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
