//! Runs `client/tick_testbed` for profilers: `profile_client_tick [ITERS]` (default 2,000,000).
//! Build it with line tables (`cargo build --profile profiling -p kinloop-client --example profile_client_tick`);
//! `perf record` shows where the time goes; `valgrind --tool=callgrind` counts instructions, which do not
//! suffer from a noisy machine.

fn main() {
    let iters = std::env::args().nth(1).map_or(2_000_000, |s| s.parse().expect("ITERS is a count"));
    let ns = kinloop_client::bench::client_tick_testbed(iters).expect("the testbed builds");
    println!("{ns:.1} ns per tick");
}
