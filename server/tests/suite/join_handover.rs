//! The join's handover (`kinloop_server::core::handover`): a linkage that waited at rest is handed to its
//! first holder without a drop.

use crate::support;

use std::time::Duration;

use kinloop_linkage::math::space::{OpPose, Planar};
use kinloop_protocol::Role;
use kinloop_server::core::VeConfig;

use support::*;

/// How far the OP strays from the grasp over a session in which a manipulator joins the Watt six-bar at
/// rest over a link whose round trip the driver measured as `measured` (none: not measured, heard at once),
/// and holds the grasp pose (its local
/// model there, still, no hand wrench) from its first uplink on, which the VE hears a round trip after the
/// join: the largest distance during the coupling's fade-in, over the whole session, and at its end; the
/// largest before the first uplink; the coupling's weight just before it; and the speed left at the end.
fn held_at_the_grasp(op: &str, measured: Option<Duration>) -> Held {
    let round_trip = measured.unwrap_or(Duration::ZERO);
    let mut ve = core(model::<Planar>("watt-six-bar"), VeConfig::default());
    let fade = ve.config().fade_time;
    let id = ve.join_measured(Duration::ZERO, request("A", Role::Manipulator, op, 3), measured).unwrap().user_id;
    let grasp: OpPose<Planar> = ve.state().users().next().unwrap().op_pose;
    let mut pose = vec![0.0; 3];
    grasp.to_slice(&mut pose);
    let mut held = Held { in_fade: 0.0, unheard: 0.0, weight_unheard: 0.0, peak: 0.0, rest: 0.0, speed: 0.0 };
    let mut seq = 0;
    // The hold lets go over the fade and `ANSWER_ROUND_TRIPS` round trips once heard; then 3 s to settle.
    let letting_go = round_trip.mul_f64(1.0 + kinloop_server::core::handover::ANSWER_ROUND_TRIPS) + fade;
    run(&mut ve, letting_go + Duration::from_secs(3), &mut Vec::new(), |ve, now, _| {
        let user = ve.state().users().next().unwrap();
        let heard = now >= round_trip;
        if heard {
            seq += 1;
            ve.handle_uplink(now, id, &uplink(seq, &[0.0; 3], &pose, &[0.0; 3])).unwrap();
        } else {
            held.weight_unheard = user.weight;
        }
        let at: OpPose<Planar> = ve.state().users().next().unwrap().op_pose;
        held.rest = (at.position - grasp.position).norm();
        held.peak = held.peak.max(held.rest);
        if now <= fade {
            held.in_fade = held.in_fade.max(held.rest);
        }
        if !heard {
            held.unheard = held.unheard.max(held.rest);
        }
    });
    assert_eq!(ve.metrics().state_restores, 0);
    held.speed = ve.state().qd.amax();
    held
}

/// What [`held_at_the_grasp`] measured (m, rad/s).
struct Held {
    in_fade: f64,
    unheard: f64,
    weight_unheard: f64,
    peak: f64,
    rest: f64,
    speed: f64,
}

/// Handed over, the OP sinks into the coupling's spring without passing where it comes to rest, and does not
/// move while the coupling fades in; a join that let the linkage fall while the coupling faded in overshoots
/// its rest several times over, most of it during the fade.
#[test]
fn a_resting_linkage_is_handed_to_its_first_holder_without_a_drop() {
    for op in ["link5", "coupler"] {
        let Held { in_fade, peak, rest, speed, .. } = held_at_the_grasp(op, None);
        println!("{op}: during the fade {in_fade:.3e} m, peak {peak:.3e} m, at rest {rest:.3e} m");
        assert!(speed < 1e-4, "{op}: settled at the end ({speed} rad/s)");
        assert!(rest > 0.0, "{op}: the spring holds the load a little below the grasp");
        assert!(peak <= 1.02 * rest, "{op}: the OP overshot its rest: peak {peak} m against {rest} m");
        assert!(in_fade <= 0.05 * rest, "{op}: the OP moved during the fade-in: {in_fade} m against {rest} m");
    }
}

/// Over a round trip longer than the silent timeout (600 ms, 300 ms each way) the grasp holds the linkage where
/// the user's local model starts, at rest, until the first uplink can arrive: the coupling stays fully in
/// and the OP does not move; the load then passes to the coupling once it has heard its user, and the OP sinks
/// into the spring without passing its rest. A grasp judged silent 250 ms after the join faded out before any
/// uplink could come, with the load handed to a PD that no hand held: the linkage fell away from the pose the
/// user's model started at.
#[test]
fn over_a_long_round_trip_the_grasp_holds_the_linkage_until_its_user_is_heard() {
    let round_trip = Duration::from_millis(600);
    assert!(round_trip > kinloop_server::core::VeConfig::default().silent_timeout);
    for op in ["link5", "coupler"] {
        let Held { unheard, weight_unheard, peak, rest, speed, .. } = held_at_the_grasp(op, Some(round_trip));
        println!("{op}: before the first uplink {unheard:.3e} m (weight {weight_unheard}), peak {peak:.3e} m, at rest {rest:.3e} m");
        assert_eq!(weight_unheard, 1.0, "{op}: the grasp faded before its user could be heard");
        assert!(rest > 0.0, "{op}: the spring holds the load a little below the grasp");
        assert!(unheard <= 0.01 * rest, "{op}: the OP moved before its user was heard: {unheard} m against {rest} m");
        assert!(peak <= 1.02 * rest, "{op}: the OP overshot its rest: peak {peak} m against {rest} m");
        assert!(speed < 1e-4, "{op}: settled at the end ({speed} rad/s)");
    }
}
