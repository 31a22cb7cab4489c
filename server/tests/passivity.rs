//! The time-domain passivity controller keeps a delayed coupling from pumping energy into the VE.

mod support;

use std::collections::VecDeque;
use std::time::Duration;

use kinloop_linkage::local_model::OpPose;
use kinloop_linkage::Planar;
use kinloop_protocol::Role;
use kinloop_server::core::AxisGains;
use kinloop_server::core::VeConfig;

use support::*;

/// A client whose local model is a free mass tied by a spring-damper to the VE's OP as it last heard of
/// it, with `delay` each way: position-position teleoperation through a delayed channel, a textbook way
/// for a coupling to generate energy. Returns the VE's kinetic energy every 10 ms and the coupling's energy
/// account at the end (J absorbed; negative: generated).
fn delayed_mass_client(passivity: bool, delay_ticks: usize, seconds: u64) -> (Vec<f64>, f64) {
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
            up.push_back(uplink(seq, &[0.0; 3], xc, &v));
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
        let (plain, _) = delayed_mass_client(false, delay_ms, 5);
        let (passive, account) = delayed_mass_client(true, delay_ms, 5);
        let (plain, passive) = (peak(&plain), peak(&passive));
        // Without the controller the delayed loop pumps far more energy into the VE than the coupling ever
        // held; with it the VE never gains more than that, and the coupling generated at most its allowance
        // on each of its three axes (plus a tick's worth).
        assert!(plain > 100.0 * STORED_AT_START_J, "delay {delay_ms} ms: plain coupling peaked at {plain:e} J");
        assert!(passive <= STORED_AT_START_J, "delay {delay_ms} ms: passive coupling reached {passive:e} J");
        assert!(account >= -3.3 * allowance, "delay {delay_ms} ms: the coupling generated {} J", -account);
    }
}
