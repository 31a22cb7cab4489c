//! The time-domain passivity controller keeps a delayed coupling from pumping energy into the VE.

use crate::support;

use std::collections::VecDeque;
use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::Planar;
use kinloop_protocol::Role;
use kinloop_server::core::AxisGains;
use kinloop_server::core::VeConfig;

use support::*;

/// A client whose local model is a free mass tied by a spring-damper to the VE's OP as it last heard of
/// it, with `delay` each way: position-position teleoperation through a delayed channel, a textbook way
/// for a coupling to generate energy. Returns the VE's kinetic energy every 10 ms and the coupling's energy
/// account at the end (J absorbed; negative: generated). A `lying` client claims in every uplink to have put
/// 10 J/s into its end of the two-port on every axis (its model wrench is zero: it put in nothing).
fn delayed_mass_client(passivity: bool, delay_ticks: usize, seconds: u64, lying: bool) -> (Vec<f64>, f64) {
    let mut config = VeConfig::paper();
    config.passivity = passivity;
    config.coupling_damping = Some(AxisGains::Uniform { linear: 2.0, angular: 0.01 });
    let mut ve = core(testbed(), config);
    let user = ve.join(Duration::ZERO, request("delayed", Role::Manipulator, "link2", 3)).unwrap().user_id;
    let dt = 1e-3;
    // Client: point mass + rotor in (x, y, θ), spring/damper toward the delayed VE pose.
    let (mass, inertia) = (0.5, 0.002);
    let (k_c, b_c) = ([400.0, 400.0, 1.0], [0.0, 0.0, 0.0]);
    let mut down: VecDeque<(Vec<f64>, Vec<f64>)> = VecDeque::new(); // snapshots in flight
    let mut up: VecDeque<kinloop_protocol::Uplink> = VecDeque::new(); // uplinks in flight
    let mut heard: Option<(Vec<f64>, Vec<f64>)> = None;
    let mut x: Option<[f64; 3]> = None;
    let mut v = [0.0; 3];
    let mut seq = 0;
    let mut energies = Vec::new();
    let mut latest = Vec::new();
    let mut tick = 0u64;
    run(&mut ve, Duration::from_secs(seconds), &mut latest, |ve, now, latest| {
        if let Some(Some(s)) = latest.get(user as usize) {
            down.push_back((s.op_pose.clone(), s.op_twist.clone()));
        }
        if down.len() > delay_ticks {
            heard = down.pop_front();
        }
        if let Some((pose, twist)) = &heard {
            let target = OpPose::<Planar>::from_slice(pose).unwrap();
            let xc = x.get_or_insert([pose[0] + 0.01, pose[1], pose[2]]);
            let own = OpPose::<Planar>::from_slice(xc).unwrap();
            let offset = target.difference(&own);
            let offset = [offset[0], offset[1], offset[2]];
            for a in 0..3 {
                let f = k_c[a] * offset[a] + b_c[a] * (twist[a] - v[a]);
                v[a] += dt * f / if a < 2 { mass } else { inertia };
                xc[a] += dt * v[a];
            }
            seq += 1;
            let mut u = uplink(seq, &[0.0; 3], xc, &v);
            if lying {
                u.energy.received_j = vec![10.0 * u.client_time_s; 3];
            }
            up.push_back(u);
        }
        if up.len() > delay_ticks {
            let u = up.pop_front().unwrap();
            let _ = ve.handle_uplink(now, user, &u);
        }
        tick += 1;
        if tick.is_multiple_of(10) {
            energies.push(ve.mechanical_energy().0);
        }
    });
    let account = ve.state().users().next().map_or(f64::NAN, |u| u.passivity.absorbed_j);
    (energies, account)
}

/// Energy the coupling's spring holds at the start: the client's mass starts 1 cm from the VE's OP.
const STORED_AT_START_J: f64 = 0.5 * 1000.0 * 0.01 * 0.01;

#[test]
fn passivity_controller_keeps_a_delayed_coupling_from_pumping_energy() {
    let peak = |e: &[f64]| e.iter().cloned().filter(|x| x.is_finite()).fold(0.0, f64::max);
    let allowance = VeConfig::paper().passivity_allowance_j;
    for delay_ms in [25, 100] {
        let (plain, _) = delayed_mass_client(false, delay_ms, 5, false);
        let (passive, account) = delayed_mass_client(true, delay_ms, 5, false);
        let (plain, passive) = (peak(&plain), peak(&passive));
        // Without the controller the delayed loop pumps far more energy into the VE than the coupling ever
        // held; with it the VE never gains more than that, and the coupling generated at most its allowance and
        // what the ticks in which a prediction of "absorbing" was wrong let through (a fraction of an allowance
        // more): one account for the port, whatever its axes.
        assert!(plain > 100.0 * STORED_AT_START_J, "delay {delay_ms} ms: plain coupling peaked at {plain:e} J");
        assert!(passive <= STORED_AT_START_J, "delay {delay_ms} ms: passive coupling reached {passive:e} J");
        assert!(account >= -1.6 * allowance, "delay {delay_ms} ms: the coupling generated {} J", -account);
    }
}

/// A client that claims energy it never put in buys at most the allowance with it: the server credits the
/// smaller of the claim and its own booking of the client's port (here zero, the model wrench being zero) plus
/// the allowance on each of the three axes, so the liar's coupling stays passive, with at most the honest
/// bound plus three allowances.
#[test]
fn a_client_claiming_energy_it_never_put_in_cannot_make_the_coupling_generate() {
    let peak = |e: &[f64]| e.iter().cloned().filter(|x| x.is_finite()).fold(0.0, f64::max);
    let allowance = VeConfig::paper().passivity_allowance_j;
    for delay_ms in [25, 100] {
        let (lied, account) = delayed_mass_client(true, delay_ms, 5, true);
        let lied = peak(&lied);
        assert!(lied <= STORED_AT_START_J, "delay {delay_ms} ms: the liar's VE reached {lied:e} J");
        assert!(account >= -(1.6 + 3.0) * allowance, "delay {delay_ms} ms: the coupling generated {} J", -account);
    }
}

/// With the passivity controller on, energy books that are non-finite, negative, shrinking or faster than the
/// device can push are refused and counted; the uplink carrying them is still used (its state moves the
/// coupling), and the snapshots carry the coupling's own books, which only grow.
#[test]
fn bad_energy_reports_are_refused_and_counted_and_the_session_carries_on() {
    let config = VeConfig { passivity: true, ..VeConfig::default() };
    let mut ve = core(testbed(), config);
    let user = ve.join(Duration::ZERO, request("books", Role::Manipulator, "link2", 3)).unwrap().user_id;
    let bad: [fn(f64) -> Vec<f64>; 4] = [
        |_| vec![f64::NAN, 0.0, 0.0],
        |_| vec![-1.0, 0.0, 0.0],
        |_| vec![0.0; 3],                  // below the good report before it: shrinking
        |t| vec![1e9 * t + 1.0, 0.0, 0.0], // far beyond 50 N at 200 rad/s over a millisecond
    ];
    let (mut seq, mut latest, mut refused_expected, mut accepted) = (0u64, Vec::new(), 0u64, 0u64);
    let mut books: Vec<(f64, f64)> = Vec::new();
    run(&mut ve, Duration::from_millis(400), &mut latest, |ve, now, latest| {
        let Some(Some(s)) = latest.get(user as usize) else { return };
        books.push((s.energy.received_j.iter().sum(), s.energy.emitted_j.iter().sum()));
        seq += 1;
        let mut u = following(s, seq, &[0.3, 0.0, 0.0]);
        // A good report every tick (0.1 J/s on x), a bad one every 50th.
        u.energy.received_j = vec![0.1 * u.client_time_s, 0.0, 0.0];
        if seq.is_multiple_of(50) {
            u.energy.received_j = bad[(seq / 50) as usize % bad.len()](u.client_time_s);
            refused_expected += 1;
        }
        accepted += ve.handle_uplink(now, user, &u).is_ok() as u64;
    });
    let m = ve.metrics();
    assert!(refused_expected >= 6, "{refused_expected}");
    assert_eq!(m.energy_reports_refused, refused_expected);
    assert_eq!(accepted, seq, "every uplink was used, its energy report apart");
    assert_eq!(m.state_restores, 0);
    assert!(books.windows(2).all(|w| w[1].0 >= w[0].0 && w[1].1 >= w[0].1), "the coupling's books only grow");
    assert!(books.last().is_some_and(|b| b.0 + b.1 > 0.0), "the pushed coupling booked energy: {books:?}");
}
