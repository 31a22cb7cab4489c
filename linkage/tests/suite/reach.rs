//! The reach survey (`kinloop_linkage::algorithms::reach`) against independent computations: a crank-rocker's coupler
//! curve from circle intersections, a serial arm's static load from finite differences of its potential
//! energy, and the groups an OP does not move in.

use kinloop_linkage::algorithms::constraint_directions::ConstraintDirections;
use kinloop_linkage::algorithms::gravity::{kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::op_path::PathShape;
use kinloop_linkage::algorithms::reach::{pin_force, static_op_load, survey_op, SurveyConfig};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::model::builtin;
use kinloop_linkage::model::scene::OpSpec;
use kinloop_linkage::{math::space::Planar, model::data::Data, model::Model};
use nalgebra::{DMatrix, DVector, Vector2, Vector3};

fn planar(name: &str) -> Model<Planar> {
    let scene = builtin::scene(name).unwrap().unwrap();
    Model::compile(&scene, name).unwrap()
}

/// The crank-rocker's crank tip and coupler-rocker pin at crank angle `theta`, by circle intersection (crank
/// 0.1 m at the origin, coupler 0.25 m, rocker 0.2 m at (0.3, 0), the branch of q0, where the pin lies above
/// the line from the rocker's pivot to the crank's tip).
fn crank_rocker_joints(theta: f64) -> (Vector2<f64>, Vector2<f64>) {
    let (a, b, c, o2) = (0.1, 0.25, 0.2, Vector2::new(0.3, 0.0));
    let tip = Vector2::new(a * theta.cos(), a * theta.sin());
    let d = o2 - tip;
    let dist = d.norm();
    // The pin B: |B − tip| = b, |B − o2| = c.
    let along = (b * b - c * c + dist * dist) / (2.0 * dist);
    let across = (b * b - along * along).sqrt();
    let unit = d / dist;
    let normal = Vector2::new(-unit.y, unit.x);
    (tip, tip + unit * along + normal * across)
}

/// The crank angles of a full turn the analytic checks sample.
fn crank_turn() -> impl Iterator<Item = f64> {
    (0..3600).map(|k| std::f64::consts::TAU * k as f64 / 3600.0)
}

/// The crank-rocker's coupler midpoint over a full crank turn ([`crank_rocker_joints`]).
fn coupler_curve() -> Vec<Vector2<f64>> {
    crank_turn()
        .map(|theta| {
            let (tip, pin) = crank_rocker_joints(theta);
            (tip + pin) * 0.5
        })
        .collect()
}

#[test]
fn the_crank_rockers_coupler_reach_is_its_coupler_curve() {
    let model = planar("fourbar-crank-rocker");
    let op = model.op_index("coupler").unwrap();
    let reach = survey_op(&model, op, &SurveyConfig::default()).unwrap();
    let curve = coupler_curve();
    let (mut lo, mut hi) = (Vector2::repeat(f64::INFINITY), Vector2::repeat(f64::NEG_INFINITY));
    for p in &curve {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    // The branch check: q0's coupler point is on the curve.
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &model.q0);
    let start = OpPose::<Planar>::of_op(&model, &data, op).position;
    let nearest = curve.iter().map(|p| (p - start).norm()).fold(f64::INFINITY, f64::min);
    assert!(nearest < 1e-4, "q0's coupler point is {nearest} m off the analytic curve");
    // The survey walks in steps of 0.04 rad: its box is the curve's within a step's travel.
    for axis in 0..2 {
        assert!(
            (reach.position_min[axis] - lo[axis]).abs() < 2e-3,
            "min {axis}: {} vs {}",
            reach.position_min[axis],
            lo[axis]
        );
        assert!(
            (reach.position_max[axis] - hi[axis]).abs() < 2e-3,
            "max {axis}: {} vs {}",
            reach.position_max[axis],
            hi[axis]
        );
    }
    assert_eq!(reach.dof, 1);
    // Every tour waypoint lies on the curve (a closed configuration), and the tour goes around it.
    assert!(reach.tour.len() >= 12, "{} waypoints", reach.tour.len());
    for w in &reach.tour {
        let off = curve.iter().map(|p| (p - w.position).norm()).fold(f64::INFINITY, f64::min);
        assert!(off < 1e-4, "a waypoint {off} m off the curve");
    }
    let spread = reach.tour.iter().map(|w| (w.position - reach.tour[0].position).norm()).fold(0.0, f64::max);
    assert!(spread > 0.5 * reach.largest_extent(), "the tour spans {spread} m of {} m", reach.largest_extent());
}

/// G = ∂V/∂q by central differences of the potential energy.
fn gravity_by_differences(model: &Model<Planar>, q: &DVector<f64>) -> DVector<f64> {
    let mut data = Data::new(model);
    let mut v = |q: &DVector<f64>| {
        forward_kinematics(model, &mut data, q);
        potential_energy(model, &data, q)
    };
    let h = 1e-6;
    DVector::from_fn(q.len(), |i, _| {
        let (mut up, mut down) = (q.clone(), q.clone());
        up[i] += h;
        down[i] -= h;
        (v(&up) - v(&down)) / (2.0 * h)
    })
}

/// The OP's Jacobian (x, y, θ) by central differences of its pose.
fn jacobian_by_differences(model: &Model<Planar>, q: &DVector<f64>, op: usize) -> DMatrix<f64> {
    let mut data = Data::new(model);
    let mut pose = |q: &DVector<f64>| {
        forward_kinematics(model, &mut data, q);
        OpPose::<Planar>::of_op(model, &data, op)
    };
    let h = 1e-7;
    let mut j = DMatrix::zeros(3, q.len());
    for i in 0..q.len() {
        let (mut up, mut down) = (q.clone(), q.clone());
        up[i] += h;
        down[i] -= h;
        let d = pose(&up).difference(&pose(&down)) / (2.0 * h);
        j.set_column(i, &d);
    }
    j
}

/// A four-bar's one motion at `q`: the null direction of the closure Jacobian W = ∂h/∂q, W by central
/// differences of the loop residual. W is 2×3 (a pin closes the loop of three joints), so the direction is its
/// rows' cross product.
fn four_bar_motion_by_differences(model: &Model<Planar>, q: &DVector<f64>) -> DVector<f64> {
    let mut data = Data::new(model);
    let mut residual = |q: &DVector<f64>| {
        forward_kinematics(model, &mut data, q);
        kinloop_linkage::algorithms::loop_closure::loop_closure(model, &mut data);
        data.closure_residual.clone()
    };
    let h = 1e-7;
    let mut w = DMatrix::zeros(model.nc(), model.nv());
    for i in 0..model.nv() {
        let (mut up, mut down) = (q.clone(), q.clone());
        up[i] += h;
        down[i] -= h;
        w.set_column(i, &((residual(&up) - residual(&down)) / (2.0 * h)));
    }
    let row = |r: usize| Vector3::from_iterator(w.row(r).iter().copied());
    DVector::from_column_slice(row(0).cross(&row(1)).normalize().as_slice())
}

/// A configuration q the OP is held still in, its static load there and its directions.
type Hold = (DVector<f64>, Vector3<f64>, ConstraintDirections<Planar>);

/// The crank-rocker's coupler held at rest at q0 and with the crank turned 2 rad: the model, the OP, and the
/// two holds.
fn crank_rocker_coupler_holds() -> (Model<Planar>, usize, Vec<Hold>) {
    let model = planar("fourbar-crank-rocker");
    let op = model.op_index("coupler").unwrap();
    let at_rest = DVector::zeros(model.nv());
    let mut data = Data::new(&model);
    let mut turned = model.q0.clone();
    turned[0] += 2.0;
    let turned = kinloop_linkage::algorithms::assemble::assemble(&model, &turned, 1e-13).unwrap().q;
    let holds = [model.q0.clone(), turned]
        .into_iter()
        .map(|q| {
            let (load, directions) = static_op_load(&model, &mut data, &q, &at_rest, op).unwrap();
            (q, load, directions)
        })
        .collect();
    (model, op, holds)
}

#[test]
fn a_four_bars_static_load_does_the_work_gravity_does_along_its_motion() {
    // Along the mechanism's one motion n (the null space of the closure Jacobian W = ∂h/∂q), a wrench F at
    // the coupler holds the linkage still when its virtual work balances gravity's: Fᵀ J n = Gᵀ n. G, J and W
    // all come from finite differences here (of the potential energy, the coupler's pose, the loop residual).
    let (model, op, holds) = crank_rocker_coupler_holds();
    for (q, load, directions) in holds {
        assert_eq!(directions.count, 2, "a 1-DOF linkage's coupler is free in one direction");
        let n = four_bar_motion_by_differences(&model, &q);
        let j = jacobian_by_differences(&model, &q, op);
        let g = gravity_by_differences(&model, &q);
        let work_load = (j.transpose() * DVector::from_column_slice(load.as_slice())).dot(&n);
        let work_gravity = g.dot(&n);
        assert!(work_gravity.abs() > 0.1, "gravity does work along the motion: {work_gravity}");
        assert!((work_load - work_gravity).abs() < 1e-5 * work_gravity.abs(), "{work_load} vs {work_gravity}");
    }
}

#[test]
fn a_grasp_without_torque_holds_the_four_bar_with_the_least_force_that_does_gravitys_work() {
    // Through a pin (no torque) a force f at the coupler holds the linkage when fᵀ J_lin n = Gᵀ n along its
    // one motion n; the least such force is |Gᵀ n| / |J_lin n|, J_lin the coupler's linear rows. G, J and n
    // come from finite differences, as above. The least wrench shares the load with a torque, so the pin's
    // force is larger than its force part where the coupler turns as it moves.
    let (model, op, holds) = crank_rocker_coupler_holds();
    for (q, load, directions) in holds {
        let n = four_bar_motion_by_differences(&model, &q);
        let j = jacobian_by_differences(&model, &q, op);
        let moved = (j.rows(0, 2) * &n).norm();
        let expected = gravity_by_differences(&model, &q).dot(&n).abs() / moved;
        let pinned = pin_force(&directions, &load);
        assert!((pinned - expected).abs() < 1e-5 * expected, "{pinned} N vs {expected} N");
        let force_part = Vector2::new(load[0], load[1]).norm();
        assert!(pinned > force_part, "{pinned} N through the pin, {force_part} N the least wrench's force");
    }
}

#[test]
fn a_translating_coupler_has_no_rotational_mobility_and_a_turning_crank_has_both() {
    let model = planar("parallelogram");
    let reach = survey_op(&model, model.op_index("coupler").unwrap(), &SurveyConfig::default()).unwrap();
    assert_eq!(reach.inverse_rotational_inertia_max, 0.0, "the parallelogram's coupler never turns");
    assert!(reach.rotation_range < 1e-6 && reach.inverse_mass_max > 0.0);
    let model = planar("fourbar-crank-rocker");
    let reach = survey_op(&model, model.op_index("crank-tip").unwrap(), &SurveyConfig::default()).unwrap();
    assert!(reach.inverse_rotational_inertia_max > 0.0 && reach.inverse_mass_max > 0.0);
    assert!(reach.rotation_range > 3.0, "the crank turns all the way round: {}", reach.rotation_range);
}

/// The slider-crank's wall stops the survey as it stops the linkage: by closed form (crank 0.05 m, rod
/// 0.15 m, slider on the x axis, x = r cos θ + √(l² − r² sin² θ)), the slider's ball (radius 0.01 m) meets
/// the wall at x = 0.195 m, with the crank within about 22° of its outer dead centre. No tour waypoint puts
/// the slider in the wall, and the walks come within a step of it (crank tip's x, the reach's largest, at
/// the crank angle where the ball touches). Before the survey knew of obstacles, its tour crossed the outer
/// dead centre, and a hand following it pressed into the wall until the device saturated.
#[test]
fn the_slider_cranks_survey_turns_back_at_its_wall() {
    let model = planar("slider-crank");
    let op = model.op_index("crank-tip").unwrap();
    let reach = survey_op(&model, op, &SurveyConfig::default()).unwrap();
    let (r, l, wall) = (0.05_f64, 0.15_f64, 0.205 - 0.01);
    let slider_x = |theta: f64| r * theta.cos() + (l * l - (r * theta.sin()).powi(2)).sqrt();
    assert!(!reach.tour.is_empty());
    for pose in &reach.tour {
        let theta = pose.position.y.atan2(pose.position.x);
        assert!(slider_x(theta) <= wall + 1e-9, "a waypoint at {:.1}° puts the slider in the wall", theta.to_degrees());
    }
    // Where the ball touches: the crank angle with slider_x = wall, by bisection on [0, π/2].
    let (mut lo, mut hi) = (0.0_f64, std::f64::consts::FRAC_PI_2);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if slider_x(mid) > wall {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let touching_x = r * hi.cos();
    // Beyond the wall the crank tip's x would reach r; the survey's stops where the ball touches, within a
    // step of 0.04 rad of crank.
    assert!(reach.position_max.x <= touching_x + 1e-9, "{} > {touching_x}", reach.position_max.x);
    assert!(reach.position_max.x > r * (hi + 0.04).cos(), "{} stops short of the wall", reach.position_max.x);
}

/// The crank-rocker's coupler path (`OpReach::path`): one closed lap of the analytic coupler curve, every
/// pose on it and all of it within a step of the path; a 2-DOF linkage has no path.
#[test]
fn the_crank_rockers_coupler_path_is_one_lap_of_its_coupler_curve() {
    let model = planar("fourbar-crank-rocker");
    let reach = survey_op(&model, model.op_index("coupler").unwrap(), &SurveyConfig::default()).unwrap();
    let path = reach.path.expect("a 1-DOF linkage has a path");
    assert!(path.is_closed(), "the crank turns all the way round");
    let curve = coupler_curve();
    let to_curve = |p: &Vector2<f64>| curve.iter().map(|c| (c - p).norm()).fold(f64::INFINITY, f64::min);
    // The analytic samples are 0.14 mm apart at most: a pose on the curve is within half of that.
    for pose in path.poses() {
        assert!(to_curve(&pose.position) < 1e-4, "a path pose is {} m off the curve", to_curve(&pose.position));
    }
    // All the curve, and only one lap: each analytic point is near the path, and the path is no longer than
    // the curve.
    let positions: Vec<Vector2<f64>> = path.poses().iter().map(|p| p.position).collect();
    for c in curve.iter().step_by(10) {
        let gap = positions.iter().map(|p| (p - c).norm()).fold(f64::INFINITY, f64::min);
        assert!(gap < 3e-3, "the path misses the curve by {gap} m");
    }
    let length = |ps: &[Vector2<f64>]| ps.windows(2).map(|w| (w[1] - w[0]).norm()).sum::<f64>();
    let (path_length, curve_length) = (length(&positions), length(&curve));
    assert!(path_length < curve_length && path_length > 0.97 * curve_length, "{path_length} vs {curve_length}");
    let testbed = planar("paper-testbed");
    let reach = survey_op(&testbed, testbed.op_index("link2").unwrap(), &SurveyConfig::default()).unwrap();
    assert_eq!((reach.dof, reach.path.is_some()), (2, false));
    // The Watt six-bar's link5 swings forth and back while its crank turns round: one pose of link5 is two
    // configurations (its walk passes each pose twice, going opposite ways), so its path is one swing.
    let six_bar = planar("watt-six-bar");
    let reach = survey_op(&six_bar, six_bar.op_index("link5").unwrap(), &SurveyConfig::default()).unwrap();
    assert_eq!((reach.dof, reach.path.map(|p| p.shape())), (1, Some(PathShape::Swing)));
    let reach = survey_op(&six_bar, six_bar.op_index("coupler").unwrap(), &SurveyConfig::default()).unwrap();
    assert!(reach.path.is_some_and(|p| p.is_closed()), "the six-bar's coupler goes round");
}

/// The crank-rocker's rocker tip (the coupler-rocker pin) swings on its circle about the rocker's pivot while
/// the crank turns round: its path is one swing (`PathShape::Swing`), limit to limit, without forces at rest.
/// Against the circle intersection: every pose on the circle, the rocker's angle monotone along the swing,
/// and the swing's ends at the extremes of the rocker's angle over a crank turn.
#[test]
fn the_crank_rockers_rocker_tip_path_is_one_swing_between_the_rockers_limits() {
    let mut scene = builtin::scene("fourbar-crank-rocker").unwrap().unwrap();
    scene.ops.push(OpSpec { name: "rocker-tip".into(), body: "rocker".into(), point: vec![0.2, 0.0] });
    let model = Model::<Planar>::compile(&scene, "fourbar-crank-rocker").unwrap();
    let reach = survey_op(&model, model.op_index("rocker-tip").unwrap(), &SurveyConfig::default()).unwrap();
    let path = reach.path.expect("the rocker's tip has a swing");
    assert_eq!(path.shape(), PathShape::Swing);
    assert!(path.rest_acceleration().is_none(), "a pose of the swing is two configurations");
    let o2 = Vector2::new(0.3, 0.0);
    let angle = |p: &Vector2<f64>| (p.y - o2.y).atan2(p.x - o2.x);
    // The pin over a crank turn (the coupler midpoint is halfway between the crank's tip and the pin).
    let (a, b) = (0.1, 0.25);
    let pins: Vec<f64> = (0..3600)
        .map(|k| {
            let theta = std::f64::consts::TAU * k as f64 / 3600.0;
            let tip = Vector2::new(a * theta.cos(), a * theta.sin());
            let (d, c) = (o2 - tip, 0.2);
            let (dist, unit) = (d.norm(), d.normalize());
            let along = (b * b - c * c + dist * dist) / (2.0 * dist);
            angle(&(tip + unit * along + Vector2::new(-unit.y, unit.x) * (b * b - along * along).sqrt()))
        })
        .collect();
    let (lo, hi) = pins.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(*p), h.max(*p)));
    let angles: Vec<f64> = path.poses().iter().map(|p| angle(&p.position)).collect();
    for p in path.poses() {
        assert!(((p.position - o2).norm() - 0.2).abs() < 1e-9, "a swing pose off the rocker's circle: {p:?}");
    }
    let rising = angles[1] > angles[0];
    assert!(angles.windows(2).all(|w| (w[1] > w[0]) == rising), "the rocker's angle is monotone along the swing");
    let (first, last) = (angles[0], angles[angles.len() - 1]);
    let (start, end) = if rising { (first, last) } else { (last, first) };
    assert!((start - lo).abs() < 2e-3 && (end - hi).abs() < 2e-3, "[{start}, {end}] against [{lo}, {hi}]");
}

/// The path's acceleration at rest against a second formulation: at configurations assembled from crank
/// angles, the reduced dynamics along the one motion n (null space of W by differences), q̈ = −n (nᵀG) / (nᵀDn)
/// with G = ∂V/∂q by differences of the potential energy and nᵀDn = 2 T(q̇ = n) from the kinetic energy,
/// maps to the coupler as J q̈ (J by differences; at rest J̇q̇ and Ẇq̇ vanish). The path, interpolated
/// between its samples, gives the same vector.
#[test]
fn the_coupler_paths_acceleration_at_rest_is_the_reduced_dynamics_under_gravity() {
    let model = planar("fourbar-crank-rocker");
    let op = model.op_index("coupler").unwrap();
    let path = survey_op(&model, op, &SurveyConfig::default()).unwrap().path.unwrap();
    let mut data = Data::new(&model);
    // Turned from q0 in small steps, each assembled from the last, so it stays on q0's branch.
    let mut q = model.q0.clone();
    for turn in [0.3, 1.2, 2.0, 3.5, 5.0] {
        let target = model.q0[0] + turn;
        while q[0] < target {
            q[0] = (q[0] + 0.05).min(target);
            q = kinloop_linkage::algorithms::assemble::assemble(&model, &q, 1e-13).unwrap().q;
        }
        let n = four_bar_motion_by_differences(&model, &q);
        forward_kinematics(&model, &mut data, &q);
        kinloop_linkage::algorithms::kinematics::forward_velocity(&model, &mut data, &n);
        let mass_along = 2.0 * kinetic_energy(&model, &data);
        let g = gravity_by_differences(&model, &q);
        let qdd = &n * (-g.dot(&n) / mass_along);
        let expected = jacobian_by_differences(&model, &q, op) * qdd;
        forward_kinematics(&model, &mut data, &q);
        let on = path.nearest(&OpPose::<Planar>::of_op(&model, &data, op), None);
        // Within the chords' sagitta of the curve (steps of a few mm).
        assert!(on.distance < 1e-4, "the configuration is on the path ({} m off)", on.distance);
        let got = Vector3::from_column_slice(on.rest_acceleration.expect("a coupler curve has them").as_slice());
        let expected = Vector3::from_column_slice(expected.as_slice());
        assert!(expected.norm() > 0.01, "gravity moves the coupler here: {expected:?}");
        assert!((got - expected).norm() < 0.02 * expected.norm(), "crank turned {turn} rad: {got:?} vs {expected:?}");
    }
}

/// `q` carried to crank angle `target` in steps of at most 0.05 rad, each assembled from the last (q's branch).
fn crank_at(model: &Model<Planar>, q: &DVector<f64>, target: f64) -> DVector<f64> {
    let mut q = q.clone();
    while (target - q[0]).abs() > 1e-12 {
        q[0] += (target - q[0]).clamp(-0.05, 0.05);
        q = kinloop_linkage::algorithms::assemble::assemble(model, &q, 1e-13).unwrap().q;
    }
    q
}

/// The crank-rocker's coupler at `q` along its motion n (`four_bar_motion_by_differences`), with energies and
/// poses alone: the inertia along the path's unit tangent in unit-consistent coordinates, `nᵀDn / |J̃n|²`
/// (twice the kinetic energy at q̇ = n over the OP's scaled speed squared), the force at rest along it,
/// `−Gᵀn / |J̃n|` (G by differences of the potential energy), and the pose.
fn coupler_mode_by_energies(model: &Model<Planar>, q: &DVector<f64>, op: usize) -> (f64, f64, OpPose<Planar>) {
    let n = four_bar_motion_by_differences(model, q);
    let twist = jacobian_by_differences(model, q, op) * &n;
    let speed = Vector3::new(twist[0], twist[1], model.length_scale * twist[2]).norm();
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    kinloop_linkage::algorithms::kinematics::forward_velocity(model, &mut data, &n);
    let mass = 2.0 * kinetic_energy(model, &data) / (speed * speed);
    let force = -gravity_by_differences(model, q).dot(&n) / speed;
    // The force's sign follows n's, which the arc's below follows too; the stiffness does not depend on it.
    let sign = if n[0] < 0.0 { -1.0 } else { 1.0 };
    (mass, sign * force, OpPose::<Planar>::of_op(model, &data, op))
}

/// The coupler path's modes (`OpReach::path_modes`, from the survey's Λ̃⁻¹ and its accelerations at rest)
/// against the reduced dynamics from energies: the inertia along the path, and the stiffness of gravity along
/// it, `−dF/ds̃`, by differences of the force at rest between configurations 0.02 rad of crank either side,
/// over the scaled chord between their poses.
#[test]
fn the_coupler_paths_modes_are_its_inertia_and_gravitys_stiffness_along_it() {
    let model = planar("fourbar-crank-rocker");
    let op = model.op_index("coupler").unwrap();
    let reach = survey_op(&model, op, &SurveyConfig::default()).unwrap();
    let (path, modes) = (reach.path.unwrap(), reach.path_modes);
    assert_eq!(modes.len(), path.poses().len(), "one mode per pose");
    let scaled = |a: &OpPose<Planar>, b: &OpPose<Planar>| {
        let d = a.difference(b);
        Vector3::new(d[0], d[1], model.length_scale * d[2]).norm()
    };
    let mut q = model.q0.clone();
    let (delta, mut stiffest) = (0.02, 0.0_f64);
    let mut checked = Vec::new();
    for turn in [0.3, 1.2, 2.0, 3.5, 5.0] {
        let target = model.q0[0] + turn;
        q = crank_at(&model, &q, target);
        let (mass, _, pose) = coupler_mode_by_energies(&model, &q, op);
        let (_, before, at_before) = coupler_mode_by_energies(&model, &crank_at(&model, &q, target - delta), op);
        let (_, after, at_after) = coupler_mode_by_energies(&model, &crank_at(&model, &q, target + delta), op);
        let stiffness = -(after - before) / scaled(&at_after, &at_before);
        let on = path.nearest(&pose, None);
        let n = path.poses().len();
        let next = (on.segment + 1) % n;
        let k = if scaled(&pose, &path.poses()[on.segment]) <= scaled(&pose, &path.poses()[next]) {
            on.segment
        } else {
            next
        };
        stiffest = stiffest.max(stiffness.abs());
        checked.push((turn, mass, stiffness, modes[k]));
    }
    assert!(stiffest > 100.0, "gravity holds the coupler stiffly somewhere: {stiffest} N/m");
    for (turn, mass, stiffness, mode) in checked {
        assert!((mode.mass - mass).abs() < 0.005 * mass, "crank turned {turn} rad: {} kg vs {mass} kg", mode.mass);
        assert!(
            (mode.rest_stiffness - stiffness).abs() < 0.02 * stiffest,
            "crank turned {turn} rad: {} N/m vs {stiffness} N/m",
            mode.rest_stiffness
        );
    }
}

/// The coupler midpoint's turning radius over a full crank turn: its distance from the coupler's instant centre,
/// where the crank's line (from its pivot at the origin through its tip) meets the rocker's (from its pivot at
/// (0.3, 0) through the pin), by Cramer's rule.
fn coupler_turning_radii() -> Vec<f64> {
    let o2 = Vector2::new(0.3, 0.0);
    crank_turn()
        .map(|theta| {
            let (tip, pin) = crank_rocker_joints(theta);
            // s tip = o2 + t (pin − o2): two equations in s and t.
            let rocker = pin - o2;
            let det = tip.x * -rocker.y + rocker.x * tip.y;
            let s = (o2.x * -rocker.y + rocker.x * o2.y) / det;
            ((tip + pin) * 0.5 - tip * s).norm()
        })
        .collect()
}

/// The survey's smallest turning radius (`OpReach::turning_radius_min_m`) against closed forms: a crank's tip
/// turns about the crank's pivot at the crank's length at every pose (the crank-rocker's 0.1 m, the
/// slider-crank's 0.05 m); the crank-rocker's coupler midpoint is nearest its instant centre (the crossing of
/// the crank's and the rocker's lines) at the analytic minimum over a crank turn, which the survey, sampling
/// real poses every few steps, meets from above within its sampling; the parallelogram's coupler never turns.
#[test]
fn the_smallest_turning_radius_is_the_distance_to_the_instant_centre() {
    let radius = |scene: &str, op: &str| {
        let model = planar(scene);
        survey_op(&model, model.op_index(op).unwrap(), &SurveyConfig::default()).unwrap().turning_radius_min_m
    };
    for (scene, length) in [("fourbar-crank-rocker", 0.1), ("slider-crank", 0.05)] {
        let r = radius(scene, "crank-tip");
        assert!((r - length).abs() < 1e-9 * length, "{scene}'s crank tip: {r} m");
    }
    let exact = coupler_turning_radii().into_iter().fold(f64::INFINITY, f64::min);
    let r = radius("fourbar-crank-rocker", "coupler");
    assert!(r >= exact * (1.0 - 1e-9) && r < exact * 1.01, "the coupler's {r} m against {exact} m");
    assert_eq!(radius("parallelogram", "coupler"), f64::INFINITY);
}
