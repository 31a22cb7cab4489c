//! Fixtures for the linkage integration tests, and the *independent* formulations the library is checked
//! against (null-space dynamics through nalgebra's SVD, finite differences).
#![allow(dead_code)]

use kinloop_linkage::{builtin, Model, Planar, Scene, Space, Spatial};
use nalgebra::{DMatrix, DVector};

/// SplitMix64: deterministic test randomness without a dependency.
pub struct Rng(pub u64);
impl Rng {
    pub fn signed(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

pub fn compile<S: Space>(scene: &Scene) -> Model<S> {
    Model::compile(scene, &scene.name).unwrap_or_else(|e| panic!("{e}"))
}

pub fn builtin_scene(name: &str) -> Scene {
    builtin::scene(name).expect("built in").expect("parses")
}

pub fn testbed() -> Model<Planar> {
    compile(&builtin_scene("paper-testbed"))
}

pub fn planar_models() -> Vec<(String, Model<Planar>)> {
    let mut v: Vec<(String, Model<Planar>)> = builtin::SCENE_FILES
        .iter()
        .filter(|(n, _)| *n != "spherical-four-bar")
        .map(|(n, _)| (n.to_string(), compile(&builtin_scene(n))))
        .collect();
    v.push(("chain12_loops3".into(), compile(&builtin::chain(12, 3))));
    v
}

pub fn spatial_models() -> Vec<(String, Model<Spatial>)> {
    vec![("spherical-four-bar".into(), compile(&builtin_scene("spherical-four-bar")))]
}

/// A state near q0 with velocities in ±1.
pub fn random_state<S: Space>(model: &Model<S>, seed: u64) -> (DVector<f64>, DVector<f64>) {
    let mut rng = Rng(seed * 7919 + 3);
    let q = DVector::from_fn(model.nq(), |i, _| model.q0[i] + 0.1 * rng.signed());
    let qd = DVector::from_fn(model.nq(), |_, _| rng.signed());
    (q, qd)
}

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
