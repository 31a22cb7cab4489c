//! `kinloop timer-floor`: the lateness of a 1 kHz loop that does nothing, timed exactly as the haptic loop
//! times itself (absolute deadlines, spin_sleep, SCHED_FIFO when permitted). It separates what the machine
//! (kernel, hypervisor, neighbours) does to a real-time loop from what the loop's own work does: a loop that
//! misses more deadlines than this floor has a problem of its own; one at the floor does not.

use std::time::Duration;

use anyhow::{ensure, Result};
use kinloop_client::driver::rt_loop::timer_floor;
use kinloop_client::driver::timing::MISS_THRESHOLD_US;
use serde_json::json;

/// Arguments of `kinloop timer-floor`.
#[derive(clap::Args, Debug)]
pub struct TimerFloorArgs {
    /// Seconds to run.
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Loop rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// Stay at normal priority (by default SCHED_FIFO is tried, as the haptic loop does).
    #[arg(long)]
    pub no_realtime: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Longest idle loop `--duration` accepts: a day.
const MAX_DURATION_S: f64 = 86_400.0;

/// Runs the idle loop and prints its lateness.
pub fn run(args: &TimerFloorArgs) -> Result<()> {
    ensure!(
        args.duration.is_finite() && args.duration > 0.0 && args.duration <= MAX_DURATION_S,
        "--duration: must be in (0, {MAX_DURATION_S}] s, got {}",
        args.duration
    );
    ensure!(
        args.rate.is_finite() && (1.0..=100_000.0).contains(&args.rate),
        "--rate: 1 to 100000 Hz, got {}",
        args.rate
    );
    if !args.json {
        eprintln!("timing an idle {} Hz loop for {} s...", args.rate, args.duration);
    }
    let (lateness, fifo) = timer_floor(args.rate, Duration::from_secs_f64(args.duration), !args.no_realtime);
    let miss_rate = lateness.misses as f64 / lateness.ticks.max(1) as f64;
    if args.json {
        println!(
            "{}",
            json!({
                "ticks": lateness.ticks,
                "loop_lateness_us_p50": lateness.p50_us,
                "loop_lateness_us_p99": lateness.p99_us,
                "loop_lateness_us_max": lateness.max_us,
                "loop_misses": lateness.misses,
                "loop_stalls": lateness.stalls,
                "miss_threshold_us": MISS_THRESHOLD_US,
                "miss_rate": miss_rate,
                "realtime_priority": fifo,
            })
        );
    } else {
        println!(
            "{} ticks, lateness p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs; {} misses (> {} µs late, {:.3} %) in {} stalls; SCHED_FIFO {}",
            lateness.ticks,
            lateness.p50_us,
            lateness.p99_us,
            lateness.max_us,
            lateness.misses,
            MISS_THRESHOLD_US,
            100.0 * miss_rate,
            lateness.stalls,
            if fifo { "on" } else { "off" }
        );
    }
    Ok(())
}
