//! Random sessions of the haptic core with the testbed VE: snapshots late, lost, stale, repeated and
//! corrupted (any field set to NaN, an infinity, zero, a negative, a huge or tiny value, or resized); device
//! readings now and then not finite or absurd; the clock jumping ahead and stepping back; both constraint
//! modes, both local-model forms, three devices. Whatever arrives, every command is finite, within the
//! device's limits, and accepted by the simulated device (the session steps on only if it is), every uplink
//! passes the server's checks, and nothing panics.

use std::time::Duration;

use kinloop_client::core::safety::{force_ratio, WrenchLimits};
use kinloop_client::core::{ConstraintMode, HapticCore, ModelForm, TickOutput};
use kinloop_client::device::{DevicePreset, DeviceState};
use kinloop_harness::{CoreHooks, Session, SessionPlan};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Planar, SceneKind};
use kinloop_linkage::testing::TestRng;
use kinloop_protocol::codec::validate;
use kinloop_protocol::{MappingRequest, SessionShape, Snapshot};
use nalgebra::{UnitComplex, Vector2, Vector3};

const TICKS: u64 = 4000;

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

/// The faults of one session, applied around the core's calls; the checks made on every tick.
struct Chaos {
    context: String,
    rng: TestRng,
    shape: SessionShape,
    limits: WrenchLimits,
    /// The core's clock: the session's, jumped ahead and stepped back now and then.
    ahead: Duration,
    back: Duration,
    delivered: u64,
    odd_readings: u64,
    backwards: u64,
}

impl Chaos {
    fn core_clock(&self, now: Duration) -> Duration {
        (now + self.ahead).saturating_sub(self.back)
    }
}

impl CoreHooks<Planar> for Chaos {
    fn snapshot(&mut self, _who: usize, core: &mut HapticCore<Planar>, now: Duration, snapshot: &mut Snapshot) {
        if self.rng.chance(0.85) {
            if self.rng.chance(0.2) {
                corrupt(snapshot, &mut self.rng);
            }
            let _ = core.handle_snapshot(self.core_clock(now), snapshot);
            self.delivered += 1;
        }
    }

    fn tick<'c>(
        &mut self,
        _who: usize,
        core: &'c mut HapticCore<Planar>,
        now: Duration,
        device: &DeviceState<Planar>,
    ) -> TickOutput<'c, Planar> {
        let reading = if self.rng.chance(0.03) {
            self.odd_readings += 1;
            odd_reading(&mut self.rng)
        } else {
            *device
        };
        let tick = now.as_millis();
        let out = core.tick(self.core_clock(now), &reading);
        let (context, command) = (&self.context, out.command);
        assert!(command.iter().all(|x| x.is_finite()), "{context}, tick {tick}: command {command}");
        let ratio = force_ratio::<Planar>(&command, &self.limits);
        assert!(ratio <= 1.0 + 1e-12, "{context}, tick {tick}: command {command} is {ratio} of the limits");
        // What the server's decoder checks before its VE sees an uplink.
        if let Some(Err(e)) = out.uplink.map(|u| validate::uplink(u, &self.shape)) {
            panic!("{context}, tick {tick}: an uplink the server refuses: {e}");
        }
        match self.rng.below(200) {
            0 => self.ahead += Duration::from_millis(100 + self.rng.below(400) as u64),
            1 => {
                self.backwards += 1;
                self.back += Duration::from_millis(1 + self.rng.below(3) as u64);
            }
            _ => {}
        }
        out
    }
}

fn session(seed: u64, mode: ConstraintMode, form: ModelForm, preset: DevicePreset) {
    let context = format!("seed {seed}, {mode:?}, {form:?}, {preset:?}");
    let mut plan = SessionPlan::paper_manipulation(mode, form).expect("the paper's plan");
    plan.clients[0].device = preset;
    if preset != DevicePreset::Paper {
        // The testbed's reach one to one is past a smaller device's workspace: the server scales it in.
        plan.clients[0].mapping = MappingRequest::default();
    }
    let mut session = Session::<Planar>::new(&plan).expect("the session");
    let limits = preset.spec(SceneKind::Planar).expect("planar spec").wrench_limits();
    let shape = session.ve().session_shape();
    let zero = Duration::ZERO;
    let mut chaos = Chaos {
        context: context.clone(),
        rng: TestRng(seed),
        shape,
        limits,
        ahead: zero,
        back: zero,
        delivered: 0,
        odd_readings: 0,
        backwards: 0,
    };
    // The VE follows the uplinks: those its guards refuse (a local model sent astray by in-range but false
    // terms) are counted by the session, not this test's subject.
    session
        .run_until_with(Duration::from_millis(TICKS), &mut chaos)
        .unwrap_or_else(|e| panic!("{context}: the session stopped (a command the device refused?): {e:#}"));
    let stats = session.core(0).expect("joined").stats();
    assert!(stats.max_force_ratio <= 1.0, "{context}: {stats:?}");
    assert!(stats.snapshots_rejected > 0 && stats.non_finite_events > 0, "{context}: {stats:?}");
    assert!(chaos.delivered > TICKS / 2 && chaos.odd_readings > 0 && chaos.backwards > 0, "{context}");
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
