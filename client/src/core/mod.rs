//! `HapticCore`: the sans-IO haptic side of one session — snapshot intake, the local model, the paper's
//! controllers, the safety envelope and the uplink — as one state machine driven by `handle_snapshot` and
//! `tick`. Time is an argument (`Duration` since any epoch); the core holds no socket, thread, clock or lock
//! and allocates nothing after construction, so the same core runs in the real-time driver and in
//! virtual-time tests and harnesses.
//!
//! One tick (paper Fig 3, Fig 4):
//! 1. take the newest snapshot received (update the local model's frozen terms and the controllers'
//!    targets; the first snapshot also maps the device onto the operational point);
//! 2. filter Λ̂⁻¹ and the constrained-direction projector (`terms_time_constant`); on a linkage of one degree
//!    of freedom, carry them along the OP's path (from the welcome) to where the model is, with the forces at
//!    rest there (`CoreConfig::follow_path`); pull the local model's OP toward the VE's OP predicted to now
//!    (first-order: fast along the constrained directions, onto the path when there is one; slow in the free
//!    ones, see `CoreConfig::free_blend_time_constant`);
//! 3. step the local model (eq 11/13) under the user's wrench: the hand wrench (force channel, when measured)
//!    plus the position channels' reaction applied to the device last tick;
//! 4. the controllers, with `e = x_d ⊖ x_m`: joint constraint (stiffness or impedance mode), impedance with
//!    Λ̂⁻¹ in the free directions, position channels, contact force channel;
//! 5. safety: non-finite check, output gate (ramp in, fade out on stale snapshots), device limits;
//! 6. the uplink (every tick, or through the perceptual deadband).
//!
//! **What drives the local model.** The hand wrench F_h (only when a sensor measures it: without one, feeding
//! an estimate forward would make the user feel the device's mass instead of the linkage's, because the
//! impedance controller that reshapes the device needs the same measurement) plus the reaction of the
//! position channels, equal and opposite to what the device received, so the teleoperator exchanges no net
//! energy of its own. Other users' wrenches are not added: the server's b̂ already contains their effect.
//! The uplink's `hand_wrench` is exactly this driving wrench, so the VE's force channel pushes the VE's OP
//! as the local model's is pushed and the graphics controller K_g, B_g only corrects the difference.

pub mod config;
pub mod controllers;
pub mod design;
pub mod safety;

mod deadband;
mod intake;
mod model;
mod observer;
mod passive_update;

use std::time::Duration;

use kinloop_linkage::algorithms::op_path::{turn_between, OpPath, PathError};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{clip_wrench_parts, SceneKind, Space, VecOps};
use kinloop_protocol::codec::limits::{MAX_SPEED, MAX_WRENCH};
use kinloop_protocol::passivity::{EnergyReports, PortBooks};
use kinloop_protocol::{uplink_flags, Mapping, SessionShape, Snapshot, Uplink, Welcome};

pub use config::{
    ConstraintMode, ConstraintWeighting, ControllerGains, CoreConfig, GainChoice, ModelForm, SafetyConfig,
    UplinkDeadband,
};
pub use intake::SnapshotRejection;
pub use passive_update::TANK_CAPACITY_J as UPDATE_TANK_CAPACITY_J;

use controllers::{
    contact_feedforward, impedance_free, joint_constraint_impedance, joint_constraint_stiffness, linearization_trust,
    position_channel, project_twist, project_wrench, twist_turn, ConstraintFrame,
};
use deadband::Deadband;
use intake::SnapshotTerms;
use model::LocalModel;
use observer::HandObserver;
use passive_update::{damper_dissipation, energy_change, CouplingSprings, UpdateTank};
use safety::{force_ratio, limit_wrench_parts, mask_unactuated, usable_state, within, OutputGate, WrenchLimits};

/// Longest step a late tick may take (a stalled loop must not integrate a huge step).
const MAX_STEP_S: f64 = 0.02;

/// The free directions' pull toward the VE takes at least this many round trips as its time constant.
///
/// Along the free directions the VE follows the model, a one-way delay late, so what that pull corrects comes
/// back a round trip `T` later. A correction `ẋ = −x(t − T) / τ` is stable only for `T < π τ / 2`: while the
/// free directions were compared with the model's own state that the VE answered (a Smith predictor, since
/// removed: see `tick`, step 2), the default `τ` of 200 ms made the testbed unstable from 200 ms one way (a
/// 400 ms round trip: `T/τ` = 2 > π/2). Compared with the VE's state predicted to now, the same fixed pull
/// is stable at 1 s one way (`tests/harness.rs`); `τ ≥ 2 T` keeps the margin the bound asks for anyway
/// (crossover at `1/τ` with at most `T/τ` = 0.5 rad of delay phase: 61°). Slower only means the model and
/// the VE part for longer before they meet again (`latency` experiment).
pub const FREE_BLEND_PER_ROUND_TRIP: f64 = 2.0;

/// Why a core could not be built for a session.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CoreError {
    /// The scene lives in another space than the core.
    #[error("the scene is {scene:?} but this client runs a {core:?} core")]
    WrongSpace {
        /// The scene's.
        scene: SceneKind,
        /// The core's.
        core: SceneKind,
    },
    /// The welcome's operational dimension disagrees with its kind.
    #[error("the welcome announces an operational space of dimension {got}, expected {expected}")]
    WrongOpDim {
        /// Announced.
        got: u8,
        /// Expected for the kind.
        expected: usize,
    },
    /// The device spec does not describe this space's axes.
    #[error("device {device}: {field} has {got} values, expected {expected}")]
    DeviceAxes {
        /// The device.
        device: String,
        /// Which list.
        field: &'static str,
        /// Its length.
        got: usize,
        /// Axes of the space.
        expected: usize,
    },
    /// The scene's length scale is unusable.
    #[error("the scene's length scale {0} is not a positive length")]
    LengthScale(f64),
    /// Gains that cannot be used.
    #[error("controller gains: {0}")]
    Gains(String),
    /// A mapping whose scales are not positive.
    #[error("the welcome's mapping (position scale {position}, force scale {force}) is not usable")]
    Mapping {
        /// Position scale.
        position: f64,
        /// Force scale.
        force: f64,
    },
    /// A tick period that is not positive.
    #[error("the tick period must be positive")]
    Period,
    /// The welcome's OP path cannot be followed.
    #[error("the welcome's OP path: {0}")]
    Path(#[from] PathError),
}

/// The wrench each controller asks for this tick, before the safety envelope, and what was commanded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerWrenches<S: Space> {
    /// Four-channel teleoperator, position channels (on the device).
    pub position_channel: S::OpVec,
    /// Joint-constraint controller.
    pub joint_constraint: S::OpVec,
    /// Impedance controller (free directions).
    pub impedance: S::OpVec,
    /// Contact force channel.
    pub contact: S::OpVec,
    /// Their sum.
    pub requested: S::OpVec,
    /// What the device is commanded after the output gate, the mapping and the limits (device units; the
    /// other wrenches here are in VE units).
    pub command: S::OpVec,
}

impl<S: Space> ControllerWrenches<S> {
    fn zero() -> Self {
        let z = S::OpVec::zero();
        ControllerWrenches {
            position_channel: z,
            joint_constraint: z,
            impedance: z,
            contact: z,
            requested: z,
            command: z,
        }
    }
}

/// Everything one tick computed, for recording and tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickReport<S: Space> {
    /// The tick's time.
    pub time: Duration,
    /// False until the first snapshot: no model, zero output.
    pub active: bool,
    /// Device pose mapped into the VE (see `CoreConfig::index_at_first_snapshot`).
    pub device_pose: OpPose<S>,
    /// Device twist.
    pub device_twist: S::OpVec,
    /// Local model OP pose after this tick's step.
    pub model_pose: OpPose<S>,
    /// Local model OP twist.
    pub model_twist: S::OpVec,
    /// Hand wrench: measured, or the observer's estimate, or zero.
    pub hand_wrench: S::OpVec,
    /// The wrench that drove the local model this tick (and goes up as the uplink's `hand_wrench`).
    pub model_wrench: S::OpVec,
    /// Per-controller wrenches.
    pub wrenches: ControllerWrenches<S>,
    /// Output gate gain in [0, 1].
    pub gain: f64,
    /// Scale the device limits applied (1 = not clamped).
    pub clamp_scale: f64,
    /// Constrained directions counted by the core (with hysteresis).
    pub constraint_count: usize,
    /// The server's count in the snapshot in use.
    pub snapshot_constraint_count: u8,
    /// Seq of the snapshot in use (0 before the first).
    pub snapshot_seq: u64,
    /// How long ago the snapshot in use arrived.
    pub snapshot_age: Option<Duration>,
    /// `x_d ⊖ x_m`.
    pub tracking_error: S::OpVec,
    /// Uplink flags of this tick.
    pub flags: u32,
}

impl<S: Space> TickReport<S> {
    fn idle(time: Duration) -> Self {
        let z = S::OpVec::zero();
        TickReport {
            time,
            active: false,
            device_pose: OpPose::identity(),
            device_twist: z,
            model_pose: OpPose::identity(),
            model_twist: z,
            hand_wrench: z,
            model_wrench: z,
            wrenches: ControllerWrenches::zero(),
            gain: 0.0,
            clamp_scale: 1.0,
            constraint_count: 0,
            snapshot_constraint_count: 0,
            snapshot_seq: 0,
            snapshot_age: None,
            tracking_error: z,
            flags: 0,
        }
    }
}

/// Counters over the core's life.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CoreStats {
    /// Ticks run.
    pub ticks: u64,
    /// Ticks with a local model (after the first snapshot).
    pub active_ticks: u64,
    /// Snapshots taken as newest.
    pub snapshots_accepted: u64,
    /// Snapshots dropped because a newer one was already there (latest wins).
    pub snapshots_superseded: u64,
    /// Snapshots refused as corrupt.
    pub snapshots_rejected: u64,
    /// Ticks whose device reading or output was non-finite or absurd (zero was commanded instead).
    pub non_finite_events: u64,
    /// Ticks whose command was clamped to the device limits.
    pub clamped_ticks: u64,
    /// Ticks with a stale snapshot.
    pub stale_ticks: u64,
    /// Largest `|f| / f_max` or `|τ| / τ_max` commanded: never above 1.
    pub max_force_ratio: f64,
    /// Uplinks built (one per active tick).
    pub uplinks_built: u64,
    /// Uplinks that left (all, or those through the deadband).
    pub uplinks_sent: u64,
    /// Sum of squared linear tracking errors |x_d − x_m|² over active ticks (m²).
    pub tracking_error_sum_sq: f64,
    /// Largest linear tracking error (m).
    pub tracking_error_max: f64,
    /// Snapshots whose energy books were refused (non-finite, negative, shrinking, or faster than the wire's
    /// largest wrench at its largest speed): the rest of the snapshot was used, the last good books kept.
    pub energy_reports_refused: u64,
    /// Ticks on which the device's presence sensor said no hand held it (output faded, `HAND_OFF` sent).
    pub hand_off_ticks: u64,
    /// Ticks whose pull toward the VE was applied only in part because it would have put more energy into
    /// the device-model coupling than its dampers had dissipated (`CoreConfig::passive_update`).
    pub updates_limited: u64,
}

impl CoreStats {
    /// RMS of the linear distance between device and local-model OP (m).
    pub fn tracking_error_rms(&self) -> f64 {
        if self.active_ticks == 0 {
            0.0
        } else {
            (self.tracking_error_sum_sq / self.active_ticks as f64).sqrt()
        }
    }

    /// Fraction of uplinks the deadband saved (0 without a deadband).
    pub fn uplink_saving(&self) -> f64 {
        if self.uplinks_built == 0 {
            0.0
        } else {
            1.0 - self.uplinks_sent as f64 / self.uplinks_built as f64
        }
    }
}

/// What a tick returns: the device command, the uplink to send (borrowed from the core's preallocated
/// message: a tick allocates nothing), and the report.
#[derive(Debug)]
pub struct TickOutput<'a, S: Space> {
    /// The wrench to command (device units).
    pub command: S::OpVec,
    /// The uplink to send this tick, if any.
    pub uplink: Option<&'a Uplink>,
    /// What the tick computed.
    pub report: &'a TickReport<S>,
}

/// Gains after resolution and capping to the device: in VE units for the controllers, which compute on the
/// VE side of the mapping, and as the device feels them.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedGains<S: Space> {
    /// k_j (N/m, scaled coordinates), VE units.
    pub joint_stiffness: f64,
    /// b_j (N s/m), VE units.
    pub joint_damping: f64,
    /// K_pc, VE units.
    pub position_stiffness: S::OpVec,
    /// B_pc, VE units.
    pub position_damping: S::OpVec,
    /// The same gains as the device renders them (device units), after the caps.
    pub device: ControllerGains,
    /// Factor applied to every stiffness so that k_j + K_pc stays within the device's stable stiffness.
    pub stiffness_cap: f64,
    /// Factor applied to every damping likewise.
    pub damping_cap: f64,
}

/// How device and VE map onto each other (`protocol::Mapping`): positions by `position` (device metres per VE
/// metre), forces by `force`, torques by `torque = force · position`; angles one to one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scales {
    /// Device metres per VE metre.
    pub position: f64,
    /// Device newtons per VE newton.
    pub force: f64,
    /// Device newton-metres per VE newton-metre.
    pub torque: f64,
}

impl Scales {
    /// From the welcome's mapping.
    pub fn of(mapping: &Mapping) -> Self {
        Scales { position: mapping.position_scale, force: mapping.force_scale, torque: mapping.torque_scale() }
    }

    /// A device twist in the VE.
    pub fn twist_to_ve<S: Space>(&self, twist: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(twist, 1.0 / self.position, 1.0)
    }

    /// A device wrench (the hand's) in the VE.
    pub fn wrench_to_ve<S: Space>(&self, wrench: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(wrench, 1.0 / self.force, 1.0 / self.torque)
    }

    /// A VE wrench on the device.
    pub fn wrench_to_device<S: Space>(&self, wrench: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(wrench, self.force, self.torque)
    }

    /// A device gain (stiffness or damping, per axis) in VE units: `F_ve = F_d / c_f` for a device
    /// displacement `c_p Δx_ve`, so `K_ve = K_d c_p / c_f`; on angular axes `K_ve = K_d / c_τ`.
    fn gain_to_ve<S: Space>(&self, gain: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(gain, self.position / self.force, 1.0 / self.torque)
    }

    /// Device masses in VE units (the mass the VE side must give a wrench to move the device as it moves).
    fn mass_to_ve<S: Space>(&self, mass: &S::OpVec) -> S::OpVec {
        self.gain_to_ve::<S>(mass)
    }

    fn per_group<S: Space>(&self, v: &S::OpVec, linear: f64, angular: f64) -> S::OpVec {
        let lin = <S::Point as VecOps>::LEN;
        let mut out = *v;
        for i in 0..S::DIM {
            out[i] *= if i < lin { linear } else { angular };
        }
        out
    }
}

/// Maps device poses into the VE: the device's displacement from where it was indexed, divided by the
/// position scale, from the OP's position then, and a handle-frame orientation offset
/// (`R_ve = R_device R_offset`), so world-frame angular velocities are the same on both sides.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DeviceIndex<S: Space> {
    device_origin: S::Point,
    ve_origin: S::Point,
    rotation: S::Rot,
    position_scale: f64,
}

impl<S: Space> DeviceIndex<S> {
    fn identity(position_scale: f64) -> Self {
        DeviceIndex {
            device_origin: S::Point::zero(),
            ve_origin: S::Point::zero(),
            rotation: S::rot_identity(),
            position_scale,
        }
    }

    fn between(device: &OpPose<S>, op: &OpPose<S>, position_scale: f64) -> Self {
        DeviceIndex {
            device_origin: device.position,
            ve_origin: op.position,
            rotation: S::rot_mul(&S::rot_inverse(&device.rotation), &op.rotation),
            position_scale,
        }
    }

    /// The workspace's centre onto the reach's centre: the whole reach then fits the workspace (the scale was
    /// chosen for it), wherever the OP is when the session starts. The orientation is indexed as in
    /// `between`.
    fn centred(device: &OpPose<S>, op: &OpPose<S>, frames: &(S::Point, S::Point), position_scale: f64) -> Self {
        DeviceIndex { device_origin: frames.0, ve_origin: frames.1, ..Self::between(device, op, position_scale) }
    }

    fn apply(&self, pose: &OpPose<S>) -> OpPose<S> {
        OpPose {
            position: self.ve_origin + (pose.position - self.device_origin) * (1.0 / self.position_scale),
            rotation: S::rot_mul(&pose.rotation, &self.rotation),
        }
    }

    /// Where a VE position lies on the device (the inverse of `apply`'s position part).
    fn device_point(&self, ve: &S::Point) -> S::Point {
        self.device_origin + (*ve - self.ve_origin) * self.position_scale
    }
}

/// The haptic core of one session (see the module documentation).
pub struct HapticCore<S: Space> {
    config: CoreConfig,
    gains: ResolvedGains<S>,
    limits: WrenchLimits,
    scales: Scales,
    /// The device's workspace and the OP's reach, when the reach has extent (see `DeviceIndex::centred`).
    boxes: Option<Boxes<S>>,
    /// The device's masses in VE units.
    device_mass: S::OpVec,
    length_scale: f64,
    user_id: u32,
    /// The session's dimensions, for the wire's checks on incoming snapshots.
    shape: SessionShape,
    // Boxed: a snapshot moves from incoming to pending to active by swapping pointers, not ~1 kB structs.
    incoming: Box<SnapshotTerms<S>>,
    pending: Box<SnapshotTerms<S>>,
    pending_fresh: bool,
    newest_seq: Option<u64>,
    active: Box<SnapshotTerms<S>>,
    has_snapshot: bool,
    model: LocalModel<S>,
    /// The snapshot's frame (filtered), as linearized at the snapshot's pose.
    frame: ConstraintFrame<S>,
    /// The frame the controllers use this tick: `frame`, carried along the OP's path to the model (see
    /// `follow_path`) when there is one.
    local: ConstraintFrame<S>,
    /// A 1-DOF linkage's OP path (`CoreConfig::follow_path`), with where the model and the snapshot were
    /// found on it last.
    path: Option<PathFollower<S>>,
    /// How far the walls of the frame in use are trusted where the model is (`place_frame`).
    trust: f64,
    index: DeviceIndex<S>,
    gate: OutputGate,
    observer: HandObserver<S>,
    reaction: S::OpVec,
    last_command: S::OpVec,
    last_now: Option<Duration>,
    one_way_delay: Duration,
    deadband: Deadband<S>,
    /// The energy the model's updates may still put into the coupling (`passive_update`).
    tank: UpdateTank,
    /// This end of the two-port: the local model's port, where the user's wrench (hand and device
    /// reaction) drives the model (`kinloop_protocol::passivity`); its books go up in every uplink.
    port: PortBooks,
    /// The VE coupling's books, as the snapshots report them (checked).
    server_energy: EnergyReports,
    uplink: Uplink,
    /// Trigonometric anchors for the three pose streams converted every tick or snapshot.
    pose_memos: PoseMemos<S>,
    stats: CoreStats,
    report: TickReport<S>,
}

/// The OP's path and where on it the model and the active snapshot's pose were found last.
#[derive(Clone, Debug)]
struct PathFollower<S: Space> {
    path: OpPath<S>,
    model_segment: Option<usize>,
    snapshot_segment: Option<usize>,
    /// Unit tangent at the active snapshot's pose (unit-consistent coordinates).
    snapshot_tangent: Option<S::OpVec>,
    /// The OP's acceleration at rest at the active snapshot's pose, as the path has it.
    snapshot_rest: S::OpVec,
    /// The forces at rest are felt where the model is, not where the snapshot was taken (false when the VE
    /// holds the linkage's weight at this OP: `Mapping::gravity_compensation` takes them out of b̂).
    rest_where_model_is: bool,
    /// The grasp is pinned: the path is its positions only, and poses are looked for by position.
    pinned: bool,
}

impl<S: Space> PathFollower<S> {
    /// The welcome's path, if it has one and the configuration follows it; `pinned`: the grasp renders no
    /// torque (`HapticCore::pinned`), so the model's angle is the linkage's business, not the hand's, and
    /// the path is followed by position (`OpPath::positions_only`; by the whole pose, a model whose angle
    /// had drifted found its point on the four-bar's coupler curve off where it was, and on a Falcon at
    /// 500 ms one way the forces at rest taken there made 9 J).
    fn of(welcome: &Welcome, config: &CoreConfig, pinned: bool) -> Result<Option<Self>, CoreError> {
        let op = &welcome.op;
        if !config.follow_path || op.path.is_empty() {
            return Ok(None);
        }
        let wire = OpPose::<S>::wire_len();
        let mut poses = Vec::with_capacity(op.path.len() / wire);
        for (i, chunk) in op.path.chunks(wire).enumerate() {
            poses.push(OpPose::from_slice(chunk).ok_or(PathError::NonFinite(i))?);
        }
        let path = OpPath::new(poses, op.path_closed, welcome.scene.length_scale)?
            .with_rest_acceleration(op.path_rest_acceleration.clone())?;
        let path = if pinned { path.positions_only()? } else { path };
        Ok(Some(PathFollower {
            path,
            model_segment: None,
            snapshot_segment: None,
            snapshot_tangent: None,
            snapshot_rest: S::OpVec::zero(),
            rest_where_model_is: !welcome.mapping.gravity_compensation,
            pinned,
        }))
    }

    /// Where `pose` is looked for on the path (by position alone when pinned).
    fn query(&self, pose: &OpPose<S>) -> OpPose<S> {
        if self.pinned {
            OpPose { position: pose.position, rotation: S::rot_identity() }
        } else {
            *pose
        }
    }
}

/// One memo per stream of poses the core reads or writes on the wire (see `Space::RotParamsMemo`): each
/// stream moves little from one conversion to the next, which the memo turns into fewer library calls.
#[derive(Clone, Copy, Debug, Default)]
struct PoseMemos<S: Space> {
    snapshot_op: S::RotParamsMemo,
    uplink_device: S::RotParamsMemo,
    uplink_model: S::RotParamsMemo,
}

/// The damper that holds a released handle: half the device's highest stable damping on each axis (linear and
/// angular), against the handle's twist, in device units.
fn brake<S: Space>(device: &crate::device::DeviceSpec, twist: &S::OpVec) -> S::OpVec {
    let lin = <S::Point as VecOps>::LEN;
    let mut w = S::OpVec::zero();
    for a in 0..S::DIM {
        let b = if a < lin { device.max_damping } else { device.max_angular_damping };
        w[a] = -0.5 * b * twist[a];
    }
    w
}

fn per_axis<S: Space>(what: &str, values: &[f64]) -> Result<S::OpVec, CoreError> {
    if values.len() != S::DIM || values.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
        return Err(CoreError::Gains(format!("{what} needs {} finite non-negative values, got {values:?}", S::DIM)));
    }
    Ok(S::OpVec::from_slice(values))
}

/// The device's workspace and the OP's reach as boxes (linear axes), to index the device so that the one
/// holds the other.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Boxes<S: Space> {
    workspace: (S::Point, S::Point),
    reach: (S::Point, S::Point),
}

impl<S: Space> Boxes<S> {
    /// `None` when the welcome's reach has no extent or does not fit the space.
    fn of(device: &crate::device::DeviceSpec, op: &kinloop_protocol::OpSummary) -> Option<Self> {
        let lin = <S::Point as VecOps>::LEN;
        if op.reach_min.len() != lin || op.reach_max.len() != lin || device.workspace_min.len() < lin {
            return None;
        }
        let extent = (0..lin).map(|a| op.reach_max[a] - op.reach_min[a]).fold(0.0, f64::max);
        if extent.is_nan() || extent <= 0.0 {
            return None;
        }
        let point = |v: &[f64]| S::Point::from_slice(&v[..lin]);
        Some(Boxes {
            workspace: (point(&device.workspace_min), point(&device.workspace_max)),
            reach: (point(&op.reach_min), point(&op.reach_max)),
        })
    }

    fn centres(&self) -> (S::Point, S::Point) {
        ((self.workspace.0 + self.workspace.1) * 0.5, (self.reach.0 + self.reach.1) * 0.5)
    }

    /// True when indexing the device where it is onto the OP where it is keeps the whole reach inside the
    /// workspace (then the device need not move to start).
    fn fits_from(&self, device: &S::Point, op: &S::Point, scale: f64) -> bool {
        let lo = *device + (self.reach.0 - *op) * scale;
        let hi = *device + (self.reach.1 - *op) * scale;
        let (w_lo, w_hi) = (self.workspace.0.as_slice(), self.workspace.1.as_slice());
        (0..<S::Point as VecOps>::LEN).all(|a| lo.as_slice()[a] >= w_lo[a] && hi.as_slice()[a] <= w_hi[a])
    }
}

impl<S: Space> HapticCore<S> {
    /// A core for the session `welcome` opened, driving `config.device`.
    pub fn new(config: CoreConfig, welcome: &Welcome) -> Result<Self, CoreError> {
        let scene = &welcome.scene;
        if scene.kind != S::KIND {
            return Err(CoreError::WrongSpace { scene: scene.kind, core: S::KIND });
        }
        if usize::from(scene.op_dim) != S::DIM {
            return Err(CoreError::WrongOpDim { got: scene.op_dim, expected: S::DIM });
        }
        if !(scene.length_scale.is_finite() && scene.length_scale > 0.0) {
            return Err(CoreError::LengthScale(scene.length_scale));
        }
        if config.period.is_zero() {
            return Err(CoreError::Period);
        }
        let device = &config.device;
        if device.mass.len() != S::DIM || device.mass.iter().any(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(CoreError::DeviceAxes {
                device: device.name.clone(),
                field: "mass",
                got: device.mass.len(),
                expected: S::DIM,
            });
        }
        let scales = Scales::of(&welcome.mapping);
        if ![scales.position, scales.force, scales.torque].iter().all(|x| x.is_finite() && *x > 0.0) {
            return Err(CoreError::Mapping { position: scales.position, force: scales.force });
        }
        let device_mass = scales.mass_to_ve::<S>(&S::OpVec::from_slice(&device.mass));
        let gains = Self::resolve_gains(&config, welcome, &scales)?;
        let shape = scene.shape();
        let config_shape = (config.form == ModelForm::Config).then_some((shape.n, shape.m));
        let pose_len = OpPose::<S>::wire_len();
        let k = S::DIM;
        let uplink = Uplink::at_rest(0, k, pose_len);
        // A pinned grasp renders no torque, whatever the device could (`Mapping::rigid_grasp`).
        let limits = WrenchLimits {
            max_torque_nm: if welcome.mapping.rigid_grasp { WrenchLimits::of(device).max_torque_nm } else { 0.0 },
            ..WrenchLimits::of(device)
        };
        let path = PathFollower::of(welcome, &config, limits.pins_the_grasp())?;
        Ok(HapticCore {
            gains,
            limits,
            boxes: Boxes::of(device, &welcome.op),
            scales,
            device_mass,
            length_scale: scene.length_scale,
            user_id: welcome.user_id,
            shape,
            incoming: Box::new(SnapshotTerms::new(config_shape)),
            pending: Box::new(SnapshotTerms::new(config_shape)),
            pending_fresh: false,
            newest_seq: None,
            active: Box::new(SnapshotTerms::new(config_shape)),
            has_snapshot: false,
            model: LocalModel::new(config_shape),
            frame: ConstraintFrame::new(),
            local: ConstraintFrame::new(),
            path,
            trust: 1.0,
            index: DeviceIndex::identity(scales.position),
            gate: OutputGate::new(&config.safety),
            observer: HandObserver::new(config.hand_observer_bandwidth, device_mass),
            reaction: S::OpVec::zero(),
            last_command: S::OpVec::zero(),
            last_now: None,
            one_way_delay: Duration::ZERO,
            deadband: Deadband::new(config.deadband),
            tank: UpdateTank::new(),
            port: PortBooks::default(),
            server_energy: EnergyReports::default(),
            uplink,
            pose_memos: PoseMemos::default(),
            stats: CoreStats::default(),
            report: TickReport::idle(Duration::ZERO),
            config,
        })
    }

    /// Picks the gains (device units), caps them to what the device renders stably (`k_j + K_pc ≤
    /// max_stiffness` and `b_j + B_pc ≤ max_damping` on the linear axes; angular gains scale by the same
    /// factors) and converts them to VE units through the mapping.
    fn resolve_gains(config: &CoreConfig, welcome: &Welcome, scales: &Scales) -> Result<ResolvedGains<S>, CoreError> {
        let period_s = config.period.as_secs_f64();
        let chosen = match &config.gains {
            GainChoice::Designed => design::designed_gains::<S>(
                &config.device,
                &welcome.mapping,
                &welcome.op,
                welcome.scene.length_scale,
                period_s,
            ),
            GainChoice::Paper => ControllerGains::paper(config.device.linear_mass(), S::DIM),
            GainChoice::Custom(g) => g.clone(),
        };
        let scalar_ok = |x: f64| x.is_finite() && x >= 0.0;
        if !scalar_ok(chosen.joint_stiffness) || !scalar_ok(chosen.joint_damping) {
            return Err(CoreError::Gains(format!(
                "k_j = {} and b_j = {} must be finite and non-negative",
                chosen.joint_stiffness, chosen.joint_damping
            )));
        }
        let position_stiffness = per_axis::<S>("K_pc", &chosen.position_stiffness)?;
        let position_damping = per_axis::<S>("B_pc", &chosen.position_damping)?;
        let linear_max = |v: &S::OpVec| S::op_lin(v).as_slice().iter().fold(0.0f64, |a, b| a.max(*b));
        let cap = |total: f64, limit: f64| {
            if limit.is_finite() && limit > 0.0 && total > limit {
                limit / total
            } else {
                1.0
            }
        };
        let stiffness_cap = cap(chosen.joint_stiffness + linear_max(&position_stiffness), config.device.max_stiffness);
        let damping_cap = cap(chosen.joint_damping + linear_max(&position_damping), config.device.max_damping);
        let device = ControllerGains {
            joint_stiffness: chosen.joint_stiffness * stiffness_cap,
            joint_damping: chosen.joint_damping * damping_cap,
            position_stiffness: (position_stiffness * stiffness_cap).as_slice().to_vec(),
            position_damping: (position_damping * damping_cap).as_slice().to_vec(),
        };
        // k_j and b_j act along the constrained directions, linear first: they scale as a linear gain.
        let joint = scales.position / scales.force;
        Ok(ResolvedGains {
            joint_stiffness: device.joint_stiffness * joint,
            joint_damping: device.joint_damping * joint,
            position_stiffness: scales.gain_to_ve::<S>(&(position_stiffness * stiffness_cap)),
            position_damping: scales.gain_to_ve::<S>(&(position_damping * damping_cap)),
            device,
            stiffness_cap,
            damping_cap,
        })
    }

    /// True when the user holds the OP as through a pin (`Mapping::rigid_grasp` false, or a device without
    /// torque): forces only, the angles left to the linkage.
    pub fn pinned(&self) -> bool {
        self.limits.pins_the_grasp()
    }

    /// The mapping's scales.
    pub fn scales(&self) -> Scales {
        self.scales
    }

    /// Where the device's handle belongs for the OP at VE position `op` under this session's mapping (a
    /// simulated device starts there, as a hand would grasp the handle where the linkage is).
    pub fn home(&self, op: &S::Point) -> S::Point {
        match &self.boxes {
            Some(boxes) => {
                let (workspace, reach) = boxes.centres();
                workspace + (*op - reach) * self.scales.position
            }
            None => self.index.device_point(op),
        }
    }

    /// The gains in use.
    pub fn gains(&self) -> &ResolvedGains<S> {
        &self.gains
    }

    /// The configuration.
    pub fn config(&self) -> &CoreConfig {
        &self.config
    }

    /// Counters so far.
    pub fn stats(&self) -> CoreStats {
        CoreStats { energy_reports_refused: self.server_energy.refused, ..self.stats }
    }

    /// The last tick's report.
    pub fn report(&self) -> &TickReport<S> {
        &self.report
    }

    /// True when the configuration-space form steps the local model.
    pub fn using_config_form(&self) -> bool {
        self.model.using_config()
    }

    /// This end's two-port books (the local model's port) and the VE coupling's as last accepted from a
    /// snapshot (`kinloop_protocol::passivity`).
    pub fn energy_books(&self) -> (&PortBooks, &EnergyReports) {
        (&self.port, &self.server_energy)
    }

    /// The driver's estimate of the one-way delay from the VE (half the RTT): snapshots are predicted forward
    /// by their age since arrival plus this.
    pub fn set_one_way_delay(&mut self, delay: Duration) {
        self.one_way_delay = delay;
    }

    /// The free directions' pull time constant: the configured one, never shorter than
    /// `CoreConfig::free_blend_round_trips` round trips.
    pub fn free_blend_time_constant(&self) -> Duration {
        self.config
            .free_blend_time_constant
            .max(self.one_way_delay.saturating_mul(2).mul_f64(self.config.free_blend_round_trips))
    }

    /// Takes a snapshot received at `now`. Returns `Ok(true)` when it is the newest so far (it will be used at
    /// the next tick), `Ok(false)` when a newer one was already there (latest wins), an error when refused.
    pub fn handle_snapshot(&mut self, now: Duration, snapshot: &Snapshot) -> Result<bool, SnapshotRejection> {
        if self.newest_seq.is_some_and(|newest| snapshot.seq <= newest) {
            self.stats.snapshots_superseded += 1;
            return Ok(false);
        }
        if snapshot.user_id != self.user_id {
            self.stats.snapshots_rejected += 1;
            return Err(SnapshotRejection::Implausible { field: "user_id" });
        }
        if let Err(rejection) = self.incoming.fill_from(
            snapshot,
            &self.shape,
            now,
            self.config.safety.max_inverse_inertia,
            &mut self.pose_memos.snapshot_op,
        ) {
            self.stats.snapshots_rejected += 1;
            return Err(rejection);
        }
        // The energy books are judged apart: a bad report is refused and counted (`EnergyReports::refused`, in
        // the stats), the state is still used.
        let e = &snapshot.energy;
        let _ =
            self.server_energy.check(snapshot.server_time_s, &e.received_j, &e.emitted_j, MAX_WRENCH * MAX_SPEED, 0.0);
        std::mem::swap(&mut self.incoming, &mut self.pending);
        self.pending_fresh = true;
        self.newest_seq = Some(snapshot.seq);
        self.stats.snapshots_accepted += 1;
        Ok(true)
    }

    /// How far the local model's constraint geometry is still trusted where the model is now, as this tick's
    /// `place_frame` found it.
    fn linearization_trust(&self) -> f64 {
        self.trust
    }

    /// The VE's OP predicted to `now`: the snapshot's pose moved along its twist for its age plus the one-way
    /// delay (at most the staleness limit).
    fn predicted_op(&self, now: Duration) -> OpPose<S> {
        let horizon =
            (now.saturating_sub(self.active.received_at) + self.one_way_delay).min(self.config.safety.max_snapshot_age);
        let mut pose = self.active.op_pose;
        pose.integrate(&self.active.op_twist, horizon.as_secs_f64());
        pose
    }

    /// Makes the pending snapshot the active one.
    fn apply_pending(&mut self, now: Duration, device: &OpPose<S>, hand_off: bool) {
        std::mem::swap(&mut self.pending, &mut self.active);
        self.pending_fresh = false;
        let first = !self.has_snapshot;
        // With the output fully faded (start, or a link that came back) nothing is felt, so the model may jump
        // onto the VE instead of being pulled there; not while the hand is off, when the model stays parked
        // where the VE holds it (jumping onto a VE that follows the model would walk both away).
        let restart = first || (self.gate.gain() == 0.0 && !hand_off);
        self.model.update(&self.active);
        self.frame.set_target(&self.active, &self.config.weighting, self.length_scale, restart, self.pinned());
        if let Some(f) = self.path.as_mut() {
            let on = f.path.nearest(&f.query(&self.active.op_pose), f.snapshot_segment);
            f.snapshot_segment = Some(on.segment);
            f.snapshot_tangent = Some(on.tangent);
            f.snapshot_rest = on.rest_acceleration;
        }
        if restart {
            // Until the VE has seen one of this client's uplinks it holds the OP where it was at the join
            // (the grasp: pose held, twist zero), so the model starts there, at rest, where the device is
            // indexed. Extrapolating a linkage that was moving when the user joined put the model ahead of
            // the device by its speed times the delay and made both loops fight over the gap (a Watt six-bar
            // swinging for 0.3 s before the join, 50 ms one way: 95 % of ticks saturated, VE restores; at rest
            // here, none saturated). Later restarts (a link that came back) find a VE that moves by itself:
            // the model starts where it is now.
            if self.active.uplink_time_s > 0.0 {
                self.model.set_state(self.predicted_op(now), self.active.op_twist);
            } else {
                self.model.set_state(self.active.op_pose, S::OpVec::zero());
            }
            self.model.set_inverse_inertia(&self.frame.inverse_inertia);
            self.reaction = S::OpVec::zero();
        }
        if first && self.config.index_at_first_snapshot {
            let (op, scale) = (&self.active.op_pose, self.scales.position);
            self.index = match &self.boxes {
                // Where the device is, if the reach fits from there (no start-up pull); else centred.
                Some(boxes) if !boxes.fits_from(&device.position, &op.position, scale) => {
                    DeviceIndex::centred(device, op, &boxes.centres(), scale)
                }
                _ => DeviceIndex::between(device, op, scale),
            };
        }
        self.has_snapshot = true;
    }

    /// What correcting the model by `moved` and `sped` would change in the energy the device-model coupling
    /// and the model hold (`passive_update`), the device at `device_pose` (`sensed`: it measures the hand).
    fn update_cost(&self, device_pose: &OpPose<S>, sensed: bool, moved: &S::OpVec, sped: &S::OpVec) -> f64 {
        let error = self.controlled(device_pose.difference(&self.model.pose()));
        let springs = self.coupling_springs(sensed);
        energy_change::<S>(&springs, &error, &self.model.twist(), &self.controlled(*moved), sped)
    }

    /// The springs of the device-model coupling as the controllers render them now (`sensed`: the device
    /// measures the hand's wrench).
    fn coupling_springs(&self, sensed: bool) -> CouplingSprings<'_, S> {
        // The acceleration-zeroing controller holds no spring, when it has a hand wrench to work with (see
        // step 4 of `tick`); without one the joints are held stiff.
        let hand_known = sensed || self.config.hand_observer_bandwidth > 0.0;
        let joint_stiffness = match (self.config.constraint_mode, hand_known) {
            (ConstraintMode::Impedance, true) => 0.0,
            _ => self.gains.joint_stiffness * self.linearization_trust(),
        };
        CouplingSprings {
            position_stiffness: &self.gains.position_stiffness,
            joint_stiffness,
            projector: &self.local.projector,
            length_scale: self.length_scale,
            inertia: &self.local.inertia,
        }
    }

    /// Sets the frame the controllers use this tick and how far they trust its walls.
    ///
    /// The snapshot's frame was linearized at the VE's pose; under delay the model runs a round trip of motion
    /// ahead of it, where the linkage's constraint has turned away from that tangent plane. The walls then
    /// soften with the model's distance from the pose (`linearization_trust`), and on a linkage of one degree
    /// of freedom whose path the welcome carries (`CoreConfig::follow_path`; the reduced form, whose Λ̂⁻¹ the
    /// frame is) the frame is carried along the path toward the model's point on it, as far as the tangent is
    /// no longer trusted (`w = 1 − trust`): turned by `w` of the angle between the tangents, the model pulled
    /// that far onto the path, the forces at rest that far from where the model is, and the walls trusted as far
    /// as either the tangent or the path is. Near the snapshot's pose (no delay) the frame is the snapshot's
    /// own, which is exact where the path, sampled every few millimetres, is only interpolated; and a model
    /// past the end of an open path (the Bennett linkage's walk stops where its closure does not converge,
    /// and the linkage goes on) counts the path less as it goes on, as the tangent is counted less away from
    /// its pose (followed whole, the Bennett coupler on a Falcon at 50 ms was pulled back to the end of its
    /// path and saturated).
    ///
    /// Only for a user alone on the linkage: with others on it each local model runs ahead along its own OP's
    /// path by its own hand, and models that disagree about the linkage's one coordinate pull the VE apart
    /// (the four-bar's coupler and crank tip shared at 300 ms and 1 s one way, 2 and 4 users: saturated and
    /// 5 cm from the devices; on the snapshots' tangents, stable).
    ///
    /// Returns the model's point on the path, the fraction `w` and the turn as it acts on twists, or `None`
    /// when the snapshot's frame is used as it is.
    fn place_frame(&mut self) -> Option<(OpPose<S>, f64, S::OpMat)> {
        self.local = self.frame;
        let (pose, l, at) = (self.model.pose(), self.length_scale, &self.active.op_pose);
        let linear = (pose.position - at.position).norm();
        let turn = S::rot_chord(&pose.rotation, &at.rotation) * l;
        self.trust = linearization_trust((linear * linear + turn * turn).sqrt(), self.config.linearization_reach * l);
        let alone = !self.active.shared;
        let follower = self.path.as_mut().filter(|_| alone && !self.model.using_config() && self.trust < 1.0)?;
        // A pinned grasp's path is its positions (`PathFollower::of`): its tangents are linear, as its frame's
        // directions are.
        let from = follower.snapshot_tangent?;
        let on = follower.path.nearest(&follower.query(&pose), follower.model_segment);
        follower.model_segment = Some(on.segment);
        // A model past the end of an open path (where the survey's walk stopped) is not where the path says:
        // the path counts as little there as a tangent that far from its pose.
        let reach = self.config.linearization_reach * l;
        let along = (1.0 - self.trust) * linearization_trust(on.past_end, reach);
        let turn = turn_between::<S>(&from, &on.tangent, along);
        let twist_turn = twist_turn::<S>(&turn, l);
        self.local = self.frame.turned(&turn, l);
        if follower.rest_where_model_is {
            // b̂ holds the forces at rest where the snapshot was taken; the model feels them where it is.
            // Carried along unchanged they are a spring felt a round trip late, which makes energy (the
            // four-bar's weight at 1 s one way: 2 J beyond the hand's work over a whole tour).
            self.local.bias += (on.rest_acceleration - twist_turn * follower.snapshot_rest) * along;
        }
        // The walls are right as far as the tangent or the path is.
        self.trust = 1.0 - (1.0 - self.trust) * (1.0 - along);
        Some((on.pose, along, twist_turn))
    }

    /// `error` with the axes no controller acts on zeroed: held as through a pin (see
    /// `ConstraintFrame::set_target`), no controller acts on angles the device can neither show nor push.
    fn controlled(&self, mut error: S::OpVec) -> S::OpVec {
        if self.pinned() {
            for i in <S::Point as VecOps>::LEN..S::DIM {
                error[i] = 0.0;
            }
        }
        error
    }

    /// One haptic tick at `now` with the device reading `device` (see the module documentation).
    pub fn tick(&mut self, now: Duration, device: &crate::device::DeviceState<S>) -> TickOutput<'_, S> {
        let dt_s = match self.last_now {
            Some(last) => now.saturating_sub(last).as_secs_f64().min(MAX_STEP_S),
            None => self.config.period.as_secs_f64(),
        };
        self.last_now = Some(now);
        self.stats.ticks += 1;
        let device_usable = usable_state::<S>(&device.pose, &device.twist);
        let hand_off = device.grasped == Some(false);
        if self.pending_fresh && device_usable {
            self.apply_pending(now, &device.pose, hand_off);
        }
        if !self.has_snapshot || !device_usable {
            return self.idle_tick(now, device_usable);
        }
        self.stats.active_ticks += 1;
        let mut flags = 0;
        if self.config.constraint_mode == ConstraintMode::Impedance {
            flags |= uplink_flags::IMPEDANCE_MODE;
        }
        let device_pose = self.index.apply(&device.pose);
        let device_twist = self.scales.twist_to_ve::<S>(&device.twist);
        let age = now.saturating_sub(self.active.received_at);
        let stale = age > self.config.safety.max_snapshot_age;
        // No hand on the handle (a presence sensor says so): a free device must not be driven, so the output
        // fades as for stale data while a damper brakes the handle, and the local model parks where it is (no
        // one drives it), so the VE's coupling holds the linkage where the hand left it rather than letting it
        // fall. When the hand returns, the model restarts on the VE and the output ramps in again.
        if hand_off {
            flags |= uplink_flags::HAND_OFF;
            self.stats.hand_off_ticks += 1;
        }

        // 2. Pull toward the VE, filter the terms.
        let fraction = |tau: Duration| if tau.is_zero() { 1.0 } else { (dt_s / tau.as_secs_f64()).min(1.0) };
        self.frame.filter(fraction(self.config.terms_time_constant));
        let on_path = self.place_frame();
        if !stale && !hand_off {
            let (constrained, free) =
                (fraction(self.config.blend_time_constant), fraction(self.free_blend_time_constant()));
            let (p, l) = (&self.local.projector, self.length_scale);
            // The model is pulled toward the VE's state predicted to now: along the constrained directions
            // fast, where the frozen terms let it drift off the linkage's curve; along the free ones over
            // round trips, as the VE follows the model there. (Comparing the free directions instead with the
            // model's own state that the VE answered, as a Smith predictor does, took the delay out of that
            // loop but put the model's corrections in it: at 50 ms one way it made the Watt six-bar's light
            // output saturate a Touch and grow energy on a Falcon, 190 of 196 pairs rendering over whole
            // tours against 194 without it, and the testbed's soft tour ran 5.4 mm from the OP at 100 ms
            // against 4.6.)
            let predicted = self.predicted_op(now);
            let (own, own_twist) = (self.model.pose(), self.model.twist());
            let mut pose = predicted.difference(&own);
            let mut ve_twist = self.active.op_twist;
            if let Some((point, along, twist_turn)) = on_path {
                // On a path the model belongs, along the constrained directions, on the path where it is
                // (where the joints hold the OP), not on the tangent line through the VE's pose; and the
                // VE's twist, along the path where the VE was, is turned to where the model is (both as far
                // as `place_frame` carries the frame).
                pose += project_twist::<S>(p, l, &(point.difference(&own) - pose)) * along;
                ve_twist = twist_turn * ve_twist;
            }
            let twist = ve_twist - own_twist;
            let (mut moved, mut sped) = model::split_correction::<S>(&pose, &twist, p, l, constrained, free);
            if self.config.passive_update {
                let sensed = device.hand_wrench.is_some();
                let fraction = self.tank.admit(self.update_cost(&device_pose, sensed, &moved, &sped));
                if fraction < 1.0 {
                    self.stats.updates_limited += 1;
                }
                moved = moved * fraction;
                sped = sped * fraction;
            }
            self.model.apply_correction(&moved, &sped);
        }
        self.model.set_inverse_inertia(&self.local.inverse_inertia);

        // 3. Step the local model under the user's wrench.
        // A sensed wrench past the protocol's range is no reading (the server would refuse the uplink).
        // The sensor saturates at the device's peaks (a hand can push harder than the motors, but the
        // linkage feels what the device can answer); a pin passes no torque (its limit is 0).
        let sensed = device.hand_wrench.filter(|w| within(w.as_slice(), MAX_WRENCH)).map(|w| {
            let (in_range, _) = clip_wrench_parts::<S>(&w, self.limits.max_force_n, self.limits.max_torque_nm);
            self.scales.wrench_to_ve::<S>(&in_range)
        });
        let estimate = self.observer.update(dt_s, &device_twist, &self.last_command);
        let hand_for_constraint = sensed.or((self.config.hand_observer_bandwidth > 0.0).then_some(estimate));
        let model_wrench = if hand_off {
            self.model.set_state(self.model.pose(), S::OpVec::zero());
            S::OpVec::zero()
        } else {
            let wrench = sensed.unwrap_or_else(S::OpVec::zero) + self.reaction;
            self.model.step(dt_s, &wrench);
            wrench
        };
        let mut power_out = [0.0; kinloop_protocol::passivity::MAX_AXES];
        let model_twist_after = self.model.twist();
        for (a, p) in power_out.iter_mut().enumerate().take(S::DIM) {
            // Power into the local model is energy this end of the two-port received.
            *p = -model_wrench[a] * model_twist_after[a];
        }
        self.port.book(&power_out[..S::DIM], dt_s);

        // 4. Controllers.
        let model_pose = self.model.pose();
        let model_twist = self.model.twist();
        let error = self.controlled(device_pose.difference(&model_pose));
        let error_rate = self.controlled(device_twist - model_twist);
        let g = &self.gains;
        let (l, p) = (self.length_scale, &self.local.projector);
        // The constrained directions soften as the model runs away from where its terms were computed
        // (`linearization_trust`): the joint-constraint controller and the position channels' constrained part.
        let trust = self.linearization_trust();
        let soften = |w: S::OpVec| if trust < 1.0 { w - project_wrench::<S>(p, l, &w) * (1.0 - trust) } else { w };
        let pc = soften(position_channel::<S>(&g.position_stiffness, &g.position_damping, &error, &error_rate));
        // The dampers' part of it, which with the joint-constraint controller's fills the update's tank
        // (`passive_update`).
        let zero = S::OpVec::zero();
        let pc_damping = soften(position_channel::<S>(&zero, &g.position_damping, &zero, &error_rate));
        let imp = match sensed {
            Some(hand) => {
                impedance_free::<S>(p, l, &self.device_mass, &self.local.inverse_inertia, &self.local.bias, &hand)
            }
            None => S::OpVec::zero(),
        };
        let (contacts, live) = self.model.contacts();
        let contact = contact_feedforward::<S>(contacts, live, &self.local.free_inertia);
        // `pc_felt`: what the device receives from the position channels once the joint-constraint controller
        // has acted, so what the local model gets back as their reaction (step 5); `damping_felt` the same
        // of the dampers, the joint-constraint controller's included.
        let (jc, pc_felt, damping_felt) = match (self.config.constraint_mode, hand_for_constraint) {
            (ConstraintMode::Impedance, Some(hand)) => (
                joint_constraint_impedance::<S>(p, l, &hand, &(pc + imp + contact)),
                // The acceleration-zeroing controller cancels the channels along the constrained directions:
                // the device feels only their free part. Reacting to the cancelled part would push the local
                // model (and, through the uplink, the VE) along directions the joints hold with K_pc times a
                // drift that grows without bound in this mode (Fig 7b): 80 N on a 10 N device after 5 s.
                pc - project_wrench::<S>(p, l, &pc),
                pc_damping - project_wrench::<S>(p, l, &pc_damping),
            ),
            // Without a hand wrench to cancel, the acceleration-zeroing mode cannot work: keep the joints stiff.
            _ => (
                joint_constraint_stiffness::<S>(p, l, g.joint_stiffness, g.joint_damping, &error, &error_rate),
                pc,
                pc_damping + joint_constraint_stiffness::<S>(p, l, 0.0, g.joint_damping, &zero, &error_rate) * trust,
            ),
        };
        let jc = if trust < 1.0 { jc * trust } else { jc };
        let requested = pc + jc + imp + contact;

        // 5. Safety.
        let mut command = S::OpVec::zero();
        let mut clamp_scale = 1.0;
        let gain;
        if !requested.is_finite() || !usable_state::<S>(&self.model.pose(), &self.model.twist()) {
            self.recover_from_non_finite(now);
            flags |= uplink_flags::SAFETY_STOP;
            gain = 0.0;
        } else {
            gain = self.gate.update(dt_s, !stale && !hand_off);
            let mut on_device = self.scales.wrench_to_device::<S>(&(requested * gain));
            if hand_off {
                // A released handle is braked, not left to coast (Haption's Virtuose engages its brakes when
                // the dead-man switch opens): a damper is passive, and it comes in as the rendering fades.
                on_device += brake::<S>(&self.config.device, &device.twist) * (1.0 - gain);
            }
            let scales;
            (command, scales) = limit_wrench_parts::<S>(&on_device, &self.limits);
            clamp_scale = scales.min();
            self.reaction = -scales.apply::<S>(&mask_unactuated::<S>(&pc_felt, &self.limits)) * gain;
        }
        self.tank.fill(damper_dissipation::<S>(&error_rate, &damping_felt, gain * clamp_scale, dt_s));
        if clamp_scale < 1.0 {
            flags |= uplink_flags::CLAMPED;
            self.stats.clamped_ticks += 1;
        }
        if stale {
            flags |= uplink_flags::STALE_SNAPSHOT | uplink_flags::FADING;
            self.stats.stale_ticks += 1;
        }
        // The observer and the report work on the VE side.
        self.last_command = self.scales.wrench_to_ve::<S>(&command);
        self.stats.max_force_ratio = self.stats.max_force_ratio.max(force_ratio::<S>(&command, &self.limits));
        // Tracking as the hand feels it: in device space.
        let distance = S::op_lin(&error).norm() * self.scales.position;
        if distance.is_finite() {
            self.stats.tracking_error_sum_sq += distance * distance;
            self.stats.tracking_error_max = self.stats.tracking_error_max.max(distance);
        }

        // 6. Uplink.
        self.stats.uplinks_built += 1;
        if self.deadband.skipped {
            flags |= uplink_flags::DEADBAND_SKIPPED;
        }
        let send = self.deadband.admit(now, &model_wrench, &model_pose, flags, self.length_scale);
        if send {
            self.fill_uplink(now, age, flags, &model_wrench, &device_pose, &device_twist);
            self.deadband.skipped = false;
            self.stats.uplinks_sent += 1;
        } else {
            self.deadband.skipped = true;
        }

        self.report = TickReport {
            time: now,
            active: true,
            device_pose,
            device_twist,
            model_pose: self.model.pose(),
            model_twist: self.model.twist(),
            hand_wrench: sensed.unwrap_or(estimate),
            model_wrench,
            wrenches: ControllerWrenches {
                position_channel: pc,
                joint_constraint: jc,
                impedance: imp,
                contact,
                requested,
                command,
            },
            gain,
            clamp_scale,
            constraint_count: self.frame.count,
            snapshot_constraint_count: self.active.constraint_count,
            snapshot_seq: self.active.seq,
            snapshot_age: Some(age),
            tracking_error: error,
            flags,
        };
        TickOutput { command, uplink: send.then_some(&self.uplink), report: &self.report }
    }

    /// Zero output before the first snapshot or with an unusable device reading.
    fn idle_tick(&mut self, now: Duration, device_usable: bool) -> TickOutput<'_, S> {
        self.report = TickReport::idle(now);
        if !device_usable {
            self.stats.non_finite_events += 1;
            self.report.flags = uplink_flags::SAFETY_STOP;
            self.gate.close();
        }
        self.last_command = S::OpVec::zero();
        TickOutput { command: S::OpVec::zero(), uplink: None, report: &self.report }
    }

    /// A non-finite wrench or model state: command zero, count it, put the model back on the VE at rest and
    /// ramp in again from zero.
    fn recover_from_non_finite(&mut self, now: Duration) {
        self.stats.non_finite_events += 1;
        self.model.set_state(self.predicted_op(now), S::OpVec::zero());
        self.reaction = S::OpVec::zero();
        self.observer.reset();
        self.gate.close();
    }

    fn fill_uplink(
        &mut self,
        now: Duration,
        age: Duration,
        flags: u32,
        model_wrench: &S::OpVec,
        device_pose: &OpPose<S>,
        device_twist: &S::OpVec,
    ) {
        let u = &mut self.uplink;
        u.seq += 1;
        u.client_time_s = now.as_secs_f64();
        u.last_snapshot_seq = self.active.seq;
        u.last_snapshot_age_s = age.as_secs_f64();
        u.hand_wrench.copy_from_slice(model_wrench.as_slice());
        device_pose.to_slice_memo(&mut u.device_pose, &mut self.pose_memos.uplink_device);
        u.device_twist.copy_from_slice(device_twist.as_slice());
        self.model.pose().to_slice_memo(&mut u.model_pose, &mut self.pose_memos.uplink_model);
        u.model_twist.copy_from_slice(self.model.twist().as_slice());
        u.flags = flags;
        u.energy.received_j.copy_from_slice(&self.port.received_j[..S::DIM]);
        u.energy.emitted_j.copy_from_slice(&self.port.emitted_j[..S::DIM]);
    }
}
