//! Ball and universal joints (nq ≠ nv), checked like the other joints: finite differences of the
//! configuration update and of the Jacobians along it, energy conserved by RK4 in free motion, and a Delta
//! robot and an RSSR four-bar written with ball joints moving as their revolute-built versions (three
//! revolutes and two near-massless gimbals per ball). Idle freedoms (a rod spinning between two balls) are
//! found and counted, and the operational-space terms stay finite. Bad input is a typed error naming the
//! file, the key and the value.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::configuration::{difference, integrate};
use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::dynamics::forward_dynamics;
use kinloop_linkage::algorithms::gravity::{kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::idle_freedoms::idle_freedoms;
use kinloop_linkage::algorithms::integrator::{step, Integrator, StepConfig};
use kinloop_linkage::algorithms::jacobian::{frame_bias_acceleration, frame_jacobian_t};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::math::space::{Space, Spatial};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::revolute_built::revolute_built;
use kinloop_linkage::model::scene::Scene;
use kinloop_linkage::model::Model;
use nalgebra::{DMatrix, DVector};

const RSSR: &str = include_str!("../scenes/rssr-ball.toml");
const DELTA: &str = include_str!("../../../scenes/delta.toml");
const UNIVERSAL: &str = include_str!("../../../scenes/rssr-four-bar.toml");

fn scene(text: &str, file: &str) -> Scene {
    Scene::from_toml_str(text, file).unwrap_or_else(|e| panic!("{e}"))
}

fn ball_models() -> Vec<(&'static str, Model<Spatial>)> {
    vec![
        ("rssr-ball", compile(&scene(RSSR, "rssr-ball.toml"))),
        ("delta-ball", compile(&scene(DELTA, "scenes/delta.toml"))),
    ]
}

/// On the models without ball joints, integrating is adding and the difference subtracting.
#[test]
fn without_balls_the_configuration_update_adds() {
    fn check<S: Space>(name: &str, model: &Model<S>) {
        let n = model.nv();
        let a = DVector::from_fn(n, |i, _| 0.1 * i as f64);
        let v = DVector::from_fn(n, |i, _| 1.0 - 0.3 * i as f64);
        let mut b = a.clone();
        integrate(model, &mut b, &v, 0.5);
        assert!((&b - (&a + &v * 0.5)).norm() < 1e-15, "{name}");
        let mut d = DVector::zeros(n);
        difference(model, &a, &b, &mut d);
        assert!((d - &v * 0.5).norm() < 1e-15, "{name}");
    }
    planar_models().iter().for_each(|(name, model)| check(name, model));
    // The ball-jointed built-in scenes are what the other tests here check.
    spatial_models().iter().filter(|(_, model)| !model.has_balls()).for_each(|(name, model)| check(name, model));
}

/// The sizes: a ball joint is 4 coordinates and 3 rates; the Delta has fewer scene bodies and joints than
/// its revolute-built version.
#[test]
fn ball_joints_take_four_coordinates_and_three_rates() {
    let rssr = compile::<Spatial>(&scene(RSSR, "rssr-ball.toml"));
    assert_eq!((rssr.nq(), rssr.nv(), rssr.nc()), (1 + 4 + 1, 1 + 3 + 1, 3));
    let delta_scene = scene(DELTA, "scenes/delta.toml");
    let delta = compile::<Spatial>(&delta_scene);
    assert_eq!((delta.nq(), delta.nv(), delta.nc()), (3 + 7 * 4, 3 + 7 * 3, 15));
    let built = revolute_built(&delta_scene, 0.005);
    assert_eq!((delta_scene.bodies.len(), delta_scene.joints.len()), (10, 10));
    assert_eq!((built.bodies.len(), built.joints.len()), (24, 24));
    let built = compile::<Spatial>(&built);
    assert_eq!((built.nq(), built.nv()), (24, 24));
}

/// What a client knows of the configuration, the layout its welcome carries, moves q exactly as the model
/// does (one function), and a layout whose balls do not fit their rates is refused naming the ball.
#[test]
fn the_layout_alone_moves_q_as_the_model_does() {
    use kinloop_linkage::algorithms::configuration::{ConfigLayout, LayoutError};
    for (name, model) in ball_models() {
        let layout = ConfigLayout::of(&model);
        assert_eq!((layout.nq(), layout.nv()), (model.nq(), model.nv()), "{name}");
        let (q, v) = random_state(&model, 7);
        let (mut by_model, mut by_layout) = (q.clone(), q.clone());
        integrate(&model, &mut by_model, &v, 0.3);
        layout.integrate(by_layout.as_mut_slice(), v.as_slice(), 0.3);
        assert_eq!(by_model, by_layout, "{name}");
        assert_eq!(layout.first_non_unit(by_layout.as_slice()), None, "{name}");
        // The first ball has none before it: its quaternion starts at its first rate.
        let k = layout.ball_rates()[0];
        by_layout[k] += 0.01;
        assert_eq!(layout.first_non_unit(by_layout.as_slice()), Some(k), "{name}");
    }
    assert_eq!(ConfigLayout::new(4, vec![2]), Err(LayoutError::BallOutOfPlace { index: 0, rate: 2, nv: 4 }));
    assert_eq!(ConfigLayout::new(7, vec![0, 2]), Err(LayoutError::BallOutOfPlace { index: 1, rate: 2, nv: 7 }));
    assert_eq!(ConfigLayout::new(7, vec![1, 4]).map(|l| l.nq()), Ok(9));
}

/// `integrate` and `difference` are inverse, and `d/dh difference(q, q ⊕ h v)` is v, to 1e-6.
#[test]
fn configuration_update_matches_finite_differences() {
    for (name, model) in ball_models() {
        for seed in 0..3 {
            let (q, v) = random_state(&model, seed);
            let mut d = DVector::zeros(model.nv());
            let h = 1e-6;
            let mut plus = q.clone();
            integrate(&model, &mut plus, &v, h);
            difference(&model, &q, &plus, &mut d);
            assert!((&d / h - &v).amax() < 1e-6, "{name}: rate {} vs {v}", &d / h);
            let mut far = q.clone();
            integrate(&model, &mut far, &v, 2.5);
            difference(&model, &q, &far, &mut d);
            // 2.5 v may turn a ball past π, where the short way differs: compare the end points instead.
            let mut again = q.clone();
            integrate(&model, &mut again, &d, 1.0);
            // (A quaternion and its negative are one orientation: compare through the difference.)
            let mut gap = DVector::zeros(model.nv());
            difference(&model, &far, &again, &mut gap);
            assert!(gap.amax() < 1e-12, "{name}: q ⊕ (far ⊖ q) is {gap} away from far");
        }
    }
}

/// J q̇ is the finite difference of every body's pose along `q ⊕ h q̇`, and J̇ q̇ that of J q̇ (1e-6).
#[test]
fn jacobians_match_finite_differences_along_the_manifold() {
    for (name, model) in ball_models() {
        let n = model.nv();
        let mut data = Data::new(&model);
        for seed in 0..3 {
            let (q, qd) = random_state(&model, seed);
            for body in (0..n).filter(|&b| !model.is_internal_body(b)) {
                let local = model.bodies[body].com + nalgebra::Vector3::new(0.013, -0.007, 0.004);
                let eval = |data: &mut Data<Spatial>, q: &DVector<f64>| {
                    forward_kinematics(&model, data, q);
                    forward_velocity(&model, data, &qd);
                    let p = data.kin.body_pos[body] + data.kin.body_rot[body] * local;
                    let mut jt = DMatrix::zeros(n, 6);
                    frame_jacobian_t(&model, &data.kin, body, &p, &mut jt);
                    (p, data.kin.body_rot[body], jt.transpose() * &qd, frame_bias_acceleration(&data.kin, body, &p))
                };
                let (_, _, v, jdqd) = eval(&mut data, &q);
                let h = 1e-6;
                let moved = |s: f64| {
                    let mut x = q.clone();
                    integrate(&model, &mut x, &qd, s * h);
                    x
                };
                let (pp, rp, vp, _) = eval(&mut data, &moved(1.0));
                let (pm, rm, vm, _) = eval(&mut data, &moved(-1.0));
                let lin = (pp - pm) * (0.5 / h);
                let ang = Spatial::rot_log(&(rp * rm.inverse())) * (0.5 / h);
                for r in 0..6 {
                    let fd = if r < 3 { lin[r] } else { ang[r - 3] };
                    assert!(
                        (fd - v[r]).abs() < 1e-6 * (1.0 + v[r].abs()),
                        "{name} body {body} row {r}: {fd} vs {}",
                        v[r]
                    );
                    let acc = (vp[r] - vm[r]) / (2.0 * h);
                    assert!(
                        (acc - jdqd[r]).abs() < 1e-5 * (1.0 + jdqd[r].abs()),
                        "{name} body {body}: J̇q̇ {acc} vs {}",
                        jdqd[r]
                    );
                }
            }
        }
    }
}

/// Mechanical energy of `(q, q̇)`.
fn energy(model: &Model<Spatial>, data: &mut Data<Spatial>, q: &DVector<f64>, qd: &DVector<f64>) -> f64 {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, qd);
    kinetic_energy(model, data) + potential_energy(model, data, q)
}

/// Largest |ΔE| and largest kinetic energy over `duration` of free motion by RK4 with projection at step `dt`.
fn energy_drift(model: &Model<Spatial>, dt: f64, duration: f64) -> (f64, f64) {
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let e0 = energy(model, &mut data, &q, &qd);
    let cfg = StepConfig { integrator: Integrator::Rk4, dt, project: true, implicit_forces: false };
    let (mut drift, mut ke): (f64, f64) = (0.0, 0.0);
    for _ in 0..(duration / dt).round() as usize {
        step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{}: {e}", model.name));
        drift = drift.max((energy(model, &mut data, &q, &qd) - e0).abs());
        ke = ke.max(kinetic_energy(model, &data));
    }
    (drift, ke)
}

/// RK4 (Runge-Kutta-Munthe-Kaas on the balls' quaternions) with projection keeps the energy of the free,
/// undamped linkages with ball and universal joints within 1e-9 J over 3 s while they swing through tens to
/// hundreds of millijoules, and stays fourth order: halving the step divides the drift by more than 8. With
/// an armature on every joint (in D and in the kinetic energy) the energy is kept as well.
#[test]
fn rk4_conserves_energy_with_ball_joints() {
    let cases = [
        ("rssr-ball", RSSR, 5e-4, 0.0),
        ("delta-ball", DELTA, DELTA_DT, 0.0),
        ("rssr-universal", UNIVERSAL, 5e-4, 0.0),
        ("rssr-ball with armatures", RSSR, 5e-4, 1e-4),
    ];
    for (name, text, dt, armature) in cases {
        let mut free = scene(text, name);
        free.joints.iter_mut().for_each(|j| (j.damping, j.armature) = (0.0, armature));
        let model = compile::<Spatial>(&free);
        let (drift, ke) = energy_drift(&model, dt, 3.0);
        let (coarse, _) = energy_drift(&model, 2.0 * dt, 3.0);
        eprintln!("{name}: dt {dt}: drift {drift:e}, coarse {coarse:e}, ke {ke}");
        assert!(ke > 1e-3, "{name}: it should move (kinetic energy up to {ke} J)");
        assert!(drift <= 1e-9, "{name}: energy drift {drift:e} J over 3 s at {dt} s (kinetic energy up to {ke} J)");
        assert!(
            drift < coarse / 8.0 || drift < 1e-13,
            "{name}: drift {coarse:e} J at {} s, {drift:e} J at {dt} s",
            2.0 * dt
        );
    }
}

/// The Delta's step for its energy check: undamped, it flails through near-singular poses, where RK4 needs
/// a finer step than the four-bars' for the same drift.
const DELTA_DT: f64 = 1.25e-4;

/// Runs `model` for 3 s of RK4 at 4 kHz from q0 and returns the positions of the joints called `names`
/// every 10 ms.
fn trajectory(model: &Model<Spatial>, names: &[&str]) -> Vec<Vec<f64>> {
    let index: Vec<usize> = names
        .iter()
        .map(|n| model.joints.iter().position(|j| j.name == *n).unwrap_or_else(|| panic!("no joint {n}")))
        .collect();
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let cfg = StepConfig { integrator: Integrator::Rk4, dt: 2.5e-4, project: true, implicit_forces: false };
    let mut out = Vec::new();
    for k in 0..12_000 {
        if k % 40 == 0 {
            out.push(index.iter().map(|&i| q[model.joints[i].q_index]).collect());
        }
        step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{}: {e}", model.name));
    }
    out
}

/// The RSSR four-bar and the Delta robot with ball joints move as their revolute-built versions: the
/// crank, rocker and arm angles agree to 1e-6 rad over 3 s (gimbals of 1 µg, under a millionth of the
/// lightest link, two parametrisations integrated independently).
#[test]
fn ball_jointed_linkages_move_as_their_revolute_built_versions() {
    let cases: [(&str, &str, &[&str]); 2] = [
        ("rssr-ball", RSSR, &["crank-pivot", "rocker-pivot"]),
        ("delta-ball", DELTA, &["arm0-pivot", "arm1-pivot", "arm2-pivot"]),
    ];
    for (name, text, shared) in cases {
        let balls = scene(text, name);
        let a = trajectory(&compile(&balls), shared);
        let b = trajectory(&compile(&revolute_built(&balls, 1e-9)), shared);
        let swing = a.iter().map(|r| (r[0] - a[0][0]).abs()).fold(0.0, f64::max);
        assert!(swing > 0.1, "{name}: the linkage should move (swing {swing} rad)");
        for (k, (ra, rb)) in a.iter().zip(&b).enumerate() {
            for (j, (x, y)) in ra.iter().zip(rb).enumerate() {
                assert!((x - y).abs() < 1e-6, "{name}: {} at {} ms: {x} vs {y}", shared[j], 10 * k);
            }
        }
    }
}

/// A rod between two ball joints spins about its own axis: the RSSR coupler once, the Delta's six rods once
/// each; the Hooke-jointed RSSR has none. The model keeps them: n − rank W counts them, and the platform's
/// Λ⁻¹ is finite and the revolute-built version's.
#[test]
fn idle_spins_are_found_counted_and_harmless() {
    let rssr = compile::<Spatial>(&scene(RSSR, "rssr-ball.toml"));
    let spins = idle_freedoms(&rssr, &rssr.q0);
    assert_eq!(spins.len(), 1, "{spins:?}");
    assert_eq!(rssr.bodies[spins[0].body].name, "coupler");
    assert_eq!(rssr.nv() - rssr.closure_rank, 2, "the crank's freedom and the spin");
    let hooke = compile::<Spatial>(&builtin_scene("rssr-four-bar"));
    assert!(idle_freedoms(&hooke, &hooke.q0).is_empty());

    let delta_scene = scene(DELTA, "scenes/delta.toml");
    let delta = compile::<Spatial>(&delta_scene);
    let spins = idle_freedoms(&delta, &delta.q0);
    let mut names: Vec<&str> = spins.iter().map(|s| delta.bodies[s.body].name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["rod0a", "rod0b", "rod1a", "rod1b", "rod2a", "rod2b"]);
    assert_eq!(delta.nv() - delta.closure_rank, 3 + 6);
    // Each spin's axis is its rod's: along the line joining the rod's two ball centres.
    let mut data = Data::new(&delta);
    forward_kinematics(&delta, &mut data, &delta.q0);
    for s in &spins {
        let rod = data.kin.body_rot[s.body] * nalgebra::Vector3::z();
        assert!(rod.cross(&s.axis).norm() < 1e-9, "{}: axis {} vs rod {rod}", delta.bodies[s.body].name, s.axis);
    }
    let inverse_inertia = |model: &Model<Spatial>| {
        let mut data = Data::new(model);
        forward_dynamics(model, &mut data, &model.q0, &model.qd0, &mut ()).expect("dynamics");
        op_space_inertia(model, &mut data, 0).expect("Λ⁻¹");
        data.op.inverse_inertia
    };
    let with_balls = inverse_inertia(&delta);
    let built = inverse_inertia(&compile(&revolute_built(&delta_scene, 1e-9)));
    assert!(with_balls.iter().all(|x| x.is_finite()));
    assert!((with_balls - built).amax() < 1e-6 * built.amax(), "{with_balls} vs {built}");
    // The parallelograms hold the platform level: its three rotations constrained, its translations free
    // (eq 10, 12), the spins notwithstanding.
    let count = constraint_directions::<Spatial>(&with_balls, delta.length_scale, DEFAULT_THRESHOLD).count;
    assert_eq!(count, 3);
}

/// A ball joint with an axis, a universal joint with parallel axes or without them, and a ball joint in a
/// planar scene are errors naming the file, the key and the value.
#[test]
fn bad_ball_and_universal_joints_are_named_errors() {
    let with = |from: &str, to: &str| {
        assert!(RSSR.contains(from), "{from}");
        let text = RSSR.replacen(from, to, 1);
        Model::<Spatial>::compile(&scene(&text, "bad.toml"), "bad.toml").unwrap_err().to_string()
    };
    let e = with("kind = \"ball\"\n", "kind = \"ball\"\naxis = [0.0, 0.0, 2.0]\n");
    assert!(e.contains("bad.toml") && e.contains("joint[1] (s1).axis") && e.contains("[0.0, 0.0, 2.0]"), "{e}");
    let e = with("kind = \"ball\"\n", "kind = \"universal\"\naxes = [[0.0, 0.0, 1.0], [0.0, 0.0, -3.0]]\n");
    assert!(e.contains("joint[1] (s1).axes") && e.contains("[0.0, 0.0, -3.0]") && e.contains("parallel"), "{e}");
    let e = with("kind = \"ball\"\n", "kind = \"universal\"\n");
    assert!(e.contains("joint[1] (s1).axes") && e.contains("needs two"), "{e}");
    let e = with("kind = \"ball\"\n", "kind = \"ball\"\nq0 = 0.3\n");
    assert!(e.contains("joint[1] (s1).q0"), "{e}");
    let planar = "kind = \"planar\"\n[[body]]\nname = \"a\"\nmass = 1.0\ninertia = 0.1\n[[joint]]\nname = \"j\"\nkind = \"ball\"\nparent = \"ground\"\nchild = \"a\"\n";
    let e = Model::<kinloop_linkage::math::space::Planar>::compile(&scene(planar, "flat.toml"), "flat.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("flat.toml") && e.contains("joint[0] (j).kind") && e.contains("spatial"), "{e}");
}

/// A universal joint is its two revolutes around a massless cross-piece: the RSSR four-bar with its Hooke
/// joint written as one `universal` moves as the shipped file's (whose spider has mass: here zeroed by
/// giving the spider to neither, so compare against the universal's own revolute-built version).
#[test]
fn universal_joint_moves_as_two_revolutes() {
    let text =
        RSSR.replacen("kind = \"ball\"\n", "kind = \"universal\"\naxes = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]\n", 1);
    let universal = scene(&text, "universal.toml");
    let model = compile::<Spatial>(&universal);
    assert_eq!((model.nq(), model.nv()), (4, 4));
    let a = trajectory(&model, &["crank-pivot", "rocker-pivot"]);
    let b = trajectory(&compile(&revolute_built(&universal, 1e-9)), &["crank-pivot", "rocker-pivot"]);
    for (ra, rb) in a.iter().zip(&b) {
        assert!((ra[0] - rb[0]).abs() < 1e-6 && (ra[1] - rb[1]).abs() < 1e-6, "{ra:?} vs {rb:?}");
    }
    assert!(idle_freedoms(&model, &model.q0).is_empty(), "a universal joint leaves the rod no spin");
}
