//! Measurements `kinloop bench --json` reports for this crate, kept next to the code they measure.
//!
//! - [`ve_tick_users`]: `server/ve_tick_users_N`, one VE tick with N users on the paper's testbed — every
//!   user's uplink, the dynamics with every coupling, and every user's snapshot terms — in ns per tick;
//! - [`ve_loop_users`]: `server/ve_loop_users_N`, the VE loop's whole iteration with N users back to back
//!   (the tick above plus encoding, ring pushes, wake-ups and the loop's statistics: [`LoopBench`]), in ns;
//! - [`ve_tick_after_pauses`]: the same tick timed one by one after pauses, as a real-time loop takes them
//!   (`kinloop experiment pauses`);
//! - [`realtime_run`]: the real VE thread (absolute deadlines, spin_sleep, SCHED_FIFO when allowed) with N
//!   synthetic in-process users for a while: tick-time percentiles and deadline misses.

use std::hint::black_box;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::model::builtin;
use kinloop_linkage::{
    error::SceneError, math::space::Planar, math::space::SceneKind, math::space::Space, math::space::Spatial,
    model::scene::Scene, model::Model,
};
use kinloop_protocol::{codec, Datagram, DeviceCaps, LocalModelForm, Role, SessionShape};
use rtrb::{Consumer, RingBuffer};
use serde::Serialize;

use crate::core::{JoinRequest, VeConfig, VeConfigError, VeCore, VeEvent};
use crate::driver::rehearsal::Rehearsal;
use crate::driver::ve_thread::{self, VeLoop, VeThreadIo};
use crate::gateway::VeLoopStats;
use crate::synthetic::SyntheticUser;
use crate::view::ViewTap;

mod synthetic_clients;

use synthetic_clients::{SyntheticClient, SyntheticJoins};

/// Why a measurement could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The scene did not load.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The VE configuration was refused.
    #[error(transparent)]
    Config(#[from] VeConfigError),
    /// A user was refused.
    #[error("user {index} was refused: {reason}")]
    Refused {
        /// Which user.
        index: usize,
        /// Why.
        reason: kinloop_protocol::RefusalReason,
    },
    /// A built-in scene is missing from this build.
    #[error("the built-in scene {0} is missing")]
    MissingScene(&'static str),
    /// Synthetic users need an operational point to hold.
    #[error("{scene} defines no operational point ([[op]]) for the synthetic users to hold")]
    NoOperationalPoint {
        /// The scene's label.
        scene: String,
    },
    /// A thread failed.
    #[error("the {0} thread failed")]
    Thread(&'static str),
}

/// The paper's testbed, compiled. All benchmark users hold its one operational point, `link2`. A synthetic
/// user only follows the VE (its target is where the VE's OP just was), so its coupling acts as a brake, and
/// the couplings' angular gains (the paper's 10⁴ N m/rad and N m s/rad) make that brake stiff on the gripped
/// link's orientation: followers on two different links take both of this 2-DOF linkage's freedoms and all
/// but lock it (users spread over links 2 and 3, or one on link 1 or 4, hold it nearly still; on link 2 alone
/// it moves), and a tick of a still linkage is not the tick to time. Real
/// users lead the VE with their local models and move it however they are spread (`experiment users`).
pub fn testbed() -> Result<Model<Planar>, BenchError> {
    let scene = builtin::scene("paper-testbed").ok_or(BenchError::MissingScene("paper-testbed"))??;
    Ok(Model::<Planar>::compile(&scene, "paper-testbed")?)
}

/// The operational point every synthetic user holds: the scene's first (not spread over several: see
/// [`testbed`]). Callers check that there is one.
fn first_op(model: &Model<impl Space>) -> String {
    model.ops.first().map(|op| op.name.clone()).unwrap_or_default()
}

fn join_request(model: &Model<impl Space>, index: usize, k: usize) -> JoinRequest {
    JoinRequest {
        name: format!("bench-{index}"),
        role: Role::Manipulator,
        op: first_op(model),
        form: LocalModelForm::OpSpace,
        device: Some(DeviceCaps::generous("bench", k)),
        mapping: Default::default(),
    }
}

/// A VE on the testbed with `users` users (all on `link2`, see [`testbed`]) whose uplinks follow their
/// newest snapshots: what [`ve_tick_users`] and [`ve_tick_after_pauses`] tick.
pub struct TickBench {
    core: VeCore<Planar>,
    ids: Vec<u32>,
    users: Vec<SyntheticUser>,
    seq: u64,
}

impl TickBench {
    /// Joins the users and ticks `warm_up` times.
    pub fn new(users: usize, warm_up: u64) -> Result<Self, BenchError> {
        let model = testbed()?;
        let mut config = VeConfig::paper();
        config.max_users = users.max(1);
        let mut core = VeCore::new(model.clone(), config)?;
        let ids = (0..users)
            .map(|i| {
                core.join(Duration::ZERO, join_request(&model, i, 3))
                    .map(|j| j.user_id)
                    .map_err(|reason| BenchError::Refused { index: i, reason })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut bench = TickBench { core, ids, users: vec![SyntheticUser::new(users); users], seq: 0 };
        for _ in 0..warm_up {
            bench.tick();
        }
        Ok(bench)
    }

    /// The VE being ticked.
    pub fn core(&self) -> &VeCore<Planar> {
        &self.core
    }

    /// One tick: every user's uplink, the VE step and every user's snapshot (read back into the next
    /// uplink).
    pub fn tick(&mut self) {
        self.tick_with(|_| {});
    }

    /// One [`Self::tick`] that also encodes the round's snapshots as the VE thread does; returns their bytes.
    pub fn tick_encoded(&mut self) -> usize {
        let mut buffer = Vec::new();
        let mut bytes = 0;
        self.tick_with(|datagram| {
            if codec::encode_datagram_into(datagram, &mut buffer).is_ok() {
                bytes += buffer.len();
            }
        });
        bytes
    }

    /// The synthetic users (in join order).
    pub fn users(&self) -> &[SyntheticUser] {
        &self.users
    }

    /// One tick, handing each snapshot built to `on_snapshot` before a synthetic user reads it.
    fn tick_with(&mut self, mut on_snapshot: impl FnMut(&Datagram)) {
        let core = black_box(&mut self.core);
        let now = core.poll_timeout();
        self.seq += 1;
        for (user, id) in self.users.iter_mut().zip(&self.ids) {
            if let Some(sample) = user.uplink(self.seq, now.as_secs_f64()) {
                let _ = core.handle_uplink_sample(now, *id, sample);
            }
        }
        core.handle_timeout(now);
        while let Some(pending) = core.poll_snapshot() {
            // Ids are handed out in increasing order (see `VeCore::join`): a search, not a scan per snapshot,
            // so the harness adds no quadratic work to the ticks it times. Each uplink answers the newest
            // snapshot, as a client's does (the VE's round trips).
            let index = self.ids.binary_search(&pending.user_id()).unwrap_or(0);
            on_snapshot(pending.datagram());
            self.users[index].on_snapshot(pending.snapshot());
        }
    }
}

/// Mean ns of one VE tick on the testbed with `users` users (see [`TickBench`]): every user's uplink, one
/// integrator step with every coupling, and every user's snapshot. `iters` ticks are measured after
/// `iters / 10` of warm-up.
pub fn ve_tick_users(users: usize, iters: u64) -> Result<f64, BenchError> {
    let mut bench = TickBench::new(users, (iters / 10).max(10))?;
    let start = Instant::now();
    for _ in 0..iters {
        bench.tick();
    }
    Ok(start.elapsed().as_nanos() as f64 / iters.max(1) as f64)
}

/// The VE loop on the testbed with `users` synthetic users behind its rings (all on `link2`, as
/// [`TickBench`]), iterated back to back: the VE loop's whole iteration as the real-time thread runs it less
/// its wait, through the same [`VeLoop`] (the function the driver calls each deadline). Between iterations each
/// synthetic client drains its snapshot ring, decodes the newest frame and pushes its next uplink (not timed,
/// and on the same thread: the rings' lines stay in this core's caches, where in real time the consumer's core
/// last held them).
pub struct LoopBench {
    ve: VeLoop<Planar>,
    clients: Vec<SyntheticClient>,
    events: Consumer<VeEvent>,
    stats: Consumer<VeLoopStats>,
    shape: SessionShape,
    frame: Vec<u8>,
    seq: u64,
}

impl LoopBench {
    /// Joins the users (the first iteration serves their joins) and iterates `warm_up` times more; the
    /// loop's timing starts after.
    pub fn new(users: usize, warm_up: u64) -> Result<Self, BenchError> {
        let model = testbed()?;
        let shape = SessionShape::of_model(&model);
        let mut config = VeConfig::paper();
        config.max_users = users.max(1);
        let core = VeCore::new(model.clone(), config)?;
        let requests: Vec<JoinRequest> = (0..users).map(|i| join_request(&model, i, 3)).collect();
        let joins = SyntheticJoins::queue(&model, &requests).ok_or(BenchError::Thread("command ring"))?;
        let (event_tx, events) = RingBuffer::new(1024);
        let (stats_tx, stats) = RingBuffer::new(4);
        let io = VeThreadIo {
            commands: joins.commands,
            events: event_tx,
            stats: stats_tx,
            record: None,
            view: None,
            room: None,
            stop: Arc::new(AtomicBool::new(false)),
        };
        let ve = VeLoop::new(core, io, Instant::now());
        let mut bench = LoopBench { ve, clients: joins.clients, events, stats, shape, frame: Vec::new(), seq: 0 };
        bench.iterate();
        for (index, mut reply) in joins.replies.into_iter().enumerate() {
            match reply.try_recv() {
                Ok(Ok(_)) => {}
                Ok(Err(reason)) => return Err(BenchError::Refused { index, reason }),
                Err(_) => return Err(BenchError::Thread("VE loop")),
            }
        }
        for _ in 0..warm_up {
            bench.iterate();
        }
        bench.ve.restart_timing();
        Ok(bench)
    }

    /// One timed iteration of the loop, after the clients' turn; returns its time.
    pub fn iterate(&mut self) -> Duration {
        self.seq += 1;
        let time_s = self.seq as f64 * 1e-3;
        for client in &mut self.clients {
            client.exchange(self.seq, time_s, &mut self.frame, &self.shape);
        }
        while self.events.pop().is_ok() {}
        while self.stats.pop().is_ok() {}
        let start = Instant::now();
        self.ve.tick_back_to_back();
        start.elapsed()
    }

    /// The loop's statistics so far (its step and stage percentiles are of the iterations since the
    /// warm-up).
    pub fn finish(self) -> VeLoopStats {
        self.ve.finish()
    }
}

/// Mean ns of one VE loop iteration with `users` users (see [`LoopBench`]), `iters` timed after `iters / 10`
/// of warm-up.
pub fn ve_loop_users(users: usize, iters: u64) -> Result<f64, BenchError> {
    let mut bench = LoopBench::new(users, (iters / 10).max(10))?;
    let total: Duration = (0..iters).map(|_| bench.iterate()).sum();
    Ok(total.as_nanos() as f64 / iters.max(1) as f64)
}

/// The loop's statistics over `iters` back-to-back iterations with `users` users, after `iters / 10` of
/// warm-up: its step's and each stage's percentiles, as the real-time loop reports them.
pub fn ve_loop_stats(users: usize, iters: u64) -> Result<VeLoopStats, BenchError> {
    let mut bench = LoopBench::new(users, (iters / 10).max(10))?;
    for _ in 0..iters {
        bench.iterate();
    }
    Ok(bench.finish())
}

/// How a real-time loop waits between ticks (and readies itself for the next).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pause {
    /// The thread sleeps (`std::thread::sleep`): the core may idle or run other work.
    Sleep,
    /// The thread busy-waits on the clock: the core stays with it.
    Spin,
    /// The thread sleeps, then ticks a one-user VE of its own on the same linkage before the timed tick,
    /// as the VE loop does before each deadline (`crate::driver::rehearsal`).
    Rehearsed,
}

impl Pause {
    /// `sleep` or `spin`, for charts and summaries.
    pub fn name(self) -> &'static str {
        match self {
            Pause::Sleep => "sleep",
            Pause::Spin => "spin",
            Pause::Rehearsed => "rehearsed",
        }
    }
}

/// The time of each of `ticks` VE ticks (as [`ve_tick_users`] runs them), each after a pause of `pause`
/// taken the way `how` says, in ns: what a tick costs when the loop has waited before it, as a real-time loop
/// does, rather than back to back (whatever ran meanwhile has evicted part of its working set).
pub fn ve_tick_after_pauses(users: usize, pause: Duration, how: Pause, ticks: usize) -> Result<Vec<f64>, BenchError> {
    let mut bench = TickBench::new(users, 100)?;
    let mut rehearsal = Rehearsal::new(bench.core.model(), bench.core.config());
    let mut times = Vec::with_capacity(ticks);
    for _ in 0..ticks {
        if !pause.is_zero() {
            match how {
                Pause::Sleep => std::thread::sleep(pause),
                Pause::Rehearsed => {
                    std::thread::sleep(pause);
                    if let Some(rehearsal) = rehearsal.as_mut() {
                        rehearsal.rehearse();
                    }
                }
                Pause::Spin => {
                    let until = Instant::now() + pause;
                    while Instant::now() < until {
                        std::hint::spin_loop();
                    }
                }
            }
        }
        let start = Instant::now();
        bench.tick();
        times.push(start.elapsed().as_nanos() as f64);
    }
    Ok(times)
}

/// A real-time run of the VE thread with synthetic users.
#[derive(Clone, Debug)]
pub struct RealtimeRun {
    /// The linkage.
    pub scene: Scene,
    /// Where it came from.
    pub scene_label: String,
    /// Synthetic users, all on the scene's first operational point, sharing the paper's push.
    pub users: usize,
    /// How long to run.
    pub duration: Duration,
    /// The VE configuration (`max_users` is raised to `users` if needed).
    pub ve: VeConfig,
    /// The VE thread's statistics are also kept as published this long into the run
    /// ([`RealtimeReport::ve_at_warm_up`]), so that a caller can count from there and leave out the start
    /// (`Duration::ZERO`: not kept).
    pub warm_up: Duration,
}

/// What a real-time run measured.
#[derive(Clone, Debug, Serialize)]
pub struct RealtimeReport {
    /// Users.
    pub users: usize,
    /// Seconds run.
    pub duration_s: f64,
    /// The VE thread's statistics (step time percentiles, deadline misses, SCHED_FIFO).
    pub ve: VeLoopStats,
    /// Snapshots the synthetic clients received.
    pub snapshots_received: u64,
    /// The VE thread's statistics as it published them (every tenth of a second) first at or after the
    /// run's warm-up; `None` without a warm-up or when the run ended first.
    pub ve_at_warm_up: Option<VeLoopStats>,
}

/// Runs the VE thread for `run.duration` with `run.users` synthetic users fed from a helper thread at
/// about 1 kHz (uplinks following each user's newest snapshot), and reports its timing.
pub fn realtime_run(run: RealtimeRun) -> Result<RealtimeReport, BenchError> {
    realtime_run_with_view(run, None)
}

/// [`realtime_run`], with the VE thread also feeding a web view's tap (`--synthetic-users N --view ADDR`:
/// what many open pages cost the VE).
pub fn realtime_run_with_view(run: RealtimeRun, view: Option<ViewTap>) -> Result<RealtimeReport, BenchError> {
    match run.scene.kind {
        SceneKind::Planar => realtime_run_in::<Planar>(run, view),
        SceneKind::Spatial => realtime_run_in::<Spatial>(run, view),
    }
}

fn realtime_run_in<S: Space>(run: RealtimeRun, view: Option<ViewTap>) -> Result<RealtimeReport, BenchError> {
    let model = Model::<S>::compile(&run.scene, &run.scene_label)?;
    if model.ops.is_empty() && run.users > 0 {
        return Err(BenchError::NoOperationalPoint { scene: run.scene_label });
    }
    let shape = SessionShape::of_model(&model);
    let mut ve = run.ve.clone();
    ve.max_users = ve.max_users.max(run.users);
    let core = VeCore::new(model.clone(), ve)?;
    let requests: Vec<JoinRequest> = (0..run.users).map(|i| join_request(&model, i, S::DIM)).collect();
    let SyntheticJoins { commands: command_rx, mut clients, replies } =
        SyntheticJoins::queue(&model, &requests).ok_or(BenchError::Thread("command ring"))?;
    let (event_tx, mut event_rx) = RingBuffer::new(1024);
    let (stats_tx, mut stats_rx) = RingBuffer::new(64);
    let stop = Arc::new(AtomicBool::new(false));
    let io = VeThreadIo {
        commands: command_rx,
        events: event_tx,
        stats: stats_tx,
        record: None,
        view,
        room: None,
        stop: stop.clone(),
    };
    let ve_thread = std::thread::Builder::new()
        .name("kinloop-ve".into())
        .spawn(move || ve_thread::run(core, io, true))
        .map_err(|_| BenchError::Thread("VE"))?;
    let users = run.users;
    let client_stop = stop.clone();
    let client_thread = std::thread::Builder::new()
        .name("kinloop-synthetic-users".into())
        .spawn(move || {
            let ids: Vec<Option<u32>> =
                replies.into_iter().map(|r| r.blocking_recv().ok().and_then(|j| j.ok()).map(|j| j.user_id)).collect();
            let mut frame = Vec::new();
            let mut received = 0u64;
            let mut seq = 0u64;
            let started = Instant::now();
            while !client_stop.load(Ordering::Relaxed) {
                seq += 1;
                let time_s = started.elapsed().as_secs_f64();
                for (client, id) in clients.iter_mut().zip(&ids) {
                    if id.is_some() && client.exchange(seq, time_s, &mut frame, &shape) {
                        received += 1;
                    }
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            received
        })
        .map_err(|_| BenchError::Thread("synthetic users"))?;
    let started = Instant::now();
    let warm_up_s = run.warm_up.as_secs_f64();
    let mut ve_at_warm_up = None;
    while started.elapsed() < run.duration {
        std::thread::sleep(Duration::from_millis(20));
        while event_rx.pop().is_ok() {}
        while let Ok(stats) = stats_rx.pop() {
            if warm_up_s > 0.0 && ve_at_warm_up.is_none() && stats.wall_s >= warm_up_s {
                ve_at_warm_up = Some(stats);
            }
        }
    }
    stop.store(true, Ordering::Relaxed);
    let ve_stats = ve_thread.join().map_err(|_| BenchError::Thread("VE"))?;
    let received = client_thread.join().map_err(|_| BenchError::Thread("synthetic users"))?;
    Ok(RealtimeReport {
        users,
        duration_s: started.elapsed().as_secs_f64(),
        ve: ve_stats,
        snapshots_received: received,
        ve_at_warm_up,
    })
}
