//! The `capacity` experiment's rooms axis: how many rooms one server carries. Each point starts a real
//! `kinloop_server::Server` hosting R rooms of the paper's testbed (its real-time executor, QUIC on
//! loopback) and drives U real client sessions into each from a `kinloop load` process ([`crate::load`]:
//! one shared clock thread stepping every user's haptic core, not a real-time thread each), for the point's
//! seconds, in blocks alternating with the idle timer floor's (the same clock and sleep and no work;
//! [`super::interleave`]). It reports each room's VE step (p50, p99) and deadline misses beside that floor,
//! restores and closure, and each user's device-to-local-model RMS and uplink loss, against the same figures
//! of one room alone (the first point).
//!
//! The clients share the machine with the server they load, as clients on the server's machine would, but
//! not its process; the load's CPU use is reported beside the point.

use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use kinloop_linkage::model::scene::Scene;
use kinloop_server::driver::rooms::{RoomReport, RoomSpec, TestKnobs};
use kinloop_server::driver::VeLoopStats;
use kinloop_server::{Access, Server, ServerConfig, ServerHandle};
use serde::{Deserialize, Serialize};

use super::interleave::{counted_since, interleave, median, BlockPair, Blocks, WARM_UP};
use super::programs::kinloop_beside_this_program;
use super::rate_ratio::RateRatio;
use crate::load::LoadSummary;
use crate::rounding::round;

/// One point of the rooms axis: R rooms of U users on one server.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoomsPoint {
    /// Rooms with users on the server.
    pub rooms: usize,
    /// Users in each room.
    pub users_per_room: usize,
    /// The slow room beside them, when the point has one: the figures below are the other rooms'.
    pub slow_room: Option<SlowRoom>,
    /// Users that rendered, of `rooms × users_per_room`, in the block where fewest did.
    pub users_rendered: usize,
    /// Median VE step (µs): each block's worst room's, the median over blocks.
    pub step_us_p50_worst: f64,
    /// 99th percentile (µs), the largest over rooms and blocks.
    pub step_us_p99_worst: f64,
    /// Fraction of VE ticks woken more than half a period late, the worst room's over every block.
    pub miss_rate_worst: f64,
    /// Fraction of the idle loop's ticks more than 500 µs late, in blocks alternating with the run's.
    pub floor_miss_rate: f64,
    /// Every room's misses pooled (the server's rate) against the idle loop's, with the ratio's interval
    /// judged against [`MISSES_BOUND`].
    pub misses_vs_floor: RateRatio,
    /// The room that missed most against the idle loop, the same way.
    pub worst_room_vs_floor: RateRatio,
    /// Every room's stalls (runs of late wake-ups, each counted once) pooled against the idle loop's. A
    /// stall of the executor's thread is one in each room on it, so the pooled count still comes in bursts;
    /// a room's own count does not.
    pub stalls_vs_floor: RateRatio,
    /// The worst room's (the one that missed most) stalls against the idle loop's.
    pub worst_room_stalls_vs_floor: RateRatio,
    /// The idle loop's and the worst room's counts block by block, in the order they alternated.
    pub blocks: Vec<BlockPair>,
    /// States restored, over every room.
    pub state_restores: u64,
    /// Largest closure residual over every room (m).
    pub max_closure_error_m: f64,
    /// Rooms with users moved off the real-time threads for overrunning at any time, released or not (the slow
    /// room not counted).
    pub rooms_quarantined: usize,
    /// Device-to-local-model RMS (mm), the median over the users.
    pub device_lm_rms_mm_median: f64,
    /// ... the largest.
    pub device_lm_rms_mm_max: f64,
    /// Uplinks the server missed (by sequence number), the largest share over the users.
    pub uplink_loss_worst: f64,
    /// The load's haptic ticks more than 500 µs late, over every user, as a share of its ticks.
    pub load_miss_rate: f64,
    /// CPU the load process (every client) used, in cores, the mean over blocks.
    pub load_cpu_cores: Option<f64>,
}

/// What the slow room did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SlowRoom {
    /// Moved off the real-time threads in every block.
    pub quarantined_every_block: bool,
    /// The largest share of a core its quarantine took, over the blocks.
    pub cpu_cores_max: f64,
}

/// The goal's bound on a server's deadline misses, as a multiple of the idle loop's on the same machine.
pub const MISSES_BOUND: f64 = 1.5;

/// How long a tick of the slow room takes ([`TestKnobs::cost`]): twice the period, so that it cannot be
/// stepped in real time at all.
pub const SLOW_ROOM_TICK: Duration = Duration::from_millis(2);

/// Its name.
pub const SLOW_ROOM: &str = "slow";

/// One point of the rooms axis's grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridPoint {
    /// Rooms with users.
    pub rooms: usize,
    /// Users in each.
    pub users_per_room: usize,
    /// A room beside them whose every tick takes [`SLOW_ROOM_TICK`] (no users: it refuses them as over
    /// budget): the others' misses must not follow it.
    pub slow_room: bool,
}

/// The rooms axis's grid, the first point being the one room alone the others are read against, the last
/// the largest with a slow room beside it.
pub fn grid(quick: bool) -> Vec<GridPoint> {
    let point = |rooms, slow_room| GridPoint { rooms, users_per_room: 2, slow_room };
    if quick {
        vec![point(1, false), point(2, true)]
    } else {
        vec![point(1, false), point(4, false), point(8, false), point(16, false), point(16, true)]
    }
}

/// How long the load runs past the counted block: its clients joined a few tenths of a second after it
/// started, and are to be holding their rooms until the block's end is read.
const LOAD_TAIL: Duration = Duration::from_millis(500);

/// One block's run: what the server reported of each room at the block's start (after the warm-up) and end,
/// and what the load reported of each user.
struct RoomsBlock {
    start: Vec<RoomReport>,
    end: Vec<RoomReport>,
    outcome: LoadSummary,
}

impl RoomsBlock {
    /// A room's (misses, stalls, ticks) over the block.
    fn counted(&self, room: &str) -> Option<(u64, u64, u64)> {
        let find = |reports: &[RoomReport]| reports.iter().find(|r| r.name == room).map(|r| r.stats.ve);
        let end = find(&self.end)?;
        Some(counted_since(&end, find(&self.start).as_ref()))
    }
}

/// Measures a grid point for `seconds`, in blocks alternating with the idle loop's ([`interleave`]): each
/// run block starts its own server and load, so that every block is the same run.
pub fn measure(
    point: GridPoint,
    seconds: f64,
    at_least_blocks: usize,
    runtime: &tokio::runtime::Runtime,
) -> Result<RoomsPoint> {
    let GridPoint { rooms, users_per_room: users, slow_room } = point;
    let scene = kinloop_linkage::model::builtin::scene("paper-testbed")
        .ok_or_else(|| anyhow!("the built-in paper-testbed is missing"))??;
    let names: Vec<String> = (1..=rooms).map(|i| format!("room{i}")).collect();
    let kinloop = kinloop_beside_this_program()?;
    let blocks = interleave(Blocks::covering(seconds, at_least_blocks), |duration| {
        run_block(&kinloop, &scene, &names, point, duration, runtime)
    })?;
    let runs = &blocks.runs;

    // Each room's counts over every block. The slow room is not among them: it is judged by what it does
    // to the others.
    let counts = |events: fn(&(u64, u64, u64)) -> u64| -> Vec<(u64, u64)> {
        names
            .iter()
            .map(|room| runs.iter().filter_map(|b| b.counted(room)).fold((0, 0), |(n, t), c| (n + events(&c), t + c.2)))
            .collect()
    };
    let (misses, stalls) = (counts(|c| c.0), counts(|c| c.1));
    let (floor_misses, floor_stalls, floor_ticks) = blocks.floor_totals();
    let rate = |c: &(u64, u64)| c.0 as f64 / c.1.max(1) as f64;
    // Every room pooled, and the worst room, each against the idle loop's. The worst room is the one with the
    // highest miss rate (a room that ran fewer ticks is not the better for it), chosen once: its stalls are
    // that same room's, so that they and the block pairs below count one room's ticks (the room with the
    // most stalls need not be the one that missed most).
    let worst_room = (0..misses.len()).max_by(|&a, &b| rate(&misses[a]).total_cmp(&rate(&misses[b]))).unwrap_or(0);
    let judged = |counts: &[(u64, u64)], floor_events: u64| {
        let against = |(n, ticks): (u64, u64)| RateRatio::new(n, ticks, floor_events, floor_ticks, MISSES_BOUND);
        let pooled = counts.iter().fold((0, 0), |(n, t), (cn, ct)| (n + cn, t + ct));
        (against(pooled), against(counts.get(worst_room).copied().unwrap_or((0, 0))))
    };
    let (misses_vs_floor, worst_room_vs_floor) = judged(&misses, floor_misses);
    let (stalls_vs_floor, worst_room_stalls_vs_floor) = judged(&stalls, floor_stalls);
    let pairs = blocks.pairs(|b| names.get(worst_room).and_then(|room| b.counted(room)).unwrap_or_default());

    // The rest is each block's whole run, as the server reported it at the block's end.
    let judged_reports = || runs.iter().flat_map(|b| b.end.iter().filter(|r| r.name != SLOW_ROOM));
    let every_ve = || judged_reports().map(|r| &r.stats.ve);
    let worst_of = |f: &dyn Fn(&VeLoopStats) -> f64| every_ve().map(f).fold(0.0, f64::max);
    // A block's worst room's median step, the median over blocks; the p99 the worst anywhere.
    let block_p50s = runs.iter().map(|b| {
        b.end.iter().filter(|r| r.name != SLOW_ROOM).map(|r| r.stats.ve.step_time.p50_ns as f64).fold(0.0, f64::max)
    });
    let mut rms: Vec<f64> = runs
        .iter()
        .flat_map(|b| b.outcome.per_user.iter().filter(|u| u.rendered).map(|u| u.device_lm_rms_mm))
        .collect();
    rms.sort_by(f64::total_cmp);
    let load_ticks: u64 = runs.iter().flat_map(|b| b.outcome.per_user.iter().map(|u| u.ticks)).sum();
    let load_misses: u64 = runs.iter().map(|b| b.outcome.lateness_misses).sum();
    let load_cpu = runs.iter().map(|b| b.outcome.cpu_cores).sum::<Option<f64>>().map(|c| c / runs.len().max(1) as f64);
    // A room released before the block's end was still sent to the quarantine: counted.
    let quarantined =
        |room: &str| runs.iter().any(|b| b.end.iter().any(|r| r.name == room && (r.quarantined || r.quarantines > 0)));
    Ok(RoomsPoint {
        rooms,
        users_per_room: users,
        slow_room: slow_room.then(|| SlowRoom {
            quarantined_every_block: runs.iter().all(|b| b.end.iter().any(|r| r.name == SLOW_ROOM && r.quarantined)),
            cpu_cores_max: runs
                .iter()
                .flat_map(|b| b.end.iter().filter(|r| r.name == SLOW_ROOM))
                .filter_map(|r| r.quarantine.as_ref().map(|q| q.share_of_core))
                .fold(0.0, f64::max),
        }),
        users_rendered: runs.iter().map(|b| b.outcome.rendered).min().unwrap_or(0),
        step_us_p50_worst: round(median(block_p50s.collect()) / 1e3, 2),
        step_us_p99_worst: round(worst_of(&|v| v.step_time.p99_ns as f64) / 1e3, 2),
        miss_rate_worst: misses.get(worst_room).map_or(0.0, rate),
        floor_miss_rate: floor_misses as f64 / floor_ticks.max(1) as f64,
        misses_vs_floor,
        worst_room_vs_floor,
        stalls_vs_floor,
        worst_room_stalls_vs_floor,
        blocks: pairs,
        state_restores: every_ve().map(|v| v.core.state_restores).sum(),
        max_closure_error_m: worst_of(&|v| v.core.max_closure_error),
        rooms_quarantined: names.iter().filter(|room| quarantined(room)).count(),
        device_lm_rms_mm_median: rms.get(rms.len() / 2).copied().map_or(0.0, |r| round(r, 3)),
        device_lm_rms_mm_max: round(rms.last().copied().unwrap_or(0.0), 3),
        uplink_loss_worst: judged_reports()
            .flat_map(|r| r.stats.per_user.iter().map(|u| u.uplink_loss))
            .fold(0.0, f64::max),
        load_miss_rate: load_misses as f64 / load_ticks.max(1) as f64,
        load_cpu_cores: load_cpu.map(|c| round(c, 3)),
    })
}

/// `kinloop load --realtime` (its clock and network worker at SCHED_FIFO when granted) with `users` clients
/// in each of the rooms `names` of `server`, for `duration`, in a process of its own, as a load is run beside
/// a server: the clients share the machine and not the server's process.
fn start_load(
    kinloop: &Path,
    server: &ServerHandle,
    names: &[String],
    users: usize,
    duration: Duration,
) -> Result<Child> {
    Command::new(kinloop)
        .args(["load", "--realtime", "--json", "--server", &server.local_addr().to_string()])
        .args(["--fingerprint", server.fingerprint()])
        .args(["--users", &(names.len() * users).to_string(), "--rooms", &names.join(",")])
        .args(["--duration", &duration.as_secs_f64().to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting {} load", kinloop.display()))
}

/// What the load printed when it ended.
fn finish_load(load: Child) -> Result<LoadSummary> {
    let output = load.wait_with_output().context("waiting for kinloop load")?;
    if !output.status.success() {
        bail!("kinloop load ended with {}: {}", output.status, String::from_utf8_lossy(&output.stderr).trim());
    }
    serde_json::from_slice(&output.stdout).context("reading kinloop load --json")
}

/// One server of the point's rooms of the scene (and the slow room when the point has it), `users` real
/// clients in each of `names` for `duration`.
fn run_block(
    kinloop: &Path,
    scene: &Scene,
    names: &[String],
    point: GridPoint,
    duration: Duration,
    runtime: &tokio::runtime::Runtime,
) -> Result<RoomsBlock> {
    let mut config = ServerConfig::new(scene.clone(), "paper-testbed", SocketAddr::from(([127, 0, 0, 1], 0)));
    let room = |name: &str, knobs| RoomSpec {
        name: name.to_owned(),
        scene: scene.clone(),
        scene_label: "paper-testbed".into(),
        access: Access::open(),
        max_users: point.users_per_room,
        record: None,
        knobs,
    };
    config.rooms = names.iter().map(|name| room(name, TestKnobs::default())).collect();
    if point.slow_room {
        config.rooms.push(room(SLOW_ROOM, TestKnobs { cost: Some(SLOW_ROOM_TICK), panic_after_ticks: None }));
    }
    config.stats_every = None;
    let server = {
        let _inside = runtime.enter();
        Server::start(config).context("starting the server")?
    };
    // The load runs its warm-up (the clients connect and join), then the counted block; the rooms' counts
    // are read at both ends of the block and taken apart.
    let load = start_load(kinloop, &server, names, point.users_per_room, WARM_UP + duration + LOAD_TAIL);
    let counted = load.map(|load| {
        std::thread::sleep(WARM_UP);
        let start = server.room_stats();
        std::thread::sleep(duration);
        (load, start, server.room_stats())
    });
    let (outcome, start, end) = match counted {
        Ok((load, start, end)) => (finish_load(load), start, end),
        Err(e) => (Err(e), Vec::new(), Vec::new()),
    };
    runtime.block_on(server.shutdown()).context("shutting the server down")?;
    Ok(RoomsBlock { start, end, outcome: outcome? })
}
