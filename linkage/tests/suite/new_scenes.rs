//! The Stephenson six-bar, the five-bar robot, the Bennett linkage and the RSSR four-bar, checked against
//! mechanism theory computed here by hand: the mobility from Gruebler-Kutzbach (corrected for the Bennett
//! linkage's three redundant closures) against `n - rank W` from nalgebra's SVD, closed-form position
//! analysis (circle intersections, Bennett's input-output relation, the RSSR displacement equation) at
//! configurations reached by re-closing the loops, and free motion under gravity: closed loops and
//! conserved energy.

use crate::common;

use std::f64::consts::PI;

use common::*;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::gravity::{kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::model::builtin::{self, SCENE_FILES};
use kinloop_linkage::model::Attachment;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::integrator::step, algorithms::integrator::Integrator,
    algorithms::integrator::StepConfig, math::space::Planar, math::space::SceneKind, math::space::Space,
    math::space::Spatial, math::space::VecOps, model::data::Data, model::Model,
};
use nalgebra::{DMatrix, DVector};

const NEW_SCENES: [(&str, SceneKind); 4] = [
    ("stephenson-six-bar", SceneKind::Planar),
    ("five-bar-robot", SceneKind::Planar),
    ("bennett-linkage", SceneKind::Spatial),
    ("rssr-four-bar", SceneKind::Spatial),
];

fn model<S: Space>(name: &str) -> Model<S> {
    compile(&builtin_scene(name))
}

/// Index of the tree joint called `name`.
fn joint<S: Space>(model: &Model<S>, name: &str) -> usize {
    model.joints.iter().position(|j| j.name == name).unwrap_or_else(|| panic!("no joint {name}"))
}

/// ‖h(q)‖ and W(q).
fn closure<S: Space>(model: &Model<S>, q: &DVector<f64>) -> (f64, DMatrix<f64>) {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    closure_residual_and_jacobian(model, &mut data);
    (data.closure_residual.norm(), data.closure_jacobian())
}

/// World position of a body-fixed point at q (the library's kinematics).
fn world_point<S: Space>(model: &Model<S>, q: &DVector<f64>, body: usize, point: &S::Point) -> Vec<f64> {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    data.kin.point(&Attachment { body: Some(body), point: *point }).as_slice().to_vec()
}

/// World position of the operational point called `name`.
fn op_position<S: Space>(model: &Model<S>, q: &DVector<f64>, name: &str) -> Vec<f64> {
    let op = &model.ops[model.op_index(name).unwrap_or_else(|| panic!("no op {name}"))];
    world_point(model, q, op.body, &op.point)
}

/// Re-closes the loops with the joints in `fixed` held (Newton steps on the others through nalgebra's SVD
/// least-squares solve, which copes with redundant closure rows).
fn close_with_fixed<S: Space>(model: &Model<S>, start: &DVector<f64>, fixed: &[usize]) -> DVector<f64> {
    let free: Vec<usize> = (0..model.nv()).filter(|j| !fixed.contains(j)).collect();
    let mut q = start.clone();
    for _ in 0..60 {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, &q);
        closure_residual_and_jacobian(model, &mut data);
        if data.closure_residual.norm() <= 1e-14 {
            return q;
        }
        let w = data.closure_jacobian();
        let w_free = DMatrix::from_fn(w.nrows(), free.len(), |r, c| w[(r, free[c])]);
        let svd = w_free.svd(true, true);
        let tol = 1e-10 * svd.singular_values.max();
        let dq = svd.solve(&data.closure_residual, tol).unwrap();
        for (c, &j) in free.iter().enumerate() {
            q[j] -= dq[c];
        }
    }
    panic!("{}: loops did not re-close from {start}", model.name);
}

/// `a - b` wrapped to (-π, π].
fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b).sin().atan2((a - b).cos())
}

/// The intersection of the circles (p, r) and (c, s) to the left of p→c (`side` = +1) or to its right (-1).
fn circles(p: [f64; 2], r: f64, c: [f64; 2], s: f64, side: f64) -> [f64; 2] {
    let (dx, dy) = (c[0] - p[0], c[1] - p[1]);
    let d = dx.hypot(dy);
    assert!(d < r + s && d > (r - s).abs(), "circles ({p:?}, {r}) and ({c:?}, {s}) do not meet");
    let a = (r * r - s * s + d * d) / (2.0 * d);
    let h = (r * r - a * a).sqrt();
    [p[0] + a * dx / d - side * h * dy / d, p[1] + a * dy / d + side * h * dx / d]
}

fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

// --- mobility --------------------------------------------------------------------------------------

/// The mobility of a mechanism from the theory: Gruebler-Kutzbach over `links` links (ground included) and
/// joints of the given freedoms, plus the known overconstraint (redundant closure equations) minus idle
/// freedoms.
struct Theory {
    spatial: bool,
    links: i64,
    joint_freedoms: &'static [i64],
    overconstraint: i64,
    idle: i64,
}

impl Theory {
    fn dof(&self) -> i64 {
        let lambda = if self.spatial { 6 } else { 3 };
        let gk = lambda * (self.links - 1) - self.joint_freedoms.iter().map(|f| lambda - f).sum::<i64>();
        gk + self.overconstraint - self.idle
    }
}

fn theory(name: &str) -> Theory {
    match name {
        // 6 links, 7 revolute joints.
        "stephenson-six-bar" => {
            Theory { spatial: false, links: 6, joint_freedoms: &[1; 7], overconstraint: 0, idle: 0 }
        }
        // 5 links, 5 revolute joints.
        "five-bar-robot" => Theory { spatial: false, links: 5, joint_freedoms: &[1; 5], overconstraint: 0, idle: 0 },
        // Spatial 4R: GK gives -2; Bennett's conditions make three closure equations redundant.
        "bennett-linkage" => Theory { spatial: true, links: 4, joint_freedoms: &[1; 4], overconstraint: 3, idle: 0 },
        // RSSR with the first S as a Hooke joint (two R through a spider): R, R, R, S, R over 5 links. As a
        // check of the bookkeeping, plain RSSR (4 links, R S S R) has GK 2 with one idle freedom: also 1.
        "rssr-four-bar" => {
            Theory { spatial: true, links: 5, joint_freedoms: &[1, 1, 1, 3, 1], overconstraint: 0, idle: 0 }
        }
        _ => unreachable!(),
    }
}

/// `(n - rank W, rank)` by nalgebra's SVD, asserting that the rank is unambiguous (a gap of at least nine
/// orders of magnitude between the kept and the dropped singular values).
fn svd_mobility(name: &str, n: usize, w: &DMatrix<f64>) -> (usize, usize) {
    let sv = w.clone().svd(false, false).singular_values;
    let max = sv.max();
    let rank = sv.iter().filter(|s| **s > 1e-9 * max).count();
    let kept_min = sv.iter().copied().filter(|s| *s > 1e-9 * max).fold(f64::INFINITY, f64::min);
    let dropped_max = sv.iter().copied().filter(|s| *s <= 1e-9 * max).fold(0.0, f64::max);
    assert!(kept_min > 1e-3 * max && dropped_max < 1e-12 * max, "{name}: ambiguous rank, singular values {sv}");
    (n - rank, rank)
}

fn check_mobility<S: Space>(name: &str, second: &DVector<f64>) {
    let model = model::<S>(name);
    let expected = theory(name).dof();
    for (label, q) in [("q0", &model.q0), ("second configuration", second)] {
        let (residual, w) = closure(&model, q);
        assert!(residual <= 1e-12, "{name} at {label}: closure residual {residual:.3e} m");
        let (dof, rank) = svd_mobility(name, model.nv(), &w);
        assert_eq!(dof as i64, expected, "{name} at {label}: n - rank W = {} - {rank}", model.nv());
        assert_eq!(rank, model.closure_rank, "{name} at {label}: the model's generic rank");
    }
}

#[test]
fn new_scenes_are_built_in_and_load_by_name() {
    for (name, kind) in NEW_SCENES {
        assert!(SCENE_FILES.iter().any(|(n, _)| *n == name), "{name} is not in SCENE_FILES");
        let (scene, label) = builtin::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((scene.name.as_str(), label.as_str(), scene.kind), (name, format!("builtin:{name}").as_str(), kind));
        assert!(!scene.ops.is_empty(), "{name}: no operational point");
    }
}

/// Every new scene compiles, its loops are closed at q0 to round-off, and its mobility from the theory
/// equals n - rank W at q0 and at a second closed configuration far from it.
#[test]
fn new_scenes_are_closed_at_q0_and_have_the_mobility_of_their_theory() {
    let counts = |name: &str| -> (usize, usize, usize) {
        match name {
            "stephenson-six-bar" | "five-bar-robot" => {
                let m = model::<Planar>(name);
                (m.nv(), m.nc(), m.closure_rank)
            }
            _ => {
                let m = model::<Spatial>(name);
                (m.nv(), m.nc(), m.closure_rank)
            }
        }
    };
    // (n, m, rank W): two pins; one pin; a revolute cut of 5 equations of which 3 redundant; one ball.
    assert_eq!(counts("stephenson-six-bar"), (5, 4, 4));
    assert_eq!(counts("five-bar-robot"), (4, 2, 2));
    assert_eq!(counts("bennett-linkage"), (3, 5, 2));
    assert_eq!(counts("rssr-four-bar"), (4, 3, 3));

    let stephenson = model::<Planar>("stephenson-six-bar");
    let crank = joint(&stephenson, "o1");
    check_mobility::<Planar>("stephenson-six-bar", &sweep(&stephenson, crank, 2.0, 8));
    let five = model::<Planar>("five-bar-robot");
    let inputs = [joint(&five, "left-motor"), joint(&five, "right-motor")];
    check_mobility::<Planar>("five-bar-robot", &five_bar_at(&five, inputs, [0.25, -0.3]));
    let bennett = model::<Spatial>("bennett-linkage");
    check_mobility::<Spatial>("bennett-linkage", &sweep(&bennett, joint(&bennett, "joint1"), -1.2, 8));
    let rssr = model::<Spatial>("rssr-four-bar");
    check_mobility::<Spatial>("rssr-four-bar", &sweep(&rssr, joint(&rssr, "crank-pivot"), 2.5, 10));
}

/// Turns the input joint by `total` from q0 in `steps` equal steps, re-closing the loops after each.
fn sweep<S: Space>(model: &Model<S>, input: usize, total: f64, steps: usize) -> DVector<f64> {
    let mut q = model.q0.clone();
    for _ in 0..steps {
        q[input] += total / steps as f64;
        q = close_with_fixed(model, &q, &[input]);
    }
    q
}

// --- the Stephenson six-bar ------------------------------------------------------------------------

/// The Stephenson six-bar's dimensions (from its header) and joint indices.
struct Stephenson {
    o1: usize,
    a: usize,
    o2: usize,
    o3: usize,
    c: usize,
}

const ST_O2: [f64; 2] = [0.25, 0.0];
const ST_O3: [f64; 2] = [-0.16, 0.28];
const ST_CRANK: f64 = 0.08;
const ST_COUPLER: f64 = 0.22;
const ST_ROCKER: f64 = 0.18;
const ST_CONNECTOR: f64 = 0.18;
const ST_OUTPUT: f64 = 0.16;
const ST_C: [f64; 2] = [0.10, 0.08];

impl Stephenson {
    fn new(model: &Model<Planar>) -> Self {
        Stephenson {
            o1: joint(model, "o1"),
            a: joint(model, "a"),
            o2: joint(model, "o2"),
            o3: joint(model, "o3"),
            c: joint(model, "c"),
        }
    }

    /// The loop equations written by hand from the joint angles: the gaps at B and at D (m).
    fn loop_gaps(&self, q: &DVector<f64>) -> (f64, f64) {
        let (th, phi) = (q[self.o1], q[self.o1] + q[self.a]);
        let a = [ST_CRANK * th.cos(), ST_CRANK * th.sin()];
        let b_coupler = [a[0] + ST_COUPLER * phi.cos(), a[1] + ST_COUPLER * phi.sin()];
        let b_rocker = [ST_O2[0] + ST_ROCKER * q[self.o2].cos(), ST_O2[1] + ST_ROCKER * q[self.o2].sin()];
        let c = [a[0] + ST_C[0] * phi.cos() - ST_C[1] * phi.sin(), a[1] + ST_C[0] * phi.sin() + ST_C[1] * phi.cos()];
        let psi = phi + q[self.c];
        let d_connector = [c[0] + ST_CONNECTOR * psi.cos(), c[1] + ST_CONNECTOR * psi.sin()];
        let d_output = [ST_O3[0] + ST_OUTPUT * q[self.o3].cos(), ST_O3[1] + ST_OUTPUT * q[self.o3].sin()];
        (dist(&b_coupler, &b_rocker), dist(&d_connector, &d_output))
    }

    /// The other four joint angles from the crank angle in closed form (circle intersections, the open
    /// four-bar and the hanging output): (a, o2, o3, c).
    fn closed_form(&self, th: f64) -> [f64; 4] {
        let a = [ST_CRANK * th.cos(), ST_CRANK * th.sin()];
        let b = circles(a, ST_COUPLER, ST_O2, ST_ROCKER, 1.0);
        let phi = (b[1] - a[1]).atan2(b[0] - a[0]);
        let c = [a[0] + ST_C[0] * phi.cos() - ST_C[1] * phi.sin(), a[1] + ST_C[0] * phi.sin() + ST_C[1] * phi.cos()];
        let d = circles(ST_O3, ST_OUTPUT, c, ST_CONNECTOR, -1.0);
        [
            phi - th,
            (b[1] - ST_O2[1]).atan2(b[0] - ST_O2[0]),
            (d[1] - ST_O3[1]).atan2(d[0] - ST_O3[0]),
            (d[1] - c[1]).atan2(d[0] - c[0]) - phi,
        ]
    }

    fn assert_closed_form(&self, what: &str, q: &DVector<f64>) {
        let (gap_b, gap_d) = self.loop_gaps(q);
        assert!(gap_b <= 1e-12 && gap_d <= 1e-12, "{what}: loop equations by hand leave {gap_b:.3e}, {gap_d:.3e} m");
        let expected = self.closed_form(q[self.o1]);
        for (k, j) in [self.a, self.o2, self.o3, self.c].into_iter().enumerate() {
            let err = angle_diff(q[j], expected[k]);
            assert!(err.abs() <= 1e-10, "{what}: joint {j} at {} vs closed form {} rad", q[j], expected[k]);
        }
    }
}

/// q0 is the closed form at 60°; the crank turns fully (24 steps of 15°) with both loops closing on the
/// same branch; and a configuration reached by the `assemble` module from a perturbed q satisfies the
/// loop equations written by hand and the closed form at its crank angle.
#[test]
fn stephenson_six_bar_follows_its_closed_form_all_the_way_round() {
    let model = model::<Planar>("stephenson-six-bar");
    let st = Stephenson::new(&model);
    assert!((model.q0[st.o1] - PI / 3.0).abs() < 1e-15);
    st.assert_closed_form("q0", &model.q0);
    let mut q = model.q0.clone();
    let mut output = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 1..=24 {
        q[st.o1] += PI / 12.0;
        q = close_with_fixed(&model, &q, &[st.o1]);
        st.assert_closed_form(&format!("crank step {k}"), &q);
        output = (output.0.min(q[st.o3]), output.1.max(q[st.o3]));
    }
    // The output rocks through about 51° per crank turn (header: from -111° to -60°).
    let swing = (output.1 - output.0).to_degrees();
    assert!((48.0..54.0).contains(&swing), "output swing {swing}°");

    let start = DVector::from_fn(model.nv(), |i, _| model.q0[i] + [0.6, -0.2, 0.15, 0.1, -0.25][i]);
    let assembled = assemble(&model, &start, 1e-14).unwrap_or_else(|e| panic!("{e}"));
    assert!((assembled.q[st.o1] - model.q0[st.o1]).abs() > 0.1, "assembly went back to q0");
    st.assert_closed_form("assembled", &assembled.q);
}

// --- the five-bar robot ----------------------------------------------------------------------------

const FB_A1: [f64; 2] = [-0.05, 0.0];
const FB_A2: [f64; 2] = [0.05, 0.0];
const FB_PROXIMAL: f64 = 0.12;
const FB_DISTAL: f64 = 0.16;

/// The effector from the two proximal angles, by hand: the circles of radius 0.16 about the elbows meet
/// on the far side of the elbows (left of B1→B2).
fn five_bar_effector(t1: f64, t2: f64) -> [f64; 2] {
    let b1 = [FB_A1[0] + FB_PROXIMAL * t1.cos(), FB_A1[1] + FB_PROXIMAL * t1.sin()];
    let b2 = [FB_A2[0] + FB_PROXIMAL * t2.cos(), FB_A2[1] + FB_PROXIMAL * t2.sin()];
    circles(b1, FB_DISTAL, b2, FB_DISTAL, 1.0)
}

/// The five-bar with its proximal angles moved by `delta` from q0 (in 6 steps) and the loop re-closed.
fn five_bar_at(model: &Model<Planar>, inputs: [usize; 2], delta: [f64; 2]) -> DVector<f64> {
    let mut q = model.q0.clone();
    for _ in 0..6 {
        q[inputs[0]] += delta[0] / 6.0;
        q[inputs[1]] += delta[1] / 6.0;
        q = close_with_fixed(model, &q, &inputs);
    }
    q
}

/// Over a 5 × 5 grid of proximal angles (±0.4 rad around q0) the effector OP, where the library's
/// kinematics put it, is the circle intersection computed by hand; the OP covers a 2-D region; a
/// configuration from `assemble` matches too.
#[test]
fn five_bar_effector_is_the_circle_intersection_of_its_proximal_angles() {
    let model = model::<Planar>("five-bar-robot");
    let inputs = [joint(&model, "left-motor"), joint(&model, "right-motor")];
    assert_eq!([model.q0[inputs[0]], model.q0[inputs[1]]], [7.0 * PI / 12.0, PI / 3.0]);
    let check = |what: &str, q: &DVector<f64>| {
        let by_hand = five_bar_effector(q[inputs[0]], q[inputs[1]]);
        let op = op_position(&model, q, "effector");
        let err = dist(&op, &by_hand);
        assert!(err <= 1e-12, "{what}: effector at {op:?}, by hand {by_hand:?} ({err:.3e} m)");
        let right_tip = world_point(&model, q, joint(&model, "right-elbow"), &nalgebra::Vector2::new(FB_DISTAL, 0.0));
        assert!(dist(&right_tip, &by_hand) <= 1e-12, "{what}: the right distal arm misses the effector");
        op
    };
    check("q0", &model.q0);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for i in -2..=2 {
        for j in -2..=2 {
            let q = five_bar_at(&model, inputs, [0.2 * i as f64, 0.2 * j as f64]);
            let p = check(&format!("proximal angles moved by ({}, {})", 0.2 * i as f64, 0.2 * j as f64), &q);
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    // A region, not a curve: several centimetres both ways.
    assert!(hi[0] - lo[0] > 0.03 && hi[1] - lo[1] > 0.03, "effector range {lo:?} to {hi:?}");

    let start = DVector::from_fn(model.nv(), |i, _| model.q0[i] + [0.2, -0.1, -0.15, 0.3][i]);
    let assembled = assemble(&model, &start, 1e-14).unwrap_or_else(|e| panic!("{e}"));
    check("assembled", &assembled.q);
}

// --- the Bennett linkage ---------------------------------------------------------------------------

const BENNETT_A: f64 = 0.10;
const BENNETT_ALPHA: f64 = PI / 6.0;
const BENNETT_BETA: f64 = PI / 3.0;

/// Bennett's conditions hold for the scene's links, and over a full turn of joint 1 (42 steps of 0.15 rad,
/// through the flat configurations θ1 = 0 and θ1 = ±π) the re-closed loop satisfies the closed-form
/// input-output relation tan(θ1/2) tan(θ2/2) = sin((β+α)/2) / sin((β-α)/2) and θ3 = -θ1.
#[test]
fn bennett_linkage_follows_its_input_output_relation() {
    let model = model::<Spatial>("bennett-linkage");
    let (j1, j2, j3) = (joint(&model, "joint1"), joint(&model, "joint2"), joint(&model, "joint3"));
    // The links as compiled: joint 2 at link 1's far end (a along x), joint 3 at link 2's (b along x).
    let b = model.joints[j3].placement_pos.x;
    assert_eq!(model.joints[j2].placement_pos, nalgebra::Vector3::new(BENNETT_A, 0.0, 0.0));
    assert!((BENNETT_A / BENNETT_ALPHA.sin() - b / BENNETT_BETA.sin()).abs() < 1e-15, "a / sin α = b / sin β");
    // The ground link at q0: joint 4's axis passes through (-b, 0, 0) along (0, sin β, cos β) (link 4 has
    // length b and twist β, like link 2).
    let link3 = j3;
    let axis4 = {
        let mut data = Data::new(&model);
        forward_kinematics(&model, &mut data, &model.q0);
        data.kin.direction(Some(link3), &nalgebra::Vector3::new(0.0, -BENNETT_ALPHA.sin(), BENNETT_ALPHA.cos()))
    };
    let expected_axis = nalgebra::Vector3::new(0.0, BENNETT_BETA.sin(), BENNETT_BETA.cos());
    assert!((axis4 - expected_axis).norm() < 1e-12, "joint 4 axis {axis4}");
    let pivot4 = world_point(&model, &model.q0, link3, &nalgebra::Vector3::new(BENNETT_A, 0.0, 0.0));
    assert!(dist(&pivot4, &[-b, 0.0, 0.0]) < 1e-12, "joint 4 at {pivot4:?}");

    let k = ((BENNETT_BETA + BENNETT_ALPHA) / 2.0).sin() / ((BENNETT_BETA - BENNETT_ALPHA) / 2.0).sin();
    // sin(θ1/2) sin(θ2/2) - K cos(θ1/2) cos(θ2/2) = 0: the relation without tan's poles.
    let relation =
        |q: &DVector<f64>| (q[j1] / 2.0).sin() * (q[j2] / 2.0).sin() - k * (q[j1] / 2.0).cos() * (q[j2] / 2.0).cos();
    assert!(relation(&model.q0).abs() < 1e-14 && (model.q0[j1] - 5.0 * PI / 9.0).abs() < 1e-15);
    let mut q = model.q0.clone();
    let mut coupler = Vec::new();
    for step in 1..=42 {
        q[j1] -= 0.15;
        q = close_with_fixed(&model, &q, &[j1]);
        let (r, third) = (relation(&q), angle_diff(q[j3], -q[j1]));
        assert!(
            r.abs() < 1e-12 && third.abs() < 1e-12,
            "step {step}: θ = {:?}: relation {r:.3e}, θ3 + θ1 = {third:.3e}",
            q.as_slice()
        );
        coupler.push(op_position(&model, &q, "coupler"));
    }
    // The coupler's midpoint really moves in 3-D (its z spans centimetres).
    let z: Vec<f64> = coupler.iter().map(|p| p[2]).collect();
    let z_span = z.iter().copied().fold(f64::NEG_INFINITY, f64::max) - z.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(z_span > 0.02, "coupler z span {z_span}");
}

// --- the RSSR four-bar -----------------------------------------------------------------------------

const RSSR_CRANK: f64 = 0.05;
const RSSR_ROCKER: f64 = 0.10;
const RSSR_COUPLER: f64 = 0.15;
const RSSR_O2: [f64; 3] = [0.02, 0.10, 0.06];

/// The rocker angle from the crank angle: A cos φ + B sin φ = C (the rocker below its pivot).
fn rssr_rocker(theta: f64) -> f64 {
    let a = 2.0 * RSSR_ROCKER * (RSSR_O2[1] - RSSR_CRANK * theta.sin());
    let b = 2.0 * RSSR_ROCKER * RSSR_O2[2];
    let c = RSSR_COUPLER.powi(2)
        - RSSR_ROCKER.powi(2)
        - RSSR_O2[2].powi(2)
        - (RSSR_CRANK * theta.cos() - RSSR_O2[0]).powi(2)
        - (RSSR_CRANK * theta.sin() - RSSR_O2[1]).powi(2);
    b.atan2(a) - (c / a.hypot(b)).acos()
}

/// Over a full crank turn (36 steps of 10°) the re-closed loop puts the rocker at the closed-form angle of
/// the RSSR displacement equation; the ball centres, written by hand from the crank and rocker angles, are
/// the coupler's length apart and where the library puts the coupler's ends; the Hooke joint stays far
/// from its singularity (the rod within 20° of horizontal).
#[test]
fn rssr_rocker_follows_the_displacement_equation() {
    let model = model::<Spatial>("rssr-four-bar");
    let (crank, rocker) = (joint(&model, "crank-pivot"), joint(&model, "rocker-pivot"));
    let coupler = joint(&model, "hooke-2");
    let mut q = model.q0.clone();
    assert!((q[crank] - PI / 6.0).abs() < 1e-15);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for step in 0..=36 {
        if step > 0 {
            q[crank] += PI / 18.0;
            q = close_with_fixed(&model, &q, &[crank]);
        }
        let (th, phi) = (q[crank], q[rocker]);
        let err = angle_diff(phi, rssr_rocker(th));
        assert!(err.abs() < 1e-10, "step {step}: rocker {phi} vs closed form {}", rssr_rocker(th));
        let s1 = [RSSR_CRANK * th.cos(), RSSR_CRANK * th.sin(), 0.0];
        let s2 = [RSSR_O2[0], RSSR_O2[1] + RSSR_ROCKER * phi.cos(), RSSR_O2[2] + RSSR_ROCKER * phi.sin()];
        assert!((dist(&s1, &s2) - RSSR_COUPLER).abs() < 1e-12);
        let rod_start = world_point(&model, &q, coupler, &nalgebra::Vector3::zeros());
        let rod_end = world_point(&model, &q, coupler, &nalgebra::Vector3::new(0.0, RSSR_COUPLER, 0.0));
        assert!(dist(&rod_start, &s1) < 1e-12 && dist(&rod_end, &s2) < 1e-12, "step {step}: ball centres");
        assert!(((s2[2] - s1[2]) / RSSR_COUPLER).abs() < 20f64.to_radians().sin(), "step {step}: rod too steep");
        lo = lo.min(phi);
        hi = hi.max(phi);
    }
    // The header: the rocker swings from about -94° to -17°.
    assert!((lo.to_degrees() + 94.3).abs() < 0.5 && (hi.to_degrees() + 16.8).abs() < 0.5, "{lo} {hi}");
}

// --- free motion -------------------------------------------------------------------------------------

/// What a free run showed.
struct Run {
    closure: f64,
    drift: f64,
    kinetic: f64,
    /// Per OP, the largest extent of its bounding box (m).
    op_ranges: Vec<(String, f64)>,
}

/// `seconds` of RK4 with projection from q0 at rest (gravity only), or, without gravity, from a velocity made
/// consistent with the closures.
fn free_run<S: Space>(model: &Model<S>, dt: f64, seconds: f64) -> Run {
    let mut data = Data::new(model);
    let mut q = model.q0.clone();
    let mut qd = DVector::zeros(model.nv());
    if !model.has_gravity {
        qd = DVector::from_fn(model.nv(), |i, _| [1.5, -1.0, 0.5, 2.0][i % 4]);
        forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
        kinloop_linkage::algorithms::integrator::project(model, &mut data, &mut q.clone(), &mut qd);
    }
    let energy = |data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>| {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, qd);
        (kinetic_energy(model, data), potential_energy(model, data, q))
    };
    let (t0, v0) = energy(&mut data, &q, &qd);
    let cfg = StepConfig { integrator: Integrator::Rk4, dt, project: true, implicit_forces: false };
    let mut run = Run { closure: 0.0, drift: 0.0, kinetic: t0, op_ranges: Vec::new() };
    let mut boxes = vec![(vec![f64::INFINITY; 3], vec![f64::NEG_INFINITY; 3]); model.ops.len()];
    for _ in 0..(seconds / dt).round() as usize {
        let report = step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{e}"));
        run.closure = run.closure.max(report.closure_error);
        let (t, v) = energy(&mut data, &q, &qd);
        run.drift = run.drift.max((t + v - t0 - v0).abs());
        run.kinetic = run.kinetic.max(t);
        for (op, (lo, hi)) in model.ops.iter().zip(&mut boxes) {
            let p = data.kin.point(&Attachment { body: Some(op.body), point: op.point });
            for (k, x) in p.as_slice().iter().enumerate() {
                lo[k] = lo[k].min(*x);
                hi[k] = hi[k].max(*x);
            }
        }
    }
    run.closure = run.closure.max(closure(model, &q).0);
    run.op_ranges = model
        .ops
        .iter()
        .zip(&boxes)
        .map(|(op, (lo, hi))| {
            let extent = (0..<S::Point as VecOps>::LEN).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
            (op.name.clone(), extent)
        })
        .collect();
    run
}

/// 3 s of free motion (gravity only; the horizontal five-bar from a consistent initial velocity) with RK4
/// at 1 kHz and projection: the loops stay closed to 1e-9 m, the OPs move, and, as no joint is damped, the
/// energy is conserved up to RK4's truncation error. The bound: drift below 1e-5 of the largest kinetic
/// energy (the bound the other conservative built-ins meet), and truncation error, not a systematic leak:
/// halving the step shrinks it by at least 8 (fourth order: 16) unless it is at round-off.
///
/// The Bennett linkage comes nearest the bound: nearly all its drift is gained where the loop swings through
/// its flat configurations (θ1 = 0 and ±π, every common normal on one line), where the closure error after
/// projection rises for a few steps. There the pivoted factorization of S keeps closure row 0 (the x gap of
/// joint 4), whose row of W vanishes at the flat configuration (|W₀| ≈ 4e-4 against ≈ 1 for the rows it
/// drops), because pivots are judged relative to each row's own S_ii.
#[test]
fn free_motion_keeps_the_loops_closed_and_conserves_energy() {
    fn check<S: Space>(name: &str) {
        let model = model::<S>(name);
        let run = free_run(&model, 1e-3, 3.0);
        let half = free_run(&model, 5e-4, 3.0);
        eprintln!(
            "{name}: closure {:.2e} m, drift {:.2e} J (dt/2: {:.2e} J), max kinetic energy {:.3e} J, OP ranges {:?}",
            run.closure, run.drift, half.drift, run.kinetic, run.op_ranges
        );
        assert!(run.closure <= 1e-9 && half.closure <= 1e-9, "{name}: closure error {:.3e} m", run.closure);
        assert!(run.kinetic > 1e-3, "{name}: the linkage should move (max kinetic energy {:.3e} J)", run.kinetic);
        for (op, extent) in &run.op_ranges {
            assert!(*extent > 0.01, "{name}: OP {op} moved only {extent} m");
        }
        assert!(run.drift < 1e-5 * run.kinetic, "{name}: energy drift {:.3e} J vs {:.3e} J", run.drift, run.kinetic);
        assert!(
            half.drift < run.drift / 8.0 || run.drift < 1e-12 * run.kinetic.max(1.0),
            "{name}: drift {:.3e} J at dt, {:.3e} J at dt/2",
            run.drift,
            half.drift
        );
    }
    check::<Planar>("stephenson-six-bar");
    check::<Planar>("five-bar-robot");
    check::<Spatial>("bennett-linkage");
    check::<Spatial>("rssr-four-bar");
}
