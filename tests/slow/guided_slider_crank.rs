//! The guided slider-crank (a cut with a spring and viscous friction, a crank with stops) renders with
//! default settings in virtual time: every pair of its renderability matrix on a perfect network, a touring
//! hand over the whole tour, within the experiment's bounds (stable, ≤ 5 % of ticks clamped, device-OP RMS
//! ≤ 5 mm).

use kinloop::experiments::renderability::{evaluate, points, Network, SECONDS};
use kinloop_client::user::HandKind;

#[test]
fn the_guided_slider_crank_renders_on_every_device_by_default() {
    // A heavy loop: it waits for the real-time sessions of the other tests rather than take a core from them.
    let _serial = crate::common::serial();
    let pairs = points(&["guided-slider-crank"], &[HandKind::Soft, HandKind::Firm]).unwrap();
    let perfect: Vec<_> = pairs.into_iter().filter(|p| p.network == Network::Perfect).collect();
    assert_eq!(perfect.len(), 2 * 3 * 2, "two OPs x three devices x two hands");
    for p in perfect {
        let r = evaluate(&p, SECONDS).unwrap();
        let said = format!(
            "{} on {:?}, {:?} hand: clamped {:.2} %, RMS {:.2} mm, failures {:?}",
            p.op,
            p.device,
            p.hand,
            r.clamped_fraction * 100.0,
            r.device_op_rms_m * 1e3,
            r.failures
        );
        eprintln!("{said}");
        assert!(r.renders, "{said}");
    }
}
