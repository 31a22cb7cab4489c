//! A sample of `kinloop experiment robustness-live`: a generated linkage (written in millimetres and
//! kilograms, as `kinloop generate` writes it) hosted by `kinloop-server --scene FILE` and held by
//! `kinloop-client --device sim:falcon --user soft` through their own `main`s (this test binary re-executed as
//! each, see `common::child`), beside the same session in virtual time: virtual time must predict what the
//! programs do.

use crate::common;

use std::time::Duration;

use common::child::{launch_as_programs_of, serve_if_child};
use kinloop::experiments::programs::Launcher;
use kinloop::experiments::robustness::Point;
use kinloop::experiments::robustness_live::evaluate;
use kinloop::generate::generate;
use kinloop_client::device::DevicePreset;
use kinloop_client::user::HandKind;

/// A session's length (s).
const SECONDS: f64 = 3.0;

/// Seed 1's coupler on a Falcon, on a perfect network and at 50 ms one way: both sessions render in real
/// processes as in virtual time, and the real device-OP RMS is the virtual one's within a quarter (the two
/// runs share the scene, the mapping, the hand's tour and the defaults; what differs is real time, the
/// real network stack and the emulated link's draws).
#[test]
fn a_generated_linkage_renders_in_real_processes_as_in_virtual_time() {
    const NAME: &str = "a_generated_linkage_renders_in_real_processes_as_in_virtual_time";
    serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(90));
    let linkage = generate(1, None);
    let launcher = Launcher::launched_by(launch_as_programs_of(NAME));
    let dir = common::temp_dir();
    for delay_ms in [0, 50] {
        let point =
            Point { seed: 1, op: "op-coupler".into(), device: DevicePreset::Falcon, hand: HandKind::Soft, delay_ms };
        let outcome = evaluate(&linkage, &point, SECONDS, &launcher, dir.path())
            .unwrap_or_else(|e| panic!("{delay_ms} ms: {e:#}"));
        println!(
            "{delay_ms} ms: real {:.3} mm, virtual {:.3} mm, {:.1} % clamped, closure {:.1e} of L",
            outcome.device_op_rms_m * 1e3,
            outcome.virtual_device_op_rms_m * 1e3,
            outcome.clamped_fraction * 100.0,
            outcome.closure_relative
        );
        assert!(outcome.live_failures.is_empty(), "{delay_ms} ms, real processes: {:?}", outcome.live_failures);
        assert!(outcome.virtual_failures.is_empty(), "{delay_ms} ms, virtual time: {:?}", outcome.virtual_failures);
        let (real, twin) = (outcome.device_op_rms_m, outcome.virtual_device_op_rms_m);
        assert!(real > 0.0 && twin > 0.0, "{delay_ms} ms: a tour that moved the device ({real}, {twin})");
        assert!((real - twin).abs() <= 0.25 * twin, "{delay_ms} ms: real {real} m against virtual {twin} m");
    }
}
