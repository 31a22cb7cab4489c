//! `kinloop demo`: the whole system in one process, in real time. A VE server ([`Server::start`]) hosts the
//! scene (by default the paper's testbed) on an ephemeral loopback port with an ephemeral certificate; N
//! clients ([`Client::start`]) connect over real QUIC, pinning the server's certificate fingerprint (more
//! than one with their haptic loops on one shared clock thread, as `kinloop load`'s users), each
//! with `kinloop-client`'s defaults: the scene's device (sim:paper planar, sim:touch spatial), the server's
//! mapping and gains, and a simulated hand touring its OP's reach, relaxed and firm in turn. The users are
//! spread over the scene's operational points in turn. With `--paper-push` they all hold the first OP and
//! share the paper's user (section VI: a constant wrench F = (−0.5 N, 0, −0.0025 N m); with N users each
//! pushes F / N, so the linkage moves as under the paper's single user). Each side impairs what it sends
//! with the same link emulation (`--delay 20ms` adds 40 ms to the round trip), each with its own seed
//! derived from `--seed`.
//!
//! Afterwards the drivers' statistics make the summary, and their `--record` files (`ve.csv`,
//! `userN.csv` in the output directory) are read back ([`records`]) into the charts of the paper's Fig 6
//! (constraint count, device and OP trajectories, joint-constraint wrench), drawn by the `paper`
//! experiment's own chart code.

pub mod records;
pub mod twin;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kinloop_client::device::{DevicePreset, DhdRequest, HdRequest};
use kinloop_client::driver::shared_clock::SharedClock;
use kinloop_client::driver::shared_network::SharedNetwork;
use kinloop_client::driver::{Client, ClientConfig, ClientHandle, ClientStats};
use kinloop_client::user::{HandSpec, UserSpec};
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_linkage::{math::space::SceneKind, model::scene::Scene};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::Trust;
use kinloop_server::driver::network_runtime::network_runtime;
use kinloop_server::driver::UserStats;
use kinloop_server::view::ViewConfig;
use kinloop_server::{Server, ServerConfig, ServerHandle, ServerStats};
use serde::Serialize;

use crate::charts::{self, Chart, Legend};
use crate::experiments::paper::{count_chart, device_op_distance, distance_series, trajectory_chart, wrench_chart};
use kinloop_harness::ClientSample;

/// Most users the demo starts (beyond one, their loops share one clock thread).
pub const MAX_USERS: usize = 64;
/// Longest demo.
pub const MAX_DURATION: Duration = Duration::from_secs(3600);
/// How long after the requested duration the demo waits for the clients' loops to end by themselves.
const FINISH_GRACE: Duration = Duration::from_secs(5);
/// Users drawn in the device-OP distance chart (more lines are unreadable).
const DISTANCE_CHART_USERS: usize = 8;

/// What the demo runs.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// The linkage.
    pub scene: Scene,
    /// Where it came from (for messages and the summary).
    pub scene_label: String,
    /// Simulated users, 1 to [`MAX_USERS`].
    pub users: usize,
    /// How long each client's loop runs.
    pub duration: Duration,
    /// Network impairments, applied by each side to what it sends (transparent: none).
    pub link: LinkConfig,
    /// Charts, records and `summary.json` go to `out/demo/`.
    pub out: PathBuf,
    /// Draw a progress bar on stderr (hidden anyway when stderr is not a terminal).
    pub progress: bool,
    /// Stop early, cleanly, on Ctrl-C.
    pub ctrl_c: bool,
    /// Ask for SCHED_FIFO for the VE and haptic threads.
    pub realtime: bool,
    /// Serve the web view of the session (`--view ADDR`).
    pub view: Option<ViewConfig>,
    /// The users share the paper's constant push on the first OP instead of touring with hands.
    pub paper_push: bool,
    /// The device every user holds (`None`: the scene's default).
    pub device: Option<DevicePreset>,
    /// A Force Dimension device the first user holds instead, through the same code as `kinloop-client
    /// --device dhd`.
    pub dhd: Option<DhdRequest>,
    /// A 3D Systems device the first user holds instead, through the same code as `kinloop-client --device
    /// hd` (its servo thread runs that user's loop).
    pub hd: Option<HdRequest>,
    /// The first user's OP (`None`: the scene's first; the others follow in turn from it).
    pub first_op: Option<String>,
    /// Every user's hand and what it intends (`None`: relaxed and firm in turn, touring the reach).
    pub hand: Option<HandSpec>,
    /// Afterwards, run the same session in virtual time ([`twin`]) and report it beside.
    pub twin: bool,
    /// Pin the server's real-time thread and network workers to one CPU (`ServerConfig::network_cpu`).
    pub pin_network: bool,
}

impl DemoOptions {
    /// The paper's testbed, one user, 3 s, a perfect network, results under `out`.
    pub fn new(out: impl Into<PathBuf>) -> Result<Self> {
        let scene = kinloop_linkage::model::builtin::scene("paper-testbed").context("the built-in paper-testbed")??;
        Ok(DemoOptions {
            scene,
            scene_label: "builtin:paper-testbed".into(),
            users: 1,
            duration: Duration::from_secs(3),
            link: LinkConfig::default(),
            out: out.into(),
            progress: true,
            ctrl_c: false,
            realtime: true,
            view: None,
            paper_push: false,
            device: None,
            dhd: None,
            hd: None,
            first_op: None,
            hand: None,
            twin: false,
            pin_network: false,
        })
    }
}

/// One user's part of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct UserSummary {
    /// Id the VE gave the user.
    pub user_id: u32,
    /// Client name.
    pub name: String,
    /// Operational point held.
    pub op: String,
    /// The client's exit statistics (`kinloop-client --json`'s keys).
    pub client: serde_json::Value,
    /// What the server measured of this user, if it saw it.
    pub server: Option<UserStats>,
    /// RMS distance between the device and the VE's OP over the ticks with output (mm), from the records,
    /// in the device's space (the VE distance times the mapping's position scale: what the hand feels).
    pub device_op_rms_mm: Option<f64>,
    /// Largest such distance (mm).
    pub device_op_max_mm: Option<f64>,
    /// Device metres per VE metre (the server's mapping).
    pub position_scale: f64,
    /// Device newtons per VE newton.
    pub force_scale: f64,
    /// When the client's loop started on the VE's clock (s): its record's times plus this are VE times.
    pub record_offset_s: f64,
}

/// What the demo measured: `kinloop demo --json` prints this object and `summary.json` holds it.
#[derive(Clone, Debug, Serialize)]
pub struct DemoSummary {
    /// Users that ran.
    pub users: usize,
    /// Scene label.
    pub scene: String,
    /// Requested seconds per client.
    pub duration_s: f64,
    /// Wall-clock seconds from the server's start to its shutdown.
    pub wall_s: f64,
    /// Stopped early by Ctrl-C.
    pub cancelled: bool,
    /// Added one-way delay per side (ms).
    pub delay_ms: f64,
    /// Delay jitter per side (ms).
    pub jitter_ms: f64,
    /// Loss probability per side.
    pub loss: f64,
    /// Seed of the link emulation.
    pub seed: u64,
    /// VE rate (Hz).
    pub ve_rate_hz: f64,
    /// VE ticks.
    pub ve_ticks: u64,
    /// Time of one VE loop iteration (µs), median.
    pub ve_tick_us_p50: f64,
    /// ... 99th percentile.
    pub ve_tick_us_p99: f64,
    /// ... largest.
    pub ve_tick_us_max: f64,
    /// The VE loop iteration's stages (p50/p99/max ns each), as the server's `--json` reports them
    /// (`ve.stages`).
    pub ve_stages: kinloop_server::gateway::StageTimes,
    /// CPU time of the VE thread over its wall time (its spin before each deadline included).
    pub ve_cpu_fraction: Option<f64>,
    /// VE wake-ups later than half a period.
    pub ve_deadline_misses: u64,
    /// Whether the VE thread got SCHED_FIFO.
    pub ve_realtime_priority: bool,
    /// Haptic ticks over every user.
    pub loop_ticks: u64,
    /// Haptic loop lateness (µs), median of the worst user.
    pub loop_lateness_us_p50: f64,
    /// ... 99th percentile of the worst user.
    pub loop_lateness_us_p99: f64,
    /// ... largest over every user.
    pub loop_lateness_us_max: f64,
    /// Haptic ticks more than 500 µs late, over every user.
    pub loop_misses: u64,
    /// Median over users of each client's median ping round trip (ms); None when no ping was answered.
    pub rtt_ms_p50: Option<f64>,
    /// Largest closure residual the VE saw (m).
    pub max_closure_error: f64,
    /// Largest commanded force over the device limit, over every user (≤ 1).
    pub max_force_ratio: f64,
    /// Uplinks the VE refused as broken or hostile.
    pub uplinks_rejected: u64,
    /// States the VE restored after a failed or torn step.
    pub ve_restores: u64,
    /// Snapshots the VE withheld (dynamics failed, or a term outside the wire's ranges).
    pub snapshots_withheld: u64,
    /// The round trips the VE weighted the users' sharing of one another's hands by.
    pub sharing: kinloop_server::core::metrics::SharingMetrics,
    /// Each user.
    pub per_user: Vec<UserSummary>,
    /// The same session in virtual time (`--twin`), when asked for.
    pub twin: Option<twin::TwinSummary>,
    /// Files written in the output directory, `summary.json` last.
    pub files: Vec<String>,
}

/// What [`run`] produced.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// The summary, as written to `summary.json`.
    pub summary: DemoSummary,
    /// The output directory (`out/demo`).
    pub dir: PathBuf,
}

/// The paper's hand wrench in the scene's operational space, shared by `users` users.
fn user_wrench(kind: SceneKind, users: usize) -> Vec<f64> {
    let [fx, fy, tz] = PAPER_WRENCH;
    let full = match kind {
        SceneKind::Planar => vec![fx, fy, tz],
        SceneKind::Spatial => vec![fx, fy, 0.0, 0.0, 0.0, tz],
    };
    full.into_iter().map(|w| w / users as f64).collect()
}

/// The link one side emulates: `side` 0 is the server, `i + 1` client `i`, each with its own seed so the
/// sides' losses and delays are independent but repeatable.
fn side_link(link: &LinkConfig, side: u64) -> Option<LinkConfig> {
    (!link.is_transparent()).then(|| LinkConfig { seed: link.seed.wrapping_add(side), ..link.clone() })
}

fn check(options: &DemoOptions) -> Result<()> {
    anyhow::ensure!((1..=MAX_USERS).contains(&options.users), "--users {}: between 1 and {MAX_USERS}", options.users);
    anyhow::ensure!(
        !options.duration.is_zero() && options.duration <= MAX_DURATION,
        "--duration {:?}: more than 0 s and at most {} s",
        options.duration,
        MAX_DURATION.as_secs()
    );
    options.link.validate().context("link emulation")?;
    anyhow::ensure!(
        !options.scene.ops.is_empty(),
        "scene {} has no operational point ([[op]]) for the users to hold",
        options.scene_label
    );
    if let Some(op) = &options.first_op {
        let names: Vec<&str> = options.scene.ops.iter().map(|o| o.name.as_str()).collect();
        anyhow::ensure!(
            names.contains(&op.as_str()),
            "--op {op}: scene {} has {}",
            options.scene_label,
            names.join(", ")
        );
    }
    Ok(())
}

/// User `i`'s operational point and simulated user (see the module documentation).
fn user_of(options: &DemoOptions, i: usize) -> (String, UserSpec) {
    let ops = &options.scene.ops;
    if options.paper_push {
        return (ops[0].name.clone(), UserSpec::Constant(user_wrench(options.scene.kind, options.users)));
    }
    let hand = options.hand.clone().unwrap_or_else(|| crate::load::hand_in_turn(i));
    let first = options.first_op.as_ref().and_then(|name| ops.iter().position(|o| &o.name == name)).unwrap_or(0);
    (ops[(first + i) % ops.len()].name.clone(), UserSpec::Hand(hand))
}

/// Runs the demo: server and clients in real time, then the summary, charts and `summary.json` in
/// `options.out/demo/`.
pub fn run(options: &DemoOptions) -> Result<DemoReport> {
    check(options)?;
    let dir = options.out.join("demo");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating the output directory {}", dir.display()))?;
    // The server's QUIC side as kinloop-server runs it: below the real-time loops, above other work.
    let realtime = options.realtime;
    let network_cpu = options.pin_network.then(kinloop_process::affinity::last_cpu);
    let runtime = network_runtime("kinloop-demo-net", network_cpu, realtime).context("starting the network runtime")?;
    let started = Instant::now();
    let mut config =
        ServerConfig::new(options.scene.clone(), options.scene_label.clone(), SocketAddr::from(([127, 0, 0, 1], 0)));
    config.ve.max_users = config.ve.max_users.max(options.users);
    config.link = side_link(&options.link, 0);
    config.record = Some(dir.join("ve.csv"));
    config.realtime = options.realtime;
    config.network_cpu = network_cpu;
    config.view = options.view.clone();
    let server = {
        let _inside = runtime.enter();
        Server::start(config).context("starting the server")?
    };
    if let Some(addr) = server.view_addr() {
        eprintln!("kinloop demo: watch it at http://{addr}/");
    }
    // The VE's clock starts with the server (its uptime counts from the same moment, to well under 1 ms).
    let ve_epoch = Instant::now() - Duration::from_secs_f64(server.stats().uptime_s);

    let cancel = Arc::new(AtomicBool::new(false));
    let ctrl_c = options.ctrl_c.then(|| {
        let cancel = cancel.clone();
        runtime.spawn(async move {
            kinloop_client::driver::stop_signal::stop_requested().await;
            cancel.store(true, Ordering::Relaxed);
        })
    });
    // One user runs as kinloop-client does, on a loop thread of its own; more share one clock thread, as
    // `kinloop load`'s users do, so the demo shows what the server does rather than what many real-time
    // threads do to a small machine.
    let (clock, network) = match options.users {
        1 => (None, None),
        _ => {
            let network = SharedNetwork::start(crate::load::NETWORK_THREADS, options.realtime)
                .context("starting the shared network")?;
            let clock = SharedClock::start(1000.0, options.realtime, Some(network.round_hook()))
                .context("starting the shared haptic clock")?;
            (Some(clock), Some(network))
        }
    };
    let shared = clock.as_ref().map(|(c, _)| c).zip(network.as_ref());
    let clients = match start_clients(options, &server, &dir, ve_epoch, shared) {
        Ok(clients) => clients,
        Err(e) => {
            // Nothing may outlive a failed start: the server's threads stop with it.
            let _ = runtime.block_on(server.shutdown());
            return Err(e);
        }
    };
    let cancelled = watch(options, &server, &clients, &cancel);
    // All at once: after Ctrl-C no loop should run on while another client is leaving.
    let finished: Result<Vec<(UserSummary, ClientStats)>> = std::thread::scope(|scope| {
        let leaving: Vec<_> = clients.into_iter().map(|(c, u)| (scope.spawn(move || c.shutdown()), u)).collect();
        leaving
            .into_iter()
            .map(|(thread, summary)| {
                let stats = thread.join().map_err(|_| anyhow!("{} panicked while shutting down", summary.name))?;
                Ok((UserSummary { client: stats.to_json(), ..summary }, stats))
            })
            .collect()
    });
    if let Some((clock, thread)) = clock {
        drop(clock);
        thread.join();
    }
    if let Some(network) = network {
        network.finish();
    }
    let server_stats = runtime.block_on(server.shutdown()).context("shutting the server down")?;
    if let Some(task) = ctrl_c {
        task.abort();
    }
    runtime.shutdown_timeout(Duration::from_secs(1));
    let wall_s = started.elapsed().as_secs_f64();
    let finished = finished?;

    let mut summary = summarize(options, finished, &server_stats, wall_s, cancelled);
    summary.files = draw(options, &dir, &mut summary.per_user)?;
    if options.twin {
        let joins: Vec<Duration> =
            summary.per_user.iter().map(|u| Duration::from_secs_f64(u.record_offset_s.max(0.0))).collect();
        let round_trip = Duration::from_secs_f64(summary.rtt_ms_p50.unwrap_or(0.0).max(0.0) / 1e3);
        let session = twin::TwinSession {
            scene: options.scene.clone(),
            users: (0..options.users).map(|i| user_of(options, i)).collect(),
            device: options.device,
            link: options.link.clone(),
            duration: options.duration,
        };
        summary.twin = Some(twin::run(&session, &joins, round_trip)?);
    }
    summary.files.push("ve.csv".into());
    summary.files.extend((1..=summary.users).map(|i| format!("user{i}.csv")));
    summary.files.push("summary.json".into());
    let path = dir.join("summary.json");
    let text = serde_json::to_string_pretty(&summary)?;
    std::fs::write(&path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
    Ok(DemoReport { summary, dir })
}

/// Starts every client against the server, or none (those already started are stopped on failure).
fn start_clients(
    options: &DemoOptions,
    server: &ServerHandle,
    dir: &Path,
    ve_epoch: Instant,
    shared: Option<(&SharedClock, &SharedNetwork)>,
) -> Result<Vec<(ClientHandle, UserSummary)>> {
    let mut clients: Vec<(ClientHandle, UserSummary)> = Vec::with_capacity(options.users);
    for i in 0..options.users {
        let name = format!("demo-user{}", i + 1);
        let mut config =
            ClientConfig::new(server.local_addr().to_string(), Trust::Fingerprint(server.fingerprint().to_string()));
        let (op, user) = user_of(options, i);
        config.op = Some(op.clone());
        config.user = user;
        config.device = options.device;
        if i == 0 {
            config.dhd = options.dhd;
            config.hd = options.hd.clone();
        }
        config.duration = Some(options.duration);
        config.link = side_link(&options.link, i as u64 + 1);
        config.record = Some(dir.join(format!("user{}.csv", i + 1)));
        config.realtime_priority = options.realtime;
        config.clock = shared.map(|(clock, _)| clock.clone());
        config.network = shared.map(|(_, network)| network.clone());
        config.client_name = name.clone();
        config.report_interval = options.duration.max(Duration::from_secs(1));
        match Client::start(config) {
            Ok(client) => {
                let loop_epoch = Instant::now() - client.uptime();
                let summary = UserSummary {
                    user_id: client.welcome().user_id,
                    name,
                    op,
                    client: serde_json::Value::Null,
                    server: None,
                    device_op_rms_mm: None,
                    device_op_max_mm: None,
                    position_scale: client.welcome().mapping.position_scale,
                    force_scale: client.welcome().mapping.force_scale,
                    record_offset_s: loop_epoch.saturating_duration_since(ve_epoch).as_secs_f64(),
                };
                clients.push((client, summary));
            }
            Err(e) => {
                for (client, _) in clients {
                    client.shutdown();
                }
                return Err(e).with_context(|| format!("starting client {} of {}", i + 1, options.users));
            }
        }
    }
    Ok(clients)
}

/// Shows progress until every client's loop has run its duration (or one failed, or Ctrl-C, or the grace
/// time ran out); true when cancelled.
fn watch(
    options: &DemoOptions,
    server: &ServerHandle,
    clients: &[(ClientHandle, UserSummary)],
    cancel: &AtomicBool,
) -> bool {
    let total_ms = options.duration.as_millis() as u64;
    let bar = ProgressBar::with_draw_target(
        Some(total_ms),
        if options.progress { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() },
    );
    if let Ok(style) = ProgressStyle::with_template("{prefix} [{bar:32}] {msg}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_prefix("kinloop demo");
    let started = Instant::now();
    let give_up = options.duration + FINISH_GRACE;
    let cancelled = loop {
        std::thread::sleep(Duration::from_millis(50));
        let elapsed = started.elapsed();
        let s = server.stats();
        bar.set_position((elapsed.as_millis() as u64).min(total_ms));
        bar.set_message(format!(
            "{:.1}/{:.1} s, {} users, VE p99 {:.1} µs, {} misses",
            elapsed.as_secs_f64().min(options.duration.as_secs_f64()),
            options.duration.as_secs_f64(),
            s.users,
            s.ve.step_time.p99_ns as f64 / 1e3,
            s.ve.deadline_misses
        ));
        if cancel.load(Ordering::Relaxed) {
            break true;
        }
        if let Some(e) = clients.iter().find_map(|(c, u)| c.fatal_error().map(|e| format!("{}: {e}", u.name))) {
            tracing::error!(error = %e, "a client stopped; ending the demo");
            break false;
        }
        if clients.iter().all(|(c, _)| c.is_finished()) {
            break false;
        }
        if elapsed > give_up {
            tracing::warn!("the clients did not finish in time; stopping them");
            break false;
        }
    };
    bar.finish_and_clear();
    cancelled
}

fn summarize(
    options: &DemoOptions,
    finished: Vec<(UserSummary, ClientStats)>,
    server: &ServerStats,
    wall_s: f64,
    cancelled: bool,
) -> DemoSummary {
    let (users, stats): (Vec<UserSummary>, Vec<ClientStats>) = finished.into_iter().unzip();
    let worst = |f: fn(&ClientStats) -> f64| stats.iter().map(f).fold(0.0, f64::max);
    let mut rtts: Vec<f64> = stats.iter().filter_map(|s| s.rtt_ms_p50).collect();
    rtts.sort_by(f64::total_cmp);
    let per_user = users
        .into_iter()
        .map(|u| {
            let seen = server.per_user.iter().find(|s| s.user_id == u.user_id).cloned();
            UserSummary { server: seen, ..u }
        })
        .collect();
    let ve = &server.ve;
    let us = |ns: u64| ns as f64 / 1e3;
    DemoSummary {
        users: options.users,
        scene: options.scene_label.clone(),
        duration_s: options.duration.as_secs_f64(),
        wall_s,
        cancelled,
        delay_ms: options.link.delay.as_secs_f64() * 1e3,
        jitter_ms: options.link.jitter.as_secs_f64() * 1e3,
        loss: options.link.loss,
        seed: options.link.seed,
        ve_rate_hz: server.ve_rate_hz,
        ve_ticks: ve.core.ticks,
        ve_tick_us_p50: us(ve.step_time.p50_ns),
        ve_tick_us_p99: us(ve.step_time.p99_ns),
        ve_tick_us_max: us(ve.step_time.max_ns),
        ve_stages: ve.stages,
        ve_cpu_fraction: ve.cpu_s.map(|cpu| cpu / ve.wall_s.max(1e-9)),
        ve_deadline_misses: ve.deadline_misses,
        ve_realtime_priority: ve.realtime_priority,
        loop_ticks: stats.iter().map(|s| s.lateness.ticks).sum(),
        loop_lateness_us_p50: worst(|s| s.lateness.p50_us),
        loop_lateness_us_p99: worst(|s| s.lateness.p99_us),
        loop_lateness_us_max: worst(|s| s.lateness.max_us),
        loop_misses: stats.iter().map(|s| s.lateness.misses).sum(),
        rtt_ms_p50: (!rtts.is_empty()).then(|| rtts[rtts.len() / 2]),
        max_closure_error: ve.core.max_closure_error,
        max_force_ratio: worst(|s| s.max_force_ratio),
        uplinks_rejected: ve.core.uplinks_rejected,
        ve_restores: ve.core.state_restores,
        snapshots_withheld: ve.core.snapshots_withheld,
        sharing: ve.core.sharing,
        per_user,
        twin: None,
        files: Vec::new(),
    }
}

/// Reads the records back, fills each user's device-OP distances, and draws the charts (Fig 6a-c for the
/// first user, the device-OP distance of the first few users); returns the files written.
fn draw(options: &DemoOptions, dir: &Path, users: &mut [UserSummary]) -> Result<Vec<String>> {
    let kind = options.scene.kind;
    let ve = records::read_ve(&dir.join("ve.csv"), kind)?;
    let mut samples: Vec<Vec<ClientSample>> = Vec::with_capacity(users.len());
    for (i, user) in users.iter_mut().enumerate() {
        let mut s = records::read_client(&dir.join(format!("user{}.csv", i + 1)), kind)?;
        records::merge(&mut s, &ve, user.user_id, user.record_offset_s);
        let distances: Vec<f64> =
            s.iter().filter(|s| s.gain > 0.0).filter_map(device_op_distance).map(|d| d * user.position_scale).collect();
        if !distances.is_empty() {
            let rms = (distances.iter().map(|d| d * d).sum::<f64>() / distances.len() as f64).sqrt();
            user.device_op_rms_mm = Some(rms * 1e3);
            user.device_op_max_mm = Some(distances.iter().fold(0.0, |a: f64, &d| a.max(d)) * 1e3);
        }
        samples.push(s);
    }
    let mut files = Vec::new();
    let mut save = |stem: &str, chart: &Chart| -> Result<()> {
        for path in charts::save(chart, &dir.join(stem)).with_context(|| format!("chart {stem}"))? {
            files.push(path.strip_prefix(dir).unwrap_or(&path).display().to_string());
        }
        Ok(())
    };
    let first = &samples[0];
    if first.iter().all(|s| s.ve_op.is_none()) {
        tracing::warn!("the first user never appeared in the VE's record: no charts");
        return Ok(files);
    }
    let n = options.users;
    let heading = |fig: &str| format!("Demo, user 1 of {n} (cf. Fig {fig})");
    save("fig6a_constraint_count", &count_chart(&heading("6a"), &options.scene.name, first))?;
    save("fig6b_trajectories", &trajectory_chart(&heading("6b"), first))?;
    save("fig6c_joint_constraint_wrench", &wrench_chart(&heading("6c"), first))?;
    let mut distance = Chart::new("Demo: device-OP distance per user", "time (s)", "device-OP distance (mm)");
    for (i, s) in samples.iter().enumerate().take(DISTANCE_CHART_USERS) {
        distance = distance.with(distance_series(&format!("user {}", i + 1), s));
    }
    distance.log_y = true;
    save("device_op_distance", &distance.legend(Legend::LowerRight))?;
    Ok(files)
}
