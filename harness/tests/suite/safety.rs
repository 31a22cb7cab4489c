//! The safety envelope: limits under hostile input, the staleness fade and the resume, non-finite values.

use std::time::Duration;

use kinloop_client::core::safety::{force_ratio, limit_wrench, limit_wrench_parts, WrenchLimits};
use kinloop_client::core::{ConstraintMode, CoreConfig, HapticCore, ModelForm, UplinkDeadband};
use kinloop_client::device::{DevicePreset, DeviceState};
use kinloop_client::user::ConstantWrench;
use kinloop_harness::{first_terms, CoreEdit, Probe, Session, SessionPlan, TickSample};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind, model::builtin};
use kinloop_protocol::{uplink_flags, ContactTerm, Snapshot, Welcome};
use nalgebra::{Vector2, Vector3};

fn paper_limits() -> WrenchLimits {
    DevicePreset::Paper.spec(SceneKind::Planar).expect("planar").wrench_limits()
}

/// Force and torque are each clamped to their peak, each keeping its direction: an excess in one never
/// shrinks the other (a torque over the peak must not give up the force that holds the joints).
#[test]
fn clamping_keeps_each_parts_direction_and_zeroes_unactuated_axes() {
    let limits = paper_limits();
    let (w, scale) = limit_wrench::<Planar>(&Vector3::new(30.0, -40.0, 0.1), &limits);
    assert!(w.xy().norm() <= limits.max_force_n && w.xy().norm() > limits.max_force_n - 1e-9);
    assert!((scale - 0.2).abs() < 1e-9);
    assert!((w.xy() - Vector2::new(30.0, -40.0) * 0.2).norm() < 1e-9, "the force's direction kept");
    assert_eq!(w[2], 0.1, "a torque within its peak is left alone");
    let (torque_heavy, parts) = limit_wrench_parts::<Planar>(&Vector3::new(0.1, 0.0, 2.0), &limits);
    assert!(torque_heavy[2] <= limits.max_torque_nm && torque_heavy[2] > limits.max_torque_nm - 1e-9);
    assert_eq!((torque_heavy[0], torque_heavy[1]), (0.1, 0.0), "a force within its peak is left alone");
    assert_eq!(parts.force, 1.0);
    assert!((parts.torque - limits.max_torque_nm / 2.0).abs() < 1e-9);
    let falcon = DevicePreset::Falcon.spec(SceneKind::Planar).expect("planar").wrench_limits();
    let (w, scale) = limit_wrench::<Planar>(&Vector3::new(1.0, 2.0, 5.0), &falcon);
    assert_eq!((w, scale), (Vector3::new(1.0, 2.0, 0.0), 1.0), "no torque actuator: torque dropped, force kept");
    let (w, scale) = limit_wrench::<Planar>(&Vector3::new(f64::NAN, 0.0, 0.0), &limits);
    assert_eq!((w, scale), (Vector3::zeros(), 0.0));
}

/// A way to corrupt a snapshot.
type Corruption = Box<dyn Fn(&mut Snapshot)>;

/// The paper's session, with `edit` applied to the core's configuration.
fn paper_session(edit: impl Fn(&mut CoreConfig) + Send + Sync + 'static) -> Session<Planar> {
    let mut plan = SessionPlan::paper_manipulation(ConstraintMode::Stiffness, ModelForm::Op).expect("the plan");
    plan.clients[0].configure = Some(CoreEdit::new(edit));
    Session::new(&plan).expect("the session")
}

/// Runs `session` for `ms` more ticks.
fn run(session: &mut Session<Planar>, probe: &mut Probe<Planar>, ms: u64) -> Vec<TickSample<Planar>> {
    let from = probe.samples.len();
    let until = if from == 0 { Duration::from_millis(ms - 1) } else { session.now() + Duration::from_millis(ms) };
    session.run_until_with(until, probe).expect("steps");
    probe.samples[from..].to_vec()
}

/// The testbed's welcome and a valid snapshot of it at rest (a few milliseconds into the paper's session),
/// with the configuration the session's core has.
fn testbed() -> (Welcome, Snapshot, CoreConfig) {
    let plan = SessionPlan::paper_manipulation(ConstraintMode::Stiffness, ModelForm::Op).expect("the plan");
    first_terms::<Planar>(&plan, Duration::from_millis(4)).expect("terms")
}

#[test]
fn force_never_exceeds_the_device_limits_even_with_hostile_snapshots() {
    let (welcome, base, config) = testbed();
    let base_snapshot = |seq: u64| Snapshot { seq, ..base.clone() };
    let mut core = HapticCore::<Planar>::new(config, &welcome).expect("core");
    let limits = paper_limits();
    let hostile: Vec<Corruption> = vec![
        Box::new(|_| {}),
        Box::new(|s| s.inverse_inertia = vec![9e5, 0.0, 0.0, 9e5, 0.0, 9e5]),
        Box::new(|s| s.op_pose[0] = f64::NAN),
        Box::new(|s| s.op_pose = vec![1e6, -1e6, 0.0]),
        Box::new(|s| s.op_twist = vec![1e7, 1e7, 1e7]),
        Box::new(|s| s.bias_accel = vec![1e9, -1e9, 1e9]),
        Box::new(|s| s.bias_accel[1] = f64::INFINITY),
        Box::new(|s| s.inverse_inertia[0] = -5.0),
        Box::new(|s| s.inverse_inertia[3] = 1e9),
        Box::new(|s| s.singular_values = vec![0.0, 0.0, 0.0]),
        Box::new(|s| s.directions = vec![1e3; 9]),
        Box::new(|s| s.constraint_count = 200),
        Box::new(|s| s.inverse_inertia.pop().map(|_| ()).unwrap_or(())),
        Box::new(|s| {
            s.contacts = vec![ContactTerm {
                point: vec![0.0, 0.0],
                normal: vec![1.0, 0.0],
                depth: 0.5,
                normal_velocity: -10.0,
                op_coupling: vec![1e5, 1e5, 1e5],
                mobility: 1e5,
                bias_accel: 0.0,
                stiffness: 1e9,
                damping: 1e6,
            }]
        }),
    ];
    let mut now = Duration::ZERO;
    let mut seq = 0;
    let mut rejected = 0;
    let device = |x: f64| DeviceState::<Planar> {
        pose: OpPose { position: Vector2::new(x, 0.01), rotation: nalgebra::UnitComplex::new(0.2) },
        twist: Vector3::new(0.3, -0.2, 1.0),
        hand_wrench: Some(Vector3::new(-0.5, 0.0, -0.0025)),
        grasped: None,
    };
    for round in 0..3 {
        for corrupt in &hostile {
            seq += 1;
            let mut s = base_snapshot(seq);
            corrupt(&mut s);
            if core.handle_snapshot(now, &s).is_err() {
                rejected += 1;
            }
            for k in 0..20 {
                let out = core.tick(now, &device(0.01 * round as f64 + 1e-3 * k as f64));
                assert!(out.command.iter().all(|x| x.is_finite()), "non-finite command");
                let ratio = force_ratio::<Planar>(&out.command, &limits);
                assert!(ratio <= 1.0 + 1e-12, "command {:?} exceeds the limits ({ratio})", out.command);
                now += Duration::from_millis(1);
            }
        }
    }
    let stats = core.stats();
    assert!(stats.max_force_ratio <= 1.0, "{}", stats.max_force_ratio);
    assert!(stats.max_force_ratio > 0.99, "the hostile terms should have pushed to the limit");
    assert_eq!(
        rejected,
        3 * 8,
        "NaN pose, twist past the wire's scene range, infinite bias, negative and huge Λ⁻¹, directions past unit length, \
         bad count, short Λ⁻¹"
    );
    assert_eq!(stats.snapshots_rejected, rejected);
}

#[test]
fn a_non_finite_device_reading_commands_zero_and_is_counted() {
    let mut session = paper_session(|_| {});
    let mut probe = Probe::default();
    run(&mut session, &mut probe, 100);
    let mut snapshot = probe.last_snapshot.expect("snapshots arrived");
    snapshot.seq = 1_000_000;
    let now = session.now() + Duration::from_millis(1);
    let core = session.core_mut(0).expect("joined");
    core.handle_snapshot(now, &snapshot).expect("valid");
    let bad = DeviceState::<Planar> {
        pose: OpPose { position: Vector2::new(f64::NAN, 0.0), rotation: nalgebra::UnitComplex::identity() },
        twist: Vector3::zeros(),
        hand_wrench: None,
        grasped: None,
    };
    let out = core.tick(now, &bad);
    assert_eq!(out.command, Vector3::zeros());
    assert_ne!(out.report.flags & uplink_flags::SAFETY_STOP, 0);
    assert_eq!(core.stats().non_finite_events, 1);
}

#[test]
fn stale_snapshots_fade_the_force_to_zero_within_the_fade_time_and_resume_smoothly() {
    let mut session = paper_session(|c| c.safety.ramp_in = Duration::from_millis(200));
    let mut probe = Probe::default();
    let before = run(&mut session, &mut probe, 600);
    let safety = &session.core(0).expect("joined").config().safety;
    let (max_age, fade) = (safety.max_snapshot_age, safety.fade_out);
    assert!(before.last().expect("ran").report.gain == 1.0);
    probe.link_up = false;
    let cut_at = session.now() + Duration::from_millis(1);
    let outage = run(&mut session, &mut probe, 400);
    let zero_from = cut_at + max_age + fade + Duration::from_millis(2);
    for s in &outage {
        if s.report.time >= zero_from {
            assert_eq!(s.command, Vector3::zeros(), "force at {:?} after the cut", s.report.time - cut_at);
            assert_ne!(s.report.flags & uplink_flags::FADING, 0);
        }
    }
    let fade_steps = outage.windows(2).map(|w| (w[1].command - w[0].command).norm()).fold(0.0f64, f64::max);
    assert!(fade_steps < 0.06, "the fade steps by {fade_steps} N");
    probe.link_up = true;
    let after = run(&mut session, &mut probe, 400);
    // The handle drifted while nothing held it; the force comes back from zero over the ramp.
    assert!(after[0].command.norm() < 0.01, "the first resumed tick pushes {} N", after[0].command.norm());
    let resume_steps = after.windows(2).map(|w| (w[1].command - w[0].command).norm()).fold(0.0f64, f64::max);
    println!("largest step: fading {fade_steps:.4} N, resuming {resume_steps:.4} N");
    assert!(resume_steps < 0.2, "the resume steps by {resume_steps} N");
    assert_eq!(after.last().expect("ran").report.gain, 1.0, "fully back");
    assert!(session.core(0).expect("joined").stats().stale_ticks > 0);
}

/// A link that goes quiet now and then (a jittery path delivers in bunches) is judged by its own gaps: the
/// first 180 ms silence fades the force, the next ones do not, as the staleness limit has grown to the
/// margin over the longest gap; a silence past `LONGEST_STALE_AGE` still fades to zero, however long the
/// link's gaps have been.
#[test]
fn a_link_that_goes_quiet_now_and_then_is_judged_by_its_own_gaps_and_a_long_silence_still_fades() {
    use kinloop_client::core::{LONGEST_STALE_AGE, STALE_GAP_MARGIN};
    let mut session = paper_session(|c| c.safety.ramp_in = Duration::from_millis(200));
    let mut probe = Probe::default();
    run(&mut session, &mut probe, 600);
    let (max_age, fade) = {
        let core = session.core(0).expect("joined");
        (core.config().safety.max_snapshot_age, core.config().safety.fade_out)
    };
    assert_eq!(session.core(0).expect("joined").stale_after(session.now()), max_age, "a steady link");
    let quiet = Duration::from_millis(180);
    assert!(quiet > max_age && quiet.mul_f64(STALE_GAP_MARGIN) < LONGEST_STALE_AGE);
    let fading = |samples: &[TickSample<Planar>]| samples.iter().any(|s| s.report.flags & uplink_flags::FADING != 0);
    for round in 0..3 {
        probe.link_up = false;
        let silence = run(&mut session, &mut probe, quiet.as_millis() as u64);
        probe.link_up = true;
        let after = run(&mut session, &mut probe, 500);
        assert_eq!(fading(&silence), round == 0, "round {round}: the first silence fades, later ones do not");
        assert_eq!(after.last().expect("ran").report.gain, 1.0, "round {round}: fully on again");
        let limit = session.core(0).expect("joined").stale_after(session.now());
        assert!(limit >= quiet.mul_f64(STALE_GAP_MARGIN), "round {round}: the limit is {limit:?}");
    }
    let stale_ticks = session.core(0).expect("joined").stats().stale_ticks;
    // A silence that does not end: zero force once the longest stale age and the fade have passed.
    probe.link_up = false;
    let cut_at = session.now() + Duration::from_millis(1);
    let outage = run(&mut session, &mut probe, 800);
    let zero_from = cut_at + LONGEST_STALE_AGE + fade + Duration::from_millis(2);
    assert!(outage.iter().any(|s| s.report.time >= zero_from), "the outage outlasts the limit and the fade");
    for s in outage.iter().filter(|s| s.report.time >= zero_from) {
        assert_eq!(s.command, Vector3::zeros(), "force at {:?} after the cut", s.report.time - cut_at);
    }
    assert!(session.core(0).expect("joined").stats().stale_ticks > stale_ticks);
}

#[test]
fn the_perceptual_deadband_saves_uplinks_and_respects_the_longest_gap() {
    let deadband = UplinkDeadband::default();
    let mut session = paper_session(move |c| c.deadband = Some(deadband));
    let samples = run(&mut session, &mut Probe::default(), 2000);
    let sent: Vec<Duration> = samples.iter().filter(|s| s.uplink_sent).map(|s| s.report.time).collect();
    let longest = sent.windows(2).map(|w| w[1] - w[0]).max().expect("several uplinks");
    let stats = session.core(0).expect("joined").stats();
    println!(
        "deadband: {} of {} uplinks sent ({:.0}% saved), longest gap {longest:?}",
        stats.uplinks_sent,
        stats.uplinks_built,
        100.0 * stats.uplink_saving()
    );
    assert_eq!(stats.uplinks_sent as usize, sent.len());
    assert!(stats.uplink_saving() > 0.3, "saving {}", stats.uplink_saving());
    assert!(longest <= deadband.max_interval, "gap {longest:?}");
    let skipped =
        samples.iter().filter(|s| s.uplink_sent && s.report.flags & uplink_flags::DEADBAND_SKIPPED != 0).count();
    assert!(skipped > 0, "uplinks after a gap say so");
}

/// The paper's push until `release_s`, no hand from then until `regrasp_s`, the push again after.
struct LetsGo {
    push: ConstantWrench<Planar>,
    release_s: f64,
    regrasp_s: f64,
}

impl kinloop_client::user::SimulatedUser<Planar> for LetsGo {
    fn wrench(&mut self, now: Duration, device: &DeviceState<Planar>) -> Vector3<f64> {
        if self.holds(now) {
            self.push.wrench(now, device)
        } else {
            Vector3::zeros()
        }
    }

    fn holds(&self, now: Duration) -> bool {
        let t = now.as_secs_f64();
        !(self.release_s..self.regrasp_s).contains(&t)
    }
}

/// A hand that lets go of a device with a presence sensor: the output fades to a damper that brakes the
/// handle (it only ever takes energy from it), the local model parks, the VE keeps the linkage where the hand
/// left it, and the uplinks say HAND_OFF; when the hand returns, the force ramps in again without a step.
#[test]
fn a_released_handle_is_braked_and_the_linkage_waits_where_the_hand_left_it() {
    let mut session = paper_session(|c| c.safety.ramp_in = Duration::from_millis(200));
    let mut probe = Probe::default();
    // The session's first tick joins the user with the paper's push, which `LetsGo` continues.
    run(&mut session, &mut probe, 1);
    let fade = session.core(0).expect("joined").config().safety.fade_out;
    let push = ConstantWrench::<Planar>::from_values(&builtin::PAPER_WRENCH).expect("3 values");
    let user = Box::new(LetsGo { push, release_s: 1.0, regrasp_s: 2.5 });
    session.rig_mut(0).expect("joined").set_user(user);
    run(&mut session, &mut probe, 3499);
    let samples = probe.samples;
    let at = |s: f64| &samples[(s * 1000.0) as usize];
    assert_eq!(at(0.9).report.flags & uplink_flags::HAND_OFF, 0);
    assert!(at(0.9).report.gain == 1.0 && at(0.9).command.norm() > 0.1, "pushing before the release");
    let released: Vec<_> = samples
        .iter()
        .filter(|s| (1.0 + fade.as_secs_f64() + 0.01..2.5).contains(&s.report.time.as_secs_f64()))
        .collect();
    assert!(released.len() > 1000);
    for s in &released {
        assert_ne!(s.report.flags & uplink_flags::HAND_OFF, 0, "{:?}", s.report.time);
        assert_eq!(s.report.gain, 0.0);
        // Only the brake acts: it opposes the handle's motion on every axis.
        for a in 0..3 {
            assert!(
                s.command[a] * s.device.twist[a] <= 1e-12,
                "{:?}: {:?} on {:?}",
                s.report.time,
                s.command,
                s.device.twist
            );
        }
        assert_eq!(s.report.model_twist, Vector3::zeros(), "the model is parked");
    }
    let parked = released[0].report.model_pose.position;
    assert!(released.iter().all(|s| (s.report.model_pose.position - parked).norm() < 1e-12));
    let last = released.last().expect("released");
    assert!(last.device.twist.xy().norm() < 1e-3, "the brake stopped the handle: {:?}", last.device.twist);
    let ve_op = |s: &TickSample<Planar>| s.ve_op.expect("the VE has the user").position;
    let op_moved = (ve_op(last) - ve_op(at(1.0))).norm();
    assert!(op_moved < 5e-3, "the VE's OP moved {op_moved} m while no hand held it");
    assert!(session.core(0).expect("joined").stats().hand_off_ticks as usize >= released.len());
    // The hand returns: the force ramps back in without a step, and the push goes on.
    let back: Vec<_> = samples.iter().filter(|s| s.report.time.as_secs_f64() >= 2.5).collect();
    assert_eq!(back[0].report.flags & uplink_flags::HAND_OFF, 0);
    let steps = back.windows(2).map(|w| (w[1].command - w[0].command).norm()).fold(0.0f64, f64::max);
    assert!(steps < 0.2, "the re-grasp steps the force by {steps} N");
    assert_eq!(back.last().expect("ran").report.gain, 1.0);
}

/// The local model's port books what the hand puts into the model, and the uplinks carry it; a snapshot whose
/// energy books are broken is still used, its books refused and counted.
#[test]
fn the_two_port_books_grow_with_the_push_and_bad_server_books_are_refused() {
    let mut session = paper_session(|_| {});
    let mut probe = Probe::default();
    run(&mut session, &mut probe, 1000);
    let (own, server) = session.core(0).expect("joined").energy_books();
    let received: f64 = own.received_j.iter().sum();
    assert!(received > 1e-4, "the paper's push did work on the local model: {own:?}");
    assert_eq!(server.refused, 0, "the VE's books are sound");
    for (n, corrupt) in [
        |s: &mut Snapshot| s.energy.received_j[0] = f64::NAN,
        |s: &mut Snapshot| s.energy.emitted_j[2] = -1.0,
        |s: &mut Snapshot| s.energy.received_j[1] = f64::INFINITY,
    ]
    .iter()
    .enumerate()
    {
        let mut s = probe.last_snapshot.clone().expect("snapshots arrived");
        s.seq = 1_000_000 + n as u64;
        s.server_time_s = 10.0 + n as f64;
        corrupt(&mut s);
        let now = session.now() + Duration::from_millis(1);
        assert_eq!(session.core_mut(0).expect("joined").handle_snapshot(now, &s), Ok(true), "the state is used");
        run(&mut session, &mut probe, 1);
    }
    let core = session.core(0).expect("joined");
    assert_eq!(core.energy_books().1.refused, 3);
    assert_eq!(core.stats().energy_reports_refused, 3);
    assert_eq!(core.stats().snapshots_rejected, 0);
}

/// A welcome whose OP path cannot be followed (poses that repeat, accelerations that do not match the poses)
/// gets a typed error that says what is wrong; a core that does not follow paths ignores it; a good path is
/// taken.
#[test]
fn a_welcome_whose_path_cannot_be_followed_is_refused_by_name() {
    use kinloop_client::core::CoreError;
    use kinloop_linkage::algorithms::op_path::PathError;
    let (mut welcome, _, config) = testbed();
    assert!(welcome.op.path.is_empty(), "the testbed has two degrees of freedom: no path");
    welcome.op.path = vec![0.1, 0.2, 0.0, 0.1, 0.2, 0.0];
    welcome.op.path_rest_acceleration = Some(vec![0.0, 0.0]);
    let error = HapticCore::<Planar>::new(config.clone(), &welcome).err().expect("refused");
    assert!(matches!(error, CoreError::Path(PathError::Repeated(0, 1))), "{error:?}");
    assert_eq!(error.to_string(), "the welcome's OP path: poses 0 and 1 of the path coincide");
    welcome.op.path = vec![0.1, 0.2, 0.0, 0.15, 0.2, 0.1];
    welcome.op.path_rest_acceleration = Some(vec![0.0]);
    let error = HapticCore::<Planar>::new(config.clone(), &welcome).err().expect("refused");
    assert!(matches!(error, CoreError::Path(PathError::RestAcceleration { got: 1, poses: 2 })), "{error:?}");
    let mut ignoring = config.clone();
    ignoring.follow_path = false;
    assert!(HapticCore::<Planar>::new(ignoring, &welcome).is_ok());
    welcome.op.path_rest_acceleration = Some(vec![0.0, -1.0]);
    assert!(HapticCore::<Planar>::new(config.clone(), &welcome).is_ok());
    // A swing with accelerations at rest: its poses are two configurations each.
    welcome.op.path_shape = kinloop_protocol::PathShape::Swing;
    let error = HapticCore::<Planar>::new(config.clone(), &welcome).err().expect("refused");
    assert!(matches!(error, CoreError::Path(PathError::RestAccelerationOnSwing)), "{error:?}");
    welcome.op.path_rest_acceleration = None;
    assert!(HapticCore::<Planar>::new(config, &welcome).is_ok());
}
