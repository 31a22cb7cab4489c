//! Springs, dampers and ranges on cuts, and ranges on tree joints, checked against independent
//! computations: each cut freedom's coordinate computed here by hand from the bodies' poses, its energy
//! `½ k (s − rest)²` against the potential energy, G against finite differences of that energy, the damper's
//! power against `−c ṡ²` with ṡ a finite difference, a joint held against its range by a known load
//! penetrating `load / k`, free motion conserving energy with RK4, and walls that never give energy back.
//! Bad values are errors naming the file, the key and the value.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::gravity::{gravity_forces, kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::joint_forces::joint_forces;
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::model::scene::{Scene, SpringSpec};
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, algorithms::integrator::project,
    algorithms::integrator::step, algorithms::integrator::Integrator, algorithms::integrator::StepConfig,
    math::space::Planar, math::space::Space, math::space::Spatial, model::data::Data, model::Model,
};
use nalgebra::{DVector, Rotation3, Vector3};

/// A built-in scene with gravity off and every tree joint's spring and damping removed, so that only the cut
/// loads under test act.
fn bare(name: &str) -> Scene {
    let mut scene = builtin_scene(name);
    scene.gravity.iter_mut().for_each(|g| *g = 0.0);
    for j in &mut scene.joints {
        j.spring = None;
        j.damping = 0.0;
    }
    for c in &mut scene.cuts {
        c.spring = None;
        c.damping = 0.0;
    }
    scene
}

/// A built-in scene laid `bare`, with a spring `(stiffness, rest)` and `damping` on its first cut (and no
/// range on its first joint).
fn with_cut_loads(name: &str, (stiffness, rest): (f64, f64), damping: f64) -> Scene {
    let mut scene = bare(name);
    scene.joints[0].range = None;
    scene.cuts[0].spring = Some(SpringSpec { stiffness, rest });
    scene.cuts[0].damping = damping;
    scene
}

/// The four-bar with a torsion spring (and, with `damping`, a damper) in its coupler-rocker pin.
fn four_bar_with_pin_spring(damping: f64) -> Scene {
    with_cut_loads("fourbar-crank-rocker", (0.8, 0.3), damping)
}

/// The guided slider-crank (its slide coordinate is the slider's x) with a spring on the guide.
fn slider_with_guide_spring(damping: f64) -> Scene {
    with_cut_loads("guided-slider-crank", (60.0, 0.16), damping)
}

/// The Bennett linkage with a torsion spring on its revolute cut.
fn bennett_with_hinge_spring(damping: f64) -> Scene {
    with_cut_loads("bennett-linkage", (0.05, -0.2), damping)
}

/// The RSSR four-bar with an isotropic torsion spring on its ball joint.
fn rssr_with_ball_spring(damping: f64) -> Scene {
    with_cut_loads("rssr-four-bar", (5.0, 0.0), damping)
}

fn body<S: Space>(model: &Model<S>, name: &str) -> usize {
    model.body_index(name).unwrap_or_else(|| panic!("no body {name}"))
}

/// Absolute angle of a planar body, by hand: the sum of the revolute joint angles from ground (the four-bar
/// has no joint frame rotations).
fn planar_angle(model: &Model<Planar>, q: &DVector<f64>, mut b: usize) -> f64 {
    let mut angle = 0.0;
    loop {
        angle += q[b];
        match model.parent(b) {
            Some(p) => b = p,
            None => return angle,
        }
    }
}

/// The four-bar pin's angle from q0: the rocker's angle relative to the coupler's, less that at q0.
fn pin_angle(model: &Model<Planar>, q: &DVector<f64>) -> f64 {
    let (coupler, rocker) = (body(model, "coupler"), body(model, "rocker"));
    let relative = |q: &DVector<f64>| planar_angle(model, q, rocker) - planar_angle(model, q, coupler);
    relative(q) - relative(&model.q0)
}

/// The guide's slide: the slider's x, from its world position.
fn slide(model: &Model<Planar>, q: &DVector<f64>) -> f64 {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    data.kin.body_pos[body(model, "slider")].x
}

/// Rotation of body b relative to body a since q0, by nalgebra: `(R_a⁻¹ R_b) (R_a0⁻¹ R_b0)⁻¹`.
fn relative_rotation(model: &Model<Spatial>, q: &DVector<f64>) -> Rotation3<f64> {
    let rot = |q: &DVector<f64>, b: Option<usize>| {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, q);
        b.map_or_else(Rotation3::identity, |b| data.kin.body_rot[b])
    };
    let (a, b) = match &model.cuts[0].freedom {
        kinloop_linkage::model::CutFreedom::Hinge { body_a, body_b, .. }
        | kinloop_linkage::model::CutFreedom::Rotation { body_a, body_b, .. } => (*body_a, *body_b),
        other => panic!("not a rotation: {other:?}"),
    };
    let rel = |q: &DVector<f64>| rot(q, a).inverse() * rot(q, b);
    rel(q) * rel(&model.q0).inverse()
}

/// Closed configurations near q0: the loops re-closed from a few perturbed starts.
fn closed_states<S: Space>(model: &Model<S>) -> Vec<DVector<f64>> {
    (0..4)
        .map(|seed| {
            let (start, _) = random_state(model, seed);
            let start = model.q0.clone() * 0.5 + start * 0.5;
            assemble(model, &start, 1e-13).unwrap_or_else(|e| panic!("{e}")).q
        })
        .collect()
}

/// A velocity that keeps the loops closed (the projection of a made-up one onto W's null space).
fn closed_velocity<S: Space>(model: &Model<S>, q: &DVector<f64>, seed: u64) -> DVector<f64> {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    closure_residual_and_jacobian(model, &mut data);
    let w = data.closure_jacobian();
    let basis = null_space(&w, model.nv());
    let (_, made_up) = random_state(model, seed);
    &basis * (basis.transpose() * made_up)
}

fn potential<S: Space>(model: &Model<S>, q: &DVector<f64>) -> f64 {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    potential_energy(model, &data, q)
}

/// G (here the cut spring's alone) against central differences of the potential energy, and the energy
/// against `½ k (s − rest)²` with `s` computed by hand, at closed configurations.
fn check_spring<S: Space>(name: &str, model: &Model<S>, by_hand: &dyn Fn(&DVector<f64>) -> f64) {
    let spring = model.cuts[0].spring.expect("a cut spring");
    let mut data = Data::new(model);
    let mut stretched = 0.0f64;
    for q in closed_states(model) {
        let expected = 0.5 * spring.stiffness * (by_hand(&q) - spring.rest).powi(2);
        let energy = potential(model, &q);
        assert!((energy - expected).abs() <= 1e-12 + 1e-9 * expected, "{name}: energy {energy} vs by hand {expected}");
        stretched = stretched.max(expected);
        forward_kinematics(model, &mut data, &q);
        gravity_forces(model, &mut data, &q);
        let h = 1e-6;
        for i in 0..model.nv() {
            let mut e = DVector::zeros(model.nv());
            e[i] = h;
            let fd = (potential(model, &(&q + &e)) - potential(model, &(&q - &e))) / (2.0 * h);
            let g = data.gravity[i];
            assert!((fd - g).abs() <= 1e-6 * (1.0 + g.abs()), "{name}: G[{i}] = {g} vs finite difference {fd}");
        }
    }
    assert!(stretched > 1e-4, "{name}: the spring should be stretched somewhere ({stretched} J)");
}

#[test]
fn cut_springs_hold_half_k_stretch_squared_and_g_is_its_gradient() {
    let four_bar: Model<Planar> = compile(&four_bar_with_pin_spring(0.0));
    check_spring("four-bar pin", &four_bar, &|q| pin_angle(&four_bar, q));
    let slider: Model<Planar> = compile(&slider_with_guide_spring(0.0));
    check_spring("guide", &slider, &|q| slide(&slider, q));
    // Spatial: the rotation since q0 by nalgebra, in body a's frame; a hinge's angle is its component along
    // the axis as written (in body a's frame).
    let scene = bennett_with_hinge_spring(0.0);
    let bennett: Model<Spatial> = compile(&scene);
    let axis_a = Vector3::from_column_slice(scene.cuts[0].axis.as_ref().unwrap()).normalize();
    check_spring("bennett hinge", &bennett, &|q| relative_rotation(&bennett, q).scaled_axis().dot(&axis_a));
    let rssr: Model<Spatial> = compile(&rssr_with_ball_spring(0.0));
    check_spring("rssr ball", &rssr, &|q| relative_rotation(&rssr, q).angle());
}

/// The damper's generalized force, along a velocity that keeps the loops closed, has power `−c ṡ²`, with ṡ a
/// central difference of the coordinate computed by hand.
fn check_damper<S: Space>(name: &str, model: &Model<S>, by_hand: &dyn Fn(&DVector<f64>) -> f64) {
    let c = model.cuts[0].damping;
    let mut data = Data::new(model);
    for (k, q) in closed_states(model).into_iter().enumerate() {
        let qd = closed_velocity(model, &q, k as u64 + 3);
        forward_kinematics(model, &mut data, &q);
        forward_velocity(model, &mut data, &qd);
        joint_forces(model, &mut data, &q, &qd);
        let power = qd.dot(&data.joint_force);
        let h = 1e-6;
        let rate = (by_hand(&(&q + &qd * h)) - by_hand(&(&q - &qd * h))) / (2.0 * h);
        let expected = -c * rate * rate;
        assert!(rate.abs() > 1e-3, "{name}: the freedom should move ({rate})");
        assert!(
            (power - expected).abs() <= 1e-6 * expected.abs(),
            "{name}: damper power {power} W vs −c ṡ² = {expected} W"
        );
    }
}

#[test]
fn cut_dampers_dissipate_exactly_c_times_rate_squared() {
    let four_bar: Model<Planar> = compile(&four_bar_with_pin_spring(0.02));
    check_damper("four-bar pin", &four_bar, &|q| pin_angle(&four_bar, q));
    let slider: Model<Planar> = compile(&slider_with_guide_spring(3.0));
    check_damper("guide", &slider, &|q| slide(&slider, q));
    let bennett: Model<Spatial> = compile(&bennett_with_hinge_spring(0.01));
    // The hinge turns about one axis: the rotation's angle is |θ|, so its rate squared is θ̇².
    check_damper("bennett hinge", &bennett, &|q| relative_rotation(&bennett, q).angle());
}

/// RK4 with projection at 1 kHz over 3 s of free motion, started with a closed velocity: the loops stay
/// closed and `T + V` (with the cut spring's energy) drifts by RK4's truncation error only, the bound the
/// conservative shipped scenes meet (1e-5 of the largest kinetic energy) and shrinking at dt/2.
fn energy_drift<S: Space>(model: &Model<S>, dt: f64) -> (f64, f64) {
    let mut data = Data::new(model);
    let mut q = model.q0.clone();
    let mut qd = closed_velocity(model, &q, 1) * 3.0;
    forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
    project(model, &mut data, &mut q.clone(), &mut qd);
    let energy = |data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>| {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, qd);
        kinetic_energy(model, data) + potential_energy(model, data, q)
    };
    let e0 = energy(&mut data, &q, &qd);
    let cfg = StepConfig { integrator: Integrator::Rk4, dt, project: true, implicit_forces: false };
    let (mut drift, mut most) = (0.0f64, 0.0f64);
    for _ in 0..(3.0 / dt).round() as usize {
        step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{e}"));
        drift = drift.max((energy(&mut data, &q, &qd) - e0).abs());
        most = most.max(kinetic_energy(model, &data));
    }
    (drift, most)
}

#[test]
fn rk4_conserves_energy_with_cut_springs() {
    fn check<S: Space>(name: &str, scene: Scene) {
        let model: Model<S> = compile(&scene);
        let (drift, kinetic) = energy_drift(&model, 1e-3);
        let (half, _) = energy_drift(&model, 5e-4);
        eprintln!("{name}: drift {drift:.2e} J (dt/2 {half:.2e} J), max kinetic energy {kinetic:.3e} J");
        assert!(kinetic > 1e-5, "{name}: should move ({kinetic} J)");
        assert!(drift < 1e-5 * kinetic, "{name}: drift {drift:.3e} J vs kinetic {kinetic:.3e} J");
        assert!(half < drift / 8.0 || drift < 1e-12, "{name}: drift {drift:.3e} at dt, {half:.3e} at dt/2");
    }
    check::<Planar>("four-bar pin", four_bar_with_pin_spring(0.0));
    check::<Planar>("guide", slider_with_guide_spring(0.0));
    check::<Spatial>("bennett hinge", bennett_with_hinge_spring(0.0));
    check::<Spatial>("rssr ball", rssr_with_ball_spring(0.0));
}

/// One body on a joint of `kind` along or about x/z, with `range`, damping `damping`, and an OP at its origin.
fn one_joint(kind: &str, range: [f64; 2], damping: f64, contact_damping: f64) -> Scene {
    let text = format!(
        "kind = \"planar\"\ncontact = {{ stiffness = 15000.0, damping = {contact_damping} }}\n\
         [[body]]\nname = \"b\"\nmass = 0.5\ncom = [0.1, 0.0]\ninertia = 2e-3\n\
         [[joint]]\nname = \"j\"\nkind = \"{kind}\"\nparent = \"ground\"\nchild = \"b\"\n\
         range = [{}, {}]\ndamping = {damping}\n[[op]]\nname = \"tip\"\nbody = \"b\"\npoint = [0.1, 0.0]\n",
        range[0], range[1]
    );
    Scene::from_toml_str(&text, "one-joint.toml").unwrap()
}

/// Runs `seconds` of RK4 at 1 kHz under a constant wrench at the OP; returns the final q and q̇.
fn settle<S: Space>(model: &Model<S>, wrench: S::OpVec, seconds: f64) -> (DVector<f64>, DVector<f64>) {
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-3, project: model.has_loops(), implicit_forces: false };
    let mut user = OpWrench::<S> { op: 0, wrench };
    for _ in 0..(seconds / 1e-3).round() as usize {
        step(model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap_or_else(|e| panic!("{e}"));
    }
    (q, qd)
}

/// A joint pushed against its upper stop by a constant load comes to rest past the stop by `load / k`: the
/// wall's penalty stiffness (the contact stiffness, times L² for an angle) against the load, to 1 % of that
/// penetration.
#[test]
fn a_joint_driven_against_its_range_stops_where_the_wall_holds_the_load() {
    let k = 15_000.0;
    // Prismatic along x: a 2 N push.
    let model: Model<Planar> = compile(&one_joint("prismatic", [-0.05, 0.02], 8.0, 300.0));
    let (q, qd) = settle(&model, Vector3::new(2.0, 0.0, 0.0), 3.0);
    let expected = 0.02 + 2.0 / k;
    assert!(qd[0].abs() < 1e-6, "at rest: {}", qd[0]);
    assert!((q[0] - expected).abs() <= 0.01 * 2.0 / k, "slider at {} m, expected {expected} m", q[0]);
    // Revolute about z: 0.05 N m, walls of k L² N m/rad.
    let model: Model<Planar> = compile(&one_joint("revolute", [-0.4, 0.3], 0.05, 300.0));
    let (q, qd) = settle(&model, Vector3::new(0.0, 0.0, 0.05), 3.0);
    let expected = 0.3 + 0.05 / (k * model.length_scale.powi(2));
    assert!(qd[0].abs() < 1e-6, "at rest: {}", qd[0]);
    assert!((q[0] - expected).abs() <= 0.01 * (expected - 0.3), "joint at {} rad, expected {expected} rad", q[0]);
    // Pushed the other way, against the lower stop.
    let (q, _) = settle(&model, Vector3::new(0.0, 0.0, -0.05), 3.0);
    let expected = -0.4 - 0.05 / (k * model.length_scale.powi(2));
    assert!((q[0] - expected).abs() <= 0.01 * (-0.4 - expected), "joint at {} rad, expected {expected} rad", q[0]);
}

/// The guide's range holds the slider against a push along it the same way: the wall takes the whole push
/// (a free crank carries no force along the guide at rest), so the slide stops at `hi + F / k`.
#[test]
fn a_cut_driven_against_its_range_stops_where_the_wall_holds_the_load() {
    let mut scene = bare("guided-slider-crank");
    scene.joints[0].range = None;
    scene.cuts[0].damping = 5.0;
    scene.cuts[0].range = Some([0.1, 0.19]);
    let model: Model<Planar> = compile(&scene);
    let slider_op = model.op_index("slider").unwrap();
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-3, project: true, implicit_forces: false };
    let mut user = OpWrench::<Planar> { op: slider_op, wrench: Vector3::new(1.5, 0.0, 0.0) };
    for _ in 0..4000 {
        step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap_or_else(|e| panic!("{e}"));
    }
    let expected = 0.19 + 1.5 / 15_000.0;
    let x = slide(&model, &q);
    assert!(qd.amax() < 1e-5, "at rest: {qd}");
    assert!((x - expected).abs() <= 0.01 * 1.5 / 15_000.0, "slider at {x} m, expected {expected} m");
}

/// A joint thrown at its stop with nothing else damping it: the total energy, the wall's spring included,
/// never rises (beyond RK4's truncation error), it bounces back, and with the walls' damping it leaves slower
/// than it came; without the walls' damping it leaves as fast (an elastic wall creates no energy either).
#[test]
fn a_range_wall_creates_no_energy() {
    for contact_damping in [300.0, 0.0] {
        let mut scene = one_joint("prismatic", [-0.05, 0.02], 0.0, contact_damping);
        scene.joints[0].qd0 = 0.8;
        let model: Model<Planar> = compile(&scene);
        let mut data = Data::new(&model);
        let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
        let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-4, project: false, implicit_forces: false };
        let energy = |data: &mut Data<Planar>, q: &DVector<f64>, qd: &DVector<f64>| {
            forward_kinematics(&model, data, q);
            forward_velocity(&model, data, qd);
            kinetic_energy(&model, data) + potential_energy(&model, data, q)
        };
        let e0 = energy(&mut data, &q, &qd);
        let mut deepest = 0.0f64;
        for _ in 0..1000 {
            step(&model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap();
            let e = energy(&mut data, &q, &qd);
            assert!(e <= e0 * (1.0 + 1e-9), "wall damping {contact_damping}: energy {e} J above the start's {e0} J");
            deepest = deepest.max(q[0] - 0.02);
        }
        assert!(deepest > 1e-4 && qd[0] < 0.0, "it should hit the wall and come back ({deepest} m, {} m/s)", qd[0]);
        if contact_damping > 0.0 {
            assert!(-qd[0] < 0.8 * 0.9, "a damped wall takes energy: leaves at {} m/s", -qd[0]);
        } else {
            // Returned to RK4's error at the wall's kinks (a few parts per million at this step).
            assert!((-qd[0] - 0.8).abs() < 1e-5, "an elastic wall returns the speed: {} m/s", -qd[0]);
        }
    }
}

/// Errors for bad new keys: each names the file, the key and the value.
#[test]
fn bad_ranges_springs_and_dampers_are_errors_naming_file_key_and_value() {
    let base = include_str!("../../../scenes/guided-slider-crank.toml");
    let cases: &[(&str, &str, &[&str])] = &[
        ("range = [0.0, 1.9]", "range = [1.0, 0.5]", &["joint[0] (crank-pivot).range", "lo < hi", "[1, 0.5]"]),
        ("range = [0.0, 1.9]", "range = [0.0, nan]", &["joint[0] (crank-pivot).range[1]", "finite", "NaN"]),
        ("range = [0.0, 1.9]", "range = [0.9, 1.9]", &["joint[0] (crank-pivot).range", "outside", "0.785"]),
        ("stiffness = 40.0", "stiffness = -40.0", &["cut[0] (guide).spring.stiffness", "≥ 0", "-40"]),
        ("rest = 0.15", "rest = inf", &["cut[0] (guide).spring.rest", "finite", "inf"]),
        ("damping = 2.0", "damping = -2.0", &["cut[0] (guide).damping", "≥ 0", "-2"]),
        ("damping = 2.0", "damping = nan", &["cut[0] (guide).damping", "finite", "NaN"]),
        ("damping = 2.0", "damping = 2.0\nrange = [0.2, 0.3]", &["cut[0] (guide).range", "outside", "0.1811"]),
        ("damping = 2.0", "damping = 2.0\nrange = [0.3, 0.2]", &["cut[0] (guide).range", "lo < hi", "[0.3, 0.2]"]),
    ];
    for (from, to, expected) in cases {
        assert!(base.contains(from), "{from}");
        let text = base.replacen(from, to, 1);
        let err = Scene::from_toml_str(&text, "bad.toml").and_then(|s| Model::<Planar>::compile(&s, "bad.toml"));
        let message = err.expect_err(to).to_string();
        assert!(message.starts_with("bad.toml: "), "{message}");
        for e in *expected {
            assert!(message.contains(e), "{to}: {message} should say {e}");
        }
    }
    // Loads a cut has nothing to act on, or a range on a freedom that is not one number.
    let weld = "kind = \"planar\"\n[[body]]\nname = \"b\"\nmass = 1.0\ninertia = 1e-3\n\
                [[joint]]\nname = \"j\"\nkind = \"revolute\"\nparent = \"ground\"\nchild = \"b\"\n\
                [[cut]]\nname = \"w\"\nkind = \"weld\"\nbody_a = \"b\"\nbody_b = \"ground\"\n";
    for (extra, key) in [("damping = 1.0", "cut[0] (w).damping"), ("spring = { stiffness = 1.0 }", "cut[0] (w).spring")]
    {
        let scene = Scene::from_toml_str(&format!("{weld}{extra}\n"), "weld.toml").unwrap();
        let message = Model::<Planar>::compile(&scene, "weld.toml").unwrap_err().to_string();
        assert!(message.contains(key) && message.contains("weld"), "{message}");
    }
    let mut rssr = builtin_scene("rssr-four-bar");
    rssr.cuts[0].range = Some([-0.5, 0.5]);
    let message = Model::<Spatial>::compile(&rssr, "rssr.toml").unwrap_err().to_string();
    assert!(message.contains("cut[0] (ball).range") && message.contains("one freedom"), "{message}");
    rssr.cuts[0].range = None;
    rssr.cuts[0].spring = Some(SpringSpec { stiffness: 1.0, rest: 0.2 });
    let message = Model::<Spatial>::compile(&rssr, "rssr.toml").unwrap_err().to_string();
    assert!(message.contains("cut[0] (ball).spring.rest"), "{message}");
}

/// A revolute cut's `axis_b` that disagrees with `axis` at q0 is an error naming the cut, both axes in world
/// axes and the angle between them; the axis that agrees is accepted and changes nothing.
#[test]
fn a_revolute_cut_whose_axes_disagree_at_q0_is_an_error() {
    let scene = builtin_scene("bennett-linkage");
    let model: Model<Spatial> = compile(&scene);
    // Body b is ground: axis_b is the world direction of the axis at q0.
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &model.q0);
    let axis_a = Vector3::from_column_slice(scene.cuts[0].axis.as_ref().unwrap());
    let body_a = model.body_index(&scene.cuts[0].body_a).unwrap();
    let world = data.kin.body_rot[body_a] * axis_a.normalize();
    let mut agreeing = scene.clone();
    agreeing.cuts[0].axis_b = Some(world.as_slice().to_vec());
    let same: Model<Spatial> = compile(&agreeing);
    assert_eq!(same.closure_rank, model.closure_rank);
    assert_eq!(same.cuts[0].primitives, model.cuts[0].primitives);
    // Tilted by 0.1 rad about a direction normal to the axis.
    let normal = world.cross(&Vector3::x()).normalize();
    let tilted = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(normal), 0.1) * world;
    let mut wrong = scene.clone();
    wrong.cuts[0].axis_b = Some(tilted.as_slice().to_vec());
    let message = Model::<Spatial>::compile(&wrong, "bennett.toml").unwrap_err().to_string();
    let show = |v: &Vector3<f64>| format!("{:.4?}", v.as_slice());
    for expected in
        ["bennett.toml: cut[0] (joint4).axis_b", "cut 'joint4'", &show(&world), &show(&tilted), "0.1000 rad"]
    {
        assert!(message.contains(expected), "{message} should say {expected}");
    }
    // Only a spatial revolute cut takes axis_b.
    let mut planar = builtin_scene("fourbar-crank-rocker");
    planar.cuts[0].axis_b = Some(vec![1.0, 0.0]);
    let message = Model::<Planar>::compile(&planar, "fourbar.toml").unwrap_err().to_string();
    assert!(
        message.contains("cut[0] (coupler-rocker).axis_b") && message.contains("only spatial revolute"),
        "{message}"
    );
}

/// Written in millimetres, a scene with cut springs, dampers and ranges moves the same way (lengths × 1000).
#[test]
fn cut_loads_and_ranges_are_unit_consistent() {
    let mut scene = bare("guided-slider-crank");
    scene.cuts[0].spring = Some(SpringSpec { stiffness: 60.0, rest: 0.16 });
    scene.cuts[0].damping = 2.0;
    scene.cuts[0].range = Some([0.12, 0.19]);
    scene.joints[0].range = Some([0.0, 1.9]);
    let metres: Model<Planar> = compile(&scene);
    let millimetres: Model<Planar> = compile(&scene.scaled_lengths(1000.0));
    let push = |m: &Model<Planar>, f: f64| {
        let op = m.op_index("slider").unwrap();
        let mut data = Data::new(m);
        let (mut q, mut qd) = (m.q0.clone(), m.qd0.clone());
        let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-3, project: true, implicit_forces: false };
        let mut user = OpWrench::<Planar> { op, wrench: Vector3::new(f, 0.0, 0.0) };
        for _ in 0..1500 {
            step(m, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
        }
        q
    };
    // Forces scale with lengths (mass and time keep their units); every joint is revolute.
    let (a, b) = (push(&metres, 4.0), push(&millimetres, 4000.0));
    assert!((&a - &b).amax() <= 1e-6, "metres {a} vs millimetres {b}");
    assert!(slide(&metres, &a) > 0.185, "the push should reach the guide's stop: {}", slide(&metres, &a));
}
