//! `kinloop load`: many real client sessions from one process, so a server's capacity is measured with
//! its clients off its critical path. Each user is a whole `kinloop-client` ([`Client::start`]: the same
//! handshake, network side, haptic core and simulated device with a scripted hand), but their haptic loops
//! all run on one [`SharedClock`] thread, stepped in turn at the loop rate, and their network sides on one
//! [`SharedNetwork`] (a runtime of a few worker threads, one QUIC endpoint, one uplink pump the clock wakes
//! once a round), instead of a real-time thread, a runtime thread and an uplink thread each. A user the
//! server refuses (an unknown room, a room over budget) is reported with the reason and the others carry on.
//!
//! The demo's many users run on the same design ([`crate::demo`]), as do the clients of the `capacity`
//! experiment's rooms axis.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use kinloop_client::driver::shared_clock::{ClockThread, SharedClock};
use kinloop_client::driver::shared_network::SharedNetwork;
use kinloop_client::driver::{Client, ClientConfig, ClientHandle, ClientStats};
use kinloop_client::user::{HandKind, HandSpec, UserSpec};
use kinloop_protocol::quic::Trust;
use serde::{Deserialize, Serialize};

/// Most users one load process starts.
pub const MAX_USERS: usize = 256;
/// How long after the requested duration the clients' loops may take to end by themselves.
const FINISH_GRACE: Duration = Duration::from_secs(5);

/// What a load process runs.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// `host:port` of the server.
    pub server: String,
    /// How the server is trusted.
    pub trust: Trust,
    /// Name the server's certificate must carry (with a CA).
    pub server_name: String,
    /// Access token (one for every user).
    pub token: String,
    /// Users, 1 to [`MAX_USERS`].
    pub users: usize,
    /// Rooms the users join in turn (user `i` joins `rooms[i % len]`); empty: the server's default room.
    pub rooms: Vec<String>,
    /// Every user's simulated user (`None`: a soft and a firm hand in turn, touring the OP's reach).
    pub user: Option<UserSpec>,
    /// How long each user's loop runs.
    pub duration: Duration,
    /// Haptic loop rate (Hz).
    pub rate_hz: f64,
    /// Ask SCHED_FIFO for the one clock thread.
    pub realtime: bool,
    /// Worker threads of the runtime every user's network side shares.
    pub network_threads: usize,
}

/// The shared runtime's worker threads unless asked otherwise: one, beside the clock thread.
pub const NETWORK_THREADS: usize = 1;

impl LoadOptions {
    /// `users` users of the default room on `server`, 10 s at 1 kHz, hands in turn, normal priority.
    pub fn new(server: impl Into<String>, trust: Trust, users: usize) -> Self {
        LoadOptions {
            server: server.into(),
            trust,
            server_name: "localhost".into(),
            token: String::new(),
            users,
            rooms: Vec::new(),
            user: None,
            duration: Duration::from_secs(10),
            rate_hz: 1000.0,
            realtime: false,
            network_threads: NETWORK_THREADS,
        }
    }

    /// The room user `i` joins (empty: the default room).
    pub fn room_of(&self, i: usize) -> &str {
        if self.rooms.is_empty() {
            ""
        } else {
            &self.rooms[i % self.rooms.len()]
        }
    }

    /// Where user `i` stands among the users of its room (0 for the first): its turn among the scene's
    /// operational points.
    fn turn_in_room(&self, i: usize) -> usize {
        i / self.rooms.len().max(1)
    }
}

/// The simulated user of user `i` when none is asked for: a relaxed and a firm hand in turn, touring the
/// reach of its operational point (the demo's users too).
pub fn hand_in_turn(i: usize) -> HandSpec {
    HandSpec::touring(if i.is_multiple_of(2) { HandKind::Soft } else { HandKind::Firm })
}

/// The client configuration of user `i` of `options`, on `clock` and `network`.
pub fn client_config(options: &LoadOptions, i: usize, clock: &SharedClock, network: &SharedNetwork) -> ClientConfig {
    let mut config = ClientConfig::new(options.server.clone(), options.trust.clone());
    config.server_name = options.server_name.clone();
    config.token = options.token.clone();
    config.room = options.room_of(i).to_owned();
    config.op_turn = options.turn_in_room(i);
    config.user = options.user.clone().unwrap_or_else(|| UserSpec::Hand(hand_in_turn(i)));
    config.rate_hz = options.rate_hz;
    config.duration = Some(options.duration);
    config.client_name = format!("load-user{}", i + 1);
    config.report_interval = options.duration.max(Duration::from_secs(1));
    config.clock = Some(clock.clone());
    config.network = Some(network.clone());
    config
}

/// One user's part of the outcome.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LoadedUser {
    /// Client name (`load-userN`).
    pub name: String,
    /// The room it asked for ("" for the default).
    pub room: String,
    /// Why it did not start (refused, unreachable), if it did not.
    pub error: Option<String>,
    /// Id the VE gave it.
    pub user_id: Option<u32>,
    /// Operational point held.
    pub op: Option<String>,
    /// It rendered: snapshots arrived and its core ran with a local model.
    pub rendered: bool,
    /// Ticks its loop ran.
    pub ticks: u64,
    /// Lateness of its ticks from the shared clock's deadlines (µs): median, 99th percentile, largest.
    pub lateness_us_p50: f64,
    /// ... 99th percentile.
    pub lateness_us_p99: f64,
    /// ... largest.
    pub lateness_us_max: f64,
    /// Ticks more than 500 µs late.
    pub lateness_misses: u64,
    /// RMS distance between the device and the local model's OP over the ticks with a local model, in the
    /// device's space (mm): what the hand feels of the coupling.
    pub device_lm_rms_mm: f64,
    /// Largest such distance (mm).
    pub device_lm_max_mm: f64,
    /// Share of ticks whose command was clamped to the device's limits.
    pub clamped_fraction: f64,
    /// Largest commanded force over the device limit (≤ 1).
    pub max_force_ratio: f64,
    /// Uplinks the core let out.
    pub uplinks_built: u64,
    /// Uplinks dropped between the loop and the network side (no free buffer, or the ring full).
    pub uplinks_dropped: u64,
    /// Uplinks the network side dropped unsent because newer ones were queued behind them (it fell behind).
    pub uplinks_superseded: u64,
    /// Uplinks the network side handed to QUIC.
    pub uplinks_sent: u64,
    /// Uplinks QUIC put on the wire (datagram frames sent); the rest of those handed to it were dropped
    /// from its send buffer, oldest first, before they could leave.
    pub uplinks_transmitted: u64,
    /// Share of the core's uplinks that never left the process (`1 - transmitted / built`); what the
    /// network then loses the server counts.
    pub uplink_loss: f64,
    /// Packets this user's connection sent that QUIC declared lost.
    pub packets_lost: u64,
    /// Snapshots QUIC received for this user (datagram frames), before its receive buffer.
    pub snapshots_arrived: u64,
    /// Snapshots received.
    pub snapshots_received: u64,
    /// Median ping round trip (ms).
    pub rtt_ms_p50: Option<f64>,
    /// Sessions after the first.
    pub reconnects: u64,
}

impl LoadedUser {
    fn refused(name: String, room: String, error: String) -> Self {
        LoadedUser {
            name,
            room,
            error: Some(error),
            user_id: None,
            op: None,
            rendered: false,
            ticks: 0,
            lateness_us_p50: 0.0,
            lateness_us_p99: 0.0,
            lateness_us_max: 0.0,
            lateness_misses: 0,
            device_lm_rms_mm: 0.0,
            device_lm_max_mm: 0.0,
            clamped_fraction: 0.0,
            max_force_ratio: 0.0,
            uplinks_built: 0,
            uplinks_dropped: 0,
            uplinks_superseded: 0,
            uplinks_sent: 0,
            uplinks_transmitted: 0,
            uplink_loss: 0.0,
            packets_lost: 0,
            snapshots_arrived: 0,
            snapshots_received: 0,
            rtt_ms_p50: None,
            reconnects: 0,
        }
    }

    /// The outcome of a user that ran, from its client's exit statistics.
    pub fn ran(name: String, room: String, user_id: u32, op: String, stats: &ClientStats) -> Self {
        let core = stats.core.unwrap_or_default();
        let share = |part: u64, whole: u64| if whole == 0 { 0.0 } else { part as f64 / whole as f64 };
        LoadedUser {
            rendered: core.active_ticks > 0 && stats.snapshots_received > 0,
            ticks: stats.lateness.ticks,
            lateness_us_p50: stats.lateness.p50_us,
            lateness_us_p99: stats.lateness.p99_us,
            lateness_us_max: stats.lateness.max_us,
            lateness_misses: stats.lateness.misses,
            device_lm_rms_mm: core.tracking_error_rms() * 1e3,
            device_lm_max_mm: core.tracking_error_max * 1e3,
            clamped_fraction: share(core.clamped_ticks, core.ticks),
            max_force_ratio: stats.max_force_ratio,
            uplinks_built: core.uplinks_sent,
            uplinks_dropped: stats.uplinks_dropped,
            uplinks_superseded: stats.uplinks_superseded,
            uplinks_sent: stats.uplinks_sent,
            uplinks_transmitted: stats.quic.datagrams_transmitted,
            uplink_loss: share(core.uplinks_sent.saturating_sub(stats.quic.datagrams_transmitted), core.uplinks_sent),
            packets_lost: stats.quic.packets_lost,
            snapshots_arrived: stats.quic.datagrams_arrived,
            snapshots_received: stats.snapshots_received,
            rtt_ms_p50: stats.rtt_ms_p50,
            reconnects: stats.reconnects,
            ..LoadedUser::refused(name, room, String::new())
        }
        .with_session(user_id, op)
    }

    fn with_session(self, user_id: u32, op: String) -> Self {
        LoadedUser { error: None, user_id: Some(user_id), op: Some(op), ..self }
    }
}

/// What `kinloop load --json` prints.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LoadSummary {
    /// Users asked for.
    pub users: usize,
    /// Users that rendered.
    pub rendered: usize,
    /// Users that did not start.
    pub refused: usize,
    /// Requested seconds per user.
    pub duration_s: f64,
    /// Haptic loop rate (Hz).
    pub rate_hz: f64,
    /// Wall-clock seconds from the first start to the last shutdown.
    pub wall_s: f64,
    /// CPU seconds the whole load process used (every thread: the clock, the network sides).
    pub cpu_s: Option<f64>,
    /// Its share of one core over the wall time.
    pub cpu_cores: Option<f64>,
    /// Worst user's lateness p99 (µs).
    pub lateness_us_p99_worst: f64,
    /// Ticks more than 500 µs late, over every user.
    pub lateness_misses: u64,
    /// Each user, in order.
    pub per_user: Vec<LoadedUser>,
}

/// A running load: the shared clock and the users it started (or why each did not start).
pub struct Load {
    clock: Option<SharedClock>,
    thread: ClockThread,
    network: SharedNetwork,
    users: Vec<(String, String, Result<ClientHandle, String>)>,
    started: Instant,
    cpu_at_start: Option<Duration>,
    duration: Duration,
    rate_hz: f64,
}

impl Load {
    /// Starts the clock, then every user in turn; a user that cannot start is kept with the reason.
    pub fn start(options: &LoadOptions) -> Result<Self> {
        anyhow::ensure!(
            (1..=MAX_USERS).contains(&options.users),
            "--users {}: between 1 and {MAX_USERS}",
            options.users
        );
        let cpu_at_start = kinloop_process::cpu::process_cpu_time();
        let network =
            SharedNetwork::start(options.network_threads, options.realtime).context("starting the shared network")?;
        let (clock, thread) = SharedClock::start(options.rate_hz, options.realtime, Some(network.round_hook()))
            .context("starting the shared haptic clock")?;
        let started = Instant::now();
        let users = (0..options.users)
            .map(|i| {
                let config = client_config(options, i, &clock, &network);
                let (name, room) = (config.client_name.clone(), config.room.clone());
                let client = Client::start(config).map_err(|e| kinloop_process::report::one_line(&e));
                if let Err(why) = &client {
                    tracing::warn!(user = %name, room = %room, %why, "did not start");
                }
                (name, room, client)
            })
            .collect();
        Ok(Load {
            clock: Some(clock),
            thread,
            network,
            users,
            started,
            cpu_at_start,
            duration: options.duration,
            rate_hz: options.rate_hz,
        })
    }

    /// The users started, by name, with their handles.
    pub fn clients(&self) -> impl Iterator<Item = (&str, &ClientHandle)> {
        self.users.iter().filter_map(|(name, _, c)| c.as_ref().ok().map(|c| (name.as_str(), c)))
    }

    /// Waits until every user's loop has run its duration (or the grace time is over).
    pub fn wait(&self) {
        let give_up = self.started + self.duration + FINISH_GRACE;
        while !self.clients().all(|(_, c)| c.is_finished()) && Instant::now() < give_up {
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Stops every user (all at once), stops the clock, and sums up.
    pub fn finish(self) -> LoadSummary {
        let Load { clock, thread, network, users, started, cpu_at_start, duration, rate_hz } = self;
        let outcomes: Vec<LoadedUser> = std::thread::scope(|scope| {
            let leaving: Vec<_> = users
                .into_iter()
                .map(|(name, room, client)| {
                    scope.spawn(move || match client {
                        Ok(client) => {
                            let (id, op) = (client.welcome().user_id, client.welcome().scene.op_name.clone());
                            let stats = client.shutdown();
                            LoadedUser::ran(name, room, id, op, &stats)
                        }
                        Err(why) => LoadedUser::refused(name, room, why),
                    })
                })
                .collect();
            leaving.into_iter().filter_map(|t| t.join().ok()).collect()
        });
        drop(clock);
        thread.join();
        network.finish();
        let wall_s = started.elapsed().as_secs_f64();
        let cpu_s = kinloop_process::cpu::process_cpu_time()
            .zip(cpu_at_start)
            .map(|(now, then)| now.saturating_sub(then).as_secs_f64());
        LoadSummary {
            users: outcomes.len(),
            rendered: outcomes.iter().filter(|u| u.rendered).count(),
            refused: outcomes.iter().filter(|u| u.error.is_some()).count(),
            duration_s: duration.as_secs_f64(),
            rate_hz,
            wall_s,
            cpu_s,
            cpu_cores: cpu_s.map(|c| c / wall_s.max(1e-9)),
            lateness_us_p99_worst: outcomes.iter().map(|u| u.lateness_us_p99).fold(0.0, f64::max),
            lateness_misses: outcomes.iter().map(|u| u.lateness_misses).sum(),
            per_user: outcomes,
        }
    }
}

/// Runs a load to its end: start, wait for the duration, stop, sum up.
pub fn run(options: &LoadOptions) -> Result<LoadSummary> {
    let load = Load::start(options)?;
    load.wait();
    Ok(load.finish())
}
