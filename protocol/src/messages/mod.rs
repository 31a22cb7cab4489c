//! Every message kinloop puts on the wire.
//!
//! Two classes travel differently:
//! - [`Control`] messages go on one reliable bidirectional QUIC stream per session, as length-prefixed frames
//!   (handshake, leave, errors, ping/pong);
//! - [`Datagram`]s ([`Snapshot`] server → client, [`Uplink`] client → server) go as unreliable QUIC datagrams,
//!   latest wins; an oversize snapshot travels on a unidirectional stream instead (see `quic::datagrams`).
//!
//! Conventions (see `docs/architecture.md`): SI units; operational-space vectors are linear part first, planar
//! `(x, y, θ)` and spatial `(v, ω)`; poses are `[x, y, θ]` planar and `[x, y, z, qw, qx, qy, qz]` spatial;
//! matrices are column-major unless a field says otherwise; symmetric matrices send their upper triangle
//! row-major. Lengths are carried by `Vec`s and checked against the session's [`SessionShape`] by the codec,
//! so one set of types serves planar and spatial scenes.
//!
//! Wire stability: the field order of these types *is* the format (bincode, no field names). Every wire
//! change lives here: the types in this file and their golden bytes in `golden.rs` (written by hand from the
//! format, checked by its tests). **One version per landing:** a branch that changes the wire (a field added,
//! removed or reordered, a message or variant added) bumps [`PROTOCOL_VERSION`] by one, once, however many
//! changes it carries, and rewrites the golden bytes it changes; what changed in each version is said by the
//! commit that bumped it, not here.
//!
//! [`SessionShape`]: crate::SessionShape

use std::fmt;

pub use kinloop_linkage::algorithms::op_path::PathShape;
use kinloop_linkage::algorithms::reach::OpReach;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use serde::{Deserialize, Serialize};

use crate::shape::{SceneKind, SessionShape};

mod admin;
mod refusal;
mod room;
pub use admin::{AdminAnswer, AdminCommand, AdminRequest, RoomSummary};
pub use refusal::{RefusalReason, Refused};
pub use room::{ResumeAnswer, ResumeRefusal, RoomState};

/// Version carried in [`Hello::version`]; a server refuses a client of another version. Bumped by one per
/// landing that changes the wire (see the module documentation).
pub const PROTOCOL_VERSION: u16 = 10;

/// Most poses of [`OpSummary::path`]: a survey's longer path is sent every other pose (or fewer). 512 spatial
/// poses with their accelerations are 33 kB, within a control frame with the rest of the welcome.
pub const MAX_PATH_POSES: usize = 512;

/// TLS application protocol name both sides offer; a peer offering anything else fails the QUIC handshake.
pub const ALPN: &[u8] = b"kinloop/1";

/// What a client does in the VE.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Role {
    /// Holds an operational point and pushes on the linkage.
    Manipulator,
    /// Receives snapshots, applies no wrench.
    Observer,
}

/// A haptic device as the server needs to know it to design the couplings and the mapping (in the spirit
/// of the IEEE 1918.1.1 handshake). Per-axis lists follow the scene's operational axes (linear first), so
/// the client describes its device in the scene's space, which it learned from [`SceneInfo`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceCaps {
    /// Human-readable device model.
    pub name: String,
    /// Actuated degrees of freedom.
    pub dof: u8,
    /// Lower workspace bound per operational axis (m, rad).
    pub workspace_min: Vec<f64>,
    /// Upper workspace bound per operational axis (m, rad).
    pub workspace_max: Vec<f64>,
    /// Peak force the device can render (N).
    pub max_force_n: f64,
    /// Force the device can hold indefinitely (N), at most the peak.
    pub continuous_force_n: f64,
    /// Peak torque the device can render (N·m); 0: its angular axes are sensed, not actuated.
    pub max_torque_nm: f64,
    /// Highest stable rendering stiffness on the linear axes (N/m).
    pub max_stiffness_n_per_m: f64,
    /// Highest stable rendering damping on the linear axes (N·s/m).
    pub max_damping_ns_per_m: f64,
    /// Highest stable rendering stiffness on the angular axes (N·m/rad).
    pub max_angular_stiffness_nm_per_rad: f64,
    /// Highest stable rendering damping on the angular axes (N·m·s/rad).
    pub max_angular_damping_nms_per_rad: f64,
    /// The mechanism's own viscous damping per axis (N·s/m, N·m·s/rad): what passivity bounds are made of.
    pub damping: Vec<f64>,
    /// Moving mass per linear axis (kg) and inertia per angular axis (kg·m²) at the handle.
    pub mass: Vec<f64>,
    /// The device's own servo rate (Hz).
    pub native_rate_hz: f64,
    /// True when the device measures the hand's wrench.
    pub has_force_sensor: bool,
}

impl DeviceCaps {
    /// A generous device of `k` operational axes (±1 m and ±π rad of travel, 100 N and 10 N·m, 5000 N/m,
    /// 1 kg, 1 kHz): for benchmarks, tests and tools whose point is not the device.
    pub fn generous(name: &str, k: usize) -> Self {
        let linear = if k == 6 { 3 } else { 2 };
        let per_axis = |lin: f64, ang: f64| (0..k).map(|a| if a < linear { lin } else { ang }).collect::<Vec<_>>();
        DeviceCaps {
            name: name.into(),
            dof: k as u8,
            workspace_min: per_axis(-1.0, -std::f64::consts::PI),
            workspace_max: per_axis(1.0, std::f64::consts::PI),
            max_force_n: 100.0,
            continuous_force_n: 50.0,
            max_torque_nm: 10.0,
            max_stiffness_n_per_m: 5000.0,
            max_damping_ns_per_m: 100.0,
            max_angular_stiffness_nm_per_rad: 50.0,
            max_angular_damping_nms_per_rad: 1.0,
            damping: per_axis(1.0, 0.01),
            mass: per_axis(1.0, 0.01),
            native_rate_hz: 1000.0,
            has_force_sensor: true,
        }
    }
}

/// Which local model the client wants in its snapshots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LocalModelForm {
    /// Reduced operational-space terms only (Λ̂⁻¹, Û, Σ̂, biases): small, the default.
    OpSpace,
    /// Also the configuration-space terms of the paper's eq 11 ([`ConfigTerms`]).
    ConfigSpace,
}

/// First control message, client → server. The server answers [`SceneInfo`] (or [`Refused`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// The client's [`PROTOCOL_VERSION`]. First field, so a server can refuse other versions politely.
    pub version: u16,
    /// Shared secret the server was started with.
    pub token: String,
    /// Free-form client name for logs.
    pub client_name: String,
    /// Manipulator or observer.
    pub role: Role,
    /// The room to join on a server of many rooms; empty: the server's only (or default) room.
    pub room: String,
}

/// The scene, server → client after an accepted [`Hello`]: what the client needs to choose a device in the
/// scene's space and an operational point before it joins.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneInfo {
    /// Scene name.
    pub name: String,
    /// Planar or spatial: the space the device must describe itself in.
    pub kind: SceneKind,
    /// The scene's operational points, in declaration order.
    pub ops: Vec<String>,
}

/// What a client asks of the mapping between its device and the VE; `None` lets the server choose.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MappingRequest {
    /// Device metres per VE metre on the linear axes.
    pub position_scale: Option<f64>,
    /// Device newtons per VE newton.
    pub force_scale: Option<f64>,
    /// The VE holds the linkage's weight at the user's OP: the user feels inertia and the loops, not weight.
    pub gravity_compensation: bool,
}

/// Second control message, client → server: the operational point, the device, the local model and the
/// mapping. The server answers [`Welcome`] (or [`Refused`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Join {
    /// Name of the operational point to hold; empty: the scene's first.
    pub op: String,
    /// The device, in the scene's space.
    pub device: DeviceCaps,
    /// Which local model to send.
    pub form: LocalModelForm,
    /// What the client asks of the mapping.
    pub mapping: MappingRequest,
}

/// What the client needs to know about the scene to size its local model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSummary {
    /// Scene name.
    pub name: String,
    /// Planar or spatial.
    pub kind: SceneKind,
    /// Generalized velocities of the tree (nv).
    pub n: u32,
    /// Loop-closure rows.
    pub m: u32,
    /// The first rate of each ball joint, ascending (spatial scenes only): its orientation is a unit
    /// quaternion in q, so nq = n + the number of balls (`kinloop_linkage`'s `ConfigLayout`).
    pub ball_rates: Vec<u32>,
    /// Operational-space dimension `k` (must equal `kind.op_dim()`).
    pub op_dim: u8,
    /// Name of the operational point granted to this client.
    pub op_name: String,
    /// The scene's characteristic length L (m): constraint directions and singular values in snapshots are
    /// expressed in the unit-consistent coordinates `(v, L ω)`.
    pub length_scale: f64,
}

impl SceneSummary {
    /// The dimensions a session on this scene checks its snapshots and uplinks against.
    pub fn shape(&self) -> SessionShape {
        let (n, m) = (self.n as usize, self.m as usize);
        SessionShape { kind: self.kind, n, nq: n + self.ball_rates.len(), m }
    }
}

/// How device and VE map onto each other for this user. A device displacement `Δx_d` is the VE displacement
/// `Δx_d / position_scale`; a VE force `F` is the device force `force_scale · F`. Angles map one to one, and
/// torques by `force_scale · position_scale`, so every axis scales power by the same factor and the mapping
/// creates no energy on any axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mapping {
    /// Device metres per VE metre.
    pub position_scale: f64,
    /// Device newtons per VE newton.
    pub force_scale: f64,
    /// The VE holds the linkage's weight at this user's OP.
    pub gravity_compensation: bool,
    /// The user holds the OP rigidly, turning it with torques; false: as through a pin, pushing with forces
    /// only (a device without torque, or an OP too light in rotation for the device to render; `design`).
    pub rigid_grasp: bool,
}

impl Mapping {
    /// One to one, a rigid grasp, no compensation.
    pub fn identity() -> Self {
        Mapping { position_scale: 1.0, force_scale: 1.0, gravity_compensation: false, rigid_grasp: true }
    }

    /// Device N·m per VE N·m.
    pub fn torque_scale(&self) -> f64 {
        self.force_scale * self.position_scale
    }

    /// A scale a side can divide by: positive and finite.
    pub fn usable_scale(scale: f64) -> bool {
        scale > 0.0 && scale.is_finite()
    }

    /// `scale` when it is usable, else one to one: what every side falls back to rather than divide by a
    /// broken mapping.
    pub fn scale_or_one(scale: f64) -> f64 {
        if Self::usable_scale(scale) {
            scale
        } else {
            1.0
        }
    }
}

/// The graphics controller's gains the server chose for this user (paper section IV, Fig 3), per
/// operational axis: `K_g` (N/m, N·m/rad) and `B_g` (N·s/m, N·m·s/rad).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CouplingGains {
    /// K_g, length `k`.
    pub stiffness: Vec<f64>,
    /// B_g, length `k`.
    pub damping: Vec<f64>,
}

/// What the server's survey found at the granted operational point (VE units), for the client's own gain
/// design and for an intended motion that stays inside the reach.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OpSummary {
    /// Where the OP was when the welcome was made (world, m), point dimension.
    pub position: Vec<f64>,
    /// Smallest world coordinates the OP reaches (m), point dimension.
    pub reach_min: Vec<f64>,
    /// Largest world coordinates the OP reaches (m), point dimension.
    pub reach_max: Vec<f64>,
    /// Reachable poses in order, as displacements (linear, rotation vector; `k` numbers each) from the OP's
    /// pose when the welcome was made.
    pub tour: Vec<f64>,
    /// Static force a hand needs to hold the OP against gravity (90th percentile over the reach, N).
    pub static_force_n: f64,
    /// The same for torque (N·m).
    pub static_torque_nm: f64,
    /// Largest inverse translational effective mass over the reach (1/kg).
    pub inverse_mass_max: f64,
    /// Largest inverse rotational effective inertia over the reach (1/(kg·m²)).
    pub inverse_rotational_inertia_max: f64,
    /// On a linkage of one degree of freedom, the poses the OP can take, in order along its one path, a
    /// survey step apart (world poses, `[x, y, θ]` or `[x, y, z, qw, qx, qy, qz]` each; at most [`MAX_PATH_POSES`]); empty
    /// otherwise. The client's local model holds the OP to it far from where a snapshot was linearized.
    pub path: Vec<f64>,
    /// The OP's acceleration at rest at each pose of `path` (gravity, springs, actuators), along the path's
    /// direction there (pose order; unit-consistent coordinates `(v, L ω)`, m/s²): one value per pose.
    /// `None` when the path carries none: a swing's pose is two configurations, whose forces at rest differ.
    pub path_rest_acceleration: Option<Vec<f64>>,
    /// How `path`'s ends are: open, closed (its last pose leads back to its first) or a swing (its ends are
    /// limits where the OP turns back while the linkage goes on).
    pub path_shape: PathShape,
}

impl OpSummary {
    /// What a survey found, its tour as displacements from `now` (the OP's pose when the welcome is made).
    pub fn from_reach<S: Space>(reach: &OpReach<S>, now: &OpPose<S>) -> Self {
        let mut tour = Vec::with_capacity(reach.tour.len() * S::DIM);
        for pose in &reach.tour {
            tour.extend_from_slice(pose.difference(now).as_slice());
        }
        let (poses, rest) = reach.path.as_ref().map_or((&[][..], None), |p| (p.poses(), p.rest_acceleration()));
        let shape = reach.path.as_ref().map_or(PathShape::Open, |p| p.shape());
        let kept = path_samples(poses.len(), shape == PathShape::Closed);
        let wire = OpPose::<S>::wire_len();
        let mut path = vec![0.0; kept.len() * wire];
        for (&k, out) in kept.iter().zip(path.chunks_mut(wire)) {
            poses[k].to_slice(out);
        }
        OpSummary {
            position: now.position.as_slice().to_vec(),
            reach_min: reach.position_min.as_slice().to_vec(),
            reach_max: reach.position_max.as_slice().to_vec(),
            tour,
            static_force_n: reach.static_force_n,
            static_torque_nm: reach.static_torque_nm,
            inverse_mass_max: reach.inverse_mass_max,
            inverse_rotational_inertia_max: reach.inverse_rotational_inertia_max,
            path,
            path_rest_acceleration: rest.map(|r| kept.iter().map(|&k| r[k]).collect()),
            path_shape: shape,
        }
    }
}

/// Which of a path's `n` poses go on the wire: all when they fit in [`MAX_PATH_POSES`], else every few, and
/// the last of a path that is not `closed` (an end where the OP stops or turns back stays where it is).
fn path_samples(n: usize, closed: bool) -> Vec<usize> {
    if n <= MAX_PATH_POSES {
        return (0..n).collect();
    }
    if closed {
        return (0..n).step_by(n.div_ceil(MAX_PATH_POSES)).collect();
    }
    let mut kept: Vec<usize> = (0..n - 1).step_by((n - 1).div_ceil(MAX_PATH_POSES - 1)).collect();
    kept.push(n - 1);
    kept
}

/// Successful handshake reply, server → client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// Random id of this session (for logs and reconnects).
    pub session_id: u64,
    /// The client's user id in the VE; snapshots and other users refer to it.
    pub user_id: u32,
    /// Scene dimensions.
    pub scene: SceneSummary,
    /// Rate of the VE loop (Hz).
    pub ve_rate_hz: f64,
    /// Rate at which snapshots are sent (Hz).
    pub snapshot_rate_hz: f64,
    /// The mapping between the device and the VE.
    pub mapping: Mapping,
    /// The graphics controller's gains for this user.
    pub coupling: CouplingGains,
    /// The operational point's reach and inertia.
    pub op: OpSummary,
}

/// Category of a [`Control::Error`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ErrorCode {
    /// The peer broke the protocol (wrong message at the wrong time).
    Protocol,
    /// The peer sent bytes that did not decode or validate.
    Decode,
    /// Something failed inside the sender.
    Internal,
    /// The sender is shutting down.
    ShuttingDown,
    /// The sender cannot keep up.
    Overloaded,
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ErrorCode::Protocol => "protocol violation",
            ErrorCode::Decode => "undecodable message",
            ErrorCode::Internal => "internal error",
            ErrorCode::ShuttingDown => "shutting down",
            ErrorCode::Overloaded => "overloaded",
        })
    }
}

/// Reliable messages on the session's control stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Control {
    /// Client → server, first frame.
    Hello(Hello),
    /// Server → client, admits the client.
    Welcome(Welcome),
    /// Server → client, refuses the client.
    Refused(Refused),
    /// Either side is leaving.
    Leave {
        /// Why, for logs.
        reason: String,
    },
    /// Either side reports a problem.
    Error {
        /// Category.
        code: ErrorCode,
        /// Details for humans.
        message: String,
    },
    /// Asks the peer to echo `nonce`.
    Ping {
        /// Echoed back in the pong.
        nonce: u64,
        /// Sender's clock when sent (s).
        t_s: f64,
    },
    /// Echo of a ping.
    Pong {
        /// The ping's nonce.
        nonce: u64,
        /// The ping's `t_s`, echoed so the pinger needs no state.
        t_s: f64,
    },
    /// Server → client, after an accepted hello.
    SceneInfo(SceneInfo),
    /// Client → server, after the scene info.
    Join(Join),
    /// Server → client, every few VE steps when the server has a room key: the VE's state, signed.
    RoomState(RoomState),
    /// Client → server, between the scene info and the join: the newest signed state the client holds,
    /// offered for the room to resume from. The server answers [`Control::ResumeAnswer`].
    Resume(RoomState),
    /// Server → client, the answer to [`Control::Resume`].
    ResumeAnswer(ResumeAnswer),
    /// Admin → server, first frame instead of a hello: create, remove or list rooms.
    Admin(AdminRequest),
    /// Server → admin, the answer to [`Control::Admin`]; the server closes after it.
    AdminAnswer(AdminAnswer),
}

impl Control {
    /// The variant's name, for errors and logs that must not print a whole message.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Control::Hello(_) => "Hello",
            Control::Welcome(_) => "Welcome",
            Control::Refused(_) => "Refused",
            Control::Leave { .. } => "Leave",
            Control::Error { .. } => "Error",
            Control::Ping { .. } => "Ping",
            Control::Pong { .. } => "Pong",
            Control::SceneInfo(_) => "SceneInfo",
            Control::Join(_) => "Join",
            Control::RoomState(_) => "RoomState",
            Control::Resume(_) => "Resume",
            Control::ResumeAnswer(_) => "ResumeAnswer",
            Control::Admin(_) => "Admin",
            Control::AdminAnswer(_) => "AdminAnswer",
        }
    }
}

/// A contact near the user's operational point, as the local model needs it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactTerm {
    /// Contact point in world (m), point dimension.
    pub point: Vec<f64>,
    /// Unit contact normal in world, point dimension.
    pub normal: Vec<f64>,
    /// Penetration depth (m); negative is a gap.
    pub depth: f64,
    /// Normal relative velocity (m/s), positive separating.
    pub normal_velocity: f64,
    /// How an operational-space acceleration maps to normal acceleration (row of J_c Λ̂-weighted), length `k`.
    pub op_coupling: Vec<f64>,
    /// Inverse effective mass along the normal (1/kg).
    pub mobility: f64,
    /// Normal acceleration with zero operational force (m/s²).
    pub bias_accel: f64,
    /// Contact stiffness the VE uses (N/m).
    pub stiffness: f64,
    /// Contact damping the VE uses (N·s/m).
    pub damping: f64,
}

/// Configuration-space local-model terms (paper eq 11), sent only when the client asked for
/// [`LocalModelForm::ConfigSpace`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConfigTerms {
    /// Generalized coordinates, length `nq` (each ball joint's unit quaternion `(w, x, y, z)` where
    /// `SceneSummary::ball_rates` puts it).
    pub q: Vec<f64>,
    /// Generalized velocities, length `n`.
    pub qd: Vec<f64>,
    /// Mass matrix, upper triangle row-major, length `n(n+1)/2`.
    pub mass_matrix: Vec<f64>,
    /// Closure Jacobian `W`, `m x n` column-major.
    pub closure_jacobian: Vec<f64>,
    /// Closure bias with Baumgarte stabilization, length `m`.
    pub closure_bias_stab: Vec<f64>,
    /// Generalized bias (Coriolis, gravity, springs), length `n`.
    pub generalized_bias: Vec<f64>,
    /// Operational-point Jacobian, `k x n` column-major.
    pub op_jacobian: Vec<f64>,
    /// Operational-point bias acceleration `J̇ q̇`, length `k`.
    pub op_bias: Vec<f64>,
}

/// The local model of interaction for one user (paper Fig 3), server → client at up to the VE rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// Per-user snapshot counter; a receiver drops anything not newer than what it has (latest wins).
    pub seq: u64,
    /// Server clock when the VE state was taken (s).
    pub server_time_s: f64,
    /// VE step counter.
    pub ve_step: u64,
    /// The user this snapshot is for.
    pub user_id: u32,
    /// Client clock (`Uplink::client_time_s`) of the newest uplink the VE had used when it took this state
    /// (0 before the first): the local-model state this VE state answers. A client whose model restarts
    /// learns from it whether the VE has heard it yet, and a judge of the session compares the VE with the
    /// device there, whatever the network's delay.
    pub uplink_time_s: f64,
    /// Operational-point pose, pose dimension.
    pub op_pose: Vec<f64>,
    /// Operational-point twist, length `k`, linear first.
    pub op_twist: Vec<f64>,
    /// Λ̂⁻¹ (eq 9), upper triangle row-major, length `k(k+1)/2`.
    pub inverse_inertia: Vec<f64>,
    /// Operational-space bias acceleration, length `k`.
    pub bias_accel: Vec<f64>,
    /// Û (eq 10/12), `k x k` column-major, orthonormal columns.
    pub directions: Vec<f64>,
    /// Σ̂, length `k`, non-increasing.
    pub singular_values: Vec<f64>,
    /// How many of the leading directions are constrained (≤ `k`).
    pub constraint_count: u8,
    /// Contacts near the operational point.
    pub contacts: Vec<ContactTerm>,
    /// How many other manipulators are on the linkage. Their hands reach this user's local model through b̂
    /// (weighted, see the server's `sharing`) and the VE it is blended toward; the model itself needs only
    /// whether it is alone, so a snapshot carries a count rather than their rows, and the bytes a round
    /// sends grow with the users rather than with their square.
    pub other_manipulators: u16,
    /// Configuration-space terms, present only for [`LocalModelForm::ConfigSpace`].
    pub config: Option<ConfigTerms>,
    /// The energy books of this user's coupling port in the VE.
    pub energy: PortEnergy,
}

/// The energy that has crossed one end of the network two-port between a user's device and the VE, per
/// operational axis, since the session began (J; N·m·rad on angular axes, also J), in the VE's units. At the
/// client the port is the local model (received: what the user's wrench, hand and device reaction, put into
/// it; emitted: what it gave back); at the server it is the user's coupling (received: what the VE gave the
/// coupling; emitted: what the coupling gave the VE), booked while its passivity controller is on (zero
/// otherwise). Both only grow. The server's controller bounds what its coupling emits by what both ends have
/// received (time-domain passivity across the network, Ryu, Artigas & Preusche 2010); see
/// [`crate::passivity`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PortEnergy {
    /// Energy into the network at this end, per axis, length `k`.
    pub received_j: Vec<f64>,
    /// Energy out of the network at this end, per axis, length `k`.
    pub emitted_j: Vec<f64>,
}

impl PortEnergy {
    /// Nothing crossed yet, `k` axes.
    pub fn zero(k: usize) -> Self {
        PortEnergy { received_j: vec![0.0; k], emitted_j: vec![0.0; k] }
    }
}

/// Bits of [`Uplink::flags`].
pub mod uplink_flags {
    /// The client is fading its output because snapshots stopped arriving.
    pub const FADING: u32 = 1 << 0;
    /// The commanded wrench exceeded the device's capabilities and was clamped.
    pub const CLAMPED: u32 = 1 << 1;
    /// The newest snapshot is older than the client's staleness threshold.
    pub const STALE_SNAPSHOT: u32 = 1 << 2;
    /// Joint-constraint control runs in acceleration-zeroing ("impedance") mode instead of stiffness mode.
    pub const IMPEDANCE_MODE: u32 = 1 << 3;
    /// One or more uplinks before this one were not sent because they fell inside the perceptual deadband.
    pub const DEADBAND_SKIPPED: u32 = 1 << 4;
    /// A safety check disabled the device output.
    pub const SAFETY_STOP: u32 = 1 << 5;
    /// The device's presence sensor says no hand holds the handle: the client has faded its output, brakes the
    /// handle and holds its local model still, so the VE's coupling keeps the linkage where the hand left it.
    pub const HAND_OFF: u32 = 1 << 6;
    /// Every bit the protocol defines; the codec refuses others.
    pub const KNOWN: u32 =
        FADING | CLAMPED | STALE_SNAPSHOT | IMPEDANCE_MODE | DEADBAND_SKIPPED | SAFETY_STOP | HAND_OFF;
}

/// What a client reports each haptic tick, client → server.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Uplink {
    /// Per-client uplink counter.
    pub seq: u64,
    /// Client clock when sent (s).
    pub client_time_s: f64,
    /// Newest snapshot seq the client has applied (0 before the first).
    pub last_snapshot_seq: u64,
    /// How long that snapshot had been held when this uplink left (s); with the snapshot's send time this gives
    /// the server an RTT estimate without synchronized clocks.
    pub last_snapshot_age_s: f64,
    /// Wrench the user's hand applies, F_h, length `k`.
    pub hand_wrench: Vec<f64>,
    /// Device pose, pose dimension.
    pub device_pose: Vec<f64>,
    /// Device twist, length `k`.
    pub device_twist: Vec<f64>,
    /// Local-model operational-point pose, pose dimension.
    pub model_pose: Vec<f64>,
    /// Local-model operational-point twist, length `k`.
    pub model_twist: Vec<f64>,
    /// Status bits, see [`uplink_flags`].
    pub flags: u32,
    /// The energy books of the client's device port.
    pub energy: PortEnergy,
}

impl Uplink {
    /// An uplink at rest: no hand wrench, every pose and twist zero (`k` operational components, `pose_dim`
    /// pose numbers), sent at `seq` milliseconds. Clients fill one in place each tick; tests start from it.
    pub fn at_rest(seq: u64, k: usize, pose_dim: usize) -> Uplink {
        Uplink {
            seq,
            client_time_s: seq as f64 * 1e-3,
            last_snapshot_seq: 0,
            last_snapshot_age_s: 0.0,
            hand_wrench: vec![0.0; k],
            device_pose: vec![0.0; pose_dim],
            device_twist: vec![0.0; k],
            model_pose: vec![0.0; pose_dim],
            model_twist: vec![0.0; k],
            flags: 0,
            energy: PortEnergy::zero(k),
        }
    }
}

/// Unreliable messages, one per QUIC datagram (or per unidirectional stream when too large for a datagram).
// Messages are built and sent one at a time, so the size gap costs nothing; boxing would cost an allocation.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Datagram {
    /// Server → client.
    Snapshot(Snapshot),
    /// Client → server.
    Uplink(Uplink),
}

#[cfg(test)]
mod golden;
