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
/// dependent additions (Rust keeps the written order of floating-point operations), this vectorizes.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let len = a.len().min(b.len());
    let (a, b) = (&a[..len], &b[..len]);
    let (mut acc0, mut acc1) = (F64x4::zero(), F64x4::zero());
    let mut i = 0;
    while i + 8 <= len {
        acc0 = acc0.add_mul(F64x4::load(&a[i..]), F64x4::load(&b[i..]));
        acc1 = acc1.add_mul(F64x4::load(&a[i + 4..]), F64x4::load(&b[i + 4..]));
        i += 8;
    }
    if i + 4 <= len {
        acc0 = acc0.add_mul(F64x4::load(&a[i..]), F64x4::load(&b[i..]));
        i += 4;
    }
    let mut s = acc0.add(acc1).sum();
    for (x, y) in a[i..].iter().zip(&b[i..]) {
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
    let mut i = 0;
    while i + 4 <= len {
        F64x4::load(&y[i..]).sub_mul(a, F64x4::load(&x[i..])).store(&mut y[i..]);
        i += 4;
    }
    for (y, x) in y[i..].iter_mut().zip(&x[i..]) {
        *y = mul_add(-alpha, *x, *y);
    }
}

/// Diagonal-pivoted, rank-revealing Cholesky of the symmetric positive semi-definite `s` into the lower
/// triangle of `l`, in pivoted order (`perm[k]` = row eliminated at step k). A row is dependent when its
/// remaining pivot falls below `tolerance` times its own original diagonal, which makes the decision
/// independent of each row's units. At most `max_rank` rows are kept. Returns the numerical rank. `scale`
/// is scratch of length m.
pub fn pivoted_cholesky(
    s: &DMatrix<f64>,
    l: &mut DMatrix<f64>,
    perm: &mut [usize],
    scale: &mut DVector<f64>,
    tolerance: f64,
    max_rank: usize,
) -> usize {
    let m = s.nrows();
    l.copy_from(s);
    for (i, p) in perm.iter_mut().enumerate() {
        *p = i;
        scale[i] = s[(i, i)].max(f64::MIN_POSITIVE);
    }
    for k in 0..m.min(max_rank) {
        let mut best = k;
        let mut best_ratio = -1.0;
        for p in k..m {
            let ratio = l[(p, p)] / scale[perm[p]];
            if ratio > best_ratio {
                best_ratio = ratio;
                best = p;
            }
        }
        if best_ratio.is_nan() || best_ratio <= tolerance {
            return k;
        }
        if best != k {
            l.swap_rows(k, best);
            l.swap_columns(k, best);
            perm.swap(k, best);
        }
        let lkk = l[(k, k)].sqrt();
        l[(k, k)] = lkk;
        for i in k + 1..m {
            l[(i, k)] /= lkk;
        }
        // Update the whole trailing block, both triangles: the symmetric row/column swaps of later pivots
        // read entries from either side of the diagonal.
        for j in k + 1..m {
            let ljk = l[(j, k)];
            for i in k + 1..m {
                let v = l[(i, k)] * ljk;
                l[(i, j)] -= v;
            }
        }
    }
    m.min(max_rank)
}

/// Solves `S x = r` in place with a factor from [`pivoted_cholesky`]; rows beyond the rank get `x = 0`.
/// `y` is scratch of length m.
pub fn pivoted_solve(l: &DMatrix<f64>, perm: &[usize], rank: usize, r: &mut DVector<f64>, y: &mut DVector<f64>) {
    for k in 0..rank {
        let mut s = r[perm[k]];
        for j in 0..k {
            s -= l[(k, j)] * y[j];
        }
        y[k] = s / l[(k, k)];
    }
    for k in (0..rank).rev() {
        let mut s = y[k];
        for j in k + 1..rank {
            s -= l[(j, k)] * y[j];
        }
        y[k] = s / l[(k, k)];
    }
    r.fill(0.0);
    for k in 0..rank {
        r[perm[k]] = y[k];
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
