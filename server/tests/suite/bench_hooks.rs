//! The bench hooks run and give plausible numbers (no timing assertions: the machine decides those).

use std::time::Duration;

use kinloop_server::bench::{realtime_run, ve_loop_users, ve_tick_users, LoopBench, RealtimeRun, TickBench};
use kinloop_server::VeConfig;

#[test]
fn ve_tick_hook_measures_every_user_count() {
    for users in [1, 4, 16, 64] {
        let ns = ve_tick_users(users, 200).unwrap();
        assert!(ns.is_finite() && ns > 0.0, "{users} users: {ns}");
        eprintln!("server/ve_tick_users_{users}: {ns:.0} ns");
    }
}

/// The loop's benchmark runs the VE loop's whole iteration with its rings live: every user's snapshot
/// reaches its client through the ring, every client's uplink reaches the VE through its ring, and the
/// loop's timing covers only the iterations after the warm-up, every stage of each.
#[test]
fn loop_bench_moves_every_snapshot_and_uplink_through_the_rings() {
    for users in [1, 16] {
        let mut bench = LoopBench::new(users, 20).unwrap();
        for _ in 0..200 {
            bench.iterate();
        }
        let stats = bench.finish();
        assert_eq!(stats.core.users as usize, users);
        assert_eq!(stats.step_time.samples, 200, "{users} users: the warm-up is not timed");
        for (stage, times) in [("encode", stats.stages.encode), ("ring push", stats.stages.ring_push)] {
            assert_eq!(times.samples, 200, "{users} users: {stage}");
            assert!(times.p50_ns > 0, "{users} users: {stage}");
        }
        assert_eq!(stats.snapshots_dropped, 0, "{users} users");
        assert_eq!(stats.core.state_restores, 0, "{users} users");
        // Each iteration's uplinks answer the snapshots of the one before (the first iterations had none).
        assert!(stats.core.uplinks_accepted >= 215 * users as u64, "{users} users: {:?}", stats.core);
    }
    let ns = ve_loop_users(4, 100).unwrap();
    assert!(ns.is_finite() && ns > 0.0, "{ns}");
}

/// The ticks the benchmark times are those of a linkage in motion, whatever the number of users: their shares
/// of the paper's push add up to it and all hold `link2`. (Shares of alternating sign cancelled on one OP,
/// and followers spread over the links braked the testbed still through the couplings' angular gains, at
/// |q̇| ≤ 6e-4 rad/s, its ticks cheaper.) Measured in the second second: |q̇|∞ at least
/// 1.4 rad/s with 1 and 4 users, 0.97 with 16, 0.27 with 64.
#[test]
fn benchmark_users_keep_the_linkage_moving() {
    for users in [1, 4, 16, 64] {
        let mut bench = TickBench::new(users, 0).unwrap();
        let mut slowest = f64::INFINITY;
        for tick in 0..2000 {
            bench.tick();
            if tick >= 1000 {
                slowest = slowest.min(bench.core().state().qd.amax());
            }
        }
        let metrics = bench.core().metrics();
        assert!(slowest >= 0.1, "{users} users: the linkage slowed to {slowest:.2e} rad/s");
        assert_eq!(metrics.state_restores, 0, "{users} users");
        assert!(metrics.max_closure_error <= 1e-9, "{users} users: closure {:.2e} m", metrics.max_closure_error);
        assert_eq!(metrics.users as usize, users, "every user joined");
    }
}

#[test]
fn realtime_run_reports_ticks_and_snapshots() {
    let scene = kinloop_linkage::model::builtin::scene("paper-testbed").unwrap().unwrap();
    let run = RealtimeRun {
        scene,
        scene_label: "paper-testbed".into(),
        users: 4,
        duration: Duration::from_millis(300),
        ve: VeConfig::paper(),
        warm_up: Duration::from_millis(100),
    };
    let report = realtime_run(run).unwrap();
    assert!(report.ve.step_time.samples > 100, "{report:?}");
    // The statistics a tenth of a second in: published from the same counters, so fewer ticks and no more
    // misses than at the end.
    let early = report.ve_at_warm_up.expect("published after the warm-up");
    assert!(early.wall_s >= 0.1 && early.wall_s < report.ve.wall_s, "{early:?}");
    assert!(early.step_time.samples < report.ve.step_time.samples);
    assert!(early.deadline_misses <= report.ve.deadline_misses);
    assert_eq!(report.ve.core.users, 4);
    assert!(report.snapshots_received > 0);
    assert_eq!(report.ve.core.state_restores, 0);
}

/// A scene without an operational point gives synthetic users nothing to hold: a typed error that names the
/// scene (it divided by the number of OPs and panicked).
#[test]
fn realtime_run_without_an_op_is_refused() {
    let mut scene = kinloop_linkage::model::builtin::scene("paper-testbed").unwrap().unwrap();
    scene.ops.clear();
    let run = RealtimeRun {
        scene,
        scene_label: "no-op-testbed".into(),
        users: 2,
        duration: Duration::from_millis(100),
        ve: VeConfig::paper(),
        warm_up: Duration::ZERO,
    };
    let error = realtime_run(run).unwrap_err();
    assert!(matches!(error, kinloop_server::bench::BenchError::NoOperationalPoint { .. }), "{error:?}");
    assert!(error.to_string().contains("no-op-testbed"), "{error}");
}
