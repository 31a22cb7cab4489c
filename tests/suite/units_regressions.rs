//! Generated linkages written in millimetres or centimetres that failed at 0 ms one way while kinloop's
//! defaults were metres and kilograms (`kinloop experiment robustness --quick --seeds 1..101`: every session of
//! seeds 1, 3, 4 and 6 was judged unstable or refused), kept as regression scenes: each OP listed, on every
//! simulated device the experiment pairs with it, under the soft hand on a perfect network, renders (stable, at
//! most 5 % of ticks clamped, device-OP RMS at most 5 mm, closure within 1e-6 of the length scale).
//!
//! And the latency sweep's points that the units change broke on an SI scene: with the lead's guessing budget
//! a fixed energy at the device, the Watt six-bar's soft coupling (`c_f c_p` about 0.07 on `sim:paper`) let
//! the VE guess fourteen times the energy it had guessed in SI before; the firm hand at 100 ms with 30 ms
//! of jitter saturated the device, and the poke at 100-300 ms without passivity made energy.

use kinloop::experiments::delay_point::{measure, Loss, Network, Point, TARGETS};
use kinloop::experiments::robustness::{evaluate, points};
use kinloop::generate::generate;
use kinloop::generate::units::UnitSystem;
use kinloop_client::device::DevicePreset;
use kinloop_client::user::HandKind;

/// Seed, the OPs of its linkage that must render (`None`: every OP), and the device (`None`: every one the
/// experiment pairs with them). Seed 4's crank is held to `sim:falcon`: since the linkage waits at rest for its
/// first holder, the touring hand on `sim:paper` and `sim:touch` takes the crank on to its dead centre, where
/// it does not render (the third class of docs/robustness.md, open); its millimetres and grams are not why.
const REGRESSIONS: [(u64, Option<&str>, Option<DevicePreset>); 4] = [
    (1, None, None),
    (6, None, None),
    (3, Some("op-rocker"), None),
    (4, Some("op-crank"), Some(DevicePreset::Falcon)),
];

#[test]
fn linkages_written_in_millimetres_and_centimetres_render_at_zero_delay() {
    for (seed, only, device) in REGRESSIONS {
        let g = generate(seed, None);
        assert_ne!(g.units, UnitSystem::SI, "seed {seed} is meant to be written in other units");
        let judged = render_at_zero_delay(seed, only, device);
        assert!(judged >= if device.is_some() { 1 } else { 3 }, "seed {seed}: {judged} sessions");
    }
}

/// Seed, OP and (`None`: every one the experiment pairs with it) device of generated linkages whose heavy
/// links fell away from the user at the join: the VE stepped the linkage from the first uplink on, while the
/// user's coupling was still fading in and held only its weight's share of the load, so the VE's OP dropped
/// centimetres (device space) from the device within a tenth of a second and was yanked back; the VE now
/// waits at rest until a coupling has faded fully in (`VeConfig::rest_unheld`).
const JOIN_DROPS: [(u64, &str, Option<DevicePreset>); 5] = [
    (74, "op-crank", None),
    (98, "op-crank", None),
    (98, "op-coupler-1", None),
    (85, "op-rocker", Some(DevicePreset::Paper)),
    (85, "op-rocker", Some(DevicePreset::Touch)),
];

#[test]
fn linkages_that_fell_away_at_the_join_render_at_zero_delay() {
    for (seed, op, device) in JOIN_DROPS {
        let judged = render_at_zero_delay(seed, Some(op), device);
        assert!(judged >= 1, "seed {seed} {op}: {judged} sessions");
    }
}

/// Runs the soft-hand sessions at 0 ms of seed `seed`'s linkage (only OP `only` and device `device` when
/// given), asserts that each renders, and returns how many ran.
fn render_at_zero_delay(seed: u64, only: Option<&str>, device: Option<DevicePreset>) -> usize {
    let g = generate(seed, None);
    let sessions = points(std::slice::from_ref(&g), &[HandKind::Soft], &[0]);
    let mut judged = 0;
    for p in sessions.iter().filter(|p| only.is_none_or(|op| p.op == op) && device.is_none_or(|d| p.device == d)) {
        let outcome = evaluate(&g, p, 10.0);
        assert!(
            outcome.failures.is_empty(),
            "seed {seed} ({:?}) {} on {:?}: {:?}",
            g.units,
            p.op,
            p.device,
            outcome.failures
        );
        judged += 1;
    }
    judged
}

#[test]
fn the_six_bar_under_delay_is_stable_with_a_budget_at_the_handle() {
    let six_bar = TARGETS.iter().position(|t| t.0 == "watt-six-bar").expect("the latency grid's six-bar");
    let clean = Network::CLEAN;
    let jittery = Network { jitter_ms: 30.0, loss: Loss::None };
    let mut cases =
        vec![Point { target: six_bar, hand: HandKind::Firm, delay_ms: 100.0, network: jittery, passivity: true }];
    for delay_ms in [100.0, 200.0, 300.0] {
        cases.push(Point { target: six_bar, hand: HandKind::Poke, delay_ms, network: clean, passivity: false });
    }
    for p in cases {
        let m = measure(&p, 10.0).expect("the session runs");
        assert!(m.verdict.stable, "{p:?}: {:?}", m.verdict.reasons);
        assert_eq!(m.ve_restores, 0, "{p:?}");
    }
}
