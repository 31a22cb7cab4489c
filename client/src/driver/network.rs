//! The network side, on a runtime thread of the client's own ([`network_thread`]) or as a task on a runtime
//! shared by many clients ([`network_task`]): the first handshake, the session's haptic side (rig, core,
//! haptic loop, uplink outlet, recorder) and its rings, and reconnection with exponential backoff when the
//! session is lost.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use kinloop_linkage::math::space::{Planar, SceneKind, Space, Spatial, VecOps};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::{
    client_endpoint, connect_resuming, ConnectError, ConnectedSession, DatagramSender, Endpoint, EndpointOptions,
};
use kinloop_protocol::{
    Hello, Join, LocalModelForm, ResumeAnswer, Role, RoomState, SceneInfo, Uplink, Welcome, PROTOCOL_VERSION,
};

use super::config::{ClientConfig, ClientError};
use super::device_clock;
use super::real::{OpenedDevice, RealSpec};
use super::record::{self, TickRecord};
use super::rt_loop::{self, LoopBody, LoopRings, LoopSettings, LoopShared};
use super::session::{drain_reports, leave, serve_session, NetRings, NetShared, Session};
use super::shared_clock::LoopEnd;
use super::uplinks::{send_uplinks, Outlet};
use crate::core::{ControllerGains, CoreConfig, HapticCore, ModelForm};
use crate::device::hd::OpenedHd;
use crate::device::presets::SimulatedDeviceBuildError;
use crate::device::{DevicePreset, HapticDevice, SimulatedRig};
use crate::user::UserContext;

pub(super) struct Started {
    pub(super) loop_thread: LoopEnd,
    pub(super) helpers: Vec<JoinHandle<()>>,
    pub(super) welcome: Welcome,
    pub(super) device: String,
    pub(super) gains: ControllerGains,
}

/// Longest a client waits for its closing connection to tell the server. A process that exits sooner sends
/// nothing, and the server keeps the user until its idle timeout.
const CLOSE_LINGER: Duration = Duration::from_secs(1);

/// How long past its longest flight an emulated link is given to let the close go: the close is queued a few
/// milliseconds after the linger starts, when the connection's driver runs.
const CLOSE_QUEUEING: Duration = Duration::from_millis(50);

/// A client's QUIC endpoint: its own, or one shared with the other clients of its process.
struct ClientEndpoint {
    quic: Endpoint,
    /// On an endpoint of the client's own, how long its close may take to leave: at least [`CLOSE_LINGER`],
    /// longer on an emulated link, where the close waits like any packet and is lost if the client stops
    /// before the link lets it go. `None` on a shared one (never emulated), which outlives the client; its
    /// owner lingers once for every client (`SharedNetwork::finish`).
    linger: Option<Duration>,
}

impl ClientEndpoint {
    /// Waits (at most its `linger`) for the closing connections to tell their server.
    async fn linger(&self) {
        if let Some(linger) = self.linger {
            let _ = tokio::time::timeout(linger, self.quic.wait_idle()).await;
        }
    }
}

/// Closes a session that will not run and lets the server be told, so it drops the user at once.
async fn abandon(endpoint: &ClientEndpoint, connection: &kinloop_protocol::quic::Connection, why: &'static [u8]) {
    connection.close(kinloop_protocol::quic::close_codes::NORMAL, why);
    endpoint.linger().await;
}

const SNAPSHOT_RING: usize = 16;
const UPLINK_RING: usize = 64;
const RECORD_RING: usize = 16_384;

/// What the network side needs from the client that starts it.
pub(super) struct NetStart {
    pub(super) config: ClientConfig,
    pub(super) real: Option<OpenedDevice>,
    pub(super) addresses: Vec<SocketAddr>,
    pub(super) shared: Arc<LoopShared>,
    pub(super) net: Arc<NetShared>,
    pub(super) started: mpsc::Sender<Result<Started, ClientError>>,
}

/// The network side on a current-thread runtime of its own (the calling thread's).
pub(super) fn network_thread(start: NetStart) {
    match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(runtime) => runtime.block_on(network_task(start, None)),
        Err(e) => {
            let _ = start.started.send(Err(ClientError::Runtime(e.to_string())));
        }
    }
}

/// The network side as a task, on `endpoint` (shared with other clients) or, without one, on an endpoint of
/// its own; runs until the client stops.
pub(super) async fn network_task(start: NetStart, endpoint: Option<Endpoint>) {
    let NetStart { config, real, addresses, shared, net, started } = start;
    let endpoint = match endpoint {
        Some(quic) => ClientEndpoint { quic, linger: None },
        None => {
            let opts = EndpointOptions { link: config.link.clone(), ..EndpointOptions::default() };
            let flight = config.link.as_ref().map_or(Duration::ZERO, LinkConfig::longest_flight);
            match client_endpoint(&config.trust, &opts) {
                Ok(quic) => ClientEndpoint { quic, linger: Some(CLOSE_LINGER.max(flight + CLOSE_QUEUEING)) },
                Err(e) => {
                    let _ = started.send(Err(e.into()));
                    return;
                }
            }
        }
    };
    let mut chosen = None;
    let spec = real.as_ref().map(OpenedDevice::spec);
    let mut first = Err(ConnectError::Declined("no server address".into()));
    for (i, address) in addresses.iter().enumerate() {
        first = open_session(&endpoint.quic, *address, &config, spec.as_ref(), None, &mut chosen).await.map(|s| (i, s));
        match &first {
            Ok(_) | Err(ConnectError::Refused(_) | ConnectError::Declined(_)) => break,
            Err(e) => tracing::warn!(server = %address, error = %e, "cannot connect; trying the next server"),
        }
    }
    let (current, session) = match first {
        Ok(s) => s,
        Err(source) => {
            // The handshake closed the connection; the server hears of it before the caller (who may exit
            // at once) hears why.
            endpoint.linger().await;
            let _ = started.send(Err(ClientError::Connect { server: config.server.clone(), source }));
            return;
        }
    };
    // The session opened, so the chooser ran.
    let Some(device) = chosen else { return };
    let config = ClientConfig { device: Some(device), op: Some(session.welcome.scene.op_name.clone()), ..config };
    match session.welcome.scene.kind {
        SceneKind::Planar => {
            let dialer = Dialer { config, model: None, addresses, current, endpoint };
            run::<Planar>(dialer, real, session, shared, net, started).await
        }
        SceneKind::Spatial => {
            let dialer = Dialer { config, model: None, addresses, current, endpoint };
            run::<Spatial>(dialer, real, session, shared, net, started).await
        }
    }
}

fn hello(config: &ClientConfig) -> Hello {
    Hello {
        version: PROTOCOL_VERSION,
        token: config.token.clone(),
        client_name: config.client_name.clone(),
        role: Role::Manipulator,
        room: config.room.clone(),
    }
}

/// The join for the scene the server described: the operational point asked for (or the scene's first)
/// and the device asked for (or the scene's default; `real`, an opened vendor device's spec, before either),
/// described in the scene's space. A device that cannot serve the scene's space is an error naming both.
pub fn choose(
    config: &ClientConfig,
    scene: &SceneInfo,
    real: Option<&RealSpec>,
) -> Result<(Join, DevicePreset), String> {
    let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(scene.kind));
    let spec = match real {
        Some(real) => real.device_spec(scene.kind),
        None => {
            device.spec(scene.kind).map_err(|e| format!("{e} (scene {} is {})", scene.name, kind_axes(scene.kind)))?
        }
    };
    let op = match &config.op {
        Some(op) => op.clone(),
        None => scene
            .ops
            .get(config.op_turn % scene.ops.len().max(1))
            .cloned()
            .ok_or_else(|| format!("scene {} has no operational point", scene.name))?,
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
    real: Option<&RealSpec>,
    offer: Option<&RoomState>,
    chosen: &mut Option<DevicePreset>,
) -> Result<ConnectedSession, ConnectError> {
    connect_resuming(endpoint, address, &config.server_name, &hello(config), offer, |scene| {
        let (join, device) = choose(config, scene, real)?;
        *chosen = Some(device);
        Ok(join)
    })
    .await
}

fn core_for<S: Space>(
    config: &ClientConfig,
    real: Option<&RealSpec>,
    welcome: &Welcome,
) -> Result<Box<HapticCore<S>>, ClientError> {
    let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND));
    let spec = match real {
        Some(real) => real.device_spec(S::KIND),
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
    Uplink::at_rest(0, S::DIM, kinloop_linkage::math::space::OpPose::<S>::wire_len())
}

/// The session's haptic side: the rig and core, the rings, the recorder, the uplink sender and the haptic
/// loop are started, the caller told, and the session served (and re-opened when lost) until the client stops.
async fn run<S: Space>(
    mut dialer: Dialer,
    real: Option<OpenedDevice>,
    session: ConnectedSession,
    shared: Arc<LoopShared>,
    net: Arc<NetShared>,
    started: mpsc::Sender<Result<Started, ClientError>>,
) {
    dialer.model = real.as_ref().map(OpenedDevice::spec);
    let model = dialer.model.clone();
    let (config, endpoint) = (&dialer.config, &dialer.endpoint);
    let (rig, core) = match rig_and_core::<S>(config, real, &session.welcome) {
        Ok(parts) => parts,
        Err(e) => {
            abandon(endpoint, &session.connection, b"client cannot render").await;
            let _ = started.send(Err(e));
            return;
        }
    };
    let gains = core.gains().device.clone();
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
    let records = config.record.as_ref().map(|path| {
        let (writer, records) = spawn_recorder::<S>(path.clone(), shared.clone());
        helpers.push(writer);
        records
    });
    let sender_slot: Arc<Mutex<Option<DatagramSender>>> =
        Arc::new(Mutex::new(Some(DatagramSender::new(session.connection.clone()))));
    let outlet = Outlet {
        uplinks: uplinks_rx,
        free: free_tx,
        sender: sender_slot.clone(),
        shared: shared.clone(),
        net: net.clone(),
    };
    let on_shared_clock = matches!(rig, Haptic::Polled(_)) && config.clock.is_some();
    let uplink_thread = match start_uplink_sender(config, on_shared_clock, outlet) {
        Ok(thread) => thread,
        Err(e) => {
            abandon(endpoint, &session.connection, b"client cannot start").await;
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
        uplink_sender: uplink_thread.as_ref().map(|t| t.thread().clone()),
    };
    let settings = LoopSettings {
        rate_hz: config.rate_hz,
        duration: config.duration,
        realtime_priority: config.realtime_priority,
        busy_wait: config.busy_wait,
        report_every: (config.rate_hz * config.report_interval.as_secs_f64()).max(1.0) as u64,
    };
    let loop_shared = shared.clone();
    let loop_end = match (rig, &config.clock) {
        (Haptic::Polled(device), Some(clock)) => clock
            .join(LoopBody::new(device, core, loop_rings, loop_shared, settings))
            .map(LoopEnd::Shared)
            .ok_or_else(|| std::io::Error::other("the shared haptic clock has stopped")),
        (rig, _) => std::thread::Builder::new()
            .name("kinloop-haptic".into())
            .spawn(move || match rig {
                Haptic::Polled(device) => rt_loop::run(device, core, loop_rings, loop_shared, settings),
                Haptic::Clocked(opened) => device_clock::run(opened, core, loop_rings, loop_shared, settings),
            })
            .map(LoopEnd::Own),
    };
    let loop_thread = match loop_end {
        Ok(t) => t,
        Err(e) => {
            abandon(endpoint, &session.connection, b"client cannot start").await;
            let _ = started.send(Err(ClientError::Runtime(e.to_string())));
            return;
        }
    };
    helpers.extend(uplink_thread);
    let welcome = session.welcome.clone();
    let device = match &model {
        Some(model) => model.label(),
        None => config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND)).name().to_owned(),
    };
    let session = Session::adopt(session);
    let _ = started.send(Ok(Started { loop_thread, helpers, welcome, device, gains }));
    let mut rings = NetRings {
        snapshots: snapshots_tx,
        spent_snapshots: spent_snapshots_rx,
        cores: cores_tx,
        spent_cores: spent_cores_rx,
        reports: reports_rx,
    };
    keep_connected(&mut dialer, session, &mut rings, &sender_slot, &shared, &net).await;
    drain_reports(&mut rings, &net);
    // Give the close frame a moment to leave.
    dialer.endpoint.linger().await;
}

/// Who sends the uplinks the loop pushes: a loop on the shared clock has them sent by the shared network's
/// pump, which the clock wakes once a round (no thread); any other loop unparks an uplink thread of its
/// client's own after each push (returned).
fn start_uplink_sender(
    config: &ClientConfig,
    on_shared_clock: bool,
    outlet: Outlet,
) -> std::io::Result<Option<JoinHandle<()>>> {
    if let Some(network) = config.network.as_ref().filter(|_| on_shared_clock) {
        network.pump_for(outlet);
        return Ok(None);
    }
    let handle = tokio::runtime::Handle::current();
    let thread = std::thread::Builder::new().name("kinloop-uplink".into()).spawn(move || {
        let _guard = handle.enter();
        send_uplinks(outlet)
    })?;
    Ok(Some(thread))
}

/// A session's device: polled by kinloop's loop, or clocked by the vendor's servo thread.
enum Haptic<S: Space> {
    Polled(Box<dyn HapticDevice<S>>),
    Clocked(OpenedHd),
}

/// A session's device (whichever kind) and its haptic core.
type DeviceAndCore<S> = (Haptic<S>, Box<HapticCore<S>>);

/// The device (an opened DHD device, or the simulated rig whose hand grasps the handle where the linkage is)
/// and the core for a session.
fn rig_and_core<S: Space>(
    config: &ClientConfig,
    real: Option<OpenedDevice>,
    welcome: &Welcome,
) -> Result<DeviceAndCore<S>, ClientError> {
    let core = core_for::<S>(config, real.as_ref().map(OpenedDevice::spec).as_ref(), welcome)?;
    match real {
        Some(OpenedDevice::Dhd(dhd)) => return Ok((Haptic::Polled(Box::new(dhd.into_device::<S>())), core)),
        Some(OpenedDevice::Hd(hd)) => return Ok((Haptic::Clocked(hd), core)),
        None => {}
    }
    let op = S::Point::from_slice(&welcome.op.position);
    let device = config.device.unwrap_or_else(|| DevicePreset::for_kind(S::KIND)).build_at::<S>(core.home(&op))?;
    let user = config.user.build::<S>(&UserContext::from_welcome(welcome))?;
    Ok((Haptic::Polled(Box::new(SimulatedRig::new(device, user))), core))
}

/// The `--record` writer thread and the ring the loop feeds it through; it stops when the loop stops, after
/// draining the ring.
fn spawn_recorder<S: Space>(path: PathBuf, shared: Arc<LoopShared>) -> (JoinHandle<()>, rtrb::Producer<TickRecord>) {
    let (tx, rx) = rtrb::RingBuffer::new(RECORD_RING);
    let stop_flag = Arc::new(AtomicBool::new(false));
    let writer_stop = stop_flag.clone();
    let writer = std::thread::spawn(move || {
        let watcher = std::thread::spawn(move || {
            while !shared.stop.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(20));
            }
            writer_stop.store(true, Ordering::Release);
        });
        match record::write_records(&path, S::KIND, rx, stop_flag) {
            Ok(rows) => tracing::info!(rows, file = %path.display(), "recording written"),
            Err(e) => tracing::error!(error = %e, file = %path.display(), "recording failed"),
        }
        let _ = watcher.join();
    });
    (writer, tx)
}

/// What re-opens a lost session: the client's configuration, the room's server addresses (the one of the
/// current session at `current`) and the endpoint.
struct Dialer {
    config: ClientConfig,
    /// An opened vendor device's spec: what every re-join describes.
    model: Option<RealSpec>,
    addresses: Vec<SocketAddr>,
    current: usize,
    endpoint: ClientEndpoint,
}

impl Dialer {
    /// One round over the room's servers in order, starting after the one lost (which is tried last), each
    /// offered the newest signed room state; the first session opened, or the last error with every
    /// server tried. A refusal or an untrusted certificate ends the round (it is final).
    async fn dial(&mut self, net: &NetShared) -> Result<ConnectedSession, ConnectError> {
        let offer = net.room_state.lock().ok().and_then(|s| s.clone());
        let count = self.addresses.len();
        let mut last = Err(ConnectError::Timeout);
        for step in 1..=count {
            let index = (self.current + step) % count;
            let address = self.addresses[index];
            let mut chosen = None;
            let attempt = open_session(
                &self.endpoint.quic,
                address,
                &self.config,
                self.model.as_ref(),
                offer.as_ref(),
                &mut chosen,
            );
            // A dead server never answers: with others to try, each gets a short while.
            let attempt = if count > 1 {
                tokio::time::timeout(DIAL_PATIENCE, attempt).await.unwrap_or(Err(ConnectError::Timeout))
            } else {
                attempt.await
            };
            match attempt {
                Ok(session) => {
                    self.current = index;
                    note_resume(&session, address, net);
                    return Ok(session);
                }
                Err(
                    e @ (ConnectError::Refused(_) | ConnectError::UntrustedCertificate { .. } | ConnectError::Alpn),
                ) => return Err(e),
                Err(e) => {
                    tracing::warn!(server = %address, error = %e, "no session there");
                    last = Err(e);
                }
            }
        }
        last
    }
}

/// How long a reconnecting client with several servers waits for each to answer.
const DIAL_PATIENCE: Duration = Duration::from_millis(1500);

/// Says and counts what the server did with the offered room state.
fn note_resume(session: &ConnectedSession, address: SocketAddr, net: &NetShared) {
    match &session.resume {
        Some(ResumeAnswer::Resumed { ve_step }) => {
            net.resumes.fetch_add(1, Ordering::Relaxed);
            tracing::info!(server = %address, ve_step, "the server resumed the room from the state this client kept");
        }
        Some(ResumeAnswer::Refused(why)) => {
            net.resumes_refused.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(server = %address, %why, "the server refused the room state this client kept");
        }
        None => {}
    }
}

/// Serves `session` and, each time it is lost, opens a new one and hands the loop a new core for it, until
/// the client stops or the new session cannot be rendered.
async fn keep_connected<S: Space>(
    dialer: &mut Dialer,
    mut session: Session,
    rings: &mut NetRings<S>,
    sender_slot: &Mutex<Option<DatagramSender>>,
    shared: &LoopShared,
    net: &NetShared,
) {
    let mut backoff = Duration::from_millis(100);
    loop {
        let ended = serve_session(&mut session, rings, shared, net).await;
        net.quic.session_ended(&session.connection);
        if let Ok(mut slot) = sender_slot.lock() {
            *slot = None;
        }
        if shared.stop.load(Ordering::Relaxed) {
            leave(&mut session).await;
            break;
        }
        shared.between_servers.store(true, Ordering::Relaxed);
        // Closed at once, so that a server draining its clients sees this one gone.
        session.connection.close(kinloop_protocol::quic::close_codes::NORMAL, b"moving on");
        tracing::warn!(why = %ended, "session lost; the force fades out while reconnecting");
        let Some(next) = reconnect(dialer, rings, shared, net, &mut backoff).await else { break };
        if next.welcome.scene.kind != S::KIND {
            tracing::error!("the server now runs a scene of another space; stopping");
            shared.stop.store(true, Ordering::Relaxed);
            break;
        }
        match core_for::<S>(&dialer.config, dialer.model.as_ref(), &next.welcome) {
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
}

/// Reconnects with exponential backoff until stopped; refusals and certificate problems are final (`None`:
/// the client is stopped and the reason kept as fatal).
async fn reconnect<S: Space>(
    dialer: &mut Dialer,
    rings: &mut NetRings<S>,
    shared: &LoopShared,
    net: &NetShared,
    backoff: &mut Duration,
) -> Option<ConnectedSession> {
    loop {
        if shared.stop.load(Ordering::Relaxed) {
            return None;
        }
        drain_reports(rings, net);
        tokio::time::sleep(*backoff).await;
        *backoff = (*backoff * 2).min(Duration::from_secs(5));
        match dialer.dial(net).await {
            Ok(s) => return Some(s),
            Err(e @ (ConnectError::Refused(_) | ConnectError::UntrustedCertificate { .. } | ConnectError::Alpn)) => {
                tracing::error!(error = %e, "reconnection refused; giving up");
                if let Ok(mut f) = net.fatal.lock() {
                    *f = Some(e.to_string());
                }
                shared.stop.store(true, Ordering::Relaxed);
                return None;
            }
            Err(e) => {
                let looked: Vec<String> = dialer.addresses.iter().map(|a| a.to_string()).collect();
                tracing::warn!(error = %e, looked = %looked.join(", "), retry_in = ?backoff, "reconnection failed; force stays at zero")
            }
        }
    }
}
