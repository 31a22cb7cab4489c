//! How the VE measures each user's round trip (`round_trip`), in virtual time: where a sample is dated.

use crate::support;

use std::time::Duration;

use kinloop_protocol::Role;
use kinloop_server::core::VeConfig;

use support::*;

/// The VE dates a round-trip sample at the uplink's arrival: an uplink that waited in the driver's ring for
/// the VE's tick (`UplinkSample::waited_s`) gives the trip less that wait, so the sharing rule judges the
/// network, not the VE's tick quantum. Two users answer each snapshot at the next tick (a trip of one 1 ms
/// tick as the VE takes the uplinks in); said to have waited 0.9 ms of it, the trip is 0.1 ms. A wait longer
/// than the trip leaves no sample, and a wait that is not a number counts as none.
#[test]
fn a_round_trip_sample_is_dated_at_the_uplinks_arrival() {
    use kinloop_server::core::metrics::{bin, SharingMetrics};
    use kinloop_server::core::UplinkSample;

    let sharing_with = |waited_s: f64| -> SharingMetrics {
        let mut ve = core(testbed(), VeConfig::paper());
        let ids = join_all(&mut ve, &[("A", Role::Manipulator, "link2"), ("B", Role::Manipulator, "link2")]);
        let hands = [[-0.5, 0.1, -0.002], [0.2, -0.3, 0.001]];
        let (mut latest, mut seq) = (Vec::new(), 0);
        run(&mut ve, Duration::from_millis(400), &mut latest, |ve, now, latest| {
            seq += 1;
            for (id, hand) in ids.iter().zip(&hands) {
                if let Some(Some(s)) = latest.get(*id as usize) {
                    let mut sample = UplinkSample::from_uplink(&following(s, seq, hand)).expect("fits");
                    sample.waited_s = waited_s;
                    ve.handle_uplink_sample(now, *id, &sample).expect("accepted");
                }
            }
        });
        ve.metrics().sharing
    };
    let at_the_tick = sharing_with(0.0);
    let about_a_tick = at_the_tick.sample_bins[bin(0.9e-3)] + at_the_tick.sample_bins[bin(1.1e-3)];
    assert!(at_the_tick.samples > 150 && about_a_tick == at_the_tick.samples, "{at_the_tick:?}");
    let arrived_earlier = sharing_with(0.9e-3);
    assert_eq!(arrived_earlier.samples, at_the_tick.samples);
    assert_eq!(arrived_earlier.sample_bins[bin(0.1e-3)], arrived_earlier.samples, "{arrived_earlier:?}");
    // Two users over either trip take each other whole: every round judged, none weighted once both are
    // measured.
    let s = arrived_earlier;
    assert!(s.rounds > 350 && s.rounds_weighted == s.rounds_unmeasured && s.rounds_unmeasured < 10, "{s:?}");
    assert_eq!(sharing_with(5e-3).samples, 0, "a wait longer than the trip");
    assert_eq!(sharing_with(f64::NAN).sample_bins, at_the_tick.sample_bins, "no number: no wait");
}
