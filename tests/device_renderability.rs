//! A sample of `kinloop experiment renderability-dhd` (the renderability matrix through a DHD device) in
//! real processes: `kinloop-server` and `kinloop-client --device dhd` through their own `main` (this test
//! binary re-executed as each, see `common::child`), the client loading the fake DHD library as an omega.3
//! or a Falcon whose hand tours the OP's reach. Each pair must render by the matrix's bounds.

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::child::{serve_if_child, Program, Role};
use kinloop::experiments::renderability::Network;
use kinloop::experiments::renderability_dhd::{evaluate, DhdPoint, Programs};
use kinloop_client::user::HandKind;

/// A pair's session (s): the quick matrix's.
const SECONDS: f64 = 2.0;

#[test]
fn a_sample_of_the_dhd_matrix_renders_in_real_processes() {
    const NAME: &str = "a_sample_of_the_dhd_matrix_renders_in_real_processes";
    serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let launch = |program: &str, args: &[String]| {
        let program = Program::named(program).unwrap_or_else(|| panic!("{program} is not a kinloop program"));
        let role = Role::Program { program, args: args.to_vec() };
        let mut command = Command::new(std::env::current_exe().expect("the test binary's path"));
        command
            .args([NAME, "--exact", "--nocapture", "--test-threads=1"])
            .env("KINLOOP_E2E_ROLE", serde_json::to_string(&role).expect("a role"))
            // The child lives while its stdin is open: as long as the runner holds it.
            .stdin(Stdio::piped());
        command
    };
    let programs = Programs::launched_by(Box::new(launch), common::fake_dhd_library());
    let pair = |scene: &str, op: &str, system, network, hand| DhdPoint {
        scene: scene.into(),
        op: op.into(),
        system,
        network,
        hand,
    };
    let sample = [
        pair("paper-testbed", "link2", 33, Network::Perfect, HandKind::Soft),
        pair("fourbar-crank-rocker", "coupler", 60, Network::Delayed50, HandKind::Firm),
        pair("bennett-linkage", "coupler", 33, Network::Delayed50, HandKind::Soft),
    ];
    let dir = common::temp_dir();
    for point in &sample {
        let result =
            evaluate(point, SECONDS, &programs, dir.path()).unwrap_or_else(|e| panic!("{}: {e:#}", point.label()));
        assert!(result.renders, "{}: {:?}", point.label(), result.failures);
        // Judged on a session that ran: ticks with output compared, a tour that moved the device.
        assert!(result.device_op_rms_m > 0.0 && result.device_op_rms_m.is_finite(), "{}", point.label());
    }
}
