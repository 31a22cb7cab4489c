//! The thin real-time shell around [`VeCore`]: [`Server::start`] runs the VE on its own OS thread
//! (`ve_thread`) and the network on the caller's tokio runtime (quinn), joined by bounded lock-free rings.
//!
//! ```text
//!  quinn tasks (tokio)                               VE thread (spin_sleep, SCHED_FIFO if allowed)
//!  accept ─ handshake ─ Command::Join ──── rtrb ───►  core.join ─► reply (oneshot)
//!  uplink receiver ───── UplinkSample ──── rtrb ───►  core.handle_uplink_sample
//!  snapshot sender ◄─ [len][bytes] frames ◄ rtrb ───  core.poll_snapshot ─► encode_datagram_into
//!  event logger    ◄──── VeEvent ──────────  rtrb ───  core.poll_event
//!  stats collector ◄──── VeLoopStats ──────  rtrb ───  every 100 ms
//!  CSV writer thread ◄── rows ───────────── rtrb ───  --record
//! ```
//! Many sessions send commands, so the command ring's producer sits behind a mutex that only network
//! tasks take; the VE thread owns every consumer and producer it touches and never waits.

mod record;
pub mod room;
mod session;
pub mod stats;
pub mod ve_thread;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use kinloop_linkage::{
    error::SceneError, math::space::Planar, math::space::SceneKind, math::space::Space, math::space::Spatial,
    math::space::VecOps, model::scene::Scene, model::Model,
};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::{
    close_codes, server_endpoint, Endpoint, EndpointError, EndpointOptions, IdentityError, ServerIdentity,
};
use kinloop_protocol::room_key::{scene_hash, RoomKey};
use kinloop_protocol::SessionShape;
use rtrb::RingBuffer;
use tokio::sync::watch;
use tokio::task::JoinHandle;

pub use crate::gateway::{LatencyHistogram, Percentiles, VeLoopStats};
pub use record::RecordError;
pub use stats::{ServerStats, UserStats};

use crate::access::Access;
use crate::core::{VeConfig, VeConfigError, VeCore, VeEvent};
use crate::fleet::{FleetEvent, FleetFeed, ONE_ROOM};
use crate::gateway::{CommandSender, Gateway, UserRegistry, FRAME_HEADER};
use crate::view::{LiveSource, ViewConfig, ViewError, ViewHandle};
use ve_thread::VeThreadIo;

/// Commands waiting for the VE thread.
const COMMAND_RING: usize = 64;
/// Events waiting for the logger.
const EVENT_RING: usize = 1024;
/// Rows waiting for the CSV writer (about 2 s of a small scene at 1 kHz).
const RECORD_RING: usize = 1 << 17;
/// How often the collector drains the VE thread's statistics and events.
const COLLECT_EVERY: Duration = Duration::from_millis(50);
/// Longest wait, by default, for the clients to move elsewhere when the server drains (`--drain-s`).
pub const DEFAULT_DRAIN: Duration = Duration::from_secs(5);
/// Past the drain, the longest wait for the network tasks to wind down.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(1);

/// Where the certificate comes from.
#[derive(Clone, Debug)]
pub enum Identity {
    /// Load from, or create once in, a directory (stable fingerprint across restarts).
    CertDir(PathBuf),
    /// A fresh self-signed certificate in memory (tests, demos).
    Ephemeral,
    /// A certificate chain and key from PEM files (one issued by the room's CA, say).
    Files {
        /// The certificate chain, end entity first.
        cert: PathBuf,
        /// Its private key.
        key: PathBuf,
    },
}

/// Everything a server needs.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// The linkage.
    pub scene: Scene,
    /// Where the scene came from, for messages.
    pub scene_label: String,
    /// UDP address to listen on.
    pub listen: SocketAddr,
    /// The VE's configuration.
    pub ve: VeConfig,
    /// Who may join.
    pub access: Access,
    /// Certificate source.
    pub identity: Identity,
    /// Impairments applied to everything the server sends (`--delay`, `--loss`...).
    pub link: Option<LinkConfig>,
    /// CSV file for one row per VE step.
    pub record: Option<PathBuf>,
    /// Log statistics this often.
    pub stats_every: Option<Duration>,
    /// Try SCHED_FIFO for the VE thread.
    pub realtime: bool,
    /// Serve the web view (`--view`).
    pub view: Option<ViewConfig>,
    /// The room's key (`--room-key`): the server signs its state for its clients and resumes from a state
    /// a client offers when it verifies (see `docs/resume.md`).
    pub room_key: Option<RoomKey>,
    /// At shutdown, how long the server waits for its clients to move after it told them to (`--drain-s`).
    pub drain: Duration,
    /// Where the server tells a fleet manager's adapter what happens (`--agones`), if anywhere.
    pub fleet: Option<FleetFeed>,
}

impl ServerConfig {
    /// A server for `scene` on `listen` with the paper's VE, open access and an ephemeral certificate.
    pub fn new(scene: Scene, scene_label: impl Into<String>, listen: SocketAddr) -> Self {
        ServerConfig {
            scene,
            scene_label: scene_label.into(),
            listen,
            ve: VeConfig::default(),
            access: Access::open(),
            identity: Identity::Ephemeral,
            link: None,
            record: None,
            stats_every: None,
            realtime: true,
            view: None,
            room_key: None,
            drain: DEFAULT_DRAIN,
            fleet: None,
        }
    }
}

/// Why a server could not start or stop cleanly.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The scene does not compile.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The VE configuration is invalid.
    #[error("invalid VE configuration: {0}")]
    Config(#[from] VeConfigError),
    /// The certificate could not be loaded or made.
    #[error(transparent)]
    Identity(#[from] IdentityError),
    /// The QUIC endpoint could not be set up.
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    /// Recording could not start.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// A thread could not be spawned or panicked.
    #[error("the {which} thread {what}")]
    Thread {
        /// Which thread.
        which: &'static str,
        /// What went wrong.
        what: String,
    },
    /// The web view could not start.
    #[error(transparent)]
    View(#[from] ViewError),
    /// The server was started outside a tokio runtime.
    #[error("the server must be started inside a tokio runtime")]
    NoRuntime,
}

/// State the network tasks share (the VE thread sees none of it).
pub(crate) struct Shared {
    /// Commands, the user registry and the rings' sizes, which the view shares.
    gateway: Arc<Gateway>,
    /// The server's endpoint, for the count of open connections.
    endpoint: Endpoint,
    ve_stats: Mutex<VeLoopStats>,
    started: Instant,
    ve_rate_hz: f64,
    access: Access,
    /// What a client learns before joining.
    scene_info: kinloop_protocol::SceneInfo,
    shutdown: watch::Sender<bool>,
    /// The view's counters, once it runs.
    view: std::sync::OnceLock<Arc<crate::view::Counters>>,
    /// The room, with a room key.
    room: Option<Arc<room::Room>>,
    /// How long a draining server waits for its clients to move.
    drain: Duration,
    /// The fleet adapter's feed.
    fleet: Option<FleetFeed>,
}

impl Shared {
    /// Tells the fleet adapter, if there is one.
    fn tell_fleet(&self, event: FleetEvent) {
        if let Some(fleet) = &self.fleet {
            fleet.send(event);
        }
    }
}

impl Shared {
    fn stats(&self) -> ServerStats {
        let mut ve = self.ve_stats.lock().map(|s| *s).unwrap_or_default();
        if let Some(room) = &self.room {
            ve.core.resumes_refused += room.refused_unseen.load(Ordering::Relaxed);
        }
        let mut per_user = Vec::new();
        self.gateway.users.for_each(|e| {
            per_user.push({
                let c = &e.counters;
                let load = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
                let (received, lost) = (load(&c.uplinks_received), load(&c.uplinks_lost));
                UserStats {
                    user_id: e.user_id,
                    name: e.name.clone(),
                    role: format!("{:?}", e.role).to_lowercase(),
                    rtt_ms: e.connection.rtt().as_secs_f64() * 1e3,
                    uplinks_received: received,
                    uplinks_lost: lost,
                    uplink_loss: if received + lost > 0 { lost as f64 / (received + lost) as f64 } else { 0.0 },
                    uplinks_undecodable: load(&c.uplinks_undecodable),
                    snapshots_sent: load(&c.snapshots_sent),
                    snapshot_bytes: load(&c.snapshot_bytes),
                    snapshots_oversize: load(&c.snapshots_oversize),
                    uplinks_clamped: load(&c.uplinks_clamped),
                    connected: c.connected.load(Ordering::Relaxed),
                }
            });
        });
        ServerStats {
            uptime_s: self.started.elapsed().as_secs_f64(),
            ve_rate_hz: self.ve_rate_hz,
            users: ve.core.users,
            connections: self.endpoint.open_connections(),
            ve,
            per_user,
            view: self.view.get().map(|v| v.snapshot()),
        }
    }
}

/// Starts servers.
pub struct Server;

impl Server {
    /// Compiles the scene, binds the endpoint, starts the VE thread and the network tasks on the current
    /// tokio runtime, and returns at once. Must be called inside a tokio runtime.
    pub fn start(config: ServerConfig) -> Result<ServerHandle, ServerError> {
        tokio::runtime::Handle::try_current().map_err(|_| ServerError::NoRuntime)?;
        match config.scene.kind {
            SceneKind::Planar => start_with::<Planar>(config),
            SceneKind::Spatial => start_with::<Spatial>(config),
        }
    }
}

/// A running server.
pub struct ServerHandle {
    local_addr: SocketAddr,
    fingerprint: String,
    shared: Arc<Shared>,
    endpoint: Endpoint,
    accept: JoinHandle<()>,
    collector: JoinHandle<()>,
    stop: Arc<AtomicBool>,
    /// See [`ServerHandle::stall_ve`].
    stall_ms: Arc<AtomicU64>,
    ve_thread: Option<std::thread::JoinHandle<VeLoopStats>>,
    recorder: Option<(Arc<AtomicBool>, std::thread::JoinHandle<std::io::Result<u64>>)>,
    view: Option<ViewHandle>,
}

impl ServerHandle {
    /// The address the server listens on (with the real port when bound to port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// SHA-256 fingerprint of the certificate, what clients pin with `--trust-fingerprint`.
    pub fn fingerprint(&self) -> &str {
        &self.fingerprint
    }

    /// Where the web view is served (`--view`), if it is.
    pub fn view_addr(&self) -> Option<SocketAddr> {
        self.view.as_ref().map(ViewHandle::local_addr)
    }

    /// Statistics so far.
    pub fn stats(&self) -> ServerStats {
        self.shared.stats()
    }

    /// A test knob: the VE thread stops ticking for `duration` at its next tick (it sleeps), as a stalled VE
    /// would; what a fleet manager sees of it is the test.
    pub fn stall_ve(&self, duration: Duration) {
        self.stall_ms.store(duration.as_millis().max(1) as u64, Ordering::Relaxed);
    }

    /// Drains: stops admitting (new connections are refused), hands each client the room's newest signed
    /// state and tells it to move (`Leave`), waits up to the configured drain time for them to go, then
    /// closes the endpoint, stops the VE thread and the recorder, and returns the final statistics.
    pub async fn shutdown(mut self) -> Result<ServerStats, ServerError> {
        if let Some(view) = self.view.take() {
            // Pages first: their grabs leave while the VE still runs.
            view.shutdown().await;
        }
        let clients = self.shared.gateway.users.connected();
        tracing::info!(clients, drain_s = self.shared.drain.as_secs_f64(), "draining: telling the clients to move");
        self.shared.tell_fleet(FleetEvent::Draining);
        let started = Instant::now();
        self.shared.shutdown.send_replace(true);
        if tokio::time::timeout(self.shared.drain + SHUTDOWN_GRACE, &mut self.accept).await.is_err() {
            self.accept.abort();
        }
        let left = self.shared.gateway.users.connected();
        tracing::info!(left, waited_s = started.elapsed().as_secs_f64(), "drained");
        self.endpoint.close(close_codes::NORMAL, b"server shutdown");
        let _ = tokio::time::timeout(SHUTDOWN_GRACE, self.endpoint.wait_idle()).await;
        self.stop.store(true, Ordering::Relaxed);
        let final_ve = match self.ve_thread.take() {
            Some(thread) => tokio::task::spawn_blocking(move || thread.join())
                .await
                .map_err(|e| ServerError::Thread { which: "VE", what: e.to_string() })?
                .map_err(|_| ServerError::Thread { which: "VE", what: "panicked".into() })?,
            None => VeLoopStats::default(),
        };
        if let Ok(mut ve) = self.shared.ve_stats.lock() {
            *ve = final_ve;
        }
        self.collector.abort();
        if let Some((stop, thread)) = self.recorder.take() {
            stop.store(true, Ordering::Release);
            let written = tokio::task::spawn_blocking(move || thread.join())
                .await
                .map_err(|e| ServerError::Thread { which: "record", what: e.to_string() })?
                .map_err(|_| ServerError::Thread { which: "record", what: "panicked".into() })?;
            if let Err(error) = written {
                tracing::error!(%error, "the recording is incomplete");
            }
        }
        self.shared.tell_fleet(FleetEvent::RoomClosed { room: ONE_ROOM.into() });
        self.shared.tell_fleet(FleetEvent::Drained);
        Ok(self.shared.stats())
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        // A handle dropped without shutdown must not leave the VE thread spinning.
        self.stop.store(true, Ordering::Relaxed);
        self.accept.abort();
        self.collector.abort();
    }
}

fn start_with<S: Space>(config: ServerConfig) -> Result<ServerHandle, ServerError> {
    let model = Model::<S>::compile(&config.scene, &config.scene_label)?;
    let (nq, n, m) = (model.nq(), model.nv(), model.nc());
    let core = VeCore::new(model, config.ve.clone())?;
    let scene_info = core.scene_info();
    for op in 0..core.model().ops.len() {
        if let Some(reach) = core.reach(op) {
            tracing::info!(op = %core.model().ops[op].name, reach_m = ?reach.extent().as_slice(), static_force_n = reach.static_force_n, lightest_mass_kg = 1.0 / reach.inverse_mass_max, "operational point surveyed");
        }
    }
    let identity = match &config.identity {
        Identity::CertDir(dir) => ServerIdentity::load_or_create(dir)?,
        Identity::Ephemeral => ServerIdentity::generate(&kinloop_protocol::quic::DEFAULT_NAMES)?,
        Identity::Files { cert, key } => ServerIdentity::load(cert, key)?,
    };
    let room = config.room_key.clone().map(|key| {
        let hash = scene_hash(&serde_json::to_vec(&config.scene).unwrap_or_default());
        Arc::new(room::Room::new(key, hash, n, core.state().qd.len()))
    });
    let options = EndpointOptions { link: config.link.clone(), ..EndpointOptions::default() };
    let endpoint = server_endpoint(config.listen, &identity, &options)?;
    let local_addr = endpoint.local_addr().map_err(|source| EndpointError::Socket { addr: config.listen, source })?;
    if config.access.is_open() {
        tracing::warn!("no --token-file: any token is accepted");
    }

    let (command_tx, command_rx) = RingBuffer::new(COMMAND_RING);
    let (event_tx, event_rx) = RingBuffer::new(EVENT_RING);
    let (stats_tx, stats_rx) = RingBuffer::new(64);
    let stop = Arc::new(AtomicBool::new(false));
    let stall_ms = Arc::new(AtomicU64::new(0));
    let recorder = match &config.record {
        Some(path) => {
            let (row_tx, row_rx) = RingBuffer::new(RECORD_RING);
            let done = Arc::new(AtomicBool::new(false));
            let thread = record::spawn_writer(path, record::header::<S>(nq, n, m), row_rx, done.clone())?;
            Some((row_tx, (done, thread)))
        }
        None => None,
    };
    let (row_tx, recorder) = match recorder {
        Some((tx, handle)) => (Some(tx), Some(handle)),
        None => (None, None),
    };
    let (view_tap, view_reader) = match &config.view {
        Some(v) => {
            let (tap, reader) = crate::view::tap::<S>(n, config.ve.max_users, config.ve.ve_rate_hz, v.frame_rate_hz);
            (Some(tap), Some(reader))
        }
        None => (None, None),
    };
    let io = VeThreadIo {
        commands: command_rx,
        events: event_tx,
        stats: stats_tx,
        record: row_tx,
        view: view_tap,
        room: room.clone(),
        stop: stop.clone(),
        heartbeat: config.fleet.as_ref().map(|f| f.heartbeat().clone()),
        stall_ms: stall_ms.clone(),
    };
    let realtime = config.realtime;
    let ve_thread = std::thread::Builder::new()
        .name("kinloop-ve".into())
        .spawn(move || ve_thread::run(core, io, realtime))
        .map_err(|e| ServerError::Thread { which: "VE", what: e.to_string() })?;

    let (shutdown, _) = watch::channel(false);
    let shared = Arc::new(Shared {
        gateway: Arc::new(Gateway {
            commands: Arc::new(CommandSender::new(command_tx)),
            users: UserRegistry::default(),
            shape: SessionShape { kind: S::KIND, n, m },
            snapshot_ring_bytes: 4 * (FRAME_HEADER + ve_thread::snapshot_size_bound::<S>(n, m)),
        }),
        endpoint: endpoint.clone(),
        ve_stats: Mutex::new(VeLoopStats::default()),
        started: Instant::now(),
        ve_rate_hz: config.ve.ve_rate_hz,
        access: config.access.clone(),
        scene_info,
        shutdown,
        view: std::sync::OnceLock::new(),
        room,
        drain: config.drain,
        fleet: config.fleet.clone(),
    });
    let view = match (&config.view, view_reader) {
        (Some(view), Some(reader)) => {
            let source = LiveSource {
                scene: config.scene.clone(),
                scene_label: config.scene_label.clone(),
                reader,
                access: config.access.clone(),
            };
            match crate::view::start_live_with(view, source, Some(shared.gateway.clone())) {
                Ok(handle) => {
                    let _ = shared.view.set(handle.counters());
                    Some(handle)
                }
                Err(error) => {
                    stop.store(true, Ordering::Relaxed);
                    return Err(error.into());
                }
            }
        }
        _ => None,
    };
    let accept = tokio::spawn(accept_loop(endpoint.clone(), shared.clone()));
    let collector = tokio::spawn(collect(shared.clone(), stats_rx, event_rx, config.stats_every));
    shared.tell_fleet(FleetEvent::Listening { addr: local_addr });
    shared.tell_fleet(FleetEvent::RoomOpened { room: ONE_ROOM.into() });
    Ok(ServerHandle {
        local_addr,
        fingerprint: identity.fingerprint.clone(),
        shared,
        endpoint,
        accept,
        collector,
        stop,
        stall_ms,
        ve_thread: Some(ve_thread),
        recorder,
        view,
    })
}

/// Accepts connections until shutdown; then, while the sessions end (each bounded by the drain), refuses
/// new ones at once rather than leaving them to time out.
async fn accept_loop(endpoint: Endpoint, shared: Arc<Shared>) {
    let mut sessions = tokio::task::JoinSet::new();
    let mut shutdown = shared.shutdown.subscribe();
    loop {
        tokio::select! {
            incoming = endpoint.accept() => match incoming {
                Some(incoming) => drop(sessions.spawn(session::serve(incoming, shared.clone()))),
                None => break,
            },
            _ = shutdown.changed() => break,
            Some(_) = sessions.join_next(), if !sessions.is_empty() => {}
        }
    }
    while !sessions.is_empty() {
        tokio::select! {
            Some(incoming) = endpoint.accept() => {
                tracing::info!(remote = %incoming.remote_address(), "refused a connection: the server is draining");
                incoming.refuse();
            }
            _ = sessions.join_next() => {}
        }
    }
}

/// Drains the VE thread's statistics and events; logs statistics every `stats_every`.
async fn collect(
    shared: Arc<Shared>,
    mut stats: rtrb::Consumer<VeLoopStats>,
    mut events: rtrb::Consumer<VeEvent>,
    stats_every: Option<Duration>,
) {
    let mut tick = tokio::time::interval(COLLECT_EVERY);
    let mut last_log = Instant::now();
    loop {
        tick.tick().await;
        while let Ok(latest) = stats.pop() {
            if let Ok(mut ve) = shared.ve_stats.lock() {
                *ve = latest;
            }
        }
        while let Ok(event) = events.pop() {
            log_event(&shared, &event);
        }
        if stats_every.is_some_and(|e| !e.is_zero() && last_log.elapsed() >= e) {
            last_log = Instant::now();
            let s = shared.stats();
            tracing::info!(
                users = s.users,
                connections = s.connections,
                step_p50_us = s.ve.step_time.p50_ns as f64 / 1e3,
                step_p99_us = s.ve.step_time.p99_ns as f64 / 1e3,
                step_max_us = s.ve.step_time.max_ns as f64 / 1e3,
                deadline_misses = s.ve.deadline_misses,
                closure_error_m = s.ve.core.closure_error,
                uplinks_rejected = s.ve.core.uplinks_rejected,
                "VE stats"
            );
            for u in s.per_user.iter().filter(|u| u.connected) {
                tracing::info!(
                    user = u.user_id,
                    name = %u.name,
                    rtt_ms = u.rtt_ms,
                    uplink_loss = u.uplink_loss,
                    snapshot_bytes = u.snapshot_bytes,
                    "user stats"
                );
            }
        }
    }
}

fn log_event(shared: &Shared, event: &VeEvent) {
    match event {
        VeEvent::UserJoined { user } => {
            tracing::info!(user, name = %shared.gateway.users.name_of(*user), "joined the VE")
        }
        VeEvent::FadingOut { user, reason } => tracing::info!(user, ?reason, "coupling fading out"),
        VeEvent::Resumed { user } => tracing::info!(user, "uplinks resumed; coupling fading in"),
        VeEvent::UserRemoved { user } => tracing::info!(user, "left the VE"),
        VeEvent::RoomResumed { step } => tracing::info!(step, "the room resumed from a client's signed state"),
        VeEvent::UplinkRejected { user, rejection, previous_burst } => {
            tracing::warn!(user, %rejection, previous_burst, "rejecting uplinks (logged once per burst)")
        }
        VeEvent::StateRestored { step, error } => {
            tracing::error!(step, %error, "VE step failed; restored the last good configuration at rest")
        }
        VeEvent::SnapshotsWithheld { step, error } => tracing::error!(step, %error, "snapshots withheld"),
        VeEvent::SnapshotInvalid { user, error } => tracing::error!(user, %error, "snapshot withheld"),
        VeEvent::TicksSkipped { count } => tracing::warn!(count, "the VE fell behind and skipped ticks"),
    }
}

/// Loads a scene argument: a file, or a built-in name (see [`kinloop_linkage::model::builtin::load`]).
pub use kinloop_linkage::model::builtin::load as load_scene;
