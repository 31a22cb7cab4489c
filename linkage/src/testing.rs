//! Test fixtures shared by this crate's unit tests and its integration tests (`tests/common`): one
//! deterministic generator, the test scenes, random states near q0.

use nalgebra::DVector;

use crate::builtin;
use crate::model::Model;
use crate::space::{Planar, SceneKind, Space, Spatial};

/// A small deterministic generator (SplitMix64) so tests need no extra dependency.
pub struct TestRng(pub u64);

impl TestRng {
    /// Next uniform number in [-1, 1).
    pub fn signed(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// An index in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.signed() + 1.0) * 0.5 * n as f64) as usize % n
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        (self.signed() + 1.0) * 0.5 < p
    }

    /// One of [`ODD_NUMBERS`].
    pub fn odd(&mut self) -> f64 {
        ODD_NUMBERS[self.below(ODD_NUMBERS.len())]
    }
}

/// Numbers the random-input tests put where a sane one belongs: not finite, huge, tiny, zero, negative.
pub const ODD_NUMBERS: &[f64] = &[f64::NAN, f64::INFINITY, -f64::INFINITY, 1e300, -1e300, 1e-300, 0.0, -0.0, 1e6, -3.0];

/// A built-in scene file, parsed (panics if it is missing or broken: tests only).
pub fn builtin_scene(name: &str) -> crate::Scene {
    builtin::scene(name).expect("built in").expect("parses")
}

/// The paper's testbed, compiled.
pub fn paper_testbed() -> Model<Planar> {
    compile(&builtin_scene("paper-testbed"))
}

/// Compiles a scene, panicking with the error (tests only).
pub fn compile<S: Space>(scene: &crate::Scene) -> Model<S> {
    Model::compile(scene, &scene.name).unwrap_or_else(|e| panic!("{e}"))
}

/// A state near q0 (±0.1 rad or m) with velocities in ±1, deterministic in `seed`.
pub fn random_state<S: Space>(model: &Model<S>, seed: u64) -> (DVector<f64>, DVector<f64>) {
    let mut rng = TestRng(seed.wrapping_mul(7919).wrapping_add(17));
    let q = DVector::from_fn(model.nq(), |i, _| model.q0[i] + 0.1 * rng.signed());
    let qd = DVector::from_fn(model.nq(), |_, _| rng.signed());
    (q, qd)
}

/// Every planar test scene: the built-in files plus generated chains (with and without loops).
pub fn planar_models() -> Vec<(String, Model<Planar>)> {
    let mut out: Vec<(String, Model<Planar>)> =
        builtin_files_of_kind(SceneKind::Planar).map(|(n, scene)| (n.to_string(), compile(&scene))).collect();
    for (links, loops) in [(8, 2), (6, 0), (12, 3)] {
        out.push((format!("chain{links}_loops{loops}"), compile(&builtin::chain(links, loops))));
    }
    out
}

/// Every spatial test scene: the built-in spatial files.
pub fn spatial_models() -> Vec<(String, Model<Spatial>)> {
    builtin_files_of_kind(SceneKind::Spatial).map(|(n, scene)| (n.to_string(), compile(&scene))).collect()
}

/// The built-in scene files of one kind, parsed, in the order of [`builtin::SCENE_FILES`].
fn builtin_files_of_kind(kind: SceneKind) -> impl Iterator<Item = (&'static str, crate::Scene)> {
    builtin::SCENE_FILES.iter().map(|(n, _)| (*n, builtin_scene(n))).filter(move |(_, scene)| scene.kind == kind)
}

/// Runs `$body` with `$name: &str` and `$model: &Model<_>` bound, for every planar and spatial test model.
#[cfg(test)]
macro_rules! for_each_model {
    ($name:ident, $model:ident => $body:block) => {{
        for (n, m) in $crate::testing::planar_models().iter() {
            let ($name, $model): (&str, &$crate::Model<$crate::Planar>) = (n.as_str(), m);
            $body
        }
        for (n, m) in $crate::testing::spatial_models().iter() {
            let ($name, $model): (&str, &$crate::Model<$crate::Spatial>) = (n.as_str(), m);
            $body
        }
    }};
}
#[cfg(test)]
pub(crate) use for_each_model;
