//! The bench hooks run and return plausible numbers (no timing assertions beyond sanity).

use std::time::Duration;

#[test]
fn the_tick_bench_and_the_loop_timing_hook_run() {
    let ns = kinloop_client::bench::client_tick_testbed(20_000).expect("testbed");
    println!("client/tick_testbed: {ns:.0} ns");
    assert!(ns.is_finite() && ns > 0.0);
    let timing = kinloop_client::bench::realtime_loop_sim(Duration::from_millis(300), 1000.0, false).expect("loop");
    println!("{timing:?}");
    assert!(timing.ticks > 100, "{timing:?}");
    assert!(timing.p50_us <= timing.p99_us && timing.p99_us <= timing.max_us.max(timing.p99_us));
}
