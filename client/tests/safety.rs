//! The safety envelope: limits under hostile input, the staleness fade and the resume, non-finite values.

mod support;

use std::time::Duration;

use kinloop_client::core::safety::{force_ratio, limit_wrench, limit_wrench_parts, WrenchLimits};
use kinloop_client::core::{ConstraintMode, HapticCore, ModelForm, UplinkDeadband};
use kinloop_client::device::{DevicePreset, DeviceState};
use kinloop_client::user::ConstantWrench;
use kinloop_linkage::local_model::OpPose;
use kinloop_linkage::{builtin, Planar, SceneKind};
use kinloop_protocol::{uplink_flags, ContactTerm, Snapshot};
use nalgebra::{Vector2, Vector3};
use support::{paper_config, ClosedLoop, TestbedVe};

fn paper_limits() -> WrenchLimits {
    WrenchLimits::of(&DevicePreset::Paper.spec(SceneKind::Planar).expect("planar"))
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
    let falcon = WrenchLimits::of(&DevicePreset::Falcon.spec(SceneKind::Planar).expect("planar"));
    let (w, scale) = limit_wrench::<Planar>(&Vector3::new(1.0, 2.0, 5.0), &falcon);
    assert_eq!((w, scale), (Vector3::new(1.0, 2.0, 0.0), 1.0), "no torque actuator: torque dropped, force kept");
    let (w, scale) = limit_wrench::<Planar>(&Vector3::new(f64::NAN, 0.0, 0.0), &limits);
    assert_eq!((w, scale), (Vector3::zeros(), 0.0));
}

/// A way to corrupt a snapshot.
type Corruption = Box<dyn Fn(&mut Snapshot)>;

/// A valid testbed snapshot to corrupt.
fn base_snapshot(seq: u64) -> Snapshot {
    let mut ve = TestbedVe::new(false);
    let mut s = ve.snapshot();
    s.seq = seq;
    s
}

#[test]
fn force_never_exceeds_the_device_limits_even_with_hostile_snapshots() {
    let ve = TestbedVe::new(false);
    let mut config = paper_config(ConstraintMode::Stiffness, ModelForm::Op);
    config.gains = kinloop_client::core::GainChoice::Paper;
    let mut core = HapticCore::<Planar>::new(config, &ve.welcome()).expect("core");
    let limits = paper_limits();
    let hostile: Vec<Corruption> = vec![
        Box::new(|_| {}),
        Box::new(|s| s.inverse_inertia = vec![9e5, 0.0, 0.0, 9e5, 0.0, 9e5]),
        Box::new(|s| s.op_pose[0] = f64::NAN),
        Box::new(|s| s.op_pose = vec![1e3, -1e3, 0.0]),
        Box::new(|s| s.op_twist = vec![1e4, 1e4, 1e4]),
        Box::new(|s| s.bias_accel = vec![1e6, -1e6, 1e6]),
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
        "NaN pose, twist past the wire's 1e3, infinite bias, negative and huge Λ⁻¹, directions past unit length, \
         bad count, short Λ⁻¹"
    );
    assert_eq!(stats.snapshots_rejected, rejected);
}

#[test]
fn a_non_finite_device_reading_commands_zero_and_is_counted() {
    let mut l = ClosedLoop::paper(ConstraintMode::Stiffness, ModelForm::Op);
    for _ in 0..100 {
        l.tick();
    }
    let snapshot = l.ve.snapshot();
    let mut snapshot = snapshot;
    snapshot.seq = 1_000_000;
    l.core.handle_snapshot(l.now, &snapshot).expect("valid");
    let bad = DeviceState::<Planar> {
        pose: OpPose { position: Vector2::new(f64::NAN, 0.0), rotation: nalgebra::UnitComplex::identity() },
        twist: Vector3::zeros(),
        hand_wrench: None,
    };
    let out = l.core.tick(l.now, &bad);
    assert_eq!(out.command, Vector3::zeros());
    assert_ne!(out.report.flags & uplink_flags::SAFETY_STOP, 0);
    assert_eq!(l.core.stats().non_finite_events, 1);
}

#[test]
fn stale_snapshots_fade_the_force_to_zero_within_the_fade_time_and_resume_smoothly() {
    let mut config = paper_config(ConstraintMode::Stiffness, ModelForm::Op);
    config.safety.ramp_in = Duration::from_millis(200);
    let (max_age, fade) = (config.safety.max_snapshot_age, config.safety.fade_out);
    let user = Box::new(ConstantWrench::<Planar>::from_values(&builtin::PAPER_WRENCH).expect("3 values"));
    let mut l = ClosedLoop::with(config, user, false);
    let before: Vec<_> = (0..600).map(|_| l.tick()).collect();
    assert!(before.last().expect("ran").report.gain == 1.0);
    l.link_up = false;
    let cut_at = l.now;
    let outage: Vec<_> = (0..400).map(|_| l.tick()).collect();
    let zero_from = cut_at + max_age + fade + Duration::from_millis(2);
    for s in &outage {
        if s.report.time >= zero_from {
            assert_eq!(s.command, Vector3::zeros(), "force at {:?} after the cut", s.report.time - cut_at);
            assert_ne!(s.report.flags & uplink_flags::FADING, 0);
        }
    }
    let fade_steps = outage.windows(2).map(|w| (w[1].command - w[0].command).norm()).fold(0.0f64, f64::max);
    assert!(fade_steps < 0.06, "the fade steps by {fade_steps} N");
    l.link_up = true;
    let after: Vec<_> = (0..400).map(|_| l.tick()).collect();
    // The handle drifted while nothing held it; the force comes back from zero over the ramp.
    assert!(after[0].command.norm() < 0.01, "the first resumed tick pushes {} N", after[0].command.norm());
    let resume_steps = after.windows(2).map(|w| (w[1].command - w[0].command).norm()).fold(0.0f64, f64::max);
    println!("largest step: fading {fade_steps:.4} N, resuming {resume_steps:.4} N");
    assert!(resume_steps < 0.2, "the resume steps by {resume_steps} N");
    assert_eq!(after.last().expect("ran").report.gain, 1.0, "fully back");
    assert!(l.core.stats().stale_ticks > 0);
}

#[test]
fn the_perceptual_deadband_saves_uplinks_and_respects_the_longest_gap() {
    let mut config = paper_config(ConstraintMode::Stiffness, ModelForm::Op);
    let deadband = UplinkDeadband::default();
    config.deadband = Some(deadband);
    let user = Box::new(ConstantWrench::<Planar>::from_values(&builtin::PAPER_WRENCH).expect("3 values"));
    let mut l = ClosedLoop::with(config, user, false);
    let samples: Vec<_> = (0..2000).map(|_| l.tick()).collect();
    let sent: Vec<Duration> = samples.iter().filter(|s| s.uplink_sent).map(|s| s.report.time).collect();
    let longest = sent.windows(2).map(|w| w[1] - w[0]).max().expect("several uplinks");
    let stats = l.core.stats();
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
