//! `pauses`: what a VE tick costs after the pause a real-time loop takes between ticks, against the same tick
//! run back to back as `kinloop bench` (`server/ve_tick_users_N`) times it.
//!
//! A 1 kHz loop works for microseconds and then waits for the rest of the millisecond. Whatever runs on the
//! core meanwhile (other threads, the host's other tenants) evicts part of the tick's code and data from the
//! caches, and the next tick fetches them again. Each point here ticks a testbed VE with N users
//! (`kinloop_server::bench::ve_tick_after_pauses`: every user's uplink, the step, every user's snapshot)
//! after a pause of P µs, slept (`std::thread::sleep`, as the VE thread's spin_sleep does for most of a
//! period), busy-waited (the core stays with the thread), or slept and then rehearsed (a tick of a one-user VE
//! of its own, as the VE loop runs before each deadline: `kinloop_server::driver::rehearsal`), and reports
//! the percentiles of the single tick's time. P = 0 is the benchmark's back-to-back case.
//!
//! Wall-clock, single-threaded, on whatever the machine is doing: the numbers move from run to run, the
//! ratios between pauses much less.

use std::time::Duration;

use anyhow::{anyhow, Result};
use kinloop_linkage::bench::quantile;
use kinloop_server::bench::{ve_tick_after_pauses, Pause};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::common::{sweep, Options, Output, Report};
use crate::charts::{Chart, Legend, Series};
use crate::rounding::round;

/// The ways a point waits before each timed tick.
const HOWS: [Pause; 3] = [Pause::Sleep, Pause::Spin, Pause::Rehearsed];

/// One point: users, pause, how, and the tick's percentiles (ns).
#[derive(Clone, Debug)]
struct Measured {
    users: usize,
    pause_us: u64,
    how: Pause,
    p10_ns: f64,
    p50_ns: f64,
    p90_ns: f64,
}

fn measure(users: usize, pause_us: u64, how: Pause, ticks: usize) -> Result<Measured> {
    let mut times = ve_tick_after_pauses(users, Duration::from_micros(pause_us), how, ticks)
        .map_err(|e| anyhow!("{users} users, {pause_us} us: {e}"))?;
    times.sort_by(f64::total_cmp);
    Ok(Measured {
        users,
        pause_us,
        how,
        p10_ns: quantile(&times, 0.1),
        p50_ns: quantile(&times, 0.5),
        p90_ns: quantile(&times, 0.9),
    })
}

/// `summary.json`'s `results` of the pauses experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PausesSummary {
    /// The one-line answer.
    pub answer: String,
    /// The longest pause of the grid (µs).
    pub longest_pause_us: u64,
    /// Per user count: the tick after the longest pause against the tick back to back.
    pub ratios_at_longest_pause: Vec<PauseRatio>,
    /// What was timed and how.
    pub setup: PausesSetup,
    /// Every point of the grid.
    pub points: Vec<PausePoint>,
}

/// One point: a tick's percentiles after a pause (µs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PausePoint {
    /// Users on the VE.
    pub users: usize,
    /// The pause before each timed tick (µs).
    pub pause_us: u64,
    /// How the pause was spent: `sleep`, `spin` or `rehearsed`.
    pub how: String,
    /// 10th percentile of the tick (µs).
    pub tick_us_p10: f64,
    /// Median tick (µs).
    pub tick_us_p50: f64,
    /// 90th percentile of the tick (µs).
    pub tick_us_p90: f64,
}

/// The median tick after the longest pause against the median back to back, for one user count.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PauseRatio {
    /// Users on the VE.
    pub users: usize,
    /// Median tick without a pause (µs).
    pub back_to_back_us: f64,
    /// Median tick after the longest pause, slept (µs).
    pub after_sleep_us: f64,
    /// Median tick after the longest pause, spun (µs).
    pub after_spin_us: f64,
    /// Median tick after the longest pause, slept and then rehearsed (µs).
    pub after_rehearsal_us: f64,
    /// `after_sleep_us / back_to_back_us`.
    pub sleep_over_back_to_back: f64,
    /// `after_spin_us / back_to_back_us`.
    pub spin_over_back_to_back: f64,
    /// `after_rehearsal_us / back_to_back_us`.
    pub rehearsal_over_back_to_back: f64,
}

/// What each point times and how it waits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PausesSetup {
    /// The timed tick.
    pub tick: String,
    /// Ticks timed per point.
    pub ticks_per_point: usize,
    /// How a slept pause is spent.
    pub sleep: String,
    /// How a spun pause is spent.
    pub spin: String,
    /// How a rehearsed pause is spent.
    pub rehearsed: String,
}

fn point_summary(m: &Measured) -> PausePoint {
    PausePoint {
        users: m.users,
        pause_us: m.pause_us,
        how: m.how.name().into(),
        tick_us_p10: round(m.p10_ns / 1e3, 3),
        tick_us_p50: round(m.p50_ns / 1e3, 3),
        tick_us_p90: round(m.p90_ns / 1e3, 3),
    }
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("pauses", options)?;
    let users: Vec<usize> = options.pick(vec![1, 4, 16], vec![1, 4]);
    let pauses_us: Vec<u64> = options.pick(vec![0, 20, 50, 100, 200, 500, 900], vec![0, 100, 900]);
    let ticks = options.pick(2_000, 200);
    let mut grid = Vec::new();
    for &n in &users {
        for &p in &pauses_us {
            for how in HOWS {
                // Without a pause the two ways are the same measurement.
                if p > 0 || how == Pause::Sleep {
                    grid.push((n, p, how));
                }
            }
        }
    }
    // One thread: a second one would be the very neighbour whose evictions this measures.
    let points =
        sweep("ticks after pauses (1 thread)", &grid, 1, options.progress, |&(n, p, how)| measure(n, p, how, ticks))?;

    let at = |n: usize, p: u64, how: Pause| {
        points.iter().find(|m| m.users == n && m.pause_us == p && (p == 0 || m.how == how))
    };
    let mut chart = Chart::new(
        "A VE tick after a pause, against the same tick back to back (p50)",
        "pause before the tick (us)",
        "tick (us)",
    )
    .legend(Legend::UpperLeft);
    for &n in &users {
        for how in HOWS {
            let series: Vec<(f64, f64)> =
                pauses_us.iter().filter_map(|&p| at(n, p, how)).map(|m| (m.pause_us as f64, m.p50_ns / 1e3)).collect();
            let who = if n == 1 { "1 user".to_string() } else { format!("{n} users") };
            chart = chart.with(Series::line(format!("{who}, {}", how.name()), series));
        }
    }
    out.chart("tick_vs_pause", &chart)?;

    let longest = pauses_us[pauses_us.len() - 1];
    let ratios: Vec<PauseRatio> = users
        .iter()
        .filter_map(|&n| {
            let base = at(n, 0, Pause::Sleep)?.p50_ns;
            let slept = at(n, longest, Pause::Sleep)?.p50_ns;
            let spun = at(n, longest, Pause::Spin)?.p50_ns;
            let rehearsed = at(n, longest, Pause::Rehearsed)?.p50_ns;
            Some(PauseRatio {
                users: n,
                back_to_back_us: round(base / 1e3, 3),
                after_sleep_us: round(slept / 1e3, 3),
                after_spin_us: round(spun / 1e3, 3),
                sleep_over_back_to_back: round(slept / base, 2),
                spin_over_back_to_back: round(spun / base, 2),
                after_rehearsal_us: round(rehearsed / 1e3, 3),
                rehearsal_over_back_to_back: round(rehearsed / base, 2),
            })
        })
        .collect();
    // The answer prints the numbers as the JSON does.
    let first = ratios.first().map(serde_json::to_value).transpose()?.unwrap_or(Value::Null);
    let answer = format!(
        "After a {longest} us pause a {}-user tick took {} us (p50) slept, {} us spun and {} us slept then \
         rehearsed, against {} us back to back ({}x, {}x and {}x): a real-time loop pays for refetching its working \
         set on every tick, which the benchmark's back-to-back ticks never show, and a rehearsal before the \
         deadline pays most of it ahead.",
        first["users"],
        first["after_sleep_us"],
        first["after_spin_us"],
        first["after_rehearsal_us"],
        first["back_to_back_us"],
        first["sleep_over_back_to_back"],
        first["spin_over_back_to_back"],
        first["rehearsal_over_back_to_back"],
    );
    let results = PausesSummary {
        answer,
        longest_pause_us: longest,
        ratios_at_longest_pause: ratios,
        setup: PausesSetup {
            tick: "kinloop_server::bench::TickBench on the paper's testbed: every user's uplink, the step, every user's snapshot".into(),
            ticks_per_point: ticks,
            sleep: "std::thread::sleep(pause) before each timed tick".into(),
            spin: "busy-wait on Instant::now() for the pause before each timed tick".into(),
            rehearsed: "std::thread::sleep(pause), then one tick of a one-user VE of its own on the same linkage \
                        (kinloop_server::driver::rehearsal::Rehearsal), before each timed tick"
                .into(),
        },
        points: points.iter().map(point_summary).collect(),
    };
    out.finish(
        "A VE tick after the pause a real-time loop takes, against back-to-back ticks",
        "57 points of 2,000 ticks; --quick fewer",
        serde_json::to_value(&results)?,
    )
}
