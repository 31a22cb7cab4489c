//! The view: a web page that draws the shared linkage live and lets a visitor grab it with the mouse
//! (`kinloop-server --view ADDR`), or replays a recording (`kinloop view FILE.csv`).
//!
//! ```text
//!  VE thread                         tokio (the server's runtime)
//!  tap (every ~16 ticks) ─ rtrb<f64> ─► hub: forward kinematics on its own Model + Data, the users'
//!        + Notify                        names/devices/RTT from the sessions ─► JSON text, once per frame
//!                                          │ watch (latest wins)
//!                                          ▼
//!                       page socket tasks (one per browser): writer sends the newest frame; reader
//!                       takes auth / grab / drag / release / seek
//!                                          │ grab: Command::Join, then UplinkSamples
//!  core ◄──── the same command and uplink rings the QUIC sessions use ◄────┘ (driven by the grabbing
//!                                                                            user's own snapshots)
//! ```
//! The VE thread only writes into a ring it never waits on and wakes the hub; many pages cost it
//! nothing more (each page reads the one shared frame). See [`messages`] for the page's protocol,
//! [`grab`] for what a mouse grip sends the VE, [`replay`] for recordings.
//!
//! **Access.** With a token file, a page must give a token: `observer` tokens watch, `manipulator` tokens
//! (and tokens without a role) may also grab; a wrong token gets a refusal and nothing of the scene.
//! Without a token file the view is open to watch, and grabbing needs [`ViewConfig::grab_without_token`]
//! (`--view-grab`). A browser's `Origin` must match the address it asked for, so another web site cannot
//! drive the view from a visitor's browser.

pub mod compose;
pub mod draw;
pub mod grab;
mod http;
mod hub;
pub mod messages;
pub mod replay;
pub mod sample;
pub mod site;
mod socket;
pub mod tap;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use kinloop_linkage::{error::SceneError, model::scene::Scene};
use kinloop_protocol::SessionShape;
use serde::Serialize;
use tokio::sync::{watch, Notify};
use tokio::task::JoinHandle;

use crate::access::Access;
use crate::gateway::Gateway;
use compose::UserInfo;
use draw::SceneInfo;
pub use tap::ViewTap;

/// Frames per second a live view aims for by default.
pub const DEFAULT_FRAME_RATE_HZ: f64 = 60.0;
/// Longest text message a page may send (bytes); longer ones get an error and are not read.
pub const MAX_MESSAGE_BYTES: usize = 4096;
/// Longest message the WebSocket layer buffers at all; beyond it the socket is closed.
pub const TRANSPORT_MAX_BYTES: usize = 64 * 1024;
/// Drag and seek messages a page may send per second (a token bucket); more are dropped and counted.
pub const MAX_EVENTS_PER_S: f64 = 100.0;
/// Frames the tap's ring holds.
const TAP_FRAMES: usize = 8;

/// How the live view is served.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewConfig {
    /// TCP address of the page (HTTP and WebSocket).
    pub listen: SocketAddr,
    /// Without a token file, let any page grab (otherwise pages only watch).
    pub grab_without_token: bool,
    /// Frames per second.
    pub frame_rate_hz: f64,
    /// Farthest a drag target may lie from its operational point (m).
    pub grab_reach_m: f64,
}

impl ViewConfig {
    /// A view on `listen`: 60 frames/s, watch-only without tokens, reach [`grab::DEFAULT_REACH_M`].
    pub fn new(listen: SocketAddr) -> Self {
        ViewConfig {
            listen,
            grab_without_token: false,
            frame_rate_hz: DEFAULT_FRAME_RATE_HZ,
            grab_reach_m: grab::DEFAULT_REACH_M,
        }
    }
}

/// Why the view could not start.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The scene does not compile.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The address could not be bound.
    #[error("cannot listen for the view on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// A recording could not be read.
    #[error(transparent)]
    Replay(#[from] replay::ReplayError),
    /// Started outside a tokio runtime.
    #[error("the view must be started inside a tokio runtime")]
    NoRuntime,
    /// A bad setting.
    #[error("{0}")]
    Config(String),
}

/// What the view counted (in the server's `--json` statistics under `view`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ViewStats {
    /// Pages connected now.
    pub pages_open: u64,
    /// Pages that opened a socket.
    pub pages_total: u64,
    /// Pages refused (wrong token, bad origin, no auth in time).
    pub pages_refused: u64,
    /// Frames the hub built.
    pub frames_built: u64,
    /// Frames sent, over all pages.
    pub frames_sent: u64,
    /// Messages that did not parse or made no sense (answered with an error).
    pub messages_malformed: u64,
    /// Messages longer than [`MAX_MESSAGE_BYTES`] (answered with an error) or than the transport takes
    /// (socket closed).
    pub messages_oversize: u64,
    /// Drag and seek events used.
    pub events_used: u64,
    /// Drag and seek events over [`MAX_EVENTS_PER_S`], dropped.
    pub events_dropped: u64,
    /// Grabs naming an operational point the scene does not have.
    pub unknown_ops: u64,
    /// Grabs the VE admitted.
    pub grabs: u64,
    /// Grabs refused (role, mode, or the VE).
    pub grabs_refused: u64,
    /// Uplinks a grab could not hand to the VE (its ring was full).
    pub uplinks_dropped: u64,
    /// Replies dropped because a page read too slowly.
    pub replies_dropped: u64,
}

/// Counter names, indices into [`Counters`].
#[derive(Clone, Copy, Debug)]
pub(crate) enum Counter {
    PagesOpen,
    PagesTotal,
    PagesRefused,
    FramesBuilt,
    FramesSent,
    Malformed,
    Oversize,
    EventsUsed,
    EventsDropped,
    UnknownOps,
    Grabs,
    GrabsRefused,
    UplinksDropped,
    RepliesDropped,
}

/// The view's counters, shared by the hub, every page task and the server's statistics.
#[derive(Debug, Default)]
pub struct Counters([AtomicU64; 14]);

impl Counters {
    pub(crate) fn add(&self, c: Counter, n: u64) {
        self.0[c as usize].fetch_add(n, Ordering::Relaxed);
    }

    pub(crate) fn bump(&self, c: Counter) {
        self.add(c, 1);
    }

    pub(crate) fn drop_one(&self, c: Counter) {
        self.0[c as usize].fetch_sub(1, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> ViewStats {
        let get = |c: Counter| self.0[c as usize].load(Ordering::Relaxed);
        ViewStats {
            pages_open: get(Counter::PagesOpen),
            pages_total: get(Counter::PagesTotal),
            pages_refused: get(Counter::PagesRefused),
            frames_built: get(Counter::FramesBuilt),
            frames_sent: get(Counter::FramesSent),
            messages_malformed: get(Counter::Malformed),
            messages_oversize: get(Counter::Oversize),
            events_used: get(Counter::EventsUsed),
            events_dropped: get(Counter::EventsDropped),
            unknown_ops: get(Counter::UnknownOps),
            grabs: get(Counter::Grabs),
            grabs_refused: get(Counter::GrabsRefused),
            uplinks_dropped: get(Counter::UplinksDropped),
            replies_dropped: get(Counter::RepliesDropped),
        }
    }
}

/// A frame ready to send: the JSON text every page receives.
#[derive(Clone, Debug)]
pub(crate) struct FrameText {
    pub text: axum::extract::ws::Utf8Bytes,
}

/// Where frames come from.
pub(crate) enum Source {
    /// A running VE.
    Live {
        /// The hub's newest frame.
        frames: watch::Receiver<Option<FrameText>>,
        /// The server, for grabs (none for `--synthetic-users`, which has no command ring to share).
        server: Option<Arc<Gateway>>,
        /// Dimensions of the VE's sessions (to decode a grab's snapshots).
        shape: SessionShape,
    },
    /// A recording.
    Replay(Mutex<replay::Replay>),
}

/// State every page task shares.
pub(crate) struct ViewShared {
    pub config: ViewConfig,
    pub access: Access,
    pub info: SceneInfo,
    pub source: Source,
    pub counters: Arc<Counters>,
    /// Pages grabbing now, for the panel.
    pub browsers: Mutex<Vec<UserInfo>>,
    pub shutdown: watch::Sender<bool>,
}

/// A running view of one room (or one recording) on a [`ViewSite`].
pub struct ViewHandle {
    addr: SocketAddr,
    shared: Arc<ViewShared>,
    /// The room's name on the site.
    name: String,
    site: Arc<site::Site>,
    /// The site, when this view started it for itself (a recording, `--synthetic-users`).
    own_site: Option<ViewSite>,
    hub: Option<JoinHandle<()>>,
}

impl ViewHandle {
    /// Where the page is served.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The live counters.
    pub fn counters(&self) -> Arc<Counters> {
        self.shared.counters.clone()
    }

    /// Counters so far.
    pub fn stats(&self) -> ViewStats {
        self.shared.counters.snapshot()
    }

    /// Closes every page of the room (grabs are released) and takes it off the site; stops the site if
    /// this view started it.
    pub async fn shutdown(mut self) -> ViewStats {
        self.shared.shutdown.send_replace(true);
        self.site.remove(&self.name);
        if let Some(site) = self.own_site.take() {
            site.shutdown().await;
        }
        if let Some(hub) = &self.hub {
            hub.abort();
        }
        self.shared.counters.snapshot()
    }
}

impl Drop for ViewHandle {
    fn drop(&mut self) {
        self.shared.shutdown.send_replace(true);
        self.site.remove(&self.name);
        if let Some(hub) = &self.hub {
            hub.abort();
        }
    }
}

/// A running site: the HTTP server on the view's address.
pub struct ViewSite {
    addr: SocketAddr,
    pub(crate) site: Arc<site::Site>,
    serve: Option<JoinHandle<()>>,
}

impl ViewSite {
    /// Binds `listen` and serves the rooms added to it. Must be called inside a tokio runtime.
    pub fn start(listen: SocketAddr) -> Result<ViewSite, ViewError> {
        tokio::runtime::Handle::try_current().map_err(|_| ViewError::NoRuntime)?;
        let site = Arc::new(site::Site::default());
        let (addr, serve) = http::serve(listen, site.clone())?;
        Ok(ViewSite { addr, site, serve: Some(serve) })
    }

    /// Where the pages are served.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving (after the rooms' pages have closed, at most a few seconds).
    pub async fn shutdown(mut self) {
        self.site.shutdown.send_replace(true);
        if let Some(mut serve) = self.serve.take() {
            if tokio::time::timeout(Duration::from_secs(3), &mut serve).await.is_err() {
                serve.abort();
            }
        }
    }
}

impl Drop for ViewSite {
    fn drop(&mut self) {
        self.site.shutdown.send_replace(true);
        if let Some(serve) = &self.serve {
            serve.abort();
        }
    }
}

/// The reading end of a [`ViewTap`].
pub struct TapReader {
    ring: rtrb::Consumer<f64>,
    notify: Arc<Notify>,
}

/// A tap for the VE thread and its reader for [`start_live`], for a scene with `n` coordinates: one frame
/// every `ve_rate_hz / frame_rate_hz` loop iterations.
pub fn tap<S: kinloop_linkage::math::space::Space>(
    n: usize,
    max_users: usize,
    ve_rate_hz: f64,
    frame_rate_hz: f64,
) -> (ViewTap, TapReader) {
    let frame = 1 + tap::frame_len::<S>(n, 2 * max_users);
    let (tx, rx) = rtrb::RingBuffer::new(TAP_FRAMES * frame);
    let notify = Arc::new(Notify::new());
    let every = (ve_rate_hz / frame_rate_hz.max(1.0)).round().max(1.0) as u64;
    (ViewTap::new(tx, notify.clone(), every, max_users), TapReader { ring: rx, notify })
}

/// [`tap`] for a scene of either space (compiles it to count its coordinates).
pub fn tap_for_scene(
    scene: &Scene,
    scene_label: &str,
    max_users: usize,
    ve_rate_hz: f64,
    config: &ViewConfig,
) -> Result<(ViewTap, TapReader), ViewError> {
    use kinloop_linkage::{math::space::Planar, math::space::SceneKind, math::space::Spatial, model::Model};
    Ok(match scene.kind {
        SceneKind::Planar => {
            let n = Model::<Planar>::compile(scene, scene_label)?.nq();
            tap::<Planar>(n, max_users, ve_rate_hz, config.frame_rate_hz)
        }
        SceneKind::Spatial => {
            let n = Model::<Spatial>::compile(scene, scene_label)?.nq();
            tap::<Spatial>(n, max_users, ve_rate_hz, config.frame_rate_hz)
        }
    })
}

/// What a live view needs besides its configuration.
pub struct LiveSource {
    /// The scene (the view compiles its own model).
    pub scene: Scene,
    /// Its label.
    pub scene_label: String,
    /// The tap's reading end.
    pub reader: TapReader,
    /// Who may watch and grab.
    pub access: Access,
}

/// The name a view's only room has on a site of its own.
const ONLY_ROOM: &str = "default";

/// Starts a live view on a site of its own with no server to grab through (`--synthetic-users`): pages
/// watch.
pub fn start_live(config: &ViewConfig, source: LiveSource) -> Result<ViewHandle, ViewError> {
    check(config)?;
    let site = ViewSite::start(config.listen)?;
    let mut view = start_room_view(&site, ONLY_ROOM, config, source, None)?;
    view.own_site = Some(site);
    Ok(view)
}

/// Starts the live view of room `name` on `site`; `server` makes grabs possible.
pub(crate) fn start_room_view(
    site: &ViewSite,
    name: &str,
    config: &ViewConfig,
    source: LiveSource,
    server: Option<Arc<Gateway>>,
) -> Result<ViewHandle, ViewError> {
    tokio::runtime::Handle::try_current().map_err(|_| ViewError::NoRuntime)?;
    check(config)?;
    let geometry = draw::geometry(&source.scene, &source.scene_label)?;
    let kind = source.scene.kind;
    let shape = SessionShape { kind, n: geometry.info().n, nq: geometry.info().n, m: 0 };
    let shape = server.as_ref().map_or(shape, |s| s.shape);
    let (frames_tx, frames_rx) = watch::channel(None);
    let shared = Arc::new(ViewShared {
        config: config.clone(),
        access: source.access,
        info: geometry.info().clone(),
        source: Source::Live { frames: frames_rx, server: server.clone(), shape },
        counters: Arc::default(),
        browsers: Mutex::new(Vec::new()),
        shutdown: watch::channel(false).0,
    });
    let hub = tokio::spawn(hub::run(
        hub::Hub { geometry, reader: source.reader, kind, frames: frames_tx, server },
        shared.clone(),
    ));
    site.site.add(name, shared.clone());
    let addr = site.local_addr();
    tracing::info!(%addr, room = name, "view: http://{addr}/room/{name}");
    let (name, site) = (name.to_owned(), site.site.clone());
    Ok(ViewHandle { addr, shared, name, site, own_site: None, hub: Some(hub) })
}

/// Serves a recording on `config.listen` (`kinloop view`).
pub fn start_replay(config: &ViewConfig, access: Access, replay: replay::Replay) -> Result<ViewHandle, ViewError> {
    tokio::runtime::Handle::try_current().map_err(|_| ViewError::NoRuntime)?;
    check(config)?;
    let shared = Arc::new(ViewShared {
        config: config.clone(),
        access,
        info: replay.scene_info().clone(),
        source: Source::Replay(Mutex::new(replay)),
        counters: Arc::default(),
        browsers: Mutex::new(Vec::new()),
        shutdown: watch::channel(false).0,
    });
    let own = ViewSite::start(config.listen)?;
    own.site.add(ONLY_ROOM, shared.clone());
    let addr = own.local_addr();
    tracing::info!(%addr, "replay: http://{addr}/");
    let site = own.site.clone();
    Ok(ViewHandle { addr, shared, name: ONLY_ROOM.into(), site, own_site: Some(own), hub: None })
}

fn check(config: &ViewConfig) -> Result<(), ViewError> {
    if !(config.frame_rate_hz.is_finite() && (1.0..=240.0).contains(&config.frame_rate_hz)) {
        return Err(ViewError::Config(format!("view frame rate {} Hz: between 1 and 240", config.frame_rate_hz)));
    }
    if !(config.grab_reach_m.is_finite() && config.grab_reach_m > 0.0 && config.grab_reach_m <= 0.5) {
        return Err(ViewError::Config(format!("grab reach {} m: more than 0 and at most 0.5 m", config.grab_reach_m)));
    }
    Ok(())
}

/// Used by the page tasks: a short, single-line version of an error for the page (serde's messages may
/// quote the input).
pub(crate) fn short(message: impl std::fmt::Display) -> String {
    let mut text: String = message.to_string().chars().filter(|c| !c.is_control()).take(200).collect();
    if text.len() >= 200 {
        text.push('…');
    }
    text
}
