//! Symmetric eigen-decomposition of small fixed-size matrices: a closed form for a cold 3x3, cyclic Jacobi
//! rotations for warm starts and 6x6.
//!
//! Λ⁻¹ is symmetric positive semi-definite, so its SVD (eq 10, 12) is its eigen-decomposition. Both methods
//! allocate nothing, return orthonormal eigenvectors, and give eigenvalues to round-off of the largest, far
//! inside the 2 % threshold that decides whether a direction is constrained (checked against nalgebra's
//! `SymmetricEigen` in the tests). A planar OP needs the 3x3 one per snapshot, so its cost is a chain of
//! dependent square roots and divisions: the closed form is written to keep that chain short.

use crate::math::dense::mul_add;
use crate::math::space::{MatOps, Space, VecOps};

/// `(t, c, s)` of the Jacobi rotation that zeroes `a_pq` given `d = a_qq - a_pp`: `t = tan φ` is the smaller
/// root of `t² + 2θt - 1 = 0` with `θ = d / (2 a_pq)` (Golub & Van Loan, Matrix Computations, §8.5.2), and
/// `c = 1/√(1 + t²)`, `s = t c`. Each rotation waits for the one before it, so what counts is the chain of
/// square roots and divisions, shortened here in three regimes that agree with the textbook formula to
/// round-off:
/// - general: with `r = √(d² + 4a_pq²)` and `g = |d| + r`, `t = 2a_pq sgn(d) / g` and `1 + t² = 2r / g`, so
///   `c = √(g / 2r)`: t and c in parallel after r (θ's division is folded in);
/// - `|θ| > 256` (typically the third sweep): series in `t₀ = a_pq / d`, `u = t₀²`:
///   `t = tan(½ atan 2t₀) = t₀ (1 - u + 2u² - 5u³)` and `c = 1 - u/2 + 11u²/8 - 69u³/16`, next terms below
///   2⁻⁷⁰: one division, no square root;
/// - `|θ| > 2²⁷` (the last sweep): `θ² + 1 = θ²` and `t² + 1 = 1` in floating point, so the textbook
///   formula is exactly `t = 1/(2θ)`, `c = 1`, `s = t`.
#[inline]
fn rotation(d: f64, apq: f64) -> (f64, f64, f64) {
    const TINY: f64 = (1u64 << 28) as f64;
    let (ad, aa) = (d.abs(), apq.abs());
    if ad > TINY * aa {
        let t = apq / d;
        return (t, 1.0, t);
    }
    if ad > 512.0 * aa {
        let t0 = apq / d;
        let u = t0 * t0;
        let t = t0 * mul_add(u, mul_add(u, mul_add(u, -5.0, 2.0), -1.0), 1.0);
        let c = mul_add(u, mul_add(u, mul_add(u, -69.0 / 16.0, 11.0 / 8.0), -0.5), 1.0);
        return (t, c, t * c);
    }
    let r = mul_add(d, d, 4.0 * apq * apq).sqrt();
    let g = ad + r;
    let t = 2.0 * apq / g;
    let t = if d.is_sign_negative() { -t } else { t };
    let c = (g / (2.0 * r)).sqrt();
    (t, c, t * c)
}

/// Eigenvalues in decreasing order and the matching unit eigenvectors as columns.
pub fn symmetric_eigen<S: Space>(a: &S::OpMat) -> (S::OpVec, S::OpMat) {
    symmetric_eigen_from::<S>(a, None)
}

/// As [`symmetric_eigen`], warm-started from a previous eigenvector matrix `guess` (the last snapshot's
/// directions; Λ⁻¹ moves little from one snapshot to the next): Jacobi runs on `Gᵀ A G`, nearly diagonal,
/// and its rotations accumulate onto G. Jacobi then converges in the cheap regimes of [`rotation`] (one
/// or two sweeps without square roots) instead of three or four from the identity, and the eigenvector signs
/// follow the guess rather than jumping. The price is that small eigenvalues are accurate relative to the
/// largest (round-off of the products, ~ε σ_max) rather than to themselves, far inside what the constraint
/// count (a 2 % threshold) and the controllers need. A guess that is not orthonormal to 1e-9 (none yet, or
/// not finite) is ignored.
pub fn symmetric_eigen_from<S: Space>(a: &S::OpMat, guess: Option<&S::OpMat>) -> (S::OpVec, S::OpMat) {
    let mut values = S::OpVec::zero();
    let mut vectors = S::OpMat::zero();
    let guess = guess.map(|g| g.as_slice());
    let (a, out) = (a.as_slice(), (values.as_mut_slice(), vectors.as_mut_slice()));
    match S::DIM {
        3 => match orthonormal_guess::<3>(guess) {
            Some(g) => warm_jacobi::<3>(a, Some(g), out.0, out.1),
            None => closed_form_3(&columns::<3>(a), out.0, out.1),
        },
        6 => warm_jacobi::<6>(a, orthonormal_guess::<6>(guess), out.0, out.1),
        n => unreachable!("operational spaces are 3- or 6-dimensional, not {n}"),
    }
    (values, vectors)
}

/// The cold 3x3 decomposition in closed form, after D. Eberly ("A Robust Eigensolver for 3x3 Symmetric
/// Matrices", Geometric Tools, 2014): the root of the characteristic cubic farthest from the other two by
/// the trigonometric formula (its cosine of a third of an arccosine found as the root of a cubic, see
/// [`largest_trisection_root`]), its eigenvector as the largest cross product of two rows of `A - λI`, then
/// the 2x2 problem on the plane orthogonal to it by one Jacobi rotation (where Eberly uses the other
/// trigonometric roots, which lose half their digits near a double root: a pair 1e-9 apart came out mixed).
/// Orthonormal by construction, and robust to repeated eigenvalues (a 1-DOF linkage's two constrained
/// directions share the eigenvalue 0: an orthonormal pair spanning that plane is returned). Eigenvalues
/// are accurate to round-off of the largest, as with the warm start.
/// Fewer instructions than cold Jacobi, which stays for warm starts (their signs follow the guess) and for
/// 6x6; the arithmetic is arranged to keep the dependency chain short (the `eigen` benchmarks compare).
fn closed_form_3(a: &[[f64; 3]; 3], values: &mut [f64], vectors: &mut [f64]) {
    // Entries within 2^±200 of one cannot overflow or underflow the cubic's coefficients or the squared
    // norms of cross products (fourth powers): decomposed as they are, so that the dependency chain does
    // not start with the scan for the largest entry (the branch is predicted). Others are scaled first by
    // a power of two near the largest entry, exactly.
    let max_abs = max_abs(a);
    const SAFE: std::ops::RangeInclusive<f64> = 6.2e-61..=1.6e60; // 2^-200..=2^200
    let (scale, inv) = if SAFE.contains(&max_abs) { (1.0, 1.0) } else { power_of_two_scale(max_abs) };
    let b: [[f64; 3]; 3] =
        if inv == 1.0 { *a } else { std::array::from_fn(|c| std::array::from_fn(|r| a[c][r] * inv)) };
    let (b01, b02, b12) = (b[1][0], b[2][0], b[2][1]);
    let off = b01 * b01 + b02 * b02 + b12 * b12;
    let mut pairs = if max_abs > 0.0 && off.is_finite() && off > 0.0 {
        let q = (b[0][0] + b[1][1] + b[2][2]) / 3.0;
        let (c00, c11, c22) = (b[0][0] - q, b[1][1] - q, b[2][2] - q);
        let p2 = (c00 * c00 + c11 * c11 + c22 * c22 + 2.0 * off) / 6.0;
        let p = p2.sqrt();
        // The eigenvalues are q + p t for the roots t of t³ - 3t = 2r, r = det((B - qI)/p)/2 in [-1, 1]
        // up to round-off (the trigonometric roots 2 cos(θ/3 + 2πk/3), cos θ = r).
        let det = c00 * (c11 * c22 - b12 * b12) - b01 * (b01 * c22 - b12 * b02) + b02 * (b01 * b12 - c11 * b02);
        // det / (2p³) as det p / (2p⁴): the division need not wait for the square root.
        let r = (det / (2.0 * p2 * p2) * p).clamp(-1.0, 1.0);
        // The root farthest from the other two is the largest when r ≥ 0 and the smallest (the largest
        // of the mirrored cubic, negated) when r < 0; it is accurate and its rows of B - λI are well
        // conditioned. The other two roots are not used (see `eigenpairs_from_normal`).
        let farthest = q + p * largest_trisection_root(r.abs()).copysign(r);
        eigenpairs_from_normal(&b, farthest, &eigenvector_from_rows(&b, farthest))
    } else {
        // Diagonal (or zero): the identity's columns, with the diagonal as values. A non-finite A gives
        // NaN values (`0 · off`), never finite ones that hide it.
        std::array::from_fn(|c| (b[c][c] + 0.0 * off, std::array::from_fn(|r| if r == c { 1.0 } else { 0.0 })))
    };
    // Decreasing order: three compare-and-swaps (NaN, from a non-finite A, stays where it is).
    for (i, j) in [(0, 1), (1, 2), (0, 1)] {
        if pairs[j].0 > pairs[i].0 {
            pairs.swap(i, j);
        }
    }
    for (c, (value, vector)) in pairs.iter().enumerate() {
        values[c] = value * scale;
        vectors[c * 3..c * 3 + 3].copy_from_slice(vector);
    }
}

/// The largest absolute entry, as a balanced tree of maxima (a left fold is a chain of nine).
fn max_abs(a: &[[f64; 3]; 3]) -> f64 {
    let col = |c: &[f64; 3]| c[0].abs().max(c[1].abs()).max(c[2].abs());
    col(&a[0]).max(col(&a[1])).max(col(&a[2]))
}

/// `(2^e, 2^-e)` with `2^e` within a factor of two of `x` (a positive normal number, else `(1, 1)`):
/// scaling by it is exact.
fn power_of_two_scale(x: f64) -> (f64, f64) {
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    let biased = (x.to_bits() & EXPONENT) >> 52;
    // 2^e and 2^-e are both normal for biased exponents 1..=2045 (2046 would need 2^-1024).
    if x > 0.0 && (1..=2045).contains(&biased) {
        (f64::from_bits(biased << 52), f64::from_bits((2046 - biased) << 52))
    } else {
        (1.0, 1.0)
    }
}

/// The largest root of `t³ - 3t = 2s` for `s` in [0, 1], `2 cos(acos(s)/3)`, in [√3, 2]: a degree-8 fit
/// (Chebyshev least squares, error below 3.2e-9) evaluated by Estrin's scheme (four levels of dependent
/// multiply-adds, not eight) and one Newton step, which squares the error to round-off (the root is simple
/// on the whole interval: the derivative `3t² - 3` is at least 6). One division where `acos` and `cos` were
/// two library calls on the chain of dependent operations.
fn largest_trisection_root(s: f64) -> f64 {
    const C: [f64; 9] = [
        1.7320508107323642,
        0.33333279938759774,
        -0.09621004522493908,
        0.04921767374583903,
        -0.030249555018482182,
        0.018840195528284195,
        -0.009945177811262612,
        0.003581939983696324,
        -0.000618643680179859,
    ];
    let s2 = s * s;
    let s4 = s2 * s2;
    let low = mul_add(mul_add(C[3], s, C[2]), s2, mul_add(C[1], s, C[0]));
    let high = mul_add(mul_add(C[7], s, C[6]), s2, mul_add(C[5], s, C[4]));
    let t = mul_add(C[8], s4 * s4, mul_add(high, s4, low));
    let t2 = t * t;
    t - mul_add(t, t2 - 3.0, -2.0 * s) / mul_add(3.0, t2, -3.0)
}

/// `x × y`.
fn cross(x: &[f64; 3], y: &[f64; 3]) -> [f64; 3] {
    [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
}

/// `x · y`.
fn dot3(x: &[f64; 3], y: &[f64; 3]) -> f64 {
    mul_add(x[0], y[0], mul_add(x[1], y[1], x[2] * y[2]))
}

/// A normal to the rows of `b - λI` for a simple eigenvalue λ of the symmetric `b`, not normalized: the rows
/// span the plane orthogonal to the eigenvector, so the largest of their three cross products is the
/// best-conditioned normal. Zero when `b = λI`.
fn eigenvector_from_rows(b: &[[f64; 3]; 3], lambda: f64) -> [f64; 3] {
    let rows: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|c| if r == c { b[c][r] - lambda } else { b[c][r] }));
    let candidates = [cross(&rows[0], &rows[1]), cross(&rows[0], &rows[2]), cross(&rows[1], &rows[2])];
    let norms = candidates.map(|x| dot3(&x, &x));
    let best = if norms[1] > norms[0] { 1 } else { 0 };
    candidates[if norms[2] > norms[best] { 2 } else { best }]
}

/// All three eigenpairs of `b` given a normal `x` (not unit) to the rows of `b - λI` for its eigenvalue λ:
/// λ with `x / |x|`, and the other two from the 2x2 symmetric M that `b` is on an orthonormal basis (u, v)
/// of the plane orthogonal to x, diagonalized by one Jacobi rotation ([`rotation`]), which also gives the
/// eigenvalues. Accurate to round-off over the gap between the two however close they are (the
/// trigonometric roots are not: near a double root the arccosine loses half the digits).
///
/// The basis is built unnormalized, `ũ ⟂ x` with a zero entry and `ṽ = x × ũ` (so `|ṽ|² = |x|² |ũ|²`),
/// and M is scaled afterwards: `m00 = ũᵀbũ / |ũ|²`, `m01 = ũᵀbṽ / (|ũ|² |x|)`, `m11 = ṽᵀbṽ / (|ũ|² |x|²)`.
/// The products with b then do not wait for the square roots and divisions of the normalizations, which
/// run beside them (this is a chain of dependent operations: its length is the cost).
fn eigenpairs_from_normal(b: &[[f64; 3]; 3], lambda: f64, x: &[f64; 3]) -> [(f64, [f64; 3]); 3] {
    let x_norm2 = dot3(x, x);
    if x_norm2 == 0.0 {
        // b = λI: every vector is an eigenvector.
        return std::array::from_fn(|c| (lambda, std::array::from_fn(|r| if r == c { 1.0 } else { 0.0 })));
    }
    let u = if x[0].abs() > x[1].abs() { [-x[2], 0.0, x[0]] } else { [0.0, x[2], -x[1]] };
    let v = cross(x, &u);
    let inv_x = 1.0 / x_norm2.sqrt();
    let u_norm2 = dot3(&u, &u);
    let inv_u2 = 1.0 / u_norm2;
    let inv_u = 1.0 / u_norm2.sqrt();
    let times =
        |y: &[f64; 3]| -> [f64; 3] { std::array::from_fn(|i| (0..3).fold(0.0, |s, j| mul_add(b[j][i], y[j], s))) };
    let (bu, bv) = (times(&u), times(&v));
    let (m00, m01, m11) =
        (dot3(&u, &bu) * inv_u2, dot3(&u, &bv) * (inv_u2 * inv_x), dot3(&v, &bv) * (inv_u2 * inv_x * inv_x));
    let w = x.map(|xi| xi * inv_x);
    let (u, v) = (u.map(|ui| ui * inv_u), v.map(|vi| vi * (inv_u * inv_x)));
    if m01 == 0.0 {
        return [(lambda, w), (m00, u), (m11, v)];
    }
    // As in `jacobi`: the rotation zeroes m01 and moves the diagonal by ∓t m01.
    let (t, c, s) = rotation(m11 - m00, m01);
    [
        (lambda, w),
        (mul_add(-t, m01, m00), std::array::from_fn(|i| mul_add(c, u[i], -s * v[i]))),
        (mul_add(t, m01, m11), std::array::from_fn(|i| mul_add(s, u[i], c * v[i]))),
    ]
}

/// Column-major N×N array from a slice.
fn columns<const N: usize>(m: &[f64]) -> [[f64; N]; N] {
    let mut out = [[0.0; N]; N];
    for (col, src) in out.iter_mut().zip(m.chunks_exact(N)) {
        col.copy_from_slice(src);
    }
    out
}

/// The guess as columns when it is orthonormal (see [`is_orthonormal`]), else none.
fn orthonormal_guess<const N: usize>(guess: Option<&[f64]>) -> Option<[[f64; N]; N]> {
    guess.map(columns::<N>).filter(is_orthonormal::<N>)
}

/// Jacobi on `Gᵀ A G` (symmetrized) from G for an orthonormal `guess` G (see [`orthonormal_guess`]), else on
/// A from the identity.
#[allow(clippy::needless_range_loop)] // i, j, k name matrix entries
fn warm_jacobi<const N: usize>(a_in: &[f64], guess: Option<[[f64; N]; N]>, values: &mut [f64], vectors: &mut [f64]) {
    let mut a = columns::<N>(a_in);
    let mut v = [[0.0; N]; N];
    for (i, col) in v.iter_mut().enumerate() {
        col[i] = 1.0;
    }
    if let Some(g) = guess {
        // A G, column by column, then Gᵀ (A G).
        let mut ag = [[0.0; N]; N];
        for j in 0..N {
            for k in 0..N {
                for i in 0..N {
                    ag[j][i] = mul_add(a[k][i], g[j][k], ag[j][i]);
                }
            }
        }
        for j in 0..N {
            for i in 0..=j {
                let x = (0..N).fold(0.0, |s, k| mul_add(g[i][k], ag[j][k], s));
                a[j][i] = x;
                a[i][j] = x;
            }
        }
        v = g;
    }
    jacobi::<N>(a, v, values, vectors);
}

/// True when the columns of `g` are orthonormal to 1e-9 (and finite).
fn is_orthonormal<const N: usize>(g: &[[f64; N]; N]) -> bool {
    (0..N).all(|i| {
        (0..=i).all(|j| {
            let d = (0..N).fold(0.0, |s, k| mul_add(g[i][k], g[j][k], s));
            (d - if i == j { 1.0 } else { 0.0 }).abs() <= 1e-9
        })
    })
}

/// Cyclic Jacobi on an N×N symmetric matrix (columns `a`), writing the eigenvalues in decreasing order and
/// the eigenvectors as columns: the rotations accumulate onto `v` (the identity, or a warm start's G). On
/// fixed-size arrays so that, for N = 3, the sweep unrolls into straight code with constant indices.
#[allow(clippy::needless_range_loop)] // p, q, r, k name matrix entries, as in the algorithm's statement
fn jacobi<const N: usize>(mut a: [[f64; N]; N], mut v: [[f64; N]; N], values: &mut [f64], vectors: &mut [f64]) {
    let scale: f64 = (0..N).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for _sweep in 0..30 {
        let mut off = 0.0;
        for q in 0..N {
            for p in 0..q {
                off += a[q][p] * a[q][p];
            }
        }
        if off <= (f64::EPSILON * scale).powi(2) * 1e-4 || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                let apq = a[q][p];
                if apq == 0.0 {
                    continue;
                }
                let (t, c, s) = rotation(a[q][q] - a[p][p], apq);
                // A ← Jᵀ A J on the symmetric matrix: the two diagonal entries in closed form (the rotation
                // zeroes a_pq), the other entries of rows and columns p, q rotated once and mirrored.
                a[p][p] = mul_add(-t, apq, a[p][p]);
                a[q][q] = mul_add(t, apq, a[q][q]);
                a[q][p] = 0.0;
                a[p][q] = 0.0;
                for r in 0..N {
                    if r == p || r == q {
                        continue;
                    }
                    // c (a_rp - t a_rq) rather than c a_rp - s a_rq: t is ready before c (see `rotation`).
                    let (arp, arq) = (a[p][r], a[q][r]);
                    let new_p = c * mul_add(-t, arq, arp);
                    let new_q = c * mul_add(t, arp, arq);
                    a[p][r] = new_p;
                    a[r][p] = new_p;
                    a[q][r] = new_q;
                    a[r][q] = new_q;
                }
                for k in 0..N {
                    let (vkp, vkq) = (v[p][k], v[q][k]);
                    v[p][k] = mul_add(c, vkp, -s * vkq);
                    v[q][k] = mul_add(s, vkp, c * vkq);
                }
            }
        }
    }
    // Selection sort by decreasing eigenvalue (N ≤ 6), swapping eigenvector columns along.
    for i in 0..N {
        values[i] = a[i][i];
    }
    for i in 0..N {
        let mut best = i;
        for j in i + 1..N {
            if values[j] > values[best] {
                best = j;
            }
        }
        if best != i {
            values.swap(i, best);
            v.swap(i, best);
        }
    }
    for (dst, col) in vectors.chunks_exact_mut(N).zip(&v) {
        dst.copy_from_slice(col);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::space::{Planar, Spatial};
    use nalgebra::{Matrix3, Matrix6};

    /// The three regimes of `rotation` agree with the textbook formula to round-off, and zero a_pq.
    #[test]
    fn rotation_regimes_match_the_textbook_formula() {
        for apq in [1.0, -0.3, 1e-3, -2e-7, 1e-12] {
            for d in [0.0, -0.0, 0.7, -2.5, 1.0, 300.0, -1e4, 1e7, 3e9] {
                let theta: f64 = d / (2.0 * apq);
                let t_ref = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c_ref = 1.0 / (t_ref * t_ref + 1.0).sqrt();
                let (t, c, s) = rotation(d, apq);
                assert!((t - t_ref).abs() <= 4.0 * f64::EPSILON * t_ref.abs(), "d {d}, a {apq}: t {t} vs {t_ref}");
                assert!((c - c_ref).abs() <= 4.0 * f64::EPSILON, "d {d}, a {apq}: c {c} vs {c_ref}");
                assert!((s - t_ref * c_ref).abs() <= 4.0 * f64::EPSILON * s.abs(), "d {d}, a {apq}: s");
                // The rotated a_pq: c s (a_pp - a_qq) + (c² - s²) a_pq = 0.
                let rotated = c * s * (-d) + (c * c - s * s) * apq;
                assert!(rotated.abs() <= 1e-15 * (d.abs() + apq.abs()), "d {d}, a {apq}: {rotated}");
            }
        }
    }

    /// Matches nalgebra's eigenvalues and reconstructs the matrix, including a rank-deficient one.
    #[test]
    fn jacobi_matches_nalgebra_and_reconstructs() {
        let b = Matrix3::new(1.0, 0.2, -0.3, 0.5, 2.0, 0.1, 0.0, -0.7, 0.4);
        let a = b * b.transpose();
        let (vals, vecs) = symmetric_eigen::<Planar>(&a);
        let mut theirs: Vec<f64> = a.symmetric_eigen().eigenvalues.iter().copied().collect();
        theirs.sort_by(|x, y| y.partial_cmp(x).unwrap());
        for i in 0..3 {
            assert!((vals[i] - theirs[i]).abs() < 1e-12, "{vals} vs {theirs:?}");
        }
        let rebuilt = vecs * Matrix3::from_diagonal(&vals) * vecs.transpose();
        assert!((rebuilt - a).norm() < 1e-12);
        assert!((vecs.transpose() * vecs - Matrix3::identity()).norm() < 1e-12);

        // Rank 4 of 6: two zero eigenvalues found as (numerically) zero.
        let c = nalgebra::SMatrix::<f64, 6, 4>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 1.7 + 0.1 * j as f64);
        let a6: Matrix6<f64> = c * c.transpose();
        let (vals6, vecs6) = symmetric_eigen::<Spatial>(&a6);
        assert!(vals6[4].abs() < 1e-12 * vals6[0] && vals6[5].abs() < 1e-12 * vals6[0], "{vals6}");
        let rebuilt6 = vecs6 * Matrix6::from_diagonal(&vals6) * vecs6.transpose();
        assert!((rebuilt6 - a6).norm() < 1e-11 * a6.norm());
    }

    /// The closed form against nalgebra's QR-based solver on matrices that stress it: random ones over many
    /// scales, rank one (two zero eigenvalues: a 1-DOF linkage's Λ⁻¹), two equal largest eigenvalues, a
    /// nearly repeated pair, diagonal ones (already decomposed) and the zero matrix. Each result is checked
    /// on its own terms too: orthonormal vectors that rebuild A to round-off of its largest eigenvalue.
    #[test]
    fn closed_form_3_matches_nalgebra_on_hard_cases() {
        let r = Matrix3::new(0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6); // a rotation
        let mut cases = vec![
            r * Matrix3::from_diagonal(&nalgebra::Vector3::new(2.0, 0.0, 0.0)) * r.transpose(),
            r * Matrix3::from_diagonal(&nalgebra::Vector3::new(3.0, 3.0, 1.0)) * r.transpose(),
            r * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0 + 1e-9, 5.0)) * r.transpose(),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(0.5, 2.0, -1.0)),
            Matrix3::zeros(),
        ];
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for scale in [1e-200, 1e-6, 1.0, 1e8, 1e200] {
            for _ in 0..50 {
                let b = Matrix3::from_fn(|_, _| next());
                cases.push((b * b.transpose()) * scale);
                let c = Matrix3::from_fn(|_, _| next());
                cases.push((c + c.transpose()) * scale);
            }
        }
        for bad in [f64::NAN, f64::INFINITY] {
            let mut a = Matrix3::identity();
            a[(0, 2)] = bad;
            a[(2, 0)] = bad;
            assert!(symmetric_eigen::<Planar>(&a).0.iter().all(|x| x.is_nan()), "{a}");
        }
        for a in cases {
            let (vals, vecs) = symmetric_eigen::<Planar>(&a);
            let mut theirs: Vec<f64> = a.symmetric_eigen().eigenvalues.iter().copied().collect();
            theirs.sort_by(|x, y| y.total_cmp(x));
            let big = vals.amax().max(f64::MIN_POSITIVE);
            for i in 0..3 {
                assert!((vals[i] - theirs[i]).abs() <= 1e-13 * big, "{a}: {vals} vs {theirs:?}");
            }
            assert!(vals[0] >= vals[1] && vals[1] >= vals[2], "decreasing: {vals}");
            assert!((vecs.transpose() * vecs - Matrix3::identity()).amax() < 1e-14, "{a}: not orthonormal {vecs}");
            let rebuilt = vecs * Matrix3::from_diagonal(&vals) * vecs.transpose();
            assert!((rebuilt - a).amax() <= 1e-13 * big, "{a}: rebuilt {rebuilt}");
        }
    }

    /// The trisection root against the trigonometric formula it replaces, and as a root of its cubic.
    #[test]
    fn largest_trisection_root_matches_the_trigonometric_formula() {
        for i in 0..=10_000 {
            let s = i as f64 / 10_000.0;
            let t = largest_trisection_root(s);
            let reference = 2.0 * (s.acos() / 3.0).cos();
            assert!((t - reference).abs() <= 4.0 * f64::EPSILON, "s {s}: {t} vs {reference}");
            assert!((t * t * t - 3.0 * t - 2.0 * s).abs() <= 1e-14, "s {s}: residual");
        }
    }

    /// Exact power-of-two scales for normal numbers, within a factor of two; the identity elsewhere.
    #[test]
    fn power_of_two_scale_is_exact_and_close() {
        for x in [1.0, 3.0, 0.7, 1e-300, 1e300, f64::MAX / 2.0, f64::MIN_POSITIVE * 3.0] {
            let (scale, inv) = power_of_two_scale(x);
            assert!(scale <= x && x < 2.0 * scale, "{x}: {scale}");
            assert_eq!(scale * inv, 1.0, "{x}");
        }
        for x in [0.0, -1.0, f64::NAN, f64::INFINITY, f64::MAX, 1e-310] {
            assert_eq!(power_of_two_scale(x), (1.0, 1.0), "{x}");
        }
    }

    /// Warm-started from the eigenvectors of a nearby matrix (as from one snapshot to the next), the result
    /// matches the cold decomposition: eigenvalues to round-off of the largest, the same eigenvectors up to
    /// sign with the guess's signs kept, and a full reconstruction; a guess that is not orthonormal (zeros, as
    /// before any snapshot, or NaN) falls back to the cold start.
    #[test]
    fn warm_start_matches_the_cold_decomposition() {
        let b = Matrix3::new(1.0, 0.2, -0.3, 0.5, 2.0, 0.1, 0.0, -0.7, 0.4);
        let a0 = b * b.transpose() + Matrix3::from_diagonal(&nalgebra::Vector3::new(0.0, 0.0, 1e-4));
        let (_, v0) = symmetric_eigen::<Planar>(&a0);
        // Flip one column of the guess: the warm result must keep that sign.
        let mut guess = v0;
        guess.column_mut(1).neg_mut();
        let nudge = Matrix3::new(0.0, 1e-3, 0.0, 1e-3, 2e-3, -1e-3, 0.0, -1e-3, 0.0);
        let a = a0 + nudge;
        let (cold_vals, cold_vecs) = symmetric_eigen::<Planar>(&a);
        let (vals, vecs) = symmetric_eigen_from::<Planar>(&a, Some(&guess));
        for i in 0..3 {
            assert!((vals[i] - cold_vals[i]).abs() <= 1e-14 * cold_vals[0], "{vals} vs {cold_vals}");
            let (warm, cold) = (vecs.column(i), cold_vecs.column(i));
            assert!((warm.dot(&cold).abs() - 1.0).abs() < 1e-12, "column {i}: {warm} vs {cold}");
            assert!(warm.dot(&guess.column(i)) > 0.9, "column {i} keeps the guess's sign");
        }
        let rebuilt = vecs * Matrix3::from_diagonal(&vals) * vecs.transpose();
        assert!((rebuilt - a).norm() < 1e-13 * a.norm());
        for bad in [Matrix3::zeros(), Matrix3::from_element(f64::NAN), guess * 1.01] {
            let (v, e) = symmetric_eigen_from::<Planar>(&a, Some(&bad));
            assert_eq!((v, e), (cold_vals, cold_vecs), "guess {bad} should be ignored");
        }
        // The spatial 6x6 path too.
        let c = nalgebra::SMatrix::<f64, 6, 6>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 1.7 + 0.1 * j as f64);
        let a6: Matrix6<f64> = c * c.transpose();
        let (_, g6) = symmetric_eigen::<Spatial>(&a6);
        let a6n = a6 + Matrix6::from_fn(|i, j| 1e-4 * ((i + j) % 3) as f64);
        let (cold6, _) = symmetric_eigen::<Spatial>(&a6n);
        let (vals6, vecs6) = symmetric_eigen_from::<Spatial>(&a6n, Some(&g6));
        assert!((vals6 - cold6).amax() <= 1e-13 * cold6[0], "{vals6} vs {cold6}");
        assert!((vecs6 * Matrix6::from_diagonal(&vals6) * vecs6.transpose() - a6n).norm() < 1e-12 * a6n.norm());
    }
}
