//! `capacity`: how many users one room carries in real time. Each point runs the real VE thread (absolute
//! deadlines, spin_sleep, SCHED_FIFO when granted) with N synthetic users (`kinloop_server::bench::realtime_run`:
//! in-process users that follow the VE and keep a client's energy books) and reports the loop's step time (p50,
//! p99), its deadline misses beside the idle timer floor measured in blocks alternating with it
//! ([`super::interleave`]: the same clock and sleep with no work, so the floor is the machine's during the run),
//! the thread's CPU use beside the figure (its hybrid sleep spins), and whether the linkage stayed whole. Beside
//! each point, the same loop's iterations back to back (`server/ve_loop_users_N`: the same `VeLoop`, its rings
//! drained between iterations) give two like-with-like ratios: the whole iteration in real time over the whole
//! iteration back to back, and the VE's own stages (intake, step, snapshot terms) over the same stages back to
//! back. The VE tick alone back to back (`server/ve_tick_users_N`) is reported too.
//!
//! Synthetic users follow the VE, so their tracking is the VE's own and not a client's: what this reports of
//! the session is its stability (restores, closure). The second axis, rooms per server with real clients
//! from the load design, is [`super::capacity_rooms`]. Wall-clock, on whatever the machine is doing: the run
//! says how loaded it was (`load_average`), and the timer floor beside each point is the measure of the
//! machine.

use std::time::Duration;

use anyhow::{anyhow, Result};
use kinloop_server::bench::{realtime_run, ve_loop_stats, ve_tick_users, RealtimeReport, RealtimeRun};
use kinloop_server::core::VeConfig;
use kinloop_server::driver::network_runtime::network_runtime;
use kinloop_server::driver::VeLoopStats;
use serde::{Deserialize, Serialize};

use super::capacity_rooms::{self, RoomsPoint, MISSES_BOUND};
use super::common::{Options, Output, Report};
use super::interleave::{counted_since, interleave, median, BlockPair, Blocks, WARM_UP};
use super::rate_ratio::RateRatio;
use crate::charts::{Chart, Legend, Series};
use crate::rounding::round;

/// `summary.json`'s `results` of the capacity experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CapacitySummary {
    /// The one-line answer.
    pub answer: String,
    /// Rooms per server on the users axis (1).
    pub rooms: usize,
    /// The host's 1-minute load average when the run began (`None` where `/proc/loadavg` is unreadable).
    pub load_average: Option<f64>,
    /// Seconds each point ran the VE thread (and as many the idle loop, in alternating blocks).
    pub seconds_per_point: f64,
    /// One point per user count.
    pub points: Vec<CapacityPoint>,
    /// Seconds each point of the rooms axis ran (and as many the idle loop, in alternating blocks).
    pub seconds_per_rooms_point: f64,
    /// The rooms axis: rooms per server × users per room, real clients from the load design.
    pub rooms_axis: Vec<RoomsPoint>,
}

/// One user count in one room.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CapacityPoint {
    /// Users in the room.
    pub users: usize,
    /// Median VE loop iteration (µs): the median block's.
    pub step_us_p50: f64,
    /// 99th percentile (µs): the worst block's.
    pub step_us_p99: f64,
    /// The same tick back to back (`server/ve_tick_users_N`, µs).
    pub bench_us: f64,
    /// `step_us_p50 / bench_us`.
    pub realtime_over_bench: f64,
    /// The whole loop iteration back to back (`server/ve_loop_users_N`), median (µs).
    pub loop_bench_us_p50: f64,
    /// `step_us_p50 / loop_bench_us_p50`: the whole iteration in real time over the same back to back.
    pub realtime_over_loop_bench: f64,
    /// The VE's own stages (intake + step + snapshot terms, p50s) in real time over the same back to back.
    pub ve_stages_over_bench: f64,
    /// The step's stages (p50, µs): intake, step, snapshot terms, encode, ring push, wake-up, stats.
    pub stages_us_p50: StageMedians,
    /// The same stages back to back (`server/ve_loop_users_N`).
    pub bench_stages_us_p50: StageMedians,
    /// Fraction of the VE loop's ticks woken more than half a period late.
    pub miss_rate: f64,
    /// Fraction of the idle loop's ticks more than 500 µs late, in blocks alternating with the VE loop's.
    pub floor_miss_rate: f64,
    /// The VE loop's misses against the idle loop's, with the ratio's interval judged against
    /// [`MISSES_BOUND`].
    pub misses_vs_floor: RateRatio,
    /// The VE loop's stalls (runs of late wake-ups, each counted once) against the idle loop's, judged the
    /// same way: misses come in runs (a host stall makes a loaded loop late until it has caught up), stalls
    /// one at a time, as the interval assumes.
    pub stalls_vs_floor: RateRatio,
    /// The idle loop's and the VE loop's counts block by block, in the order they alternated.
    pub blocks: Vec<BlockPair>,
    /// CPU time over wall time of the VE thread (its hybrid sleep's spinning included).
    pub cpu_fraction: Option<f64>,
    /// SCHED_FIFO granted to the VE thread.
    pub realtime_priority: bool,
    /// Snapshots the rings had no room for.
    pub snapshots_dropped: u64,
    /// Energy reports of the synthetic users the server refused (a client's books are accepted).
    pub energy_reports_refused: u64,
    /// States restored after a failed step.
    pub state_restores: u64,
    /// Largest closure residual (m).
    pub max_closure_error_m: f64,
}

/// Medians of the loop's main stages (µs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageMedians {
    /// Uplinks into the core.
    pub intake: f64,
    /// The integrator step.
    pub step: f64,
    /// Every user's local-model terms.
    pub snapshot_terms: f64,
    /// Encoding.
    pub encode: f64,
    /// Ring pushes.
    pub ring_push: f64,
    /// Wake-ups.
    pub wake: f64,
    /// Events, recorder, view tap and the loop's statistics.
    pub rest: f64,
}

impl StageMedians {
    fn of(ve: &VeLoopStats) -> Self {
        let us = |ns: u64| round(ns as f64 / 1e3, 2);
        let s = &ve.stages;
        StageMedians {
            intake: us(s.intake.p50_ns),
            step: us(s.step.p50_ns),
            snapshot_terms: us(s.snapshot_terms.p50_ns),
            encode: us(s.encode.p50_ns),
            ring_push: us(s.ring_push.p50_ns),
            wake: us(s.wake.p50_ns),
            rest: us(s.events_record.p50_ns + s.view.p50_ns + s.stats.p50_ns),
        }
    }

    /// The VE's own stages: intake, step and snapshot terms.
    fn ve_own(&self) -> f64 {
        self.intake + self.step + self.snapshot_terms
    }
}

fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg").ok()?.split_whitespace().next()?.parse().ok()
}

fn measure(users: usize, seconds: f64, at_least_blocks: usize, bench_iters: u64) -> Result<CapacityPoint> {
    let scene = kinloop_linkage::model::builtin::scene("paper-testbed")
        .ok_or_else(|| anyhow!("the built-in paper-testbed is missing"))??;
    let blocks = interleave(Blocks::covering(seconds, at_least_blocks), |duration| {
        let run = RealtimeRun {
            scene: scene.clone(),
            scene_label: "paper-testbed".into(),
            users,
            duration: WARM_UP + duration,
            ve: VeConfig::paper(),
            warm_up: WARM_UP,
        };
        realtime_run(run).map_err(|e| anyhow!("{users} users: {e}"))
    })?;
    let bench_ns = ve_tick_users(users, bench_iters).map_err(|e| anyhow!("{users} users: {e}"))?;
    let looped = ve_loop_stats(users, bench_iters).map_err(|e| anyhow!("{users} users: {e}"))?;
    let (floor_misses, floor_stalls, floor_ticks) = blocks.floor_totals();
    // Misses are counted after each block's warm-up; the step's figures are the whole run's.
    let counted = |r: &RealtimeReport| counted_since(&r.ve, r.ve_at_warm_up.as_ref());
    let pairs = blocks.pairs(counted);
    let (misses, stalls, ticks) =
        blocks.runs.iter().map(counted).fold((0, 0, 0), |(m, s, t), (bm, bs, bt)| (m + bm, s + bs, t + bt));
    let ves: Vec<&VeLoopStats> = blocks.runs.iter().map(|r| &r.ve).collect();
    let sum = |f: fn(&VeLoopStats) -> u64| ves.iter().map(|v| f(v)).sum::<u64>();
    // The block whose median step is the median block's speaks for the point's p50 and stages; its p99 is
    // the worst block's, so that a block with a slow stretch is not averaged away.
    let p50 = median(ves.iter().map(|v| v.step_time.p50_ns as f64).collect());
    let typical = *ves.iter().find(|v| v.step_time.p50_ns as f64 == p50).ok_or_else(|| anyhow!("no blocks"))?;
    let p99_ns = ves.iter().map(|v| v.step_time.p99_ns).max().unwrap_or(0);
    let cpu = ves.iter().map(|v| v.cpu_s).sum::<Option<f64>>();
    let wall: f64 = ves.iter().map(|v| v.wall_s).sum();
    let us = |ns: u64| round(ns as f64 / 1e3, 2);
    let (stages, bench_stages) = (StageMedians::of(typical), StageMedians::of(&looped));
    let p50_ns = typical.step_time.p50_ns;
    Ok(CapacityPoint {
        users,
        step_us_p50: us(p50_ns),
        step_us_p99: us(p99_ns),
        bench_us: round(bench_ns / 1e3, 2),
        realtime_over_bench: round(p50_ns as f64 / bench_ns.max(1.0), 2),
        loop_bench_us_p50: us(looped.step_time.p50_ns),
        realtime_over_loop_bench: round(p50_ns as f64 / looped.step_time.p50_ns.max(1) as f64, 2),
        ve_stages_over_bench: round(stages.ve_own() / bench_stages.ve_own().max(1e-3), 2),
        stages_us_p50: stages,
        bench_stages_us_p50: bench_stages,
        miss_rate: misses as f64 / ticks.max(1) as f64,
        floor_miss_rate: floor_misses as f64 / floor_ticks.max(1) as f64,
        misses_vs_floor: RateRatio::new(misses, ticks, floor_misses, floor_ticks, MISSES_BOUND),
        stalls_vs_floor: RateRatio::new(stalls, ticks, floor_stalls, floor_ticks, MISSES_BOUND),
        blocks: pairs,
        cpu_fraction: cpu.map(|cpu| round(cpu / wall.max(1e-9), 3)),
        realtime_priority: ves.iter().all(|v| v.realtime_priority),
        snapshots_dropped: sum(|v| v.snapshots_dropped),
        energy_reports_refused: sum(|v| v.core.energy_reports_refused),
        state_restores: sum(|v| v.core.state_restores),
        max_closure_error_m: ves.iter().map(|v| v.core.max_closure_error).fold(0.0, f64::max),
    })
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("capacity", options)?;
    let users: Vec<usize> = options.pick(vec![1, 2, 4, 16, 64], vec![1, 4]);
    let seconds = options.seconds.unwrap_or(options.pick(10.0, 0.5));
    let bench_iters = options.pick(5_000, 200);
    // The quick grid's points are shorter than a block; two blocks each still alternate.
    let least_blocks = options.pick(1, 2);
    let load = load_average();
    let mut points = Vec::with_capacity(users.len());
    // One point at a time: the points share the machine they measure.
    for &n in &users {
        if options.progress {
            eprintln!("capacity: {n} users, {seconds} s");
        }
        points.push(measure(n, seconds, least_blocks, bench_iters)?);
    }

    let xs = |f: fn(&CapacityPoint) -> f64| points.iter().map(|p| (p.users as f64, f(p))).collect::<Vec<_>>();
    let chart = Chart::new("VE loop iteration against users in one room", "users", "step (us)")
        .legend(Legend::UpperLeft)
        .with(Series::line("real time, p50", xs(|p| p.step_us_p50)))
        .with(Series::line("real time, p99", xs(|p| p.step_us_p99)))
        .with(Series::line("back to back, whole iteration", xs(|p| p.loop_bench_us_p50)))
        .with(Series::line("back to back, VE tick alone", xs(|p| p.bench_us)));
    out.chart("step_vs_users", &chart)?;
    let chart = Chart::new("Deadline misses against users, beside the idle loop's", "users", "missed ticks (%)")
        .legend(Legend::UpperLeft)
        .with(Series::line("VE loop", xs(|p| 100.0 * p.miss_rate)))
        .with(Series::line("idle loop (timer floor)", xs(|p| 100.0 * p.floor_miss_rate)));
    out.chart("misses_vs_users", &chart)?;

    let rooms_seconds = options.seconds.unwrap_or(options.pick(10.0, 2.0));
    // The server's QUIC side as kinloop-server runs it.
    let runtime = network_runtime("kinloop-capacity-net", None, true)?;
    let mut rooms_axis = Vec::new();
    for point in capacity_rooms::grid(options.quick) {
        if options.progress {
            let slow = if point.slow_room { " and a slow room" } else { "" };
            eprintln!("capacity: {} rooms of {} users{slow}, {rooms_seconds} s", point.rooms, point.users_per_room);
        }
        rooms_axis.push(capacity_rooms::measure(point, rooms_seconds, least_blocks, &runtime)?);
    }
    runtime.shutdown_timeout(Duration::from_secs(1));
    // The slow room's point is read beside the plain point of as many rooms, not drawn on their line.
    let plain = || rooms_axis.iter().filter(|p| p.slow_room.is_none());
    let rx = |f: fn(&RoomsPoint) -> f64| plain().map(|p| (p.rooms as f64, f(p))).collect::<Vec<_>>();
    let chart = Chart::new("VE step against rooms per server (2 users each, real clients)", "rooms", "step (us)")
        .legend(Legend::UpperLeft)
        .with(Series::line("worst room, p50", rx(|p| p.step_us_p50_worst)))
        .with(Series::line("worst room, p99", rx(|p| p.step_us_p99_worst)));
    out.chart("step_vs_rooms", &chart)?;
    let chart = Chart::new("Deadline misses against rooms, beside the idle loop's", "rooms", "missed ticks (%)")
        .legend(Legend::UpperLeft)
        .with(Series::line("worst room", rx(|p| 100.0 * p.miss_rate_worst)))
        .with(Series::line("idle loop (timer floor)", rx(|p| 100.0 * p.floor_miss_rate)));
    out.chart("misses_vs_rooms", &chart)?;

    let last = points.last().ok_or_else(|| anyhow!("no points"))?;
    let answer = format!(
        "{} users in one room: step p50 {} us, p99 {} us ({}x the same iteration back to back, {} us; the VE's own \
         stages {}x); misses {:.3} % beside the idle loop's {:.3} % (in {} alternating blocks a side): {}; stalls: {}; \
         load average {}.",
        last.users,
        last.step_us_p50,
        last.step_us_p99,
        last.realtime_over_loop_bench,
        last.loop_bench_us_p50,
        last.ve_stages_over_bench,
        100.0 * last.miss_rate,
        100.0 * last.floor_miss_rate,
        last.blocks.len(),
        last.misses_vs_floor.describe(),
        last.stalls_vs_floor.describe(),
        load.map_or("unknown".to_string(), |l| format!("{l:.2}")),
    );
    let rooms_answer = |r: &RoomsPoint| {
        let slow = match &r.slow_room {
            Some(slow) => format!(
                " and a room whose every tick takes {} ms (quarantined in every block: {}, at most {:.2} of a core)",
                capacity_rooms::SLOW_ROOM_TICK.as_millis(),
                slow.quarantined_every_block,
                slow.cpu_cores_max
            ),
            None => String::new(),
        };
        format!(
            " {} rooms of {}{slow}: worst room's step p99 {} us, misses (every room's) {:.3} % beside the floor's \
             {:.3} %: {}; the worst room's {}; its stalls {}; {} restores, device-LM RMS median {} mm.",
            r.rooms,
            r.users_per_room,
            r.step_us_p99_worst,
            100.0 * r.misses_vs_floor.events as f64 / r.misses_vs_floor.ticks.max(1) as f64,
            100.0 * r.floor_miss_rate,
            r.misses_vs_floor.describe(),
            r.worst_room_vs_floor.describe(),
            r.worst_room_stalls_vs_floor.describe(),
            r.state_restores,
            r.device_lm_rms_mm_median
        )
    };
    let mut answer = answer;
    for r in plain().next_back().into_iter().chain(rooms_axis.iter().filter(|p| p.slow_room.is_some())) {
        answer.push_str(&rooms_answer(r));
    }
    let results = CapacitySummary {
        answer,
        rooms: 1,
        load_average: load,
        seconds_per_point: seconds,
        points,
        seconds_per_rooms_point: rooms_seconds,
        rooms_axis,
    };
    out.finish(
        "Users per room against the real-time VE loop's step, misses beside the timer floor, and stability",
        "users: 5 points of 2 x 10 s, rooms: 5 points of 2 x 10 s (the last with a slow room); --quick 2 + 2 \
         points of 2 x 0.5 s and 2 x 2 s, each in two blocks a side",
        serde_json::to_value(&results)?,
    )
}
