//! The simulated device plant against closed forms, its limits, and the simulated users.

use std::path::Path;
use std::time::Duration;

use kinloop_client::device::{
    DevicePreset, DeviceSpec, DeviceState, HapticDevice, SimulatedDevice, SimulatedDeviceParams, SimulatedRig,
};
use kinloop_client::user::{HandKind, HandSpec, Intent, PathSpec, ReplayedWrench, SimulatedUser, UserSpec};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind, math::space::Spatial};
use nalgebra::{UnitComplex, Vector2, Vector3, Vector6};

fn unit_spec(max_force: f64) -> DeviceSpec {
    DeviceSpec {
        name: "test handle".into(),
        dof: 3,
        kind: SceneKind::Planar,
        workspace_min: vec![-10.0, -10.0, -10.0],
        workspace_max: vec![10.0, 10.0, 10.0],
        max_force_n: max_force,
        continuous_force_n: max_force,
        max_torque_nm: max_force,
        max_stiffness: 1000.0,
        max_damping: 100.0,
        max_angular_stiffness: 10.0,
        max_angular_damping: 1.0,
        damping: vec![0.0; 3],
        native_rate_hz: 1000.0,
        has_force_sensor: true,
        has_presence_sensor: false,
        mass: vec![2.0, 2.0, 0.5],
    }
}

fn at_origin() -> OpPose<Planar> {
    OpPose { position: Vector2::zeros(), rotation: UnitComplex::identity() }
}

#[test]
fn a_free_mass_under_constant_force_follows_the_parabola() {
    let mut d =
        SimulatedDevice::<Planar>::new(unit_spec(100.0), &SimulatedDeviceParams::ideal(3), at_origin()).unwrap();
    d.set_command(&Vector3::new(1.0, -2.0, 0.0));
    let hand = Vector3::new(0.0, 0.0, 0.25);
    for _ in 0..1000 {
        d.advance(1e-3, &hand);
    }
    let t = 1.0;
    let expected = Vector2::new(0.5 * 1.0 / 2.0 * t * t, 0.5 * -2.0 / 2.0 * t * t);
    let error = (d.true_pose().position - expected).norm();
    // Semi-implicit Euler at 10 kHz: x_n = ½ a t² + ½ a h t, a relative error of h / t = 1e-4.
    assert!(error < 2e-4 * expected.norm(), "position error {error}");
    assert!((d.true_twist()[0] - 0.5).abs() < 1e-12, "velocity is exact");
    let angle = d.true_pose().rotation.angle();
    assert!((angle - 0.5 * 0.25 / 0.5).abs() < 1e-3, "angle {angle}");
}

#[test]
fn viscous_damping_gives_the_exponential_approach_to_terminal_velocity() {
    let mut params = SimulatedDeviceParams::ideal(3);
    params.damping = vec![4.0, 4.0, 0.0];
    let mut d = SimulatedDevice::<Planar>::new(unit_spec(100.0), &params, at_origin()).unwrap();
    d.set_command(&Vector3::new(2.0, 0.0, 0.0));
    for _ in 0..500 {
        d.advance(1e-3, &Vector3::zeros());
    }
    // v(t) = F/b (1 − e^{−b t / m}) with F = 2, b = 4, m = 2, t = 0.5.
    let expected = 0.5 * (1.0 - (-1.0f64).exp());
    assert!((d.true_twist()[0] - expected).abs() < 1e-4 * expected, "{} vs {expected}", d.true_twist()[0]);
}

#[test]
fn the_motors_saturate_and_the_walls_hold() {
    let mut spec = unit_spec(5.0);
    spec.workspace_min = vec![-0.1, -0.1, -10.0];
    spec.workspace_max = vec![0.1, 0.1, 10.0];
    let mut params = SimulatedDeviceParams::ideal(3);
    params.damping = vec![20.0, 20.0, 0.1];
    params.wall_stiffness = vec![5000.0, 5000.0, 0.0];
    params.wall_damping = vec![50.0, 50.0, 0.0];
    let mut d = SimulatedDevice::<Planar>::new(spec, &params, at_origin()).unwrap();
    d.set_command(&Vector3::new(30.0, 40.0, 0.0));
    assert!((d.applied_command() - Vector3::new(3.0, 4.0, 0.0)).norm() < 1e-9, "saturated, direction kept");
    for _ in 0..3000 {
        d.advance(1e-3, &Vector3::zeros());
    }
    // At rest against both walls: penetration = force / wall stiffness.
    let p = d.true_pose().position;
    assert!((p.x - (0.1 + 3.0 / 5000.0)).abs() < 1e-5 && (p.y - (0.1 + 4.0 / 5000.0)).abs() < 1e-5, "{p:?}");
}

#[test]
fn encoders_quantize_and_locked_axes_stay_put() {
    let mut falcon = DevicePreset::Falcon.build::<Planar>().unwrap();
    falcon.set_command(&Vector3::new(0.3, 0.0, 0.0));
    for _ in 0..50 {
        falcon.advance(1e-3, &Vector3::new(0.0, 0.0, 1.0));
    }
    let (pose, _) = falcon.sample();
    let counts = pose.position.x / 6e-5;
    assert!((counts - counts.round()).abs() < 1e-9, "reads whole encoder counts");
    assert_eq!(falcon.true_pose().rotation.angle(), 0.0, "the Falcon has no rotation: θ is locked");
    assert!(DevicePreset::Paper.build::<Spatial>().is_err(), "the paper's device is planar");
    let mut touch = DevicePreset::Touch.build::<Spatial>().unwrap();
    touch.set_command(&Vector6::new(0.0, 0.0, 1.0, 5.0, 0.0, 0.0));
    assert_eq!(touch.applied_command(), Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0), "no torque actuators");
}

#[test]
fn presets_and_users_parse_with_clear_errors() {
    assert_eq!("sim:paper".parse::<DevicePreset>().unwrap(), DevicePreset::Paper);
    let e = "sim:phantom".parse::<DevicePreset>().unwrap_err().to_string();
    assert!(e.contains("sim:falcon"), "{e}");
    assert!(matches!("constant:-0.5,0,-0.0025".parse::<UserSpec>().unwrap(), UserSpec::Constant(v) if v.len() == 3));
    for bad in ["constant:1,x", "path:line:0,0,1", "path:circle:-1,2", "path:waypoints:1", "wave:1", "replay:"] {
        assert!(bad.parse::<UserSpec>().is_err(), "{bad} should be refused");
    }
    for (name, kind) in
        [("soft", HandKind::Soft), ("firm", HandKind::Firm), ("release", HandKind::Release), ("poke", HandKind::Poke)]
    {
        assert_eq!(name.parse::<UserSpec>().unwrap(), UserSpec::Hand(HandSpec::touring(kind)));
    }
    assert!(matches!(
        "firm:circle:0.01,2".parse::<UserSpec>().unwrap(),
        UserSpec::Hand(HandSpec { kind: HandKind::Firm, intent: Intent::Path(_) })
    ));
    assert!(matches!("soft:hold".parse::<UserSpec>().unwrap(), UserSpec::Hand(HandSpec { intent: Intent::Hold, .. })));
    assert_eq!("paper".parse::<UserSpec>().unwrap(), UserSpec::paper());
    for bad in ["soft:circle:x", "tense", "firm:spiral:1"] {
        assert!(bad.parse::<UserSpec>().is_err(), "{bad} should be refused");
    }
    let err = match UserSpec::Constant(vec![1.0, 2.0]).build::<Planar>(&Default::default()) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("two values for a planar wrench"),
    };
    assert!(err.contains("3"), "{err}");
}

#[test]
fn a_path_hand_pulls_the_handle_along_the_path() {
    let spec: PathSpec = "line:0,0,0.02,0.01,0.5".parse().unwrap();
    assert_eq!(spec.offset(1.0), [0.02, 0.01]);
    assert_eq!(spec.offset(0.0), [0.0, 0.0]);
    let circle: PathSpec = "circle:0.01,1".parse().unwrap();
    let half = circle.offset(0.5);
    assert!((half[0] + 0.02).abs() < 1e-12 && half[1].abs() < 1e-12, "{half:?}");
    let waypoints: PathSpec = "waypoints:0.5:0.01,0;0.01,0.01".parse().unwrap();
    assert_eq!(waypoints.offset(0.5), [0.01, 0.0]);
    assert_eq!(waypoints.offset(3.0), [0.01, 0.01]);
    let user = UserSpec::Hand(HandSpec { kind: HandKind::Soft, intent: Intent::Path(spec) })
        .build::<Planar>(&Default::default())
        .unwrap();
    let device = DevicePreset::Paper.build::<Planar>().unwrap();
    let mut rig = SimulatedRig::new(device, user);
    let start = rig.true_pose().position;
    for k in 0..2000 {
        let now = Duration::from_millis(k);
        rig.read(now).unwrap();
        rig.command(now, &Vector3::zeros()).unwrap();
    }
    let moved = rig.true_pose().position - start;
    assert!((moved - Vector2::new(0.02, 0.01)).norm() < 1e-3, "the hand brought the handle to {moved:?}");
}

#[test]
fn a_replayed_wrench_is_interpolated_and_held() {
    let text = "time_s,hand_fx,hand_fy,hand_tz\n0,0,0,0\n1,1,-2,0.5\n";
    let mut replay = ReplayedWrench::<Planar>::parse(text, Path::new("inline.csv")).unwrap();
    assert!((replay.at(0.25) - Vector3::new(0.25, -0.5, 0.125)).norm() < 1e-12);
    assert_eq!(replay.at(5.0), Vector3::new(1.0, -2.0, 0.5));
    let state = DeviceState::<Planar> { pose: at_origin(), twist: Vector3::zeros(), hand_wrench: None, grasped: None };
    assert_eq!(replay.wrench(Duration::from_millis(500), &state), Vector3::new(0.5, -1.0, 0.25));
    for (bad, what) in [
        ("t,fx,fy\n0,1,2\n", "no column"),
        ("t,fx,fy,tz\n0,1,2,x\n", "not a finite number"),
        ("t,fx,fy,tz\n1,0,0,0\n0,0,0,0\n", "backwards"),
        ("t,fx,fy,tz\n", "no samples"),
    ] {
        let e = ReplayedWrench::<Planar>::parse(bad, Path::new("bad.csv")).unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
}
