//! The thin driver around [`HapticCore`]: a real-time loop thread ([`rt_loop`]) and the QUIC session on a
//! tokio runtime of its own, connected by bounded lock-free rings (rtrb). Usable in-process
//! ([`Client::start`] → [`ClientHandle`]) and by the `kinloop-client` binary.
//!
//! Threads: the haptic loop (SCHED_FIFO when permitted); the network thread (a current-thread tokio
//! runtime: handshake, snapshot reception, pings, reconnection with exponential backoff); an uplink sender
//! (parked until the loop unparks it: futex wake, no lock on the loop's side); a CSV writer with `--record`.
//! When the server goes away the loop keeps running: its snapshots age, the core fades the force out, and
//! a new session's core (re-indexed to the new first snapshot) is handed over when the client reconnects.

pub mod record;
pub mod rt_loop;
pub mod timing;

use std::net::{SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kinloop_linkage::space::{Planar, SceneKind, Space, Spatial, VecOps};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::{
    client_endpoint, connect, ConnectError, ConnectedSession, DatagramReceiver, DatagramSender, Endpoint,
    EndpointError, EndpointOptions, Trust,
};
use kinloop_protocol::{
    Control, Datagram, Hello, Join, LocalModelForm, MappingRequest, Role, SceneInfo, Uplink, Welcome, PROTOCOL_VERSION,
};

use crate::core::{
    ConstraintMode, ControllerGains, CoreConfig, CoreError, CoreStats, GainChoice, HapticCore, ModelForm,
    UplinkDeadband,
};
use crate::device::dhd::specs::ModelSpec;
use crate::device::dhd::{DhdError, DhdLibrary, OpenedDhd};
use crate::device::presets::SimulatedDeviceBuildError;
use crate::device::{DevicePreset, DhdRequest, HapticDevice, SimulatedRig};
use crate::user::{UserContext, UserError, UserSpec};
use rt_loop::{LoopReport, LoopRings, LoopSettings, LoopShared};
use timing::LatenessSummary;

/// Everything a client needs.
#[derive(Clone, Debug)]
pub struct ClientConfig {
    /// `host:port` of the server.
    pub server: String,
    /// Name the server's certificate must carry (with `Trust::CaFile`).
    pub server_name: String,
    /// Shared secret.
    pub token: String,
    /// How the server is trusted.
    pub trust: Trust,
    /// Operational point to hold; `None`: the scene's first.
    pub op: Option<String>,
    /// The simulated device; `None`: the one for the scene's space ([`DevicePreset::for_kind`]).
    pub device: Option<DevicePreset>,
    /// A Force Dimension device through the DHD SDK instead of the simulated one (`--device dhd`).
    pub dhd: Option<DhdRequest>,
    /// The simulated user.
    pub user: UserSpec,
    /// What to ask of the mapping between device and VE (scales, gravity compensation).
    pub mapping: MappingRequest,
    /// Loop rate (Hz).
    pub rate_hz: f64,
    /// Stop after this long (None: until shutdown).
    pub duration: Option<Duration>,
    /// Joint-constraint rendering.
    pub constraint_mode: ConstraintMode,
    /// Local model form.
    pub form: ModelForm,
    /// Gains.
    pub gains: GainChoice,
    /// Uplink deadband.
    pub deadband: Option<UplinkDeadband>,
    /// Emulated impairments on what this client sends.
    pub link: Option<LinkConfig>,
    /// CSV file, one row per tick.
    pub record: Option<PathBuf>,
    /// Try SCHED_FIFO for the loop.
    pub realtime_priority: bool,
    /// Spin before each deadline (see `rt_loop::LoopSettings::busy_wait`); false for many clients on a
    /// small machine.
    pub busy_wait: bool,
    /// Name for the server's logs.
    pub client_name: String,
    /// Interval of the periodic timing log.
    pub report_interval: Duration,
}

impl ClientConfig {
    /// Defaults: the scene's first operational point, the device for the scene's space, a relaxed hand
    /// touring the reach, the server's mapping, 1 kHz, stiffness mode, reduced local model, designed gains.
    pub fn new(server: impl Into<String>, trust: Trust) -> Self {
        ClientConfig {
            server: server.into(),
            server_name: "localhost".into(),
            token: String::new(),
            trust,
            op: None,
            device: None,
            dhd: None,
            user: UserSpec::soft_hand(),
            mapping: MappingRequest::default(),
            rate_hz: 1000.0,
            duration: None,
            constraint_mode: ConstraintMode::Stiffness,
            form: ModelForm::Op,
            gains: GainChoice::Designed,
            deadband: None,
            link: None,
            record: None,
            realtime_priority: true,
            busy_wait: true,
            client_name: "kinloop-client".into(),
            report_interval: Duration::from_secs(5),
        }
    }
}

/// Why a client could not start or run.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The server address does not resolve.
    #[error("server address {address:?}: {why}")]
    Address {
        /// As given.
        address: String,
        /// Why.
        why: String,
    },
    /// A setting out of range.
    #[error("{0}")]
    Setting(String),
    /// The QUIC endpoint could not be made.
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    /// The first connection failed.
    #[error("cannot connect to {server}: {source}")]
    Connect {
        /// The server.
        server: String,
        /// Why.
        source: ConnectError,
    },
    /// The device cannot serve the scene.
    #[error(transparent)]
    Device(#[from] SimulatedDeviceBuildError),
    /// The DHD library or device cannot be used.
    #[error(transparent)]
    Dhd(#[from] DhdError),
    /// The user cannot be built.
    #[error(transparent)]
    User(#[from] UserError),
    /// The core refused the session.
    #[error("the session cannot be rendered: {0}")]
    Core(#[from] CoreError),
    /// A thread or runtime could not start.
    #[error("cannot start the client: {0}")]
    Runtime(String),
}

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
    /// Sessions after the first.
    pub reconnects: u64,
    /// Record rows dropped.
    pub records_dropped: u64,
    /// The device failed (its force was zeroed and the loop stopped).
    pub device_lost: bool,
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
            "stale_ticks": core.stale_ticks,
            "clamped_ticks": core.clamped_ticks,
            "non_finite_events": core.non_finite_events,
            "reconnects": self.reconnects,
            "records_dropped": self.records_dropped,
            "device_lost": self.device_lost,
        })
    }
}

/// Counters the network side keeps.
#[derive(Debug, Default)]
struct NetShared {
    snapshots_received: AtomicU64,
    uplinks_sent: AtomicU64,
    reconnects: AtomicU64,
    rtt_ms: Mutex<Vec<f64>>,
    last_report: Mutex<Option<LoopReport>>,
    fatal: Mutex<Option<String>>,
}

/// A running client.
pub struct ClientHandle {
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
    loop_thread: Option<JoinHandle<CoreStats>>,
    net_thread: Option<JoinHandle<()>>,
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
        let address = resolve(&config.server)?;
        let dhd = open_dhd(&mut config)?;
        let shared = Arc::new(LoopShared::default());
        let net = Arc::new(NetShared::default());
        let (started_tx, started_rx) = mpsc::channel();
        let (thread_shared, thread_net) = (shared.clone(), net.clone());
        let net_thread = std::thread::Builder::new()
            .name("kinloop-net".into())
            .spawn(move || network_thread(config, dhd, address, thread_shared, thread_net, started_tx))
            .map_err(|e| ClientError::Runtime(e.to_string()))?;
        match started_rx.recv() {
            Ok(Ok(started)) => Ok(ClientHandle {
                shared,
                net,
                loop_thread: Some(started.loop_thread),
                net_thread: Some(net_thread),
                helper_threads: started.helpers,
                started: Instant::now(),
                welcome: started.welcome,
                device: started.device,
                gains: started.gains,
            }),
            Ok(Err(e)) => {
                let _ = net_thread.join();
                Err(e)
            }
            Err(_) => {
                let _ = net_thread.join();
                Err(ClientError::Runtime("the network thread ended before the session started".into()))
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
            reconnects: self.net.reconnects.load(Ordering::Relaxed),
            records_dropped: self.shared.records_dropped.load(Ordering::Relaxed),
            device_lost: self.shared.device_lost.load(Ordering::Relaxed),
        }
    }

    /// True once the loop has stopped (duration over, device lost, or shut down).
    pub fn is_finished(&self) -> bool {
        self.loop_thread.as_ref().is_none_or(|t| t.is_finished())
    }

    /// A fatal network error that stopped the client, if any.
    pub fn fatal_error(&self) -> Option<String> {
        self.net.fatal.lock().ok().and_then(|f| f.clone())
    }

    /// Time since start.
    pub fn uptime(&self) -> Duration {
        self.started.elapsed()
    }

    /// Waits for the loop to end by itself (its duration), then stops everything.
    pub fn wait(mut self) -> ClientStats {
        if let Some(t) = self.loop_thread.take() {
            self.finish_with(t.join().ok());
        }
        self.shutdown()
    }

    /// Stops the loop (the device is commanded zero), leaves the session and joins every thread.
    pub fn shutdown(mut self) -> ClientStats {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.loop_thread.take() {
            self.finish_with(t.join().ok());
        }
        if let Some(t) = self.net_thread.take() {
            let _ = t.join();
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

struct Started {
    loop_thread: JoinHandle<CoreStats>,
    helpers: Vec<JoinHandle<()>>,
    welcome: Welcome,
    device: String,
    gains: ControllerGains,
}

/// Opens the DHD device `config` asks for. When it cannot be used and a simulated fallback was asked for,
/// says why and switches `config` to the fallback; otherwise the error.
fn open_dhd(config: &mut ClientConfig) -> Result<Option<OpenedDhd>, ClientError> {
    let Some(request) = config.dhd else { return Ok(None) };
    let opened = DhdLibrary::find().and_then(|library| OpenedDhd::open(Arc::new(library), request.index));
    match (opened, request.fallback) {
        (Ok(device), _) => {
            if device.calibrated() == Some(false) {
                tracing::warn!(
                    "the DHD device is not calibrated (drdIsInitialized false); calibrate it with the SDK's tools"
                );
            }
            Ok(Some(device))
        }
        (Err(e), Some(fallback)) => {
            tracing::warn!("{e}; using {} as asked", fallback.name());
            config.dhd = None;
            config.device = Some(fallback);
            Ok(None)
        }
        (Err(e), None) => Err(e.into()),
    }
}

/// The network side's ends of the rings.
struct NetRings<S: Space> {
    snapshots: rtrb::Producer<kinloop_protocol::Snapshot>,
    spent_snapshots: rtrb::Consumer<kinloop_protocol::Snapshot>,
    cores: rtrb::Producer<Box<HapticCore<S>>>,
    spent_cores: rtrb::Consumer<Box<HapticCore<S>>>,
    reports: rtrb::Consumer<LoopReport>,
}

/// Longest a client waits for its closing connection to tell the server. A process that exits sooner sends
/// nothing, and the server keeps the user until its idle timeout.
const CLOSE_LINGER: Duration = Duration::from_secs(1);

/// Closes a session that will not run and waits (at most [`CLOSE_LINGER`]) for the server to be told, so it
/// drops the user at once.
async fn abandon(endpoint: &Endpoint, connection: &kinloop_protocol::quic::Connection, why: &'static [u8]) {
    connection.close(kinloop_protocol::quic::close_codes::NORMAL, why);
    let _ = tokio::time::timeout(CLOSE_LINGER, endpoint.wait_idle()).await;
}

const SNAPSHOT_RING: usize = 16;
const UPLINK_RING: usize = 64;
const RECORD_RING: usize = 16_384;

fn network_thread(
    config: ClientConfig,
    dhd: Option<OpenedDhd>,
    address: SocketAddr,
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
    started: mpsc::Sender<Result<Started, ClientError>>,
) {
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(rt) => rt,
        Err(e) => {
            let _ = started.send(Err(ClientError::Runtime(e.to_string())));
            return;
        }
    };
    runtime.block_on(async move {
        let opts = EndpointOptions { link: config.link.clone(), ..EndpointOptions::default() };
        let endpoint = match client_endpoint(&config.trust, &opts) {
            Ok(e) => e,
            Err(e) => {
                let _ = started.send(Err(e.into()));
                return;
            }
        };
        let mut chosen = None;
        let model = dhd.as_ref().map(OpenedDhd::model);
        let session = match open_session(&endpoint, address, &config, model, &mut chosen).await {
            Ok(s) => s,
            Err(source) => {
                // The handshake closed the connection; the server hears of it before the caller (who may exit
                // at once) hears why.
                let _ = tokio::time::timeout(CLOSE_LINGER, endpoint.wait_idle()).await;
                let _ = started.send(Err(ClientError::Connect { server: config.server.clone(), source }));
                return;
            }
        };
        // The session opened, so the chooser ran.
        let Some(device) = chosen else { return };
        let config = ClientConfig { device: Some(device), op: Some(session.welcome.scene.op_name.clone()), ..config };
        match session.welcome.scene.kind {
            SceneKind::Planar => run::<Planar>(config, dhd, address, endpoint, session, shared, net, started).await,
            SceneKind::Spatial => run::<Spatial>(config, dhd, address, endpoint, session, shared, net, started).await,
        }
    });
}

fn hello(config: &ClientConfig) -> Hello {
    Hello {
        version: PROTOCOL_VERSION,
        token: config.token.clone(),
        client_name: config.client_name.clone(),
        role: Role::Manipulator,
    }
}

/// The join for the scene the server described: the operational point asked for (or the scene's first)
/// and the device asked for (or the scene's default; `real`, an opened DHD device's model, before either),
/// described in the scene's space. A device that cannot serve the scene's space is an error naming both.
pub fn choose(
    config: &ClientConfig,
    scene: &SceneInfo,
    real: Option<&ModelSpec>,
) -> Result<(Join, DevicePreset), String> {
    let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(scene.kind));
    let spec = match real {
        Some(model) => model.device_spec(scene.kind),
        None => {
            device.spec(scene.kind).map_err(|e| format!("{e} (scene {} is {})", scene.name, kind_axes(scene.kind)))?
        }
    };
    let op = match &config.op {
        Some(op) => op.clone(),
        None => scene.ops.first().cloned().ok_or_else(|| format!("scene {} has no operational point", scene.name))?,
    };
    let form = match config.form {
        ModelForm::Op => LocalModelForm::OpSpace,
        ModelForm::Config => LocalModelForm::ConfigSpace,
    };
    Ok((Join { op, device: spec.caps(), form, mapping: config.mapping.clone() }, device))
}

/// A space and its axes, for messages.
fn kind_axes(kind: SceneKind) -> &'static str {
    match kind {
        SceneKind::Planar => "planar (axes x, y, θ)",
        SceneKind::Spatial => "spatial (axes x, y, z, rx, ry, rz)",
    }
}

async fn open_session(
    endpoint: &Endpoint,
    address: SocketAddr,
    config: &ClientConfig,
    real: Option<&ModelSpec>,
    chosen: &mut Option<DevicePreset>,
) -> Result<ConnectedSession, ConnectError> {
    connect(endpoint, address, &config.server_name, &hello(config), |scene| {
        let (join, device) = choose(config, scene, real)?;
        *chosen = Some(device);
        Ok(join)
    })
    .await
}

fn core_for<S: Space>(
    config: &ClientConfig,
    real: Option<&ModelSpec>,
    welcome: &Welcome,
) -> Result<Box<HapticCore<S>>, ClientError> {
    let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND));
    let spec = match real {
        Some(model) => model.device_spec(S::KIND),
        None => device.spec(S::KIND).map_err(SimulatedDeviceBuildError::from)?,
    };
    let mut core_config = CoreConfig::new(spec);
    core_config.constraint_mode = config.constraint_mode;
    core_config.form = config.form;
    core_config.gains = config.gains.clone();
    core_config.deadband = config.deadband;
    core_config.period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let core = HapticCore::<S>::new(core_config, welcome)?;
    let g = core.gains();
    tracing::info!(
        k_j = g.device.joint_stiffness,
        b_j = g.device.joint_damping,
        k_pc = ?g.device.position_stiffness,
        b_pc = ?g.device.position_damping,
        "controller gains (device units)"
    );
    if g.stiffness_cap < 1.0 || g.damping_cap < 1.0 {
        tracing::warn!(
            stiffness = g.stiffness_cap,
            damping = g.damping_cap,
            "gains scaled down to what the device renders stably"
        );
    }
    Ok(Box::new(core))
}

fn empty_uplink<S: Space>() -> Uplink {
    Uplink::at_rest(0, S::DIM, kinloop_linkage::local_model::OpPose::<S>::wire_len())
}

#[allow(clippy::too_many_arguments)]
async fn run<S: Space>(
    config: ClientConfig,
    dhd: Option<OpenedDhd>,
    address: SocketAddr,
    endpoint: Endpoint,
    session: ConnectedSession,
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
    started: mpsc::Sender<Result<Started, ClientError>>,
) {
    let model = dhd.as_ref().map(OpenedDhd::model);
    let setup = || -> Result<(Box<dyn HapticDevice<S>>, _), ClientError> {
        let core = core_for::<S>(&config, model, &session.welcome)?;
        if let Some(dhd) = dhd {
            return Ok((Box::new(dhd.into_device::<S>()), core));
        }
        // The simulated hand grasps the handle where the linkage is.
        let op = S::Point::from_slice(&session.welcome.op.position);
        let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND)).build_at::<S>(core.home(&op))?;
        let user = config.user.build::<S>(&UserContext::from_welcome(&session.welcome))?;
        Ok((Box::new(SimulatedRig::new(device, user)), core))
    };
    let (rig, core, gains) = match setup().map(|(rig, core)| {
        let gains = core.gains().device.clone();
        (rig, core, gains)
    }) {
        Ok(parts) => parts,
        Err(e) => {
            abandon(&endpoint, &session.connection, b"client cannot render").await;
            let _ = started.send(Err(e));
            return;
        }
    };
    let (snapshots_tx, snapshots_rx) = rtrb::RingBuffer::new(SNAPSHOT_RING);
    let (spent_snapshots_tx, spent_snapshots_rx) = rtrb::RingBuffer::new(2 * SNAPSHOT_RING);
    let (mut free_tx, free_rx) = rtrb::RingBuffer::new(UPLINK_RING);
    for _ in 0..UPLINK_RING {
        let _ = free_tx.push(empty_uplink::<S>());
    }
    let (uplinks_tx, uplinks_rx) = rtrb::RingBuffer::new(UPLINK_RING);
    let (cores_tx, cores_rx) = rtrb::RingBuffer::new(2);
    let (spent_cores_tx, spent_cores_rx) = rtrb::RingBuffer::new(4);
    let (reports_tx, reports_rx) = rtrb::RingBuffer::new(64);
    let mut helpers = Vec::new();
    let records = match &config.record {
        Some(path) => {
            let (tx, rx) = rtrb::RingBuffer::new(RECORD_RING);
            let (path, stop) = (path.clone(), shared.clone());
            let stop_flag = Arc::new(std::sync::atomic::AtomicBool::new(false));
            let writer_stop = stop_flag.clone();
            helpers.push(std::thread::spawn(move || {
                // Stop when the loop stops, after draining.
                let watcher = std::thread::spawn(move || {
                    while !stop.stop.load(Ordering::Relaxed) {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    writer_stop.store(true, Ordering::Release);
                });
                match record::write_records(&path, S::KIND, rx, stop_flag) {
                    Ok(rows) => tracing::info!(rows, file = %path.display(), "recording written"),
                    Err(e) => tracing::error!(error = %e, file = %path.display(), "recording failed"),
                }
                let _ = watcher.join();
            }));
            Some(tx)
        }
        None => None,
    };
    let sender_slot: Arc<Mutex<Option<DatagramSender>>> =
        Arc::new(Mutex::new(Some(DatagramSender::new(session.connection.clone()))));
    let uplink_thread = {
        let (slot, shared, net) = (sender_slot.clone(), shared.clone(), net.clone());
        let handle = tokio::runtime::Handle::current();
        std::thread::Builder::new().name("kinloop-uplink".into()).spawn(move || {
            let _guard = handle.enter();
            send_uplinks(uplinks_rx, free_tx, slot, shared, net)
        })
    };
    let uplink_thread = match uplink_thread {
        Ok(t) => t,
        Err(e) => {
            abandon(&endpoint, &session.connection, b"client cannot start").await;
            let _ = started.send(Err(ClientError::Runtime(e.to_string())));
            return;
        }
    };
    let loop_rings = LoopRings {
        snapshots: snapshots_rx,
        spent_snapshots: spent_snapshots_tx,
        uplinks: uplinks_tx,
        free_uplinks: free_rx,
        cores: cores_rx,
        spent_cores: spent_cores_tx,
        records,
        reports: reports_tx,
        uplink_sender: Some(uplink_thread.thread().clone()),
    };
    let settings = LoopSettings {
        rate_hz: config.rate_hz,
        duration: config.duration,
        realtime_priority: config.realtime_priority,
        busy_wait: config.busy_wait,
        report_every: (config.rate_hz * config.report_interval.as_secs_f64()).max(1.0) as u64,
    };
    let loop_shared = shared.clone();
    let loop_thread = std::thread::Builder::new()
        .name("kinloop-haptic".into())
        .spawn(move || rt_loop::run(rig, core, loop_rings, loop_shared, settings));
    let loop_thread = match loop_thread {
        Ok(t) => t,
        Err(e) => {
            abandon(&endpoint, &session.connection, b"client cannot start").await;
            let _ = started.send(Err(ClientError::Runtime(e.to_string())));
            return;
        }
    };
    helpers.push(uplink_thread);
    let welcome = session.welcome.clone();
    let device = match model {
        Some(model) => format!("dhd ({})", model.name),
        None => config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND)).name().to_owned(),
    };
    let mut session = Session::adopt(session);
    let _ = started.send(Ok(Started { loop_thread, helpers, welcome, device, gains }));
    let mut rings = NetRings {
        snapshots: snapshots_tx,
        spent_snapshots: spent_snapshots_rx,
        cores: cores_tx,
        spent_cores: spent_cores_rx,
        reports: reports_rx,
    };
    let mut backoff = Duration::from_millis(100);
    loop {
        let ended = serve_session(&mut session, &mut rings, &shared, &net).await;
        if let Ok(mut slot) = sender_slot.lock() {
            *slot = None;
        }
        if shared.stop.load(Ordering::Relaxed) {
            leave(&mut session).await;
            break;
        }
        tracing::warn!(why = %ended, "session lost; the force fades out while reconnecting");
        // Reconnect with exponential backoff until stopped; refusals and certificate problems are final.
        let next = loop {
            if shared.stop.load(Ordering::Relaxed) {
                break None;
            }
            drain_reports(&mut rings, &net);
            tokio::time::sleep(backoff).await;
            backoff = (backoff * 2).min(Duration::from_secs(5));
            match open_session(&endpoint, address, &config, model, &mut None).await {
                Ok(s) => break Some(s),
                Err(
                    e @ (ConnectError::Refused(_) | ConnectError::UntrustedCertificate { .. } | ConnectError::Alpn),
                ) => {
                    tracing::error!(error = %e, "reconnection refused; giving up");
                    if let Ok(mut f) = net.fatal.lock() {
                        *f = Some(e.to_string());
                    }
                    shared.stop.store(true, Ordering::Relaxed);
                    break None;
                }
                Err(e) => tracing::warn!(error = %e, retry_in = ?backoff, "reconnection failed"),
            }
        };
        let Some(next) = next else { break };
        if next.welcome.scene.kind != S::KIND {
            tracing::error!("the server now runs a scene of another space; stopping");
            shared.stop.store(true, Ordering::Relaxed);
            break;
        }
        match core_for::<S>(&config, model, &next.welcome) {
            Ok(core) => {
                while rings.spent_cores.pop().is_ok() {}
                if rings.cores.push(core).is_err() {
                    tracing::error!("the haptic loop did not take the new session's core");
                }
            }
            Err(e) => {
                tracing::error!(error = %e, "cannot render the new session; stopping");
                shared.stop.store(true, Ordering::Relaxed);
                break;
            }
        }
        session = Session::adopt(next);
        if let Ok(mut slot) = sender_slot.lock() {
            *slot = Some(DatagramSender::new(session.connection.clone()));
        }
        net.reconnects.fetch_add(1, Ordering::Relaxed);
        backoff = Duration::from_millis(100);
        tracing::info!(session = session.welcome.session_id, "reconnected");
    }
    drain_reports(&mut rings, &net);
    // Give the close frame a moment to leave.
    let _ = tokio::time::timeout(CLOSE_LINGER, endpoint.wait_idle()).await;
}

fn drain_reports<S: Space>(rings: &mut NetRings<S>, net: &NetShared) {
    while let Ok(report) = rings.reports.pop() {
        tracing::info!(
            elapsed_s = report.elapsed.as_secs_f64(),
            constraint_count = report.constraint_count,
            gain = report.gain,
            snapshot_age_ms = report.snapshot_age.map(|a| a.as_secs_f64() * 1e3),
            tracking_rms_mm = report.core.tracking_error_rms() * 1e3,
            max_force_ratio = report.core.max_force_ratio,
            "haptic loop"
        );
        if let Ok(mut last) = net.last_report.lock() {
            *last = Some(report);
        }
    }
    while rings.spent_snapshots.pop().is_ok() {}
    while rings.spent_cores.pop().is_ok() {}
}

/// A live session: the connection, the control stream's sending half, and a task reading its other half.
struct Session {
    connection: kinloop_protocol::quic::Connection,
    send: kinloop_protocol::quic::SendStream,
    control: tokio::sync::mpsc::Receiver<Result<Control, String>>,
    reader: tokio::task::JoinHandle<()>,
    welcome: Welcome,
}

impl Session {
    /// Takes over a connected session; its control stream is read by a task of its own so that a frame
    /// half-read when another event wins a `select!` is never lost.
    fn adopt(connected: ConnectedSession) -> Self {
        let ConnectedSession { connection, send, mut recv, welcome, .. } = connected;
        let (tx, control) = tokio::sync::mpsc::channel(16);
        let reader = tokio::spawn(async move {
            loop {
                let message = kinloop_protocol::quic::recv_control(&mut recv).await.map_err(|e| e.to_string());
                let failed = message.is_err();
                if tx.send(message).await.is_err() || failed {
                    break;
                }
            }
        });
        Session { connection, send, control, reader, welcome }
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

async fn leave(session: &mut Session) {
    let bye = Control::Leave { reason: "client shutting down".into() };
    let _ =
        tokio::time::timeout(Duration::from_millis(200), kinloop_protocol::quic::send_control(&mut session.send, &bye))
            .await;
    session.connection.close(kinloop_protocol::quic::close_codes::NORMAL, b"bye");
}

/// Receives snapshots and answers the control stream until the session ends or the client stops.
async fn serve_session<S: Space>(
    session: &mut Session,
    rings: &mut NetRings<S>,
    shared: &LoopShared,
    net: &NetShared,
) -> String {
    // The handshake and the join have measured the round trip already: the core knows the delay from the
    // session's first tick rather than from the first pong, a round trip later. (At 1 s one way the first
    // two seconds pulled the local model toward the VE as fast as on a LAN, and the testbed with a Falcon
    // clamped 2-10 % of its ticks where virtual time, whose client knows its delay, clamped none.)
    shared.set_round_trip(session.connection.rtt());
    let scene = &session.welcome.scene;
    let shape = scene.shape();
    let mut receiver = DatagramReceiver::new(session.connection.clone(), shape);
    let mut ping = tokio::time::interval(Duration::from_millis(250));
    let mut housekeeping = tokio::time::interval(Duration::from_millis(50));
    let epoch = Instant::now();
    let mut nonce = 0u64;
    loop {
        tokio::select! {
            datagram = receiver.recv() => match datagram {
                Ok(Datagram::Snapshot(snapshot)) => {
                    net.snapshots_received.fetch_add(1, Ordering::Relaxed);
                    while rings.spent_snapshots.pop().is_ok() {}
                    // A full ring means the loop is behind: this snapshot is dropped, a newer one follows.
                    let _ = rings.snapshots.push(snapshot);
                }
                Ok(Datagram::Uplink(_)) => {}
                Err(e) if e.is_fatal() => return e.to_string(),
                Err(e) => tracing::debug!(error = %e, "datagram refused"),
            },
            message = session.control.recv() => match message {
                Some(Ok(Control::Pong { t_s, .. })) => {
                    let rtt_ms = (epoch.elapsed().as_secs_f64() - t_s) * 1e3;
                    if let Ok(rtt) = Duration::try_from_secs_f64(rtt_ms * 1e-3) {
                        shared.set_round_trip(rtt);
                        if let Ok(mut r) = net.rtt_ms.lock() {
                            if r.len() < 100_000 {
                                r.push(rtt_ms);
                            }
                        }
                    }
                }
                Some(Ok(Control::Ping { nonce, t_s })) => {
                    let _ = kinloop_protocol::quic::send_control(&mut session.send, &Control::Pong { nonce, t_s }).await;
                }
                Some(Ok(Control::Leave { reason })) => return format!("the server left: {reason}"),
                Some(Ok(Control::Error { code, message })) => return format!("the server reported {code}: {message}"),
                Some(Ok(_)) => {}
                Some(Err(e)) => return format!("control stream: {e}"),
                None => return "control stream closed".into(),
            },
            _ = ping.tick() => {
                nonce += 1;
                let message = Control::Ping { nonce, t_s: epoch.elapsed().as_secs_f64() };
                if let Err(e) = kinloop_protocol::quic::send_control(&mut session.send, &message).await {
                    return format!("control stream: {e}");
                }
            },
            _ = housekeeping.tick() => {
                drain_reports(rings, net);
                if shared.stop.load(Ordering::Relaxed) {
                    return "stopping".into();
                }
            },
            reason = session.connection.closed() => return reason.to_string(),
        }
    }
}

/// The uplink sender thread: parked until the loop pushes, sends, returns the buffers.
fn send_uplinks(
    mut uplinks: rtrb::Consumer<Uplink>,
    mut free: rtrb::Producer<Uplink>,
    sender: Arc<Mutex<Option<DatagramSender>>>,
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
) {
    loop {
        while let Ok(uplink) = uplinks.pop() {
            let message = Datagram::Uplink(uplink);
            if let Ok(guard) = sender.lock() {
                if let Some(s) = guard.as_ref() {
                    if s.send(&message).is_ok() {
                        net.uplinks_sent.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            if let Datagram::Uplink(buffer) = message {
                // Back to the loop for reuse: it never allocates a buffer of its own.
                let _ = free.push(buffer);
            }
        }
        if shared.stop.load(Ordering::Relaxed) && uplinks.is_empty() {
            break;
        }
        std::thread::park_timeout(Duration::from_millis(10));
    }
}
