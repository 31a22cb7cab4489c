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

pub mod network_runtime;
mod record;
pub mod rehearsal;
pub mod room;
pub mod rooms;
mod session;
pub mod stats;
pub mod ve_thread;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
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
use rtrb::{Producer, RingBuffer};
use tokio::sync::watch;
use tokio::task::JoinHandle;

pub use crate::gateway::{LatencyHistogram, Percentiles, VeLoopStats};
pub use record::RecordError;
pub use stats::{ServerStats, UserStats};

use crate::access::Access;
use crate::core::{VeConfig, VeConfigError, VeCore, VeEvent};
use crate::fleet::{FleetEvent, FleetFeed, FleetRoom};
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
/// What a draining server tells its clients.
const DRAINING: &str = "the server is draining: move to another server of the room";

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
    /// The rooms (`--rooms`); empty: one room, "default", of the fields above.
    pub rooms: Vec<rooms::RoomSpec>,
    /// Real-time threads stepping the rooms (`--rt-threads`).
    pub rt_threads: usize,
    /// The CPU the executor's first real-time thread is pinned to (`--pin-network`), where the caller pins
    /// its network runtime's workers too ([`kinloop_process::affinity`]): each round's wake-up of the network
    /// side is then a run-queue insertion on that CPU, not an interrupt to the other. `None`: not pinned.
    pub network_cpu: Option<usize>,
    /// Tokens of the admin command (`--admin-token`); `None`: no admin command is accepted.
    pub admin: Option<Access>,
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
            rooms: Vec::new(),
            rt_threads: rooms::default_rt_threads(),
            network_cpu: None,
            admin: None,
        }
    }

    /// The rooms to open at start: the rooms file's, or one "default" room of the single-scene fields.
    fn room_specs(&self) -> Vec<rooms::RoomSpec> {
        if !self.rooms.is_empty() {
            return self.rooms.clone();
        }
        vec![rooms::RoomSpec {
            name: rooms::DEFAULT_ROOM.into(),
            scene: self.scene.clone(),
            scene_label: self.scene_label.clone(),
            access: self.access.clone(),
            max_users: self.ve.max_users,
            record: self.record.clone(),
            knobs: rooms::TestKnobs::default(),
        }]
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
    /// A room could not open.
    #[error("room {room:?}: {source}")]
    Room {
        /// The room.
        room: String,
        /// Why.
        source: Box<ServerError>,
    },
    /// The executor has no budget for another room.
    #[error("{0}")]
    OverBudget(#[from] rooms::OverBudget),
}

/// One room's state the network tasks share (the VE thread sees none of it).
pub(crate) struct Shared {
    /// The room's name.
    name: String,
    /// What the executor measures of the room.
    cell: Arc<rooms::RoomCell>,
    /// The executor, which admits users.
    executor: Arc<rooms::Executor>,
    /// What sessions tell their clients when the room closes.
    leave_reason: Mutex<String>,
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
    /// How long a closing room waits for its clients to move.
    drain: Duration,
    /// The room's side of the fleet adapter's feed.
    fleet: Arc<FleetRoom>,
}

impl Shared {
    /// Tells the fleet adapter, if there is one.
    fn tell_fleet(&self, event: FleetEvent) {
        self.fleet.send(event);
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
                let quic = e.connection.stats();
                UserStats {
                    user_id: e.user_id,
                    name: e.name.clone(),
                    role: format!("{:?}", e.role).to_lowercase(),
                    rtt_ms: e.connection.rtt().as_secs_f64() * 1e3,
                    uplinks_received: received,
                    uplinks_lost: lost,
                    uplink_loss: if received + lost > 0 { lost as f64 / (received + lost) as f64 } else { 0.0 },
                    uplinks_undecodable: load(&c.uplinks_undecodable),
                    uplinks_dropped: load(&c.uplinks_dropped),
                    datagrams_arrived: quic.frame_rx.datagram,
                    datagrams_transmitted: quic.frame_tx.datagram,
                    packets_lost: quic.path.lost_packets,
                    snapshots_sent: load(&c.snapshots_sent),
                    snapshot_bytes: load(&c.snapshot_bytes),
                    snapshots_oversize: load(&c.snapshots_oversize),
                    uplinks_clamped: load(&c.uplinks_clamped),
                    connected: c.connected.load(Ordering::Relaxed),
                    ended: c.ended.get().copied(),
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
    /// Binds the endpoint, starts the rooms' executor and opens every room (the rooms file's, or one
    /// "default" room of `config.scene`), starts the network tasks on the current tokio runtime, and
    /// returns at once. Must be called inside a tokio runtime.
    pub fn start(config: ServerConfig) -> Result<ServerHandle, ServerError> {
        tokio::runtime::Handle::try_current().map_err(|_| ServerError::NoRuntime)?;
        let identity = match &config.identity {
            Identity::CertDir(dir) => ServerIdentity::load_or_create(dir)?,
            Identity::Ephemeral => ServerIdentity::generate(&kinloop_protocol::quic::DEFAULT_NAMES)?,
            Identity::Files { cert, key } => ServerIdentity::load(cert, key)?,
        };
        let options = EndpointOptions { link: config.link.clone(), ..EndpointOptions::default() };
        let endpoint = server_endpoint(config.listen, &identity, &options)?;
        let local_addr =
            endpoint.local_addr().map_err(|source| EndpointError::Socket { addr: config.listen, source })?;
        let heartbeat = config.fleet.as_ref().map(|f| f.heartbeat().clone());
        let executor = rooms::Executor::start(config.rt_threads, config.realtime, heartbeat, config.network_cpu)
            .map_err(|e| ServerError::Thread { which: "rooms", what: e.to_string() })?;
        let view = config.view.as_ref().map(|v| crate::view::ViewSite::start(v.listen)).transpose()?;
        let host = Arc::new(rooms::Host {
            view,
            endpoint: endpoint.clone(),
            executor: executor.clone(),
            table: Mutex::new(std::collections::BTreeMap::new()),
            admin: config.admin.clone(),
            template: config.clone(),
            shutdown: watch::channel(false).0,
            announced: AtomicBool::new(false),
        });
        for spec in config.room_specs() {
            let name = spec.name.clone();
            if let Err(error) = host.open(spec, false) {
                executor.shutdown();
                return Err(ServerError::Room { room: name, source: Box::new(error) });
            }
        }
        // The fleet hears of the server first, then of its rooms (later rooms as they open); the rooms its
        // allocations ask for are created through the host.
        if let Some(fleet) = &config.fleet {
            fleet.offer_rooms(Arc::downgrade(&host) as std::sync::Weak<dyn crate::fleet::allocation::RoomCreator>);
        }
        host.announce(local_addr);
        let accept = tokio::spawn(accept_loop(endpoint.clone(), host.clone()));
        Ok(ServerHandle { local_addr, fingerprint: identity.fingerprint.clone(), host, endpoint, accept })
    }
}

/// A running server.
pub struct ServerHandle {
    local_addr: SocketAddr,
    fingerprint: String,
    host: Arc<rooms::Host>,
    endpoint: Endpoint,
    accept: JoinHandle<()>,
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

    /// Where the rooms' web view is served (`--view`), if it is: `/` lists them, `/room/NAME` shows one.
    pub fn view_addr(&self) -> Option<SocketAddr> {
        self.host.view.as_ref().map(crate::view::ViewSite::local_addr)
    }

    /// Statistics so far of the first room (the only one of a `--scene` server).
    pub fn stats(&self) -> ServerStats {
        self.host.first(|room| room.shared.stats()).unwrap_or_default()
    }

    /// A test knob: the rooms' executor stops stepping for `duration` from its next pass (it sleeps), as a
    /// stalled executor would; what a fleet manager sees of it is the test.
    pub fn stall_ve(&self, duration: Duration) {
        self.host.executor.stall(duration);
    }

    /// Statistics so far of every room, by name.
    pub fn room_stats(&self) -> Vec<rooms::RoomReport> {
        self.host.reports()
    }

    /// Drains (see [`ServerHandle::shutdown_rooms`]) and returns the final statistics of the first room.
    pub async fn shutdown(self) -> Result<ServerStats, ServerError> {
        Ok(self.shutdown_rooms().await?.into_iter().next().map(|r| r.stats).unwrap_or_default())
    }

    /// Drains: stops admitting on every room (new connections are refused), hands each client its room's
    /// newest signed state and tells it to move (`Leave`), waits up to the configured drain time for them to
    /// go, then closes the endpoint, stops the rooms and their recorders, and returns every room's final
    /// statistics.
    pub async fn shutdown_rooms(mut self) -> Result<Vec<rooms::RoomReport>, ServerError> {
        let opened = self.host.take_all();
        let clients: usize = opened.iter().map(|room| room.shared.gateway.users.connected()).sum();
        let drain = self.host.template.drain;
        tracing::info!(clients, drain_s = drain.as_secs_f64(), "draining: telling the clients to move");
        self.host.tell_fleet(FleetEvent::Draining);
        let started = Instant::now();
        for room in &opened {
            room.begin_close(DRAINING);
        }
        self.host.shutdown.send_replace(true);
        if tokio::time::timeout(drain + SHUTDOWN_GRACE, &mut self.accept).await.is_err() {
            self.accept.abort();
        }
        let left: usize = opened.iter().map(|room| room.shared.gateway.users.connected()).sum();
        tracing::info!(left, waited_s = started.elapsed().as_secs_f64(), "drained");
        self.endpoint.close(close_codes::NORMAL, b"server shutdown");
        let _ = tokio::time::timeout(SHUTDOWN_GRACE, self.endpoint.wait_idle()).await;
        let mut reports = Vec::new();
        for room in opened {
            reports.push(room.finish().await?);
        }
        if let Some(view) = self.host.view.as_ref() {
            view.site.shutdown.send_replace(true);
        }
        let executor = self.host.executor.clone();
        let _ = tokio::task::spawn_blocking(move || executor.shutdown()).await;
        self.host.tell_fleet(FleetEvent::Drained);
        Ok(reports)
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        // A handle dropped without shutdown must not leave the rooms' threads spinning.
        for room in self.host.take_all() {
            room.begin_close("the server is shutting down");
            room.stop.store(true, Ordering::Relaxed);
        }
        self.host.executor.shutdown_soon();
        self.accept.abort();
    }
}

/// A room, open: its shared state and the tasks and threads it owns.
pub(crate) struct OpenRoom {
    shared: Arc<Shared>,
    collector: JoinHandle<()>,
    stop: Arc<AtomicBool>,
    recorder: Option<Recorder>,
    view: Option<ViewHandle>,
}

/// A room's record writer: the flag that tells it the rows are done, and its thread (rows written).
type Recorder = (Arc<AtomicBool>, std::thread::JoinHandle<std::io::Result<u64>>);

impl OpenRoom {
    /// Tells its sessions to leave (with `reason`); [`OpenRoom::finish`] then stops its VE.
    fn begin_close(&self, reason: &str) {
        if let Ok(mut leave) = self.shared.leave_reason.lock() {
            *leave = reason.to_owned();
        }
        self.shared.shutdown.send_replace(true);
    }

    /// Waits for its VE to finish, stops its recorder and view, and returns its final statistics.
    async fn finish(mut self) -> Result<rooms::RoomReport, ServerError> {
        if let Some(view) = self.view.take() {
            view.shutdown().await;
        }
        self.stop.store(true, Ordering::Relaxed);
        let deadline = Instant::now() + SHUTDOWN_GRACE;
        while !self.shared.cell.done() && Instant::now() < deadline {
            tokio::time::sleep(COLLECT_EVERY / 5).await;
        }
        // The collector takes the final statistics the VE published as it finished.
        tokio::time::sleep(2 * COLLECT_EVERY).await;
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
        self.shared.fleet.closed();
        Ok(rooms::RoomReport::of(&self.shared))
    }
}

/// Opens a room: compiles its scene, builds its VE and rings, starts its recorder, view and collector, and
/// places it on the executor (refused when the budget has no room).
/// `allocated`: opened for a fleet's allocation, which counted it.
pub(crate) fn open_room(host: &rooms::Host, spec: rooms::RoomSpec, allocated: bool) -> Result<OpenRoom, ServerError> {
    match spec.scene.kind {
        SceneKind::Planar => open_room_with::<Planar>(host, spec, allocated),
        SceneKind::Spatial => open_room_with::<Spatial>(host, spec, allocated),
    }
}

fn open_room_with<S: Space>(host: &rooms::Host, spec: rooms::RoomSpec, allocated: bool) -> Result<OpenRoom, ServerError>
where
    VeCore<S>: Send,
{
    let config = &host.template;
    let model = Model::<S>::compile(&spec.scene, &spec.scene_label)?;
    let (nq, n, m) = (model.nq(), model.nv(), model.nc());
    let ve_config = VeConfig { max_users: spec.max_users, ..config.ve.clone() };
    let core = VeCore::new(model, ve_config.clone())?;
    let scene_info = core.scene_info();
    for op in 0..core.model().ops.len() {
        if let Some(reach) = core.reach(op) {
            // In the scene's own units (a scene written in mm and g is surveyed in them): no SI suffixes.
            tracing::info!(room = %spec.name, op = %core.model().ops[op].name, reach = ?reach.extent().as_slice(), static_force = reach.static_force_n, lightest_mass = 1.0 / reach.inverse_mass_max, "operational point surveyed, in the scene's units");
        }
    }
    let room = config.room_key.clone().map(|key| {
        let hash = scene_hash(&serde_json::to_vec(&spec.scene).unwrap_or_default());
        Arc::new(room::Room::new(key, hash, n, core.state().qd.len()))
    });
    if spec.access.is_open() {
        tracing::warn!(room = %spec.name, "no token file: any token is accepted");
    }

    let (command_tx, command_rx) = RingBuffer::new(COMMAND_RING);
    let (event_tx, event_rx) = RingBuffer::new(EVENT_RING);
    let (stats_tx, stats_rx) = RingBuffer::new(64);
    let stop = Arc::new(AtomicBool::new(false));
    let (row_tx, recorder) = match &spec.record {
        Some(path) => {
            let (row_tx, recorder) = start_recorder::<S>(path, (nq, n, m))?;
            (Some(row_tx), Some(recorder))
        }
        None => (None, None),
    };
    // Every room is on the view's site (`/room/NAME`).
    let view_config = config.view.as_ref().zip(host.view.as_ref());
    let (view_tap, view_reader) = match view_config {
        Some((v, _)) => {
            let (tap, reader) = crate::view::tap::<S>(n, ve_config.max_users, ve_config.ve_rate_hz, v.frame_rate_hz);
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
    };
    let (shutdown, _) = watch::channel(false);
    let fleet = Arc::new(FleetRoom::new(config.fleet.clone(), spec.name.clone(), allocated));
    let on_close = {
        let (shutdown, fleet) = (shutdown.clone(), fleet.clone());
        Box::new(move |_reason: &str| {
            shutdown.send_replace(true);
            fleet.closed();
        }) as Box<dyn Fn(&str) + Send + Sync>
    };
    let cell = Arc::new(rooms::RoomCell::new(spec.name.clone(), ve_config.ve_rate_hz, on_close));
    let shared = Arc::new(Shared {
        name: spec.name.clone(),
        cell: cell.clone(),
        executor: host.executor.clone(),
        leave_reason: Mutex::new("the server is shutting down".into()),
        gateway: Arc::new(Gateway {
            commands: Arc::new(CommandSender::new(command_tx)),
            users: UserRegistry::default(),
            shape: SessionShape { kind: S::KIND, n, nq, m },
            snapshot_ring_bytes: 4 * (FRAME_HEADER + ve_thread::snapshot_size_bound::<S>(n, m)),
        }),
        endpoint: host.endpoint.clone(),
        ve_stats: Mutex::new(VeLoopStats::default()),
        started: Instant::now(),
        ve_rate_hz: ve_config.ve_rate_hz,
        access: spec.access.clone(),
        scene_info,
        shutdown,
        view: std::sync::OnceLock::new(),
        room,
        drain: config.drain,
        fleet,
    });
    // The room's time starts on the executor's grid, so the rooms of a thread are due together.
    let epoch = host.executor.grid_start(ve_config.ve_period());
    let hosted = rooms::Hosted::new(ve_thread::VeLoop::new(core, io, epoch), spec.knobs);
    if let Err(error) = host.executor.place(Box::new(hosted), cell) {
        shared.fleet.closed();
        return Err(error.into());
    }
    let view = match (view_config, view_reader) {
        (Some((view, site)), Some(reader)) => {
            let source = LiveSource {
                scene: spec.scene.clone(),
                scene_label: spec.scene_label.clone(),
                reader,
                access: spec.access.clone(),
            };
            match crate::view::start_room_view(site, &spec.name, view, source, Some(shared.gateway.clone())) {
                Ok(handle) => {
                    let _ = shared.view.set(handle.counters());
                    Some(handle)
                }
                Err(error) => {
                    stop.store(true, Ordering::Relaxed);
                    shared.fleet.closed();
                    return Err(error.into());
                }
            }
        }
        _ => None,
    };
    let collector = tokio::spawn(collect(shared.clone(), stats_rx, event_rx, config.stats_every));
    Ok(OpenRoom { shared, collector, stop, recorder, view })
}

/// The writer thread of a room's `--record` file and the VE thread's end of its ring.
fn start_recorder<S: Space>(
    path: &Path,
    (nq, n, m): (usize, usize, usize),
) -> Result<(Producer<f64>, Recorder), ServerError> {
    let (row_tx, row_rx) = RingBuffer::new(RECORD_RING);
    let done = Arc::new(AtomicBool::new(false));
    let thread = record::spawn_writer(path, record::header::<S>(nq, n, m), row_rx, done.clone())?;
    Ok((row_tx, (done, thread)))
}

/// Accepts connections until shutdown; then, while the sessions end (each bounded by the drain), refuses
/// new ones at once rather than leaving them to time out.
async fn accept_loop(endpoint: Endpoint, host: Arc<rooms::Host>) {
    let mut sessions = tokio::task::JoinSet::new();
    let mut shutdown = host.shutdown.subscribe();
    loop {
        tokio::select! {
            incoming = endpoint.accept() => match incoming {
                Some(incoming) => drop(sessions.spawn(session::serve(incoming, host.clone()))),
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

/// Loads a scene argument: an MJCF model (`.xml`), a scene file, or a built-in name (see
/// [`kinloop_mjcf::load::load`], the one reader every command uses).
pub use kinloop_mjcf::load::load as load_scene;
