//! VeCore in virtual time: the paper's manipulation, users pulling against each other, joins and leaves,
//! hostile uplinks, passivity.

mod support;

use std::time::Duration;

use kinloop_linkage::builtin::PAPER_WRENCH;
use kinloop_protocol::Role;
use kinloop_server::core::VeConfig;

use support::*;

/// The paper's manipulation: F_h = (−0.5 N, 0, −0.0025 N m) at the COM of link 2 for 10 s at 1 kHz, the
/// user's local model following the VE; the loop stays closed to 1e-9 m.
#[test]
fn paper_manipulation_keeps_the_loop_closed_to_1e_9_m_for_10_s() {
    let mut ve = core(testbed(), VeConfig::paper());
    let user = ve.join(Duration::ZERO, request("paper", Role::Manipulator, "link2", 3)).unwrap().user_id;
    let mut latest = Vec::new();
    let mut seq = 0;
    let mut worst: f64 = 0.0;
    run(&mut ve, Duration::from_secs(10), &mut latest, |ve, now, latest| {
        if let Some(Some(s)) = latest.get(user as usize) {
            seq += 1;
            ve.handle_uplink(now, user, &following(s, seq, &PAPER_WRENCH)).unwrap();
        }
        worst = worst.max(ve.state().closure_error);
    });
    let metrics = ve.metrics();
    assert_eq!(metrics.ticks, 10_000);
    assert_eq!(metrics.state_restores, 0);
    assert!(worst <= 1e-9, "closure error reached {worst:e} m");
    assert!(metrics.max_closure_error <= 1e-9);
    // The linkage did move: the force channel pushed it.
    let moved = (ve.state().q - &ve.model().q0).norm();
    assert!(moved > 0.1, "the linkage barely moved ({moved} rad)");
}
