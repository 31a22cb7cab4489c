//! The bench hooks run and give plausible numbers (no timing assertions: the machine decides those).

use std::time::Duration;

use kinloop_server::bench::{realtime_run, ve_tick_users, RealtimeRun};
use kinloop_server::VeConfig;

#[test]
fn ve_tick_hook_measures_every_user_count() {
    for users in [1, 4, 16, 64] {
        let ns = ve_tick_users(users, 200).unwrap();
        assert!(ns.is_finite() && ns > 0.0, "{users} users: {ns}");
        eprintln!("server/ve_tick_users_{users}: {ns:.0} ns");
    }
}

#[test]
fn realtime_run_reports_ticks_and_snapshots() {
    let scene = kinloop_linkage::builtin::scene("paper-testbed").unwrap().unwrap();
    let run = RealtimeRun {
        scene,
        scene_label: "paper-testbed".into(),
        users: 4,
        duration: Duration::from_millis(300),
        ve: VeConfig::paper(),
    };
    let report = realtime_run(run).unwrap();
    assert!(report.ve.step_time.samples > 100, "{report:?}");
    assert_eq!(report.ve.core.users, 4);
    assert!(report.snapshots_received > 0);
    assert_eq!(report.ve.core.state_restores, 0);
}
