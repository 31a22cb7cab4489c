//! Random sessions of the haptic core beside the testbed VE: snapshots late, lost, stale, repeated and
//! corrupted (any field set to NaN, an infinity, zero, a negative, a huge or tiny value, or resized); device
//! readings now and then not finite or absurd; the clock jumping ahead and stepping back; both constraint
//! modes, both local-model forms, three devices. Whatever arrives, every command is finite, within the
//! device's limits, and accepted by the simulated device, every uplink passes the server's checks, and
//! nothing panics.

mod support;

use std::time::Duration;

use kinloop_client::core::safety::force_ratio;
use kinloop_client::core::{ConstraintMode, HapticCore, ModelForm};
use kinloop_client::device::{DevicePreset, DeviceState, HapticDevice, SimulatedRig};
use kinloop_client::user::ConstantWrench;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::testing::TestRng;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind, model::builtin};
use kinloop_protocol::codec::validate;
use kinloop_protocol::Snapshot;
use nalgebra::{UnitComplex, Vector2, Vector3};
use support::{paper_config, TestbedVe};

const TICKS: usize = 4000;

/// Sets one number of one field to an odd value, or resizes one field.
fn corrupt(s: &mut Snapshot, rng: &mut TestRng) {
    let odd = rng.odd();
    let field: &mut Vec<f64> = match rng.below(7) {
        0 => &mut s.op_pose,
        1 => &mut s.op_twist,
        2 => &mut s.inverse_inertia,
        3 => &mut s.bias_accel,
        4 => &mut s.directions,
        5 => &mut s.singular_values,
        _ => {
            match rng.below(3) {
                0 => s.constraint_count = rng.below(256) as u8,
                1 => s.server_time_s = odd,
                _ => s.seq = s.seq.wrapping_sub(rng.below(5) as u64),
            }
            return;
        }
    };
    if rng.chance(0.2) {
        let len = field.len();
        field.resize(rng.below(len + 2), 0.5);
    } else if !field.is_empty() {
        let i = rng.below(field.len());
        field[i] = odd;
    }
}

/// A reading no device should give.
fn odd_reading(rng: &mut TestRng) -> DeviceState<Planar> {
    let (a, b) = (rng.odd(), rng.odd());
    DeviceState {
        pose: OpPose { position: Vector2::new(a, 0.01), rotation: UnitComplex::new(0.1) },
        twist: Vector3::new(0.0, b, 0.0),
        hand_wrench: if rng.chance(0.5) { None } else { Some(Vector3::new(rng.odd(), 0.0, 0.0)) },
        grasped: if rng.chance(0.5) { None } else { Some(rng.chance(0.5)) },
    }
}

fn session(seed: u64, mode: ConstraintMode, form: ModelForm, preset: DevicePreset) {
    let context = format!("seed {seed}, {mode:?}, {form:?}, {preset:?}");
    let mut rng = TestRng(seed);
    // The VE moves under the paper's wrench alone (the server's guards, which would refuse the uplinks of a
    // local model sent astray by in-range but false terms, are not this test's subject).
    let mut ve = TestbedVe::new(form == ModelForm::Config);
    ve.set_hand_only(Vector3::from_column_slice(&builtin::PAPER_WRENCH));
    let shape = ve.welcome().scene.shape();
    let mut config = paper_config(mode, form);
    config.device = preset.spec(SceneKind::Planar).expect("planar spec");
    let limits = config.device.wrench_limits();
    let mut core = HapticCore::<Planar>::new(config, &ve.welcome()).expect("core");
    let user = ConstantWrench::<Planar>::from_values(&builtin::PAPER_WRENCH).expect("3 values");
    let mut rig = SimulatedRig::new(preset.build::<Planar>().expect("device"), Box::new(user));
    let mut now = Duration::from_millis(1);
    let (mut delivered, mut odd_readings, mut backwards) = (0, 0, 0);
    for tick in 0..TICKS {
        ve.step();
        let mut snapshot = ve.snapshot();
        if rng.chance(0.85) {
            if rng.chance(0.2) {
                corrupt(&mut snapshot, &mut rng);
            }
            let _ = core.handle_snapshot(now, &snapshot);
            delivered += 1;
        }
        let reading = if rng.chance(0.03) {
            odd_readings += 1;
            odd_reading(&mut rng)
        } else {
            rig.read(now).expect("the simulated device reads")
        };
        let out = core.tick(now, &reading);
        let command = out.command;
        assert!(command.iter().all(|x| x.is_finite()), "{context}, tick {tick}: command {command}");
        let ratio = force_ratio::<Planar>(&command, &limits);
        assert!(ratio <= 1.0 + 1e-12, "{context}, tick {tick}: command {command} is {ratio} of the limits");
        // What the server's decoder checks before its VE sees an uplink.
        if let Some(Err(e)) = out.uplink.map(|u| validate::uplink(u, &shape)) {
            panic!("{context}, tick {tick}: an uplink the server refuses: {e}");
        }
        rig.command(now, &command).unwrap_or_else(|e| panic!("{context}, tick {tick}: the device refused: {e}"));
        now = match rng.below(200) {
            0 => now + Duration::from_millis(100 + rng.below(400) as u64),
            1 => {
                backwards += 1;
                now.saturating_sub(Duration::from_millis(1 + rng.below(3) as u64))
            }
            _ => now + Duration::from_millis(1),
        };
    }
    let stats = core.stats();
    assert!(stats.max_force_ratio <= 1.0, "{context}: {stats:?}");
    assert!(stats.snapshots_rejected > 0 && stats.non_finite_events > 0, "{context}: {stats:?}");
    assert!(delivered > TICKS / 2 && odd_readings > 0 && backwards > 0, "{context}");
}

#[test]
fn random_sessions_keep_every_command_finite_and_within_the_device() {
    let mut seed = 1;
    for mode in [ConstraintMode::Stiffness, ConstraintMode::Impedance] {
        for form in [ModelForm::Op, ModelForm::Config] {
            for preset in [DevicePreset::Paper, DevicePreset::Falcon, DevicePreset::Touch] {
                session(seed, mode, form, preset);
                seed += 1;
            }
        }
    }
}
