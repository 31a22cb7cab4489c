//! The simulated hand against closed forms: a mass-spring-damper on the handle, its release, its poke, and
//! its tour of the waypoints it is given.

use std::time::Duration;

use kinloop_client::device::HapticDevice;
use kinloop_client::device::{DevicePreset, DeviceSpec, SimulatedDevice, SimulatedDeviceParams, SimulatedRig};
use kinloop_client::user::hand::{POKE_AT_S, POKE_DURATION_S, POKE_STEP_M, RELEASE_AT_S};
use kinloop_client::user::hand::{TOUR_PUSH_EASE_N, TOUR_PUSH_STALL_N, TOUR_STALL_S};
use kinloop_client::user::{HandImpedance, HandKind, HandSpec, Intent, UserContext, UserSpec};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind};
use nalgebra::{UnitComplex, Vector2, Vector3};

/// A frictionless, undamped handle of `mass` kg per linear axis (and a heavy one in θ), no walls in reach.
fn ideal_device(mass: f64) -> SimulatedDevice<Planar> {
    let spec = DeviceSpec {
        mass: vec![mass, mass, 1.0],
        workspace_min: vec![-10.0, -10.0, -100.0],
        workspace_max: vec![10.0, 10.0, 100.0],
        ..DevicePreset::Paper.spec(SceneKind::Planar).unwrap()
    };
    let start = OpPose { position: Vector2::zeros(), rotation: UnitComplex::identity() };
    SimulatedDevice::new(spec, &SimulatedDeviceParams::ideal(3), start).unwrap()
}

fn rig(kind: HandKind, intent: Intent, tour: Vec<Vector3<f64>>, mass: f64) -> SimulatedRig<Planar> {
    let user = UserSpec::Hand(HandSpec { kind, intent }).build::<Planar>(&UserContext { tour }).unwrap();
    SimulatedRig::new(ideal_device(mass), user)
}

/// Runs the rig at 1 kHz with a constant `command` until `seconds`, calling `each` after every read.
fn run(
    rig: &mut SimulatedRig<Planar>,
    seconds: f64,
    command: Vector3<f64>,
    mut each: impl FnMut(f64, &SimulatedRig<Planar>),
) {
    for k in 0..=(seconds * 1000.0) as u64 {
        let now = Duration::from_millis(k);
        rig.read(now).unwrap();
        rig.command(now, &command).unwrap();
        each(k as f64 * 1e-3, rig);
    }
}

#[test]
fn a_held_handle_under_a_force_step_moves_as_the_hand_mass_spring_damper_says() {
    // Hand of mass m_h, damping b, stiffness k on a handle of mass m_d, holding still; a step force F on
    // the handle. Closed form of the second-order step: x(t) = F/k (1 − e^{−ζω t}(cos ω_d t + ζ/√(1−ζ²)
    // sin ω_d t)), ω = √(k/(m_d + m_h)), ζ = b / (2 √(k (m_d + m_h))).
    let hand = HandImpedance::soft();
    let (m_d, f) = (0.2, 0.5);
    let m = m_d + hand.mass;
    let omega = (hand.stiffness / m).sqrt();
    let zeta = hand.damping / (2.0 * (hand.stiffness * m).sqrt());
    let omega_d = omega * (1.0 - zeta * zeta).sqrt();
    let expected = |t: f64| {
        f / hand.stiffness
            * (1.0
                - (-zeta * omega * t).exp()
                    * ((omega_d * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (omega_d * t).sin()))
    };
    let mut rig = rig(HandKind::Soft, Intent::Hold, Vec::new(), m_d);
    let mut worst: f64 = 0.0;
    run(&mut rig, 2.0, Vector3::new(f, 0.0, 0.0), |t, rig| {
        worst = worst.max((rig.true_pose().position.x - expected(t)).abs());
    });
    // The hand's wrench is held over each 1 ms tick: a small phase error against the continuous form.
    assert!(worst < 0.03 * f / hand.stiffness, "largest error {worst} m against a travel of {} m", f / hand.stiffness);
}

#[test]
fn a_released_handle_feels_no_hand_and_carries_no_hand_mass() {
    let (m_d, f) = (0.2, 0.3);
    let mut rig = rig(HandKind::Release, Intent::Hold, Vec::new(), m_d);
    let (mut at_release, mut velocity_at_release) = (0.0, 0.0);
    run(&mut rig, RELEASE_AT_S + 0.5, Vector3::new(f, 0.0, 0.0), |t, rig| {
        if (t - RELEASE_AT_S).abs() < 5e-4 {
            at_release = rig.true_pose().position.x;
            velocity_at_release = rig.device().true_twist().x;
        }
        if t > RELEASE_AT_S {
            assert_eq!(rig.hand_wrench(), Vector3::zeros(), "the hand let go at {t}");
        }
    });
    // Free flight of the handle alone: x = x₀ + v₀ t + ½ (F/m_d) t².
    let t = 0.5;
    let free = at_release + velocity_at_release * t + 0.5 * f / m_d * t * t;
    let x = rig.true_pose().position.x;
    assert!((x - free).abs() < 0.01 * (free - at_release), "handle at {x}, free flight predicts {free}");
}

#[test]
fn a_poke_steps_the_hand_force_by_its_stiffness_times_the_step() {
    let hand = HandImpedance::firm();
    let mut rig = rig(HandKind::Poke, Intent::Hold, Vec::new(), 1e3);
    let mut before = Vector3::zeros();
    let mut during = Vector3::zeros();
    run(&mut rig, POKE_AT_S + POKE_DURATION_S + 0.2, Vector3::zeros(), |t, rig| {
        if (t - (POKE_AT_S - 0.01)).abs() < 5e-4 {
            before = rig.hand_wrench();
        }
        if (t - (POKE_AT_S + 0.05)).abs() < 5e-4 {
            during = rig.hand_wrench();
        }
    });
    // The 1000 kg handle barely moves: the jump is the hand's spring on the step.
    let jump = during.x - before.x;
    assert!((jump - hand.stiffness * POKE_STEP_M).abs() < 0.05 * hand.stiffness * POKE_STEP_M, "jump {jump} N");
    assert!(
        rig.hand_wrench().x.abs() < 0.1 * hand.stiffness * POKE_STEP_M,
        "the poke is over: {:?}",
        rig.hand_wrench()
    );
}

#[test]
fn a_touring_hand_takes_a_free_handle_through_every_waypoint_and_back() {
    let waypoints: Vec<Vector3<f64>> =
        vec![Vector3::new(0.02, 0.0, 0.0), Vector3::new(0.02, 0.02, 0.0), Vector3::new(-0.01, 0.02, 0.0)];
    let mut rig = rig(HandKind::Firm, Intent::Tour, waypoints.clone(), 0.1);
    let mut closest = vec![f64::INFINITY; waypoints.len()];
    let mut back_home = f64::INFINITY;
    run(&mut rig, 8.0, Vector3::zeros(), |t, rig| {
        let p = rig.true_pose().position;
        for (c, w) in closest.iter_mut().zip(&waypoints) {
            *c = c.min((p - w.xy()).norm());
        }
        if t > 4.0 {
            back_home = back_home.min((p - waypoints[0].xy()).norm());
        }
    });
    for (i, c) in closest.iter().enumerate() {
        assert!(*c < 1e-3, "waypoint {i} missed by {c} m");
    }
    assert!(back_home < 1e-3, "the tour comes back to its first waypoint ({back_home} m)");
}

/// A tour that leads past a wall the handle cannot pass (a linkage that jams, or turned where the waypoints
/// did not): the waypoint lies 5 cm beyond a wall 1 cm from the grasp, a stiff spring the device renders. The
/// soft hand, which tours by feel, presses on the wall, moving its intention on only while the pull stays
/// below [`TOUR_PUSH_STALL_N`], and never pulls harder than that (within the handle's settling, 5 %) once it
/// stands at rest against the wall; stopped for [`TOUR_STALL_S`], it turns back and takes the handle home to
/// its grasp, setting out without a jump of its wrench (its pace grows, as a person's would, over a fifth of
/// a second: at once, its wrench would jump by half a newton). The firm hand pushes on into the wall.
#[test]
fn a_touring_hand_stops_at_a_handle_that_will_not_come_and_turns_back() {
    let (wall_m, wall_n_per_m) = (0.01, 3000.0);
    let waypoints = vec![Vector3::new(0.06, 0.0, 0.0), Vector3::new(0.06, 0.001, 0.0)];
    for kind in [HandKind::Soft, HandKind::Firm] {
        assert_eq!(kind.tours_by_feel(), kind == HandKind::Soft);
        let mut rig = rig(kind, Intent::Tour, waypoints.clone(), 0.1);
        let (mut pressed, mut at_rest_max, mut stood_s, mut home_after) = (0.0f64, 0.0f64, 0.0, None);
        let (mut last_wrench, mut turn_jump) = (None, 0.0f64);
        for k in 0..12_000u64 {
            let (now, t) = (Duration::from_millis(k), k as f64 * 1e-3);
            rig.read(now).unwrap();
            let x = rig.true_pose().position.x;
            rig.command(now, &Vector3::new(-wall_n_per_m * (x - wall_m).max(0.0), 0.0, 0.0)).unwrap();
            let wrench = rig.hand_wrench().xy();
            let pull = wrench.norm();
            // Setting out home: from rest at the wall until the handle leaves it.
            if stood_s > TOUR_STALL_S && x > wall_m {
                turn_jump =
                    last_wrench.map_or(turn_jump, |w: nalgebra::Vector2<f64>| turn_jump.max((wrench - w).norm()));
            }
            last_wrench = Some(wrench);
            pressed = pressed.max(pull);
            // At rest against the wall, after the approach's transient has died out.
            if x > wall_m && rig.device().true_twist()[0].abs() < 1e-4 {
                stood_s += 1e-3;
                if stood_s > 0.5 {
                    at_rest_max = at_rest_max.max(pull);
                }
            }
            if pressed >= TOUR_PUSH_EASE_N && home_after.is_none() && x < 1e-3 {
                home_after = Some(t);
            }
        }
        assert!(pressed >= TOUR_PUSH_EASE_N, "{kind:?}: the hand never pressed on the wall ({pressed} N)");
        if !kind.tours_by_feel() {
            assert!(pressed > 3.0 * TOUR_PUSH_STALL_N, "{kind:?}: a firm grasp pushes on ({pressed} N)");
            continue;
        }
        assert!(
            at_rest_max > 0.0 && at_rest_max <= TOUR_PUSH_STALL_N * 1.05,
            "{kind:?}: at rest against the wall the hand pulls {at_rest_max} N"
        );
        assert!(turn_jump < 0.2, "{kind:?}: setting out home the hand's wrench jumped by {turn_jump} N in a tick");
        let home = home_after.unwrap_or_else(|| panic!("{kind:?}: the hand never turned back to its grasp"));
        assert!(home > TOUR_STALL_S, "{kind:?}: home at {home} s");
    }
}

/// A tour round a handle that turns a whole circle (the testbed's link 2 over its reach): waypoints an eighth
/// of a turn apart, their angles given as logarithms within ±π of the grasp (so 3π/4 is followed by −π). On
/// its way forth the wrist turns a light handle steadily through them, never spinning back the long way round
/// between two neighbours: followed continuously, the handle's angle only grows, past 1.5π.
#[test]
fn a_tour_round_a_whole_turn_keeps_the_wrist_turning_one_way() {
    use std::f64::consts::{FRAC_PI_4, PI};
    let wrapped = |a: f64| (a + PI).rem_euclid(2.0 * PI) - PI;
    let waypoints: Vec<Vector3<f64>> =
        (1..8).map(|k| Vector3::new(0.001 * k as f64, 0.0, wrapped(k as f64 * FRAC_PI_4))).collect();
    let spec = DeviceSpec {
        mass: vec![0.1, 0.1, 2e-3],
        workspace_min: vec![-10.0, -10.0, -100.0],
        workspace_max: vec![10.0, 10.0, 100.0],
        ..DevicePreset::Paper.spec(SceneKind::Planar).unwrap()
    };
    let start = OpPose { position: Vector2::zeros(), rotation: UnitComplex::identity() };
    let device = SimulatedDevice::new(spec, &SimulatedDeviceParams::ideal(3), start).unwrap();
    let user = UserSpec::Hand(HandSpec { kind: HandKind::Firm, intent: Intent::Tour })
        .build::<Planar>(&UserContext { tour: waypoints })
        .unwrap();
    let mut rig = SimulatedRig::new(device, user);
    let (mut unwrapped, mut last, mut furthest, mut back_spin) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    // Forth: seven segments of at least 0.6 s each from the grasp.
    run(&mut rig, 4.0, Vector3::zeros(), |_, rig| {
        let angle = rig.true_pose().rotation.angle();
        unwrapped += wrapped(angle - last);
        last = angle;
        furthest = furthest.max(unwrapped);
        back_spin = back_spin.max(furthest - unwrapped);
    });
    assert!(furthest > 1.5 * PI, "the handle turned only {furthest} rad forth");
    assert!(back_spin < 0.1, "the handle turned back by {back_spin} rad on the way forth");
}
