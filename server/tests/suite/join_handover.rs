//! The join's handover (`kinloop_server::core::handover`): a linkage that waited at rest is handed to its
//! first holder without a drop.

use crate::support;

use std::time::Duration;

use kinloop_linkage::math::space::{OpPose, Planar};
use kinloop_protocol::Role;
use kinloop_server::core::VeConfig;

use support::*;

/// How far the OP strays from the grasp over a session in which a manipulator joins the Watt six-bar at
/// rest and holds the grasp pose (its local model there, still, no hand wrench): the largest distance during
/// the coupling's fade-in, over the whole session, and at its end; and the speed left at the end.
fn held_at_the_grasp(op: &str) -> (f64, f64, f64, f64) {
    let mut ve = core(model::<Planar>("watt-six-bar"), VeConfig::default());
    let fade = ve.config().fade_time;
    let id = ve.join(Duration::ZERO, request("A", Role::Manipulator, op, 3)).unwrap().user_id;
    let grasp: OpPose<Planar> = ve.state().users().next().unwrap().op_pose;
    let mut pose = vec![0.0; 3];
    grasp.to_slice(&mut pose);
    let (mut seq, mut in_fade, mut peak, mut last) = (0, 0.0f64, 0.0f64, 0.0);
    run(&mut ve, Duration::from_secs(3), &mut Vec::new(), |ve, now, _| {
        seq += 1;
        ve.handle_uplink(now, id, &uplink(seq, &[0.0; 3], &pose, &[0.0; 3])).unwrap();
        let at: OpPose<Planar> = ve.state().users().next().unwrap().op_pose;
        last = (at.position - grasp.position).norm();
        peak = peak.max(last);
        if now <= fade {
            in_fade = in_fade.max(last);
        }
    });
    assert_eq!(ve.metrics().state_restores, 0);
    (in_fade, peak, last, ve.state().qd.amax())
}

/// Handed over, the OP sinks into the coupling's spring without passing where it comes to rest, and does not
/// move while the coupling fades in; a join that let the linkage fall while the coupling faded in overshoots
/// its rest several times over, most of it during the fade.
#[test]
fn a_resting_linkage_is_handed_to_its_first_holder_without_a_drop() {
    for op in ["link5", "coupler"] {
        let (in_fade, peak, rest, speed) = held_at_the_grasp(op);
        println!("{op}: during the fade {in_fade:.3e} m, peak {peak:.3e} m, at rest {rest:.3e} m");
        assert!(speed < 1e-4, "{op}: settled at the end ({speed} rad/s)");
        assert!(rest > 0.0, "{op}: the spring holds the load a little below the grasp");
        assert!(peak <= 1.02 * rest, "{op}: the OP overshot its rest: peak {peak} m against {rest} m");
        assert!(in_fade <= 0.05 * rest, "{op}: the OP moved during the fade-in: {in_fade} m against {rest} m");
    }
}
