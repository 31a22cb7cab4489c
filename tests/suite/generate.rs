//! The linkage generator: every seed's scene compiles, is closed at q0 (checked by computing the loop
//! residual from the scene's own numbers, independently of how the generator laid it out), keeps a degree
//! of freedom, reads back from the TOML it writes, and the same seed writes the same scene; and a few
//! hundred seeds cover every class, unit system and extra.

use std::collections::BTreeMap;

use kinloop::cli::generate::scene_text;
use kinloop::generate::{generate, Class};
use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::{
    math::space::Planar, math::space::SceneKind, math::space::Space, math::space::Spatial, model::data::Data,
    model::scene::Scene, model::Model,
};

const SEEDS: std::ops::Range<u64> = 1..501;

/// The loop residual at q0 relative to the model's length scale, and the mobility (q's dimension minus
/// the closure Jacobian's rank).
fn closure_and_mobility<S: Space>(scene: &Scene) -> (f64, usize) {
    let model = Model::<S>::compile(scene, &scene.name).unwrap_or_else(|e| panic!("{}: {e}", scene.name));
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &model.q0);
    closure_residual_and_jacobian(&model, &mut data);
    let residual = data.closure_residual.amax() / model.length_scale;
    let w = data.closure_jacobian_t.clone();
    let largest = w.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(f64::MIN_POSITIVE);
    let rank = if w.ncols() == 0 { 0 } else { w.svd(false, false).rank(1e-9 * largest) };
    (residual, model.nv() - rank)
}

#[test]
fn every_seed_compiles_closed_at_q0_with_a_degree_of_freedom_and_reads_back() {
    for seed in SEEDS {
        let generated = generate(seed, None);
        let scene = &generated.scene;
        let (residual, mobility) = match scene.kind {
            SceneKind::Planar => closure_and_mobility::<Planar>(scene),
            SceneKind::Spatial => closure_and_mobility::<Spatial>(scene),
        };
        assert!(
            residual <= 1e-9,
            "seed {seed} ({}): closure residual {residual:e} of the length scale",
            generated.class
        );
        assert!(mobility >= 1, "seed {seed} ({}): no degree of freedom", generated.class);
        let expected_mobility = if generated.class == Class::FiveBar { 2 } else { 1 };
        if !matches!(generated.class, Class::Bennett | Class::SphericalFourBar) {
            assert_eq!(mobility, expected_mobility, "seed {seed} ({})", generated.class);
        }
        assert_eq!(scene.ops.len(), scene.bodies.len(), "seed {seed}: an operational point on every link");
        let read = Scene::from_toml_str(&scene_text(&generated), "generated").expect("the written TOML reads back");
        assert_eq!(&read, scene, "seed {seed}");
    }
}

#[test]
fn the_same_seed_writes_the_same_scene_and_neighbours_differ() {
    for seed in [1, 2, 77, 12345] {
        assert_eq!(scene_text(&generate(seed, None)), scene_text(&generate(seed, None)));
        assert_ne!(scene_text(&generate(seed, None)), scene_text(&generate(seed + 1, None)));
    }
    let asked = generate(9, Some(Class::StephensonSixBar));
    assert_eq!(asked.class, Class::StephensonSixBar);
}

/// Lengths spread over two orders of magnitude and masses over three, in every unit system; every class,
/// near-singular draws, springs, dampers, actuators and obstacles all occur, each at least a minimum number
/// of times in the 500 seeds.
#[test]
fn five_hundred_seeds_cover_every_class_unit_system_and_extra() {
    let mut classes = BTreeMap::new();
    let mut units = BTreeMap::new();
    let mut extras = BTreeMap::new();
    let (mut near, mut masses) = (0, Vec::new());
    for seed in SEEDS {
        let g = generate(seed, None);
        *classes.entry(g.class).or_insert(0) += 1;
        *units.entry(g.units).or_insert(0) += 1;
        for e in &g.extras {
            *extras.entry(*e).or_insert(0) += 1;
        }
        near += usize::from(g.near_singular);
        masses.extend(g.scene.bodies.iter().map(|b| b.mass / g.units.per_kilogram()));
    }
    println!("classes {classes:?}\nunits {units:?}\nextras {extras:?}\nnear-singular {near}");
    assert_eq!(classes.len(), Class::ALL.len(), "{classes:?}");
    assert!(classes.values().all(|&n| n >= 15), "{classes:?}");
    assert_eq!(units.len(), 6, "{units:?}");
    assert!(units.values().all(|&n| n >= 40), "{units:?}");
    for extra in ["gravity", "spring", "damper", "actuator", "obstacle"] {
        assert!(extras.get(extra).copied().unwrap_or(0) >= 20, "{extra}: {extras:?}");
    }
    assert!(near >= 50, "{near} near-singular draws");
    let (lightest, heaviest) = masses.iter().fold((f64::MAX, 0.0f64), |(lo, hi), m| (lo.min(*m), hi.max(*m)));
    assert!(heaviest / lightest > 300.0, "masses from {lightest} to {heaviest} kg");
}
