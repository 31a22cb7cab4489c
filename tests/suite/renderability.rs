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
/// answered (a Smith predictor) instead of with the VE's state predicted to now, the six-bar saturates a Touch
/// and grows energy on a Falcon, and the crank tip grows energy on a Falcon.
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

/// The five-bar robot's effector on `sim:paper` under a firm hand, on a perfect network: in the free
/// directions only the position channels hold the device to the local model, and with a third of the damping
/// budget (the joint-constraint controller took two thirds) they left the device's mass at a damping ratio of
/// 0.3 with the hand on it; where the handle spins near the linkage's singular elbow the controllers then gave
/// the hand more than it put in over the tour (energy growth). With two thirds of the damping in the
/// channels the pair renders, and the same session with the designed gains split the old way still grows
/// energy, more than twice as much.
#[test]
fn the_five_bar_effector_renders_under_a_firm_hand_with_the_damping_in_the_channels() {
    use kinloop::experiments::common::session;
    use kinloop::experiments::verdict::judge;
    use kinloop_client::core::config::{ControllerGains, GainChoice};
    use kinloop_client::user::{HandSpec, UserSpec};
    use kinloop_harness::{ClientPlan, CoreEdit, SessionPlan};
    let p =
        Point { network: Network::Perfect, ..pair("five-bar-robot", "effector", DevicePreset::Paper, HandKind::Firm) };
    let designed = evaluate(&p, SECONDS).unwrap();
    assert!(designed.renders, "{:?} (excess {:?} J)", designed.failures, designed.energy_excess_j);
    // k_j, b_j, K_pc (x, y, angle), B_pc (x, y, angle): the linear damping budget is b_j + B_pc, which the old
    // split gave two thirds to the joints; the angular channel had a third of its budget, half of today's.
    let g = designed.gains.clone();
    assert_eq!(g.len(), 8, "{g:?}");
    let budget = g[1] + g[5];
    let old_split = ControllerGains {
        joint_stiffness: g[0],
        joint_damping: budget * 2.0 / 3.0,
        position_stiffness: g[2..5].to_vec(),
        position_damping: vec![budget / 3.0, budget / 3.0, g[7] / 2.0],
    };
    let mut client = ClientPlan::new("user", "effector", DevicePreset::Paper);
    client.user = UserSpec::Hand(HandSpec::touring(HandKind::Firm));
    client.configure = Some(CoreEdit::new(move |c| c.gains = GainChoice::Custom(old_split.clone())));
    let plan = SessionPlan {
        scene: kinloop_linkage::model::builtin::scene("five-bar-robot").unwrap().unwrap(),
        ve: kinloop_server::core::VeConfig::default(),
        clients: vec![client],
        duration: std::time::Duration::from_secs_f64(SECONDS),
        record_every: 1,
    };
    let (summary, rec) = session(&plan).unwrap();
    let old = judge(&summary, &rec);
    assert!(!old.stable && old.reasons.contains(&"energy growth"), "{old:?}");
    let excess = designed.energy_excess_j.unwrap();
    assert!(excess < 0.5 * old.energy_excess_j, "designed {excess} J against the old split's {old:?}");
}
