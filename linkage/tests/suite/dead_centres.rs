//! Exact dead centres and change points, where the loops pin an operational point or free it more than
//! anywhere near: the constraint count (eq 12) follows the OP's mobility computed independently, from the
//! geometry alone. Each Jacobian below is written from the joints' world positions at the configuration
//! (a revolute joint at c moves a point p at (-(p_y - c_y), p_x - c_x) and turns it at 1; a prismatic joint
//! moves it along its axis), the closures' null space comes from nalgebra's SVD, and the mobility is the
//! rank of the OP's Jacobian on that null space: the count must be 3 minus it.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::model::scene::Scene;
use kinloop_linkage::{algorithms::dynamics::forward_dynamics, math::space::Planar, model::data::Data, model::Model};
use nalgebra::{DMatrix, DVector, Matrix3};
use std::f64::consts::PI;

/// A planar joint as it sits at the configuration under test.
#[derive(Clone, Copy)]
enum Joint {
    /// Turning about this world point.
    Revolute([f64; 2]),
    /// Sliding along this world direction.
    Prismatic([f64; 2]),
}

/// A planar tree at one configuration: joint i carries body i and hangs from body `parent` (None: ground).
struct Geometry(Vec<(Joint, Option<usize>)>);

impl Geometry {
    /// The rows (ẋ, ẏ, θ̇) of the point at world position `p` fixed to `body` (None: ground), per joint rate.
    fn jacobian(&self, body: Option<usize>, p: [f64; 2]) -> DMatrix<f64> {
        let mut j = DMatrix::zeros(3, self.0.len());
        let mut at = body;
        while let Some(b) = at {
            let (joint, parent) = self.0[b];
            let column = match joint {
                Joint::Revolute(c) => [-(p[1] - c[1]), p[0] - c[0], 1.0],
                Joint::Prismatic(u) => [u[0], u[1], 0.0],
            };
            j.column_mut(b).copy_from_slice(&column);
            at = parent;
        }
        j
    }

    /// W for pins joining, at world point p, body a to body b: the rows (x, y) of `J_a - J_b`, stacked.
    fn pins(&self, pins: &[(Option<usize>, Option<usize>, [f64; 2])]) -> DMatrix<f64> {
        let rows: Vec<DMatrix<f64>> =
            pins.iter().map(|&(a, b, p)| (self.jacobian(a, p) - self.jacobian(b, p)).rows(0, 2).into_owned()).collect();
        DMatrix::from_fn(2 * rows.len(), self.0.len(), |r, c| rows[r / 2][(r % 2, c)])
    }
}

/// The number of independent OP motions the closures allow: rank of `J_op N`, N a basis of null(W).
fn mobility(w: &DMatrix<f64>, j_op: &DMatrix<f64>) -> usize {
    let jn = j_op * null_space(w, w.ncols());
    if jn.ncols() == 0 {
        return 0;
    }
    jn.svd(false, false).singular_values.iter().filter(|s| **s > 1e-9 * j_op.norm()).count()
}

/// Compiles `scene` (its q0 is the configuration under test), checks that the compiled closures allow the
/// same motions as the hand-written W, and returns, per OP, the count and Λ⁻¹ there.
fn counts(scene: &Scene, w: &DMatrix<f64>) -> Vec<(usize, Matrix3<f64>)> {
    let model: Model<Planar> = compile(scene);
    let mut data = Data::new(&model);
    forward_dynamics(&model, &mut data, &model.q0, &DVector::zeros(model.nv()), &mut ()).unwrap();
    let (compiled, hand) = (data.closure_jacobian(), w);
    assert!((&compiled * null_space(hand, model.nv())).amax() < 1e-12, "{}: W is not the scene's", model.name);
    assert!((hand * null_space(&compiled, model.nv())).amax() < 1e-12, "{}: W is not the scene's", model.name);
    (0..model.ops.len())
        .map(|op| {
            op_space_inertia(&model, &mut data, op).unwrap();
            let inverse = data.op.inverse_inertia;
            (constraint_directions::<Planar>(&inverse, model.length_scale, DEFAULT_THRESHOLD).count, inverse)
        })
        .collect()
}

/// The built-in slider-crank (crank 0.05 m, rod 0.15 m, slider on x; ops crank tip, slider) turned by
/// `tilt`, with the crank at `crank` from the slider's axis and the rod as the loop requires. Returns the
/// scene and its geometry: the crank pivot at the origin, the crank-rod joint, the slider's joint.
fn slider_crank(tilt: f64, crank: f64) -> (Scene, DMatrix<f64>, Geometry, [[f64; 2]; 2]) {
    let (a, b) = (0.05, 0.15);
    let rod = -(a * crank.sin() / b).asin();
    let s = a * crank.cos() + b * rod.cos();
    let mut scene = builtin_scene("slider-crank");
    scene.obstacles.clear();
    scene.joints[0].q0 = tilt + crank;
    scene.joints[1].q0 = rod - crank;
    scene.joints[2].q0 = s;
    scene.joints[2].axis = Some(vec![tilt.cos(), tilt.sin()]);
    let along = |x: f64, y: f64| [x * tilt.cos() - y * tilt.sin(), x * tilt.sin() + y * tilt.cos()];
    let elbow = along(a * crank.cos(), a * crank.sin());
    let geometry = Geometry(vec![
        (Joint::Revolute([0.0, 0.0]), None),
        (Joint::Revolute(elbow), Some(0)),
        (Joint::Prismatic(along(1.0, 0.0)), None),
    ]);
    let slider = along(s, 0.0);
    let w = geometry.pins(&[(Some(1), Some(2), slider)]);
    (scene, w, geometry, [elbow, slider])
}

/// At a dead centre (crank and rod in line with the slider's axis) the slider cannot move in any
/// direction: all three are constrained, whether the dead centre falls on exact numbers (the outer one,
/// untilted) or leaves round-off (the inner one, crank at π; tilted mechanisms), where Λ⁻¹ came out at
/// ~1e-31 of its open-loop value and read as one free direction. The crank tip keeps one motion.
#[test]
fn slider_at_a_dead_centre_is_immobile() {
    for (tilt, crank) in [(0.0, 0.0), (0.0, PI), (PI / 6.0, 0.0), (PI / 6.0, PI), (1.0, 0.0), (-2.0, PI)] {
        let (scene, w, geometry, [elbow, slider]) = slider_crank(tilt, crank);
        let case = format!("tilt {tilt:.3}, crank {crank:.3}");
        assert_eq!(mobility(&w, &geometry.jacobian(Some(2), slider)), 0, "{case}: the slider is pinned");
        assert_eq!(mobility(&w, &geometry.jacobian(Some(0), elbow)), 1, "{case}: the crank tip turns");
        let found = counts(&scene, &w);
        assert_eq!(found[1].0, 3, "{case}: slider, Λ⁻¹ = {}", found[1].1);
        assert_eq!(found[1].1, Matrix3::zeros(), "{case}: an immobile OP's Λ⁻¹ is zero");
        assert_eq!(found[0].0, 2, "{case}: crank tip");
    }
}

/// Off the dead centre the slider moves again (one free direction) as soon as its closed-loop mobility
/// exceeds `IMMOBILE_TOLERANCE` (1e-10) of its open-loop one: 1e-4 rad away it is already ~2e-8 of it.
#[test]
fn slider_just_off_a_dead_centre_is_mobile() {
    for crank in [1e-4, -1e-3, PI - 1e-4, 0.3] {
        let (scene, w, geometry, [_, slider]) = slider_crank(0.4, crank);
        assert_eq!(mobility(&w, &geometry.jacobian(Some(2), slider)), 1, "crank {crank}");
        let found = counts(&scene, &w);
        assert_eq!(found[1].0, 2, "crank {crank}: Λ⁻¹ = {}", found[1].1);
    }
}

/// A Grashof change-point four-bar (ground 0.3, crank 0.1, coupler 0.25, rocker 0.15: 0.1 + 0.3 = 0.25 +
/// 0.15) with every link on one line: the loop loses rank and the linkage two instantaneous motions. The
/// coupler's midpoint can move across the line and turn (one constraint, along the line); the rocker's
/// tip only turns with the rocker (two constraints).
#[test]
fn change_point_four_bar_frees_the_coupler() {
    let scene = Scene::from_toml_str(
        r#"
        name = "change-point-four-bar"
        kind = "planar"
        gravity = [0.0, 0.0]
        body = [
            { name = "crank", mass = 0.1, com = [-0.05, 0.0], inertia = 1e-4 },
            { name = "coupler", mass = 0.2, com = [0.125, 0.0], inertia = 1e-3 },
            { name = "rocker", mass = 0.15, com = [-0.075, 0.0], inertia = 3e-4 },
        ]
        joint = [
            { name = "crank", kind = "revolute", parent = "ground", child = "crank" },
            { name = "crank-coupler", kind = "revolute", parent = "crank", child = "coupler", origin = [-0.1, 0.0] },
            { name = "rocker", kind = "revolute", parent = "ground", child = "rocker", origin = [0.3, 0.0] },
        ]
        cut = [{ name = "coupler-rocker", kind = "pin", body_a = "coupler", point_a = [0.25, 0.0], body_b = "rocker", point_b = [-0.15, 0.0] }]
        op = [
            { name = "coupler-middle", body = "coupler", point = [0.125, 0.0] },
            { name = "rocker-tip", body = "rocker", point = [-0.15, 0.0] },
        ]
        "#,
        "change-point-four-bar",
    )
    .unwrap();
    // Crank from (0, 0) to (-0.1, 0), coupler to (0.15, 0), rocker back to its pivot at (0.3, 0).
    let geometry = Geometry(vec![
        (Joint::Revolute([0.0, 0.0]), None),
        (Joint::Revolute([-0.1, 0.0]), Some(0)),
        (Joint::Revolute([0.3, 0.0]), None),
    ]);
    let w = geometry.pins(&[(Some(1), Some(2), [0.15, 0.0])]);
    let expected = [
        3 - mobility(&w, &geometry.jacobian(Some(1), [0.025, 0.0])),
        3 - mobility(&w, &geometry.jacobian(Some(2), [0.15, 0.0])),
    ];
    assert_eq!(expected, [1, 2], "the geometry's own answer");
    let found: Vec<usize> = counts(&scene, &w).iter().map(|c| c.0).collect();
    assert_eq!(found, expected);
}

/// The built-in parallelogram (three cranks of 0.1 m on pivots at 0, 0.2 and 0.4 m, one coupler) folded
/// flat, every crank along the ground line: both closures lose their components along the line, and the
/// coupler's OP can move across the line and turn (the anti-parallelogram branch meets the parallelogram
/// one here): one constraint.
#[test]
fn parallelogram_folded_flat_frees_the_coupler() {
    let mut scene = builtin_scene("parallelogram");
    for joint in &mut scene.joints {
        joint.q0 = 0.0;
    }
    let geometry = Geometry(vec![
        (Joint::Revolute([0.0, 0.0]), None),
        (Joint::Revolute([0.1, 0.0]), Some(0)),
        (Joint::Revolute([0.2, 0.0]), None),
        (Joint::Revolute([0.4, 0.0]), None),
    ]);
    let w = geometry.pins(&[(Some(1), Some(2), [0.3, 0.0]), (Some(1), Some(3), [0.5, 0.0])]);
    let expected = 3 - mobility(&w, &geometry.jacobian(Some(1), [0.4, 0.0]));
    assert_eq!(expected, 1, "the geometry's own answer");
    assert_eq!(counts(&scene, &w)[0].0, expected);
}
