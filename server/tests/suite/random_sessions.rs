//! Random sessions: on every built-in scene, users join (with known and unknown OPs, odd devices, both roles
//! and both local-model forms), leave (known and unknown ids), push (following their snapshots, far off
//! them, with odd numbers, stale and repeated sequence numbers) while virtual time moves on in small steps,
//! in jumps past the catch-up limit, and backwards. Whatever happens, nothing panics, the VE's state stays
//! finite with its loops closed, every snapshot sent passes the receiver's wire checks and goes to a present
//! user, and the metrics add up.

use crate::support;

use std::time::Duration;

use kinloop_linkage::model::builtin::SCENE_FILES;
use kinloop_linkage::testing::TestRng;
use kinloop_linkage::{math::space::Planar, math::space::Space, math::space::Spatial};
use kinloop_protocol::codec::validate;
use kinloop_protocol::{DeviceCaps, LocalModelForm, MappingRequest, Role, Snapshot};
use kinloop_server::core::{JoinRequest, VeConfig, VeCore};
use support::{core, device, model, uplink};

const OPERATIONS: usize = 6000;

/// A device description, now and then with odd limits.
fn some_device(rng: &mut TestRng, dof: usize) -> Option<DeviceCaps> {
    let mut caps = device(dof);
    match rng.below(6) {
        0 => None,
        1 => {
            caps.max_force_n = rng.odd();
            caps.max_stiffness_n_per_m = rng.odd();
            Some(caps)
        }
        2 => {
            caps.dof = rng.below(9) as u8;
            caps.workspace_max.truncate(rng.below(dof + 1));
            Some(caps)
        }
        _ => Some(caps),
    }
}

fn session<S: Space>(scene: &str, seed: u64) {
    let model = model::<S>(scene);
    let ops: Vec<String> = model.ops.iter().map(|op| op.name.clone()).collect();
    let length_scale = model.length_scale;
    let mut ve: VeCore<S> = core(model, VeConfig::paper());
    let shape = ve.session_shape();
    let mut rng = TestRng(seed);
    let mut now = Duration::ZERO;
    // Per user id: present, the next sequence number, the newest snapshot.
    let mut present: Vec<bool> = Vec::new();
    let mut seqs: Vec<u64> = Vec::new();
    let mut latest: Vec<Option<Snapshot>> = Vec::new();
    let (mut joins, mut refusals, mut leaves) = (0u64, 0u64, 0u64);
    let mut sent = 0u64;
    for operation in 0..OPERATIONS {
        let context = format!("{scene}, seed {seed}, operation {operation}");
        match rng.below(20) {
            0 => {
                let op = if rng.chance(0.8) { ops[rng.below(ops.len())].clone() } else { "no-such-op".into() };
                let role = if rng.chance(0.8) { Role::Manipulator } else { Role::Observer };
                let form = if rng.chance(0.7) { LocalModelForm::OpSpace } else { LocalModelForm::ConfigSpace };
                let device = some_device(&mut rng, S::DIM);
                // Now and then a mapping asked for with odd scales: refused or used, never a panic.
                let odd_scale = |rng: &mut TestRng| rng.chance(0.2).then(|| rng.odd());
                let mapping = MappingRequest {
                    position_scale: odd_scale(&mut rng),
                    force_scale: odd_scale(&mut rng),
                    gravity_compensation: rng.chance(0.3),
                };
                match ve.join(now, JoinRequest { name: format!("u{operation}"), role, op, form, device, mapping }) {
                    Ok(joined) => {
                        let id = joined.user_id as usize;
                        if present.len() <= id {
                            present.resize(id + 1, false);
                            seqs.resize(id + 1, 1);
                            latest.resize(id + 1, None);
                        }
                        assert!(!present[id], "{context}: id {id} given twice");
                        present[id] = true;
                        joins += 1;
                    }
                    Err(_) => refusals += 1,
                }
            }
            1 => {
                // Present users may leave; ids never given are unknown; a user who left is known while its
                // coupling fades out, and unknown once removed.
                let id = rng.below(present.len() + 2);
                let left = ve.leave(now, id as u32);
                if present.get(id).copied().unwrap_or(false) {
                    assert!(left.is_ok(), "{context}: leave of present user {id}");
                    present[id] = false;
                    leaves += 1;
                } else if id >= present.len() {
                    assert!(left.is_err(), "{context}: leave of never-joined id {id}");
                }
            }
            2 => {
                // Time jumps: past the catch-up limit, or backwards (which must change nothing).
                if rng.chance(0.5) {
                    now += Duration::from_millis(50 + rng.below(2000) as u64);
                } else {
                    let before = ve.state().q.clone_owned();
                    ve.handle_timeout(now.saturating_sub(Duration::from_millis(rng.below(50) as u64 + 1)));
                    assert_eq!(ve.state().q, &before, "{context}: a tick ran at a past time");
                }
            }
            _ => {
                let users: Vec<usize> = (0..present.len()).filter(|&id| present[id]).collect();
                for &id in &users {
                    let Some(snapshot) = &latest[id] else { continue };
                    let mut hand = vec![0.0; S::DIM];
                    for h in &mut hand {
                        *h = 2.0 * rng.signed();
                    }
                    let mut pose = snapshot.op_pose.clone();
                    let mut twist = snapshot.op_twist.clone();
                    let seq = if rng.chance(0.05) { seqs[id].saturating_sub(rng.below(3) as u64) } else { seqs[id] };
                    let (i, odd, off) = (rng.below(S::DIM), rng.odd(), 0.05 * rng.signed());
                    let (p, t) = (i % pose.len(), i % twist.len());
                    match rng.below(25) {
                        0 => hand[i] = odd,
                        1 => pose[p] += odd,
                        2 => twist[t] = odd,
                        3 => pose[p] += off,
                        4 => hand.truncate(i),
                        _ => {}
                    }
                    let _ = ve.handle_uplink(now, id as u32, &uplink(seq, &hand, &pose, &twist));
                    seqs[id] = seqs[id].max(seq + 1);
                }
                now += Duration::from_micros(rng.below(3000) as u64);
            }
        }
        ve.handle_timeout(now);
        while let Some(pending) = ve.poll_snapshot() {
            let id = pending.user_id() as usize;
            assert!(present.get(id).copied().unwrap_or(false), "{context}: a snapshot for absent user {id}");
            let snapshot = pending.snapshot().clone();
            if let Err(e) = validate::snapshot(&snapshot, &shape) {
                panic!("{context}: a snapshot the receiver would refuse: {e}");
            }
            latest[id] = Some(snapshot);
            sent += 1;
        }
        // A snapshot may be withheld for its own OP's terms (a linkage yanked beyond the wire's ranges).
        while ve.poll_event().is_some() {}
        let state = ve.state();
        assert!(state.q.iter().chain(state.qd.iter()).all(|x| x.is_finite()), "{context}: state not finite");
        assert!(state.closure_error <= 1e-6 * length_scale, "{context}: closure {:.3e}", state.closure_error);
    }
    // Long enough for every leaving user's coupling to fade out and the user to be removed.
    for _ in 0..2000 {
        now += Duration::from_millis(1);
        ve.handle_timeout(now);
        while ve.poll_snapshot().is_some() {
            sent += 1;
        }
    }
    let metrics = ve.metrics();
    let context = format!("{scene}, seed {seed}: {metrics:?}");
    assert_eq!(metrics.users as usize, present.iter().filter(|p| **p).count(), "{context}");
    assert_eq!(
        (metrics.users_joined, metrics.users_left, metrics.joins_refused),
        (joins, leaves, refusals),
        "{context}"
    );
    assert_eq!(metrics.snapshots_built, sent, "{context}");
    // The session did what it was meant to: users came and went, pushed, and were refused and rejected.
    assert!(joins >= 10 && leaves >= 3 && refusals >= 3 && sent >= 1000, "{context}");
    assert!(
        metrics.uplinks_accepted >= 1000 && metrics.uplinks_rejected >= 10 && metrics.skipped_ticks > 0,
        "{context}"
    );
}

#[test]
fn random_sessions_keep_the_ve_sound_on_every_scene() {
    for (seed, (scene, text)) in SCENE_FILES.iter().enumerate() {
        if text.contains("kind = \"spatial\"") {
            session::<Spatial>(scene, seed as u64 + 1);
        } else {
            session::<Planar>(scene, seed as u64 + 1);
        }
    }
}
