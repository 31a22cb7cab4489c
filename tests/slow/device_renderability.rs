//! Samples of `kinloop experiment renderability-dhd` and `renderability-hd` (the renderability matrix
//! through a vendor's device) in real processes: `kinloop-server` and `kinloop-client --device dhd|hd`
//! through their own `main` (this test binary re-executed as each, see `common::child`), the client loading
//! the fake DHD library as an omega.3 or a Falcon, or the fake OpenHaptics library as a Touch whose servo
//! thread runs the client's loop, with a hand that tours the OP's reach. Each pair must render by the
//! matrix's bounds.

use crate::common;

use std::path::PathBuf;
use std::time::Duration;

use common::child::{launch_as_programs_of, serve_if_child};
use kinloop::experiments::renderability::Network;
use kinloop::experiments::renderability_device::{evaluate, DevicePoint, FakeDevice, Programs};
use kinloop_client::user::HandKind;

/// A pair's session (s): the quick matrix's.
const SECONDS: f64 = 2.0;

/// The programs of test `name` (this binary re-executed as each), the fake library at `fake`.
fn programs(name: &'static str, fake: PathBuf) -> Programs {
    Programs::launched_by(launch_as_programs_of(name), fake)
}

fn pair(scene: &str, op: &str, device: FakeDevice, network: Network, hand: HandKind) -> DevicePoint {
    DevicePoint { scene: scene.into(), op: op.into(), device, network, hand }
}

/// Each of `sample` renders, judged on a session that ran: ticks with output compared, a tour that moved
/// the device.
fn assert_renders(sample: &[DevicePoint], programs: &Programs) {
    let dir = common::temp_dir();
    for point in sample {
        let result =
            evaluate(point, SECONDS, programs, dir.path()).unwrap_or_else(|e| panic!("{}: {e:#}", point.label()));
        assert!(result.renders, "{}: {:?}", point.label(), result.failures);
        assert!(result.device_op_rms_m > 0.0 && result.device_op_rms_m.is_finite(), "{}", point.label());
    }
}

#[test]
fn a_sample_of_the_dhd_matrix_renders_in_real_processes() {
    const NAME: &str = "a_sample_of_the_dhd_matrix_renders_in_real_processes";
    serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let sample = [
        pair("paper-testbed", "link2", FakeDevice::Dhd(33), Network::Perfect, HandKind::Soft),
        pair("fourbar-crank-rocker", "coupler", FakeDevice::Dhd(60), Network::Delayed50, HandKind::Firm),
        pair("bennett-linkage", "coupler", FakeDevice::Dhd(33), Network::Delayed50, HandKind::Soft),
    ];
    assert_renders(&sample, &programs(NAME, common::fake_dhd_library()));
}

/// A planar and a spatial scene through the Touch, the spatial one the ball-jointed Delta.
#[test]
fn a_sample_of_the_hd_matrix_renders_in_real_processes() {
    const NAME: &str = "a_sample_of_the_hd_matrix_renders_in_real_processes";
    serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let sample = [
        pair("paper-testbed", "link2", FakeDevice::Touch, Network::Perfect, HandKind::Firm),
        pair("delta", "platform", FakeDevice::Touch, Network::Delayed50, HandKind::Soft),
    ];
    assert_renders(&sample, &programs(NAME, common::fake_hd_library()));
}
