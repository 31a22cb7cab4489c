//! The graphics controller's frequency follows the round trip the server measured when the user joined, and
//! only softens mid-session (`design::CouplingFrequency`, docs/robustness.md).

use crate::support;

use std::collections::VecDeque;
use std::f64::consts::TAU;
use std::time::Duration;

use kinloop_linkage::math::space::Planar;
use kinloop_protocol::{Role, Snapshot, Uplink};
use kinloop_server::core::{VeConfig, VeCore};

use support::*;

/// The welcome's gains for a manipulator of the testbed's link 2 joining `ve` over `round_trip`.
fn joined_gains(ve: &mut VeCore<Planar>, round_trip: Option<Duration>) -> (Vec<f64>, Vec<f64>) {
    let request = request("u", Role::Manipulator, "link2", 3);
    let joined = match round_trip {
        Some(_) => ve.join_measured(Duration::ZERO, request, round_trip),
        None => ve.join(Duration::ZERO, request),
    };
    let coupling = joined.expect("joins").welcome.coupling;
    (coupling.stiffness, coupling.damping)
}

/// A user over a loopback-fast link (no round trip, or a millisecond) gets 20 Hz, the rate margins' cap at
/// 1 kHz; 1.25 ms gets 16 Hz; a 100 ms round trip gets the default 8 Hz, as a join whose round trip was not
/// measured does. The gains are checked against `K = m ω²`, `B = 2 m ω` from the OP's lightest effective mass
/// over its reach, computed here from the survey.
#[test]
fn a_user_over_a_slow_link_gets_the_default_gains_and_one_over_a_fast_link_stiffer_ones() {
    let mut ve = core(testbed(), VeConfig::default());
    let op = ve.model().op_index("link2").expect("link2 is an OP");
    let reach = ve.reach(op).expect("surveyed");
    let (mass, inertia) = (1.0 / reach.inverse_mass_max, 1.0 / reach.inverse_rotational_inertia_max);
    let cases = [
        (Some(Duration::ZERO), 20.0),
        (Some(Duration::from_millis(1)), 20.0),
        (Some(Duration::from_micros(1250)), 16.0),
        (Some(Duration::from_millis(100)), 8.0),
        (None, 8.0),
    ];
    for (round_trip, hz) in cases {
        let (stiffness, damping) = joined_gains(&mut ve, round_trip);
        let omega = TAU * hz;
        for (a, m) in [mass, mass, inertia].into_iter().enumerate() {
            let close = |got: f64, want: f64| (got - want).abs() <= 1e-9 * want;
            assert!(close(stiffness[a], m * omega * omega), "{round_trip:?}, axis {a}: K {}", stiffness[a]);
            assert!(close(damping[a], 2.0 * m * omega), "{round_trip:?}, axis {a}: B {}", damping[a]);
        }
    }
}

/// A user joins over a fast link and pushes link 2 while its local model follows the VE, answering each
/// snapshot at once (the VE measures a tick's round trip, which keeps the 20 Hz); after a second its answers
/// come 100 ms late (`round_trip`). The coupling softens to the default 8 Hz and its K never rises on any uplink. At each
/// change the VE's mechanical energy stays what it was and the spring `½ w K e²` (computed here from the
/// coupling's target and the OP's pose) holds no more than before, so the change puts no energy in.
#[test]
fn a_round_trip_that_grows_mid_session_only_softens_the_coupling() {
    let mut ve = core(testbed(), VeConfig::default());
    let user = ve.join_measured(Duration::ZERO, request("u", Role::Manipulator, "link2", 3), Some(Duration::ZERO));
    let user = user.expect("joins").user_id;
    let stiffness = |ve: &VeCore<Planar>| ve.state().users().next().expect("one user").coupling_stiffness;
    let joined = stiffness(&ve);
    let spring = |ve: &VeCore<Planar>, k: &nalgebra::Vector3<f64>| {
        let u = ve.state().users().next().expect("one user");
        let e = u.coupling_target.difference(&u.op_pose);
        (0..3).map(|a| 0.5 * u.weight * k[a] * e[a] * e[a]).sum::<f64>()
    };
    let push = [-0.3, 0.2, 0.0];
    let (mut seq, mut changes, mut stiffest) = (0, 0, joined);
    let mut heard: VecDeque<Snapshot> = VecDeque::new();
    let mut latest = Vec::new();
    run(&mut ve, Duration::from_secs(3), &mut latest, |ve, now, latest| {
        let Some(Some(newest)) = latest.get(user as usize) else { return };
        if heard.back().is_none_or(|s| s.seq != newest.seq) {
            heard.push_back(newest.clone());
        }
        let lag = if now < Duration::from_secs(1) { 0 } else { 100 };
        while heard.len() > lag + 1 {
            heard.pop_front();
        }
        let answered = heard.front().expect("one heard");
        seq += 1;
        let up = Uplink { last_snapshot_seq: answered.seq, ..uplink(seq, &push, &newest.op_pose, &newest.op_twist) };
        let before = stiffness(ve);
        let (kinetic, potential) = ve.mechanical_energy();
        ve.handle_uplink(now, user, &up).expect("a sane uplink");
        let after = stiffness(ve);
        assert!((0..3).all(|a| after[a] <= stiffest[a]), "K rose at {now:?}: {after:?} after {stiffest:?}");
        stiffest = after;
        if after != before {
            assert!(now > Duration::from_secs(1), "softened at {now:?} on a fast link");
            changes += 1;
            let (kinetic_after, potential_after) = ve.mechanical_energy();
            assert_eq!(kinetic_after + potential_after, kinetic + potential);
            let (held_before, held_after) = (spring(ve, &before), spring(ve, &after));
            assert!(held_after <= held_before, "the spring gained {} at {now:?}", held_after - held_before);
        }
    });
    assert!(changes >= 1, "the coupling never softened");
    assert_eq!(ve.metrics().couplings_softened, changes);
    let ratio = (8.0f64 / 20.0).powi(2);
    let last = stiffness(&ve);
    assert!((0..3).all(|a| (last[a] - joined[a] * ratio).abs() <= 1e-9 * joined[a]), "{last:?} from {joined:?}");
    assert_eq!(ve.metrics().state_restores, 0);
}
