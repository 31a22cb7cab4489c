//! Joint springs integrated implicitly at the step (`algorithms::implicit_joint_forces`), checked against the
//! explicit step on a spring stiff enough to make it diverge.

use kinloop_linkage::algorithms::integrator::{step, StepConfig};
use kinloop_linkage::math::space::Planar;
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::scene::{Scene, SpringSpec};
use kinloop_linkage::model::Model;
use nalgebra::DVector;

/// A 5 g pendulum of 1 cm on a spring sized for a 5 kg link (k = 3 m g L with m = 5 kg): its natural
/// frequency sqrt(k / I) is about 2,700 rad/s, so a 1 ms explicit step (h ω ≈ 2.7 > 2) diverges.
fn stiff_pendulum() -> Model<Planar> {
    let mut scene = Scene::from_toml_str(
        r#"
kind = "planar"
gravity = [0.0, 0.0]

[[body]]
name = "link"
mass = 0.005
com = [0.005, 0.0]
inertia = 4e-8

[[joint]]
name = "pivot"
kind = "revolute"
parent = "ground"
child = "link"
q0 = 0.3
"#,
        "stiff.toml",
    )
    .expect("the test scene parses");
    scene.joints[0].spring = Some(SpringSpec { stiffness: 3.0 * 5.0 * 9.81 * 0.01, rest: 0.0 });
    Model::compile(&scene, "stiff").expect("the test scene compiles")
}

/// Runs one second at 1 kHz; returns the largest |q| seen, or None if a step failed.
fn largest_angle(implicit: bool) -> Option<f64> {
    let model = stiff_pendulum();
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), DVector::zeros(model.nv()));
    let cfg = StepConfig { implicit_forces: implicit, ..StepConfig::euler(1e-3) };
    let mut largest: f64 = 0.0;
    for _ in 0..1000 {
        step(&model, &mut data, &mut q, &mut qd, &mut (), &cfg).ok()?;
        largest = largest.max(q[0].abs());
    }
    Some(largest)
}

#[test]
fn a_stiff_joint_spring_stays_bounded_when_implicit() {
    let largest = largest_angle(true).expect("the implicit steps succeed");
    // A passive spring released at rest from 0.3 rad never passes 0.3 rad (the implicit step only loses energy).
    assert!(largest <= 0.3 + 1e-12, "largest angle {largest}");
}

#[test]
fn the_same_spring_explicit_diverges() {
    // The independent check that the test above exercises the stiff case: the explicit step blows up.
    assert!(largest_angle(false).is_none_or(|a| a > 10.0));
}
