//! `approach_op` (where a linkage would be if its operational point were led to a target) against
//! configurations found by another algorithm: `assemble` closing the loops at a turned crank, and the
//! coupler's tangent from finite differences of such configurations.

use kinloop_linkage::approach::{approach_op, ApproachScratch, MAX_STEPS};
use kinloop_linkage::assemble::assemble;
use kinloop_linkage::kinematics::forward_kinematics;
use kinloop_linkage::local_model::OpPose;
use kinloop_linkage::loop_closure::loop_closure;
use kinloop_linkage::{builtin, Data, Model, Planar};
use nalgebra::{DVector, Vector3};

fn four_bar() -> (Model<Planar>, usize) {
    let scene = builtin::scene("fourbar-crank-rocker").unwrap().unwrap();
    let model = Model::compile(&scene, "fourbar").unwrap();
    let op = model.op_index("coupler").unwrap();
    (model, op)
}

/// The closed configuration with the crank (joint 0) turned by `by` from q0, and the coupler's pose there.
fn turned(model: &Model<Planar>, op: usize, by: f64) -> (DVector<f64>, OpPose<Planar>) {
    let mut q = model.q0.clone();
    q[0] += by;
    let q = assemble(model, &q, 1e-13).unwrap().q;
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &q);
    let pose = OpPose::of_op(model, &data, op);
    (q, pose)
}

fn closure_residual(model: &Model<Planar>, q: &DVector<f64>) -> f64 {
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    loop_closure(model, &mut data);
    data.closure_residual.norm()
}

/// `|(Δp, L Δθ)|`.
fn scaled_distance(a: &OpPose<Planar>, b: &OpPose<Planar>, length_scale: f64) -> f64 {
    let d = a.difference(b);
    Vector3::new(d[0], d[1], d[2] * length_scale).norm()
}

#[test]
fn the_coupler_is_led_to_a_pose_the_crank_reaches() {
    let (model, op) = four_bar();
    let mut data = Data::new(&model);
    let mut scratch = ApproachScratch::new(&model);
    // 0.1 rad of crank moves the coupler point about 1 cm; 0.6 rad, several cm round the curve's bend.
    for by in [0.1, -0.3, 0.6] {
        let (_, target) = turned(&model, op, by);
        let mut q = model.q0.clone();
        let reached = approach_op(&model, &mut data, &mut q, op, &target, &mut scratch).unwrap();
        let off = scaled_distance(&reached.pose, &target, model.length_scale);
        assert!(off < 1e-6, "crank turned {by} rad: the coupler stopped {off} m from the pose ({} steps)", reached.steps);
        assert!(reached.steps <= MAX_STEPS);
        assert!(closure_residual(&model, &q) < 1e-9, "the configuration reached is closed");
        // The pose reported is the configuration's.
        forward_kinematics(&model, &mut data, &q);
        assert!(scaled_distance(&OpPose::of_op(&model, &data, op), &reached.pose, model.length_scale) < 1e-12);
    }
}

#[test]
fn off_the_curve_the_coupler_stops_at_the_foot_of_the_normal() {
    // A target off the coupler's path (x, y, θ) by a few millimetres along a normal of the path's tangent
    // (scaled coordinates, as the free directions are): the nearest pose the linkage reaches is that
    // tangent's point, where the error is normal to the motion.
    let (model, op) = four_bar();
    let l = model.length_scale;
    let scaled = |d: nalgebra::Vector3<f64>| Vector3::new(d[0], d[1], d[2] * l);
    let (_, foot) = turned(&model, op, 0.4);
    let h = 1e-5;
    let tangent = scaled(turned(&model, op, 0.4 + h).1.difference(&turned(&model, op, 0.4 - h).1)).normalize();
    for (helper, depth) in [(Vector3::z(), 0.003), (Vector3::x(), -0.002)] {
        let normal = (helper - tangent * tangent.dot(&helper)).normalize() * depth;
        let mut target = foot;
        target.integrate(&Vector3::new(normal[0], normal[1], normal[2] / l), 1.0);
        let mut q = model.q0.clone();
        let mut data = Data::new(&model);
        let reached = approach_op(&model, &mut data, &mut q, op, &target, &mut ApproachScratch::new(&model)).unwrap();
        let off = scaled_distance(&reached.pose, &foot, l);
        assert!(off < 1e-5, "stopped {off} m from the foot of the normal (depth {depth} m)");
        assert!(closure_residual(&model, &q) < 1e-9);
    }
}

#[test]
fn a_target_at_the_pose_leaves_the_configuration_where_it_is() {
    let (model, op) = four_bar();
    let (q1, pose) = turned(&model, op, 0.2);
    let mut q = q1.clone();
    let mut data = Data::new(&model);
    let reached = approach_op(&model, &mut data, &mut q, op, &pose, &mut ApproachScratch::new(&model)).unwrap();
    assert_eq!(reached.steps, 0);
    assert_eq!(q, q1);
    assert_eq!(reached.directions.count, 2, "one free direction: a 1-DOF linkage");
}
