//! Symmetric eigen-decomposition of small fixed-size matrices by cyclic Jacobi rotations.
//!
//! Λ⁻¹ is symmetric positive semi-definite, so its SVD (eq 10, 12) is its eigen-decomposition. Jacobi is
//! chosen over a QR-based solver because it computes small eigenvalues to high *relative* accuracy — what
//! decides whether a direction is constrained — has no allocation, and for 3x3 and 6x6 converges in a few
//! sweeps (measured against nalgebra's `SymmetricEigen` in the tests and benches).

use crate::dense::mul_add;
use crate::space::{MatOps, Space, VecOps};

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
    match S::DIM {
        3 => warm_jacobi::<3>(a.as_slice(), guess, values.as_mut_slice(), vectors.as_mut_slice()),
        6 => warm_jacobi::<6>(a.as_slice(), guess, values.as_mut_slice(), vectors.as_mut_slice()),
        n => unreachable!("operational spaces are 3- or 6-dimensional, not {n}"),
    }
    (values, vectors)
}

/// Column-major N×N array from a slice.
fn columns<const N: usize>(m: &[f64]) -> [[f64; N]; N] {
    let mut out = [[0.0; N]; N];
    for (col, src) in out.iter_mut().zip(m.chunks_exact(N)) {
        col.copy_from_slice(src);
    }
    out
}

/// `Gᵀ A G` (symmetrized) and G when `guess` is an orthonormal G, else A and the identity.
#[allow(clippy::needless_range_loop)] // i, j, k name matrix entries
fn warm_jacobi<const N: usize>(a_in: &[f64], guess: Option<&[f64]>, values: &mut [f64], vectors: &mut [f64]) {
    let mut a = columns::<N>(a_in);
    let mut v = [[0.0; N]; N];
    for (i, col) in v.iter_mut().enumerate() {
        col[i] = 1.0;
    }
    if let Some(g) = guess.map(columns::<N>).filter(is_orthonormal::<N>) {
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
/// the eigenvectors as columns: the rotations accumulate onto `v` (the identity, or a warm start's G). On fixed-size arrays so that, for N = 3, the sweep unrolls into straight
/// code with constant indices.
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
    use crate::{Planar, Spatial};
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
