//! Shared pieces of the server's tests: scenes, users and uplinks in virtual time.
#![allow(dead_code)]

use std::time::Duration;

use kinloop_linkage::model::builtin;
use kinloop_linkage::{math::space::Planar, math::space::Space, model::scene::Scene, model::Model};
use kinloop_protocol::{DeviceCaps, LocalModelForm, MappingRequest, Role, Snapshot, Uplink};
use kinloop_server::core::{JoinRequest, VeConfig, VeCore};

/// A built-in scene compiled for space `S`.
pub fn model<S: Space>(name: &str) -> Model<S> {
    let scene: Scene = builtin::scene(name).expect("built-in scene").expect("parses");
    Model::compile(&scene, name).expect("compiles")
}

/// The paper's testbed.
pub fn testbed() -> Model<Planar> {
    model("paper-testbed")
}

/// A VE on `model` with `config`.
pub fn core<S: Space>(model: Model<S>, config: VeConfig) -> VeCore<S> {
    VeCore::new(model, config).expect("valid config")
}

/// A device able to push 50 N / 5 N·m.
pub fn device(k: usize) -> DeviceCaps {
    DeviceCaps {
        max_force_n: 50.0,
        continuous_force_n: 25.0,
        max_torque_nm: 5.0,
        max_stiffness_n_per_m: 3000.0,
        max_damping_ns_per_m: 50.0,
        ..DeviceCaps::generous("test device", k)
    }
}

/// A join request for `op` with `role`, mapped one to one (the tests speak in VE units).
pub fn request(name: &str, role: Role, op: &str, k: usize) -> JoinRequest {
    JoinRequest {
        name: name.into(),
        role,
        op: op.into(),
        form: LocalModelForm::OpSpace,
        device: Some(device(k)),
        mapping: MappingRequest { position_scale: Some(1.0), force_scale: Some(1.0), gravity_compensation: false },
    }
}

/// An uplink whose local model sits where `snapshot` put the OP ("following along"), with hand wrench `hand`,
/// answering that snapshot at once (so the VE measures the round trip: a tick).
pub fn following(snapshot: &Snapshot, seq: u64, hand: &[f64]) -> Uplink {
    Uplink { last_snapshot_seq: snapshot.seq, ..uplink(seq, hand, &snapshot.op_pose, &snapshot.op_twist) }
}

/// An uplink with the given hand wrench and local-model pose and twist.
pub fn uplink(seq: u64, hand: &[f64], pose: &[f64], twist: &[f64]) -> Uplink {
    Uplink {
        seq,
        client_time_s: seq as f64 * 1e-3,
        last_snapshot_seq: 0,
        last_snapshot_age_s: 0.0,
        hand_wrench: hand.to_vec(),
        device_pose: pose.to_vec(),
        device_twist: twist.to_vec(),
        model_pose: pose.to_vec(),
        model_twist: twist.to_vec(),
        flags: 0,
        energy: kinloop_protocol::PortEnergy::zero(twist.len()),
    }
}

/// Runs ticks until `core.poll_timeout()` passes `until`, calling `each(core, now)` before every tick and
/// collecting each user's newest snapshot into `latest` (indexed by user id).
pub fn run<S: Space>(
    core: &mut VeCore<S>,
    until: Duration,
    latest: &mut Vec<Option<Snapshot>>,
    mut each: impl FnMut(&mut VeCore<S>, Duration, &[Option<Snapshot>]),
) {
    while core.poll_timeout() <= until {
        let now = core.poll_timeout();
        each(core, now, latest);
        core.handle_timeout(now);
        while let Some(pending) = core.poll_snapshot() {
            let id = pending.user_id() as usize;
            if latest.len() <= id {
                latest.resize(id + 1, None);
            }
            latest[id] = Some(pending.snapshot().clone());
        }
    }
}

/// Joins each `(name, role, op)` at time zero; their ids, in order.
pub fn join_all<S: Space>(core: &mut VeCore<S>, joins: &[(&str, Role, &str)]) -> Vec<u32> {
    let k = S::DIM;
    joins
        .iter()
        .map(|(name, role, op)| core.join(Duration::ZERO, request(name, *role, op, k)).unwrap().user_id)
        .collect()
}

/// Runs until `until` (as [`run`]) with user `ids[i]` pushing `hands[i]` while its local model follows its
/// newest snapshot; returns each user's newest snapshot (indexed by user id) and how many uplinks the VE
/// refused.
pub fn run_following<S: Space>(
    core: &mut VeCore<S>,
    until: Duration,
    ids: &[u32],
    hands: &[[f64; 3]],
) -> (Vec<Option<Snapshot>>, usize) {
    let mut latest = Vec::new();
    let (mut seq, mut refused) = (0, 0);
    run(core, until, &mut latest, |core, now, latest| {
        seq += 1;
        for (id, hand) in ids.iter().zip(hands) {
            if let Some(Some(s)) = latest.get(*id as usize) {
                refused += core.handle_uplink(now, *id, &following(s, seq, hand)).is_err() as usize;
            }
        }
    });
    (latest, refused)
}
