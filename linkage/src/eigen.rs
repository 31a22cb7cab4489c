//! Symmetric eigen-decomposition of small fixed-size matrices by cyclic Jacobi rotations.
//!
//! Λ⁻¹ is symmetric positive semi-definite, so its SVD (eq 10, 12) is its eigen-decomposition. Jacobi is
//! chosen over a QR-based solver because it computes small eigenvalues to high *relative* accuracy — what
//! decides whether a direction is constrained — has no allocation, and for 3x3 and 6x6 converges in a few
//! sweeps (measured against nalgebra's `SymmetricEigen` in the tests and benches).

use crate::space::{MatOps, Space, VecOps};

/// Eigenvalues in decreasing order and the matching unit eigenvectors as columns.
pub fn symmetric_eigen<S: Space>(a: &S::OpMat) -> (S::OpVec, S::OpMat) {
    let n = S::DIM;
    let mut a = *a;
    let mut v = S::OpMat::identity();
    let scale: f64 = (0..n).map(|i| a[(i, i)].abs()).fold(0.0, f64::max);
    for _sweep in 0..30 {
        let mut off = 0.0;
        for p in 0..n {
            for q in p + 1..n {
                off += a[(p, q)] * a[(p, q)];
            }
        }
        if off <= (f64::EPSILON * scale).powi(2) * 1e-4 || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
                a[(p, q)] = 0.0;
                a[(q, p)] = 0.0;
                for k in 0..n {
                    let (vkp, vkq) = (v[(k, p)], v[(k, q)]);
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    // Selection sort by decreasing eigenvalue (n ≤ 6), swapping eigenvector columns along.
    let mut values = S::OpVec::zero();
    for i in 0..n {
        values[i] = a[(i, i)];
    }
    for i in 0..n {
        let mut best = i;
        for j in i + 1..n {
            if values[j] > values[best] {
                best = j;
            }
        }
        if best != i {
            values.as_mut_slice().swap(i, best);
            for k in 0..n {
                let tmp = v[(k, i)];
                v[(k, i)] = v[(k, best)];
                v[(k, best)] = tmp;
            }
        }
    }
    (values, v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Planar, Spatial};
    use nalgebra::{Matrix3, Matrix6};

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
}
