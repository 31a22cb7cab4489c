//! Fixtures for the linkage integration tests, and the *independent* formulations the library is checked
//! against (null-space dynamics through nalgebra's SVD, finite differences).
#![allow(dead_code, unused_imports)]

use nalgebra::{DMatrix, DVector};

pub use kinloop_linkage::testing::{
    builtin_scene, compile, displaced, paper_testbed as testbed, planar_models, random_state, spatial_models,
    TestRng as Rng,
};

/// An orthonormal basis of the null space of W (n×(n-r)), from nalgebra's SVD.
pub fn null_space(w: &DMatrix<f64>, n: usize) -> DMatrix<f64> {
    if w.nrows() == 0 {
        return DMatrix::identity(n, n);
    }
    // Pad W to at least n rows so the SVD gives a full V.
    let mut padded = DMatrix::zeros(w.nrows().max(n), n);
    padded.view_mut((0, 0), (w.nrows(), n)).copy_from(w);
    let svd = padded.svd(false, true);
    let v_t = svd.v_t.unwrap();
    let smax = svd.singular_values.max();
    let cols: Vec<usize> = (0..n).filter(|&i| svd.singular_values[i] <= 1e-9 * smax).collect();
    DMatrix::from_fn(n, cols.len(), |r, c| v_t[(cols[c], r)])
}

/// Constrained accelerations by the null-space (independent-coordinates) method:
/// q̈ = q̈_p + N y with q̈_p = -W⁺ w_stab and (Nᵀ D N) y = Nᵀ (τ - D q̈_p).
pub fn null_space_accelerations(
    d: &DMatrix<f64>,
    w: &DMatrix<f64>,
    w_stab: &DVector<f64>,
    tau: &DVector<f64>,
) -> DVector<f64> {
    let n = d.nrows();
    let qdd_p = if w.nrows() == 0 { DVector::zeros(n) } else { -w.clone().pseudo_inverse(1e-12).unwrap() * w_stab };
    let nmat = null_space(w, n);
    let reduced = nmat.transpose() * d * &nmat;
    let y = reduced.lu().solve(&(nmat.transpose() * (tau - d * &qdd_p))).unwrap();
    qdd_p + nmat * y
}

/// Λ⁻¹ by the null-space formula J N (Nᵀ D N)⁻¹ Nᵀ Jᵀ.
/// W's condition number over the rows the null-space formula keeps (singular values above 1e-9 σ_max).
pub fn kept_condition(w: &DMatrix<f64>) -> f64 {
    if w.nrows() == 0 {
        return 1.0;
    }
    let sv = w.clone().svd(false, false).singular_values;
    let smax = sv.max();
    let smin = sv.iter().copied().filter(|&s| s > 1e-9 * smax).fold(f64::INFINITY, f64::min);
    smax / smin
}

pub fn null_space_inverse_inertia(d: &DMatrix<f64>, w: &DMatrix<f64>, j: &DMatrix<f64>) -> DMatrix<f64> {
    let nmat = null_space(w, d.nrows());
    let reduced = nmat.transpose() * d * &nmat;
    let inv = reduced.try_inverse().unwrap();
    j * &nmat * inv * nmat.transpose() * j.transpose()
}

pub fn assert_close(what: &str, a: &DMatrix<f64>, b: &DMatrix<f64>, rel: f64) {
    let scale = 1.0 + a.amax().max(b.amax());
    let err = (a - b).amax();
    assert!(err <= rel * scale, "{what}: max difference {err:.3e} (scale {scale:.3e})\n{a}\n{b}");
}
