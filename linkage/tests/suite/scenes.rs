//! Scene validation names the file and the key; assembly finds the nearest closed configuration.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::{
    error::SceneError, math::space::Planar, math::space::Spatial, model::scene::Scene, model::Model,
};

fn error_for(text: &str) -> SceneError {
    let scene = Scene::from_toml_str(text, "bad.toml");
    match scene {
        Err(e) => e,
        Ok(s) => Model::<Planar>::compile(&s, "bad.toml").expect_err("should be rejected"),
    }
}

const BASE: &str = r#"
kind = "planar"
[[body]]
name = "a"
mass = 1.0
inertia = 0.01
[[body]]
name = "b"
mass = 1.0
inertia = 0.01
[[joint]]
name = "ja"
kind = "revolute"
parent = "ground"
child = "a"
[[joint]]
name = "jb"
kind = "revolute"
parent = "a"
child = "b"
origin = [0.1, 0.0]
"#;

#[test]
fn errors_name_the_file_the_key_and_the_problem() {
    let cases: &[(&str, &str, &[&str])] = &[
        ("mass = 1.0", "mass = -2.0", &["bad.toml", "body[0] (a).mass", "positive"]),
        (
            "inertia = 0.01\n[[body]]\nname = \"b\"",
            "inertia = 0.0\n[[body]]\nname = \"b\"",
            &["body[0] (a).inertia", "positive"],
        ),
        ("parent = \"a\"", "parent = \"nobody\"", &["joint[1] (jb).parent", "unknown body 'nobody'", "ground, a, b"]),
        ("origin = [0.1, 0.0]", "origin = [0.1, 0.0, 0.3]", &["joint[1] (jb).origin", "expected 2 numbers"]),
        ("origin = [0.1, 0.0]", "origin = [0.1, nan]", &["joint[1] (jb).origin[1]", "finite"]),
        ("name = \"b\"\nmass", "name = \"a\"\nmass", &["body[1].name", "duplicate name 'a'"]),
        ("parent = \"ground\"\nchild = \"a\"", "parent = \"b\"\nchild = \"a\"", &["cycle", "joint"]),
    ];
    for (from, to, expected) in cases {
        assert!(BASE.contains(from), "fixture: {from}");
        let text = BASE.replacen(from, to, 1);
        let msg = error_for(&text).to_string();
        for e in *expected {
            assert!(msg.contains(e), "for `{to}` expected `{e}` in: {msg}");
        }
    }
}

#[test]
fn spatial_inertia_must_be_positive_definite_and_cuts_must_fit_the_kind() {
    let spatial = r#"
kind = "spatial"
[[body]]
name = "a"
mass = 1.0
inertia = [1.0, 1.0, 1.0, 2.0, 0.0, 0.0]
[[joint]]
name = "ja"
kind = "revolute"
parent = "ground"
child = "a"
"#;
    let s = Scene::from_toml_str(spatial, "s.toml").unwrap();
    let msg = Model::<Spatial>::compile(&s, "s.toml").unwrap_err().to_string();
    assert!(msg.contains("body[0] (a).inertia") && msg.contains("not positive definite"), "{msg}");

    let pin_in_space = spatial.replace("2.0, 0.0, 0.0]", "0.0, 0.0, 0.0]")
        + "[[cut]]\nname = \"c\"\nkind = \"pin\"\nbody_a = \"a\"\nbody_b = \"ground\"\n";
    let s = Scene::from_toml_str(&pin_in_space, "s.toml").unwrap();
    let msg = Model::<Spatial>::compile(&s, "s.toml").unwrap_err().to_string();
    assert!(msg.contains("cut[0] (c).kind") && msg.contains("spherical"), "{msg}");
}

/// A loop given an explicit point that does not close at q0 is refused with the residual; `compile_unclosed`
/// accepts it and assembly finds the nearest closed configuration.
#[test]
fn unclosed_loop_is_reported_and_assembly_closes_it() {
    let text = BASE.to_string()
        + "[[cut]]\nname = \"tip\"\nkind = \"pin\"\nbody_a = \"b\"\npoint_a = [0.1, 0.0]\nbody_b = \"ground\"\npoint_b = [0.15, 0.05]\n";
    let scene = Scene::from_toml_str(&text, "open.toml").unwrap();
    let err = Model::<Planar>::compile(&scene, "open.toml").unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("cut[0] (tip)") && msg.contains("not closed at q0") && msg.contains("--assemble"), "{msg}");
    let SceneError::NotClosed { residual, .. } = err else { panic!("{err:?}") };
    // At q0 = 0 the tip is at (0.2, 0): 0.05·√2 from (0.15, 0.05).
    assert!((residual - 0.05 * 2f64.sqrt()).abs() < 1e-12, "{residual}");

    let model = Model::<Planar>::compile_unclosed(&scene, "open.toml").unwrap();
    let a = assemble(&model, &model.q0, 1e-13).unwrap();
    assert!(a.residual <= 1e-13 && a.initial_residual > 0.07);
    // Independent check of the closed configuration: the tip of a two-link (0.1, 0.1) arm at (0.15, 0.05).
    let (t1, t2) = (a.q[0], a.q[0] + a.q[1]);
    let tip = (0.1 * t1.cos() + 0.1 * t2.cos(), 0.1 * t1.sin() + 0.1 * t2.sin());
    assert!((tip.0 - 0.15).abs() < 1e-12 && (tip.1 - 0.05).abs() < 1e-12, "{tip:?}");
}

/// A loop that cannot close (target out of reach) is a clear assembly error, not a panic.
#[test]
fn assembly_of_an_unreachable_loop_fails_cleanly() {
    let text = BASE.to_string()
        + "[[cut]]\nname = \"tip\"\nkind = \"pin\"\nbody_a = \"b\"\npoint_a = [0.1, 0.0]\nbody_b = \"ground\"\npoint_b = [1.0, 1.0]\n";
    let scene = Scene::from_toml_str(&text, "far.toml").unwrap();
    let model = Model::<Planar>::compile_unclosed(&scene, "far.toml").unwrap();
    let err = assemble(&model, &model.q0, 1e-12).unwrap_err();
    assert!(err.to_string().contains("did not converge"), "{err}");
}

#[test]
fn every_builtin_scene_compiles_and_is_closed_at_q0() {
    for (name, _) in kinloop_linkage::model::builtin::SCENE_FILES {
        let scene = builtin_scene(name);
        let residual = match scene.kind {
            kinloop_linkage::math::space::SceneKind::Planar => closure_at_q0(&compile::<Planar>(&scene)),
            kinloop_linkage::math::space::SceneKind::Spatial => closure_at_q0(&compile::<Spatial>(&scene)),
        };
        assert!(residual < 1e-12, "{name}: {residual}");
    }
}

fn closure_at_q0<S: kinloop_linkage::math::space::Space>(model: &Model<S>) -> f64 {
    let mut data = kinloop_linkage::model::data::Data::new(model);
    kinloop_linkage::algorithms::dynamics::forward_dynamics(model, &mut data, &model.q0, &model.qd0, &mut ()).unwrap();
    data.closure_residual.amax()
}
