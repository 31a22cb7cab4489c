//! What a client is asked to do ([`ClientConfig`]) and what can stop it ([`ClientError`]).

use std::path::PathBuf;
use std::time::Duration;

use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::{ConnectError, EndpointError, Trust};
use kinloop_protocol::MappingRequest;

use crate::core::{ConstraintMode, CoreError, GainChoice, ModelForm, UplinkDeadband};
use crate::device::dhd::DhdError;
use crate::device::hd::HdError;
use crate::device::presets::SimulatedDeviceBuildError;
use crate::device::{DevicePreset, DhdRequest, HdRequest};
use crate::user::{UserError, UserSpec};

/// With fallback servers, a session whose server sent nothing for this long is lost and the next server is
/// tried: longer than any scheduling stall of a live server, short enough to move within 2 s of a crash.
pub const SILENT_SERVER: Duration = Duration::from_millis(600);

/// Everything a client needs.
#[derive(Clone, Debug)]
pub struct ClientConfig {
    /// `host:port` of the server.
    pub server: String,
    /// More servers of the same room (`host:port`), tried in order after `server` when a session is lost
    /// (and when the first connection fails); with any, a server silent for [`SILENT_SERVER`] is lost.
    pub fallback_servers: Vec<String>,
    /// Name the server's certificate must carry (with `Trust::CaFile`).
    pub server_name: String,
    /// Shared secret.
    pub token: String,
    /// The room to join on a server of many rooms (`--room`); empty: the server's default room.
    pub room: String,
    /// How the server is trusted.
    pub trust: Trust,
    /// Operational point to hold; `None`: the scene's operational points taken in turn, this one's turn
    /// being `op_turn` (0: the first).
    pub op: Option<String>,
    /// With `op` unset, which of the scene's operational points (modulo their count) to hold: clients
    /// started together spread over them.
    pub op_turn: usize,
    /// The simulated device; `None`: the one for the scene's space ([`DevicePreset::for_kind`]).
    pub device: Option<DevicePreset>,
    /// A Force Dimension device through the DHD SDK instead of the simulated one (`--device dhd`).
    pub dhd: Option<DhdRequest>,
    /// A 3D Systems device through OpenHaptics instead of the simulated one (`--device hd`): the vendor's
    /// servo thread then runs the loop (`device_clock`).
    pub hd: Option<HdRequest>,
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
    /// Step the haptic loop on this clock, shared with other clients of the process, instead of a thread
    /// of its own (`rt_loop`); `realtime_priority` and `busy_wait` are then the clock's. A device whose
    /// vendor owns the clock (`hd`) keeps its own.
    pub clock: Option<super::shared_clock::SharedClock>,
    /// Run the network side on this runtime and endpoint, shared with other clients of the process, instead
    /// of a runtime thread (and an uplink thread) of its own; with `clock` too, the uplinks leave through
    /// the network's pump, which the clock wakes once a round.
    pub network: Option<super::shared_network::SharedNetwork>,
}

impl ClientConfig {
    /// Defaults: the scene's first operational point, the device for the scene's space, a relaxed hand
    /// touring the reach, the server's mapping, 1 kHz, stiffness mode, reduced local model, designed gains.
    pub fn new(server: impl Into<String>, trust: Trust) -> Self {
        ClientConfig {
            server: server.into(),
            fallback_servers: Vec::new(),
            server_name: "localhost".into(),
            token: String::new(),
            room: String::new(),
            trust,
            op: None,
            op_turn: 0,
            device: None,
            dhd: None,
            hd: None,
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
            clock: None,
            network: None,
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
    /// The HD library or device cannot be used.
    #[error(transparent)]
    Hd(#[from] HdError),
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
