//! The thin driver around [`HapticCore`]: a real-time loop thread ([`rt_loop`]) and the QUIC session on a
//! tokio runtime of its own, connected by bounded lock-free rings (rtrb). Usable in-process
//! ([`Client::start`] → [`ClientHandle`]) and by the `kinloop-client` binary.
//!
//! Threads: the haptic loop (SCHED_FIFO when permitted); the network thread (a current-thread tokio
//! runtime: handshake, snapshot reception, pings, reconnection with exponential backoff); an uplink sender
//! (parked until the loop unparks it: futex wake, no lock on the loop's side); a CSV writer with `--record`.
//! The many clients of one process share instead one clock thread for their loops ([`shared_clock`]) and
//! one runtime, endpoint and uplink pump for their network sides ([`shared_network`]).
//! When the server goes away the loop keeps running: its snapshots age, the core fades the force out, and
//! a new session's core (re-indexed to the new first snapshot) is handed over when the client reconnects.

mod config;
pub mod device_clock;
mod network;
pub mod real;
pub mod record;
pub mod rt_loop;
mod session;
pub mod shared_clock;
pub mod shared_network;
pub mod stop_signal;
pub mod timing;
mod uplinks;

use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::atomic::Ordering;
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kinloop_protocol::Welcome;

use crate::core::{ControllerGains, CoreStats};
use crate::device::dhd::{DhdLibrary, OpenedDhd};
use crate::device::hd::{HdLibrary, OpenedHd};
pub use config::{ClientConfig, ClientError};
pub use network::choose;
use network::{network_task, network_thread, NetStart};
use real::OpenedDevice;
use rt_loop::{LoopReport, LoopShared};
use session::NetShared;
pub use session::QuicCounts;
use shared_clock::LoopEnd;
use timing::LatenessSummary;

/// What a client has measured.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct ClientStats {
    /// Loop lateness.
    pub lateness: LatenessSummary,
    /// Ticks per second achieved.
    pub rate_hz: f64,
    /// Median round-trip time of control-stream pings (ms), if any were answered.
    pub rtt_ms_p50: Option<f64>,
    /// Largest commanded force over the device limit, over every session (≤ 1).
    pub max_force_ratio: f64,
    /// The current session's core counters (None before the first report).
    pub core: Option<CoreStats>,
    /// Snapshots received from the network.
    pub snapshots_received: u64,
    /// Uplinks sent on the network.
    pub uplinks_sent: u64,
    /// Uplinks dropped between loop and network.
    pub uplinks_dropped: u64,
    /// Uplinks dropped unsent because newer ones were queued behind them (the sender fell behind).
    pub uplinks_superseded: u64,
    /// What QUIC counted: datagrams that left and arrived, packets lost.
    pub quic: QuicCounts,
    /// Sessions after the first.
    pub reconnects: u64,
    /// Record rows dropped.
    pub records_dropped: u64,
    /// The device failed (its force was zeroed and the loop stopped).
    pub device_lost: bool,
    /// Reconnections on which the server resumed the room from the state this client kept.
    pub resumes: u64,
    /// Reconnections on which the server refused that state.
    pub resumes_refused: u64,
    /// The haptic loop's time zero on the system clock (s since the Unix epoch), once it ticked: the record's
    /// times count from it.
    pub loop_epoch_unix_s: Option<f64>,
}

impl ClientStats {
    /// The exit summary as flat JSON (the keys `kinloop bench` and scripts read).
    pub fn to_json(&self) -> serde_json::Value {
        let core = self.core.unwrap_or_default();
        serde_json::json!({
            "ticks": self.lateness.ticks,
            "loop_rate_hz": self.rate_hz,
            "loop_lateness_us_p50": self.lateness.p50_us,
            "loop_lateness_us_p99": self.lateness.p99_us,
            "loop_lateness_us_max": self.lateness.max_us,
            "loop_misses": self.lateness.misses,
            "rtt_ms_p50": self.rtt_ms_p50,
            "max_force_ratio": self.max_force_ratio,
            "tracking_error_rms_m": core.tracking_error_rms(),
            "tracking_error_max_m": core.tracking_error_max,
            "uplink_saving": core.uplink_saving(),
            "snapshots_received": self.snapshots_received,
            "snapshots_rejected": core.snapshots_rejected,
            "uplinks_sent": self.uplinks_sent,
            "uplinks_dropped": self.uplinks_dropped,
            "uplinks_superseded": self.uplinks_superseded,
            "uplinks_transmitted": self.quic.datagrams_transmitted,
            "snapshots_arrived": self.quic.datagrams_arrived,
            "packets_lost": self.quic.packets_lost,
            "stale_ticks": core.stale_ticks,
            "clamped_ticks": core.clamped_ticks,
            "non_finite_events": core.non_finite_events,
            "reconnects": self.reconnects,
            "records_dropped": self.records_dropped,
            "device_lost": self.device_lost,
            "loop_epoch_unix_s": self.loop_epoch_unix_s,
        })
    }
}

/// A running client.
pub struct ClientHandle {
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
    loop_thread: Option<LoopEnd>,
    net_end: Option<NetEnd>,
    helper_threads: Vec<JoinHandle<()>>,
    started: Instant,
    welcome: Welcome,
    device: String,
    gains: ControllerGains,
}

/// A client: see [`Client::start`].
pub struct Client;

impl Client {
    /// Connects (the first handshake is awaited, so bad addresses, tokens or certificates fail here with a
    /// clear error), then starts the haptic loop and the network side.
    pub fn start(mut config: ClientConfig) -> Result<ClientHandle, ClientError> {
        if !(config.rate_hz.is_finite() && (10.0..=20_000.0).contains(&config.rate_hz)) {
            return Err(ClientError::Setting(format!("rate {} Hz must be between 10 and 20000", config.rate_hz)));
        }
        let addresses = std::iter::once(&config.server)
            .chain(&config.fallback_servers)
            .map(|server| resolve(server))
            .collect::<Result<Vec<_>, _>>()?;
        let real = open_real(&mut config)?;
        let shared = Arc::new(LoopShared::default());
        let silence_limit = (addresses.len() > 1).then_some(config::SILENT_SERVER);
        let net = Arc::new(NetShared { silence_limit, ..NetShared::default() });
        let (started, started_rx) = mpsc::channel();
        let network = config.network.clone();
        let start = NetStart { config, real, addresses, shared: shared.clone(), net: net.clone(), started };
        let net_end = match network {
            Some(network) => {
                let endpoint = network.endpoint_for(&start.config.trust, start.config.link.as_ref())?;
                let (done, ended) = mpsc::channel::<()>();
                network.spawn(async move {
                    network_task(start, endpoint).await;
                    drop(done);
                });
                NetEnd::Task(ended)
            }
            None => NetEnd::Thread(
                std::thread::Builder::new()
                    .name("kinloop-net".into())
                    .spawn(move || network_thread(start))
                    .map_err(|e| ClientError::Runtime(e.to_string()))?,
            ),
        };
        match started_rx.recv() {
            Ok(Ok(started)) => Ok(ClientHandle {
                shared,
                net,
                loop_thread: Some(started.loop_thread),
                net_end: Some(net_end),
                helper_threads: started.helpers,
                started: Instant::now(),
                welcome: started.welcome,
                device: started.device,
                gains: started.gains,
            }),
            Ok(Err(e)) => {
                net_end.join();
                Err(e)
            }
            Err(_) => {
                net_end.join();
                Err(ClientError::Runtime("the network side ended before the session started".into()))
            }
        }
    }
}

impl ClientHandle {
    /// What the server granted.
    pub fn welcome(&self) -> &Welcome {
        &self.welcome
    }

    /// The device in use (the one asked for, or the scene's default), by name.
    pub fn device(&self) -> &str {
        &self.device
    }

    /// The controller gains in use, as the device renders them.
    pub fn gains(&self) -> &ControllerGains {
        &self.gains
    }

    /// What this client chose and was granted, as JSON: operational point, device, mapping, the server's
    /// coupling gains and the client's own.
    pub fn session_json(&self) -> serde_json::Value {
        let w = &self.welcome;
        serde_json::json!({
            "scene": w.scene.name,
            "op": w.scene.op_name,
            "device": self.device,
            "position_scale": w.mapping.position_scale,
            "force_scale": w.mapping.force_scale,
            "torque_scale": w.mapping.torque_scale(),
            "gravity_compensation": w.mapping.gravity_compensation,
            "coupling_stiffness": w.coupling.stiffness,
            "coupling_damping": w.coupling.damping,
            "joint_stiffness": self.gains.joint_stiffness,
            "joint_damping": self.gains.joint_damping,
            "position_stiffness": self.gains.position_stiffness,
            "position_damping": self.gains.position_damping,
        })
    }

    /// Measurements so far.
    pub fn stats(&self) -> ClientStats {
        let lateness = self.shared.lateness.summary();
        let elapsed = Duration::from_nanos(self.shared.elapsed_ns.load(Ordering::Relaxed)).as_secs_f64();
        let rtt = self.net.rtt_ms.lock().map(|r| median(&r)).unwrap_or(None);
        ClientStats {
            lateness,
            rate_hz: if elapsed > 0.0 { lateness.ticks as f64 / elapsed } else { 0.0 },
            rtt_ms_p50: rtt,
            max_force_ratio: self.shared.max_force_ratio(),
            core: self.net.last_report.lock().ok().and_then(|r| r.map(|r| r.core)),
            snapshots_received: self.net.snapshots_received.load(Ordering::Relaxed),
            uplinks_sent: self.net.uplinks_sent.load(Ordering::Relaxed),
            uplinks_dropped: self.shared.uplinks_dropped.load(Ordering::Relaxed),
            uplinks_superseded: self.net.uplinks_superseded.load(Ordering::Relaxed),
            quic: self.net.quic.total(),
            reconnects: self.net.reconnects.load(Ordering::Relaxed),
            records_dropped: self.shared.records_dropped.load(Ordering::Relaxed),
            device_lost: self.shared.device_lost.load(Ordering::Relaxed),
            resumes: self.net.resumes.load(Ordering::Relaxed),
            resumes_refused: self.net.resumes_refused.load(Ordering::Relaxed),
            loop_epoch_unix_s: Some(self.shared.epoch_unix_ns.load(Ordering::Relaxed))
                .filter(|&ns| ns > 0)
                .map(|ns| ns as f64 * 1e-9),
        }
    }

    /// The newest signed room state a server sent this client (what it offers when it reconnects).
    pub fn room_state(&self) -> Option<kinloop_protocol::RoomState> {
        self.net.room_state.lock().ok().and_then(|s| s.clone())
    }

    /// True once the loop has stopped (duration over, device lost, or shut down).
    pub fn is_finished(&self) -> bool {
        self.loop_thread.as_ref().is_none_or(LoopEnd::is_finished)
    }

    /// A fatal network error that stopped the client, if any.
    pub fn fatal_error(&self) -> Option<String> {
        self.net.fatal.lock().ok().and_then(|f| f.clone())
    }

    /// Time since start.
    pub fn uptime(&self) -> Duration {
        self.started.elapsed()
    }

    /// Runs until the loop ends by itself (its duration, a lost device, a fatal error) or SIGINT/SIGTERM
    /// arrives ([`stop_signal::stop_requested`]), then stops everything through [`Self::shutdown`], so the
    /// device is commanded zero force and released however the run ends. Without a runtime for the signals
    /// (an OS failure, said once) it waits for the loop alone.
    pub fn run_until_stopped(self) -> ClientStats {
        match tokio::runtime::Builder::new_current_thread().enable_all().build() {
            Ok(runtime) => runtime.block_on(async {
                let mut signal = std::pin::pin!(stop_signal::stop_requested());
                let mut poll = tokio::time::interval(Duration::from_millis(50));
                while !self.is_finished() {
                    tokio::select! {
                        _ = &mut signal => {
                            tracing::info!("asked to stop: zeroing the force and releasing the device");
                            break;
                        }
                        _ = poll.tick() => {}
                    }
                }
            }),
            Err(e) => {
                tracing::warn!("no runtime to handle Ctrl-C ({e}); running to the loop's end");
                while !self.is_finished() {
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
        self.shutdown()
    }

    /// Stops the loop (the device is commanded zero), leaves the session and joins every thread.
    pub fn shutdown(mut self) -> ClientStats {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.loop_thread.take() {
            self.finish_with(t.join());
        }
        if let Some(end) = self.net_end.take() {
            end.join();
        }
        for t in self.helper_threads.drain(..) {
            let _ = t.join();
        }
        self.stats()
    }

    fn finish_with(&mut self, last: Option<CoreStats>) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let (Some(core), Ok(mut report)) = (last, self.net.last_report.lock()) {
            match report.as_mut() {
                Some(r) => r.core = core,
                None => {
                    *report = Some(LoopReport {
                        elapsed: Duration::ZERO,
                        core,
                        constraint_count: 0,
                        gain: 0.0,
                        snapshot_age: None,
                    })
                }
            }
        }
    }
}

impl Drop for ClientHandle {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
    }
}

/// Where a client's network side runs: a thread of its own, or a task on a shared runtime (which drops the
/// sender when it ends).
enum NetEnd {
    Thread(JoinHandle<()>),
    Task(mpsc::Receiver<()>),
}

/// Longest a client waits for a network task on a shared runtime to end once asked to stop (it leaves its
/// session within a few hundred milliseconds unless the runtime is stuck).
const NET_END_PATIENCE: Duration = Duration::from_secs(5);

impl NetEnd {
    fn join(self) {
        match self {
            NetEnd::Thread(thread) => drop(thread.join()),
            NetEnd::Task(ended) => drop(ended.recv_timeout(NET_END_PATIENCE)),
        }
    }
}

fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    Some(sorted[sorted.len() / 2])
}

fn resolve(server: &str) -> Result<SocketAddr, ClientError> {
    let error = |why: String| ClientError::Address { address: server.to_owned(), why };
    server
        .to_socket_addrs()
        .map_err(|e| error(format!("{e} (write HOST:PORT, e.g. 127.0.0.1:4433)")))?
        .next()
        .ok_or_else(|| error("resolves to no address".into()))
}

/// Opens the vendor device `config` asks for (DHD or HD). When it cannot be used and a simulated fallback
/// was asked for, says why and switches `config` to the fallback; otherwise the error.
fn open_real(config: &mut ClientConfig) -> Result<Option<OpenedDevice>, ClientError> {
    let (opened, fallback) = if let Some(request) = config.dhd {
        let opened = DhdLibrary::find().and_then(|library| OpenedDhd::open_for_rendering(Arc::new(library), &request));
        (opened.map(OpenedDevice::Dhd).map_err(ClientError::from), request.fallback)
    } else if let Some(request) = config.hd.clone() {
        let opened = HdLibrary::find().and_then(|library| OpenedHd::open(library, &request));
        (opened.map(OpenedDevice::Hd).map_err(ClientError::from), request.fallback)
    } else {
        return Ok(None);
    };
    match (opened, fallback) {
        (Ok(device), _) => Ok(Some(device)),
        (Err(e), Some(fallback)) => {
            tracing::warn!("{e}; using {} as asked", fallback.name());
            config.dhd = None;
            config.hd = None;
            config.device = Some(fallback);
            Ok(None)
        }
        (Err(e), None) => Err(e),
    }
}
