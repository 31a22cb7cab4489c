//! Test fixtures shared by this crate's unit tests and its integration tests (`tests/common`): one
//! deterministic generator (defined with the mathematics, whose own tests use it), the test scenes, random
//! states near q0.

use nalgebra::DVector;

pub use crate::math::rng::{TestRng, ODD_NUMBERS};
use crate::math::space::{Planar, SceneKind, Space, Spatial};
use crate::model::builtin;
use crate::model::Model;

/// A built-in scene file, parsed (panics if it is missing or broken: tests only).
pub fn builtin_scene(name: &str) -> crate::model::scene::Scene {
    builtin::scene(name).expect("built in").expect("parses")
}

/// The paper's testbed, compiled.
pub fn paper_testbed() -> Model<Planar> {
    compile(&builtin_scene("paper-testbed"))
}

/// Compiles a scene, panicking with the error (tests only).
pub fn compile<S: Space>(scene: &crate::model::scene::Scene) -> Model<S> {
    Model::compile(scene, &scene.name).unwrap_or_else(|e| panic!("{e}"))
}

/// A state near q0 (±0.1 rad or m) with velocities in ±1, deterministic in `seed`.
pub fn random_state<S: Space>(model: &Model<S>, seed: u64) -> (DVector<f64>, DVector<f64>) {
    let mut rng = TestRng(seed.wrapping_mul(7919).wrapping_add(17));
    let step = DVector::from_fn(model.nv(), |_, _| 0.1 * rng.signed());
    let mut q = model.q0.clone();
    crate::algorithms::configuration::integrate(model, &mut q, &step, 1.0);
    let qd = DVector::from_fn(model.nv(), |_, _| rng.signed());
    (q, qd)
}

/// `q ⊕ h v` (see [`crate::algorithms::configuration::integrate`]): the configuration a finite difference
/// steps to, on the manifold when the model has ball joints.
pub fn displaced<S: Space>(model: &Model<S>, q: &DVector<f64>, v: &DVector<f64>, h: f64) -> DVector<f64> {
    let mut out = q.clone();
    crate::algorithms::configuration::integrate(model, &mut out, v, h);
    out
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
fn builtin_files_of_kind(kind: SceneKind) -> impl Iterator<Item = (&'static str, crate::model::scene::Scene)> {
    builtin::SCENE_FILES.iter().map(|(n, _)| (*n, builtin_scene(n))).filter(move |(_, scene)| scene.kind == kind)
}

/// Runs `$body` with `$name: &str` and `$model: &Model<_>` bound, for every planar and spatial test model.
#[cfg(test)]
macro_rules! for_each_model {
    ($name:ident, $model:ident => $body:block) => {{
        for (n, m) in $crate::testing::planar_models().iter() {
            let ($name, $model): (&str, &$crate::model::Model<$crate::math::space::Planar>) = (n.as_str(), m);
            $body
        }
        for (n, m) in $crate::testing::spatial_models().iter() {
            let ($name, $model): (&str, &$crate::model::Model<$crate::math::space::Spatial>) = (n.as_str(), m);
            $body
        }
    }};
}
#[cfg(test)]
pub(crate) use for_each_model;
