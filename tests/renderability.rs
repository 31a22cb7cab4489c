//! Pairs of the renderability matrix that a light operational point makes hard, run over the touring hand's
//! whole tour at 50 ms one way (`kinloop experiment renderability` runs all 196 pairs; CI runs these).

use kinloop::experiments::renderability::{evaluate, Network, Point, SECONDS};
use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::HandKind;

fn pair(scene: &str, op: &str, device: DevicePreset, hand: HandKind) -> Point {
    Point { scene: scene.into(), op: op.into(), device, network: Network::Delayed50, hand }
}

/// The Watt six-bar's output link and the slider-crank's crank tip are light and turn fast under the hand; at
/// 50 ms one way, with the local model's free directions compared with the model's own state that the VE
/// answered (a Smith predictor) instead of with the VE's state predicted to now, the six-bar saturated a Touch
/// on 77 % of its ticks and grew energy on a Falcon, and the crank tip grew energy on a Falcon.
#[test]
fn light_outputs_render_on_weak_devices_at_50_ms_over_a_whole_tour() {
    let pairs = [
        pair("watt-six-bar", "link5", DevicePreset::Touch, HandKind::Firm),
        pair("watt-six-bar", "link5", DevicePreset::Touch, HandKind::Soft),
        pair("watt-six-bar", "link5", DevicePreset::Falcon, HandKind::Soft),
        pair("slider-crank", "crank-tip", DevicePreset::Falcon, HandKind::Soft),
    ];
    for p in pairs {
        let r = evaluate(&p, SECONDS).unwrap();
        assert!(
            r.renders,
            "{}:{} on {:?}, {:?} hand: {:?} (clamped {:.1} %, RMS {:.1} mm)",
            p.scene,
            p.op,
            p.device,
            p.hand,
            r.failures,
            r.clamped_fraction * 100.0,
            r.device_op_rms_m * 1e3
        );
    }
}
