//! `VeCore`: the virtual environment as a sans-IO state machine.
//!
//! One linkage, many users. The core owns the scene's [`Model`], its [`Data`] workspace and the state
//! `(q, q̇)`, and is driven entirely from outside, quinn-proto style: every method takes `&mut self`, time
//! is a [`Duration`] argument since an arbitrary epoch, and nothing inside reads a clock, touches a socket,
//! spawns a thread or takes a lock. The same core runs under the real-time driver and in virtual time.
//!
//! ```text
//! join / leave ─────────────┐
//! handle_uplink(now, ..) ───┤                ┌─► poll_snapshot()  (every user, at the snapshot rate)
//!                           ├─► VeCore ──────┼─► poll_event()     (log lines)
//! handle_timeout(now) ──────┘   ▲            └─► state(), metrics()
//!        poll_timeout() ────────┘ (next tick)
//! ```
//!
//! A tick (`handle_timeout`) is the paper's section II and IV in order: each user's fade and passivity
//! scale are updated, then one [`kinloop_linkage::algorithms::integrator::step`] integrates eq 4 with every user's coupling
//! ([`coupling`]) and the penalty contacts; a failed step restores the last good state. After the last
//! tick due, if a snapshot is due, every user's local model of interaction is built ([`snapshots`]).
//!
//! Allocation: join and leave allocate (per-user buffers); ticks, uplinks and snapshots for a fixed set of
//! users do not (the `no_allocation` test counts).

mod closing;
pub mod config;
pub mod coupling;
pub mod design;
pub mod device_side;
pub mod events;
pub mod fade;
pub mod guards;
pub mod handover;
pub mod metrics;
pub mod passivity;
pub mod playout;
pub mod prefetch;
mod resume;
pub mod round_trip;
pub mod sharing;
mod snapshots;
mod tick;
pub mod users;
pub mod ve_forces;

use std::time::Duration;

use kinloop_linkage::algorithms::configuration::ConfigLayout;
use kinloop_linkage::algorithms::contact::{Contact, PenaltyContacts};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::algorithms::reach::{survey_op, OpReach, SurveyConfig};
use kinloop_linkage::error::DynamicsError;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{
    algorithms::energy_guard::EnergyGuard, algorithms::integrator::step_guarded, algorithms::integrator::StepConfig,
    math::space::Space, math::space::VecOps, model::data::Data, model::Model,
};
use kinloop_protocol::{
    Datagram, Mapping, OpSummary, RefusalReason, Role, SceneInfo, SceneSummary, SessionShape, Snapshot, Uplink, Welcome,
};
use nalgebra::{DMatrix, DVector};

pub use config::{
    AxisGains, GuardLimits, VeConfig, VeConfigError, DEFAULT_COUPLING_LEAD_DELAYS_S, DEFAULT_COUPLING_LEAD_MAX_S,
};
pub use coupling::Coupling;
pub use events::{FadeReason, VeEvent};
pub use guards::{UplinkRejection, UplinkSample, WrenchLimits};
pub use metrics::VeMetrics;
pub use passivity::PassivityObserver;
pub use users::{JoinRequest, Presence, UserId};

use events::EventQueue;
use fade::Fade;
use users::{RejectionBurst, SnapshotSlot, User};
use ve_forces::{stage_weights, Evaluation, VeForces};

/// A step that starts with a closure residual above this fraction of the scene's length scale (0.46 mm on the
/// testbed; the paper's manipulation shows 1e-10 m with projection and 4e-6 m with Baumgarte alone) is treated
/// as failed, and only steps that start below it become restore points (see `VeCore::tick`). The
/// experiments' divergence criterion (closure error over 1 mm) lies just beyond it.
pub const BROKEN_CLOSURE_PER_LENGTH: f64 = 0.01;

/// A projected step that ends with its loops open beyond this fraction of the scene's length scale (the
/// closure a scene is assembled to by default, and the robustness experiment's bound) is re-assembled onto them
/// (see `VeCore::tick`): the projection stops after its last pass, which near a loss of rank (a Delta near
/// a singular pose, pushed hard) can leave the loops open by a thousandth of the length scale.
pub const OPEN_CLOSURE_PER_LENGTH: f64 = 1e-6;

/// A successful join.
#[derive(Clone, Debug, PartialEq)]
pub struct Joined {
    /// The new user's id.
    pub user_id: UserId,
    /// What to tell the client.
    pub welcome: Welcome,
}

/// A leave or lookup for a user the VE does not have.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("no user {user} in the VE")]
pub struct UnknownUser {
    /// The id given.
    pub user: UserId,
}

/// A snapshot ready to send, borrowed from the core until the next call.
#[derive(Debug)]
pub struct PendingSnapshot<'a> {
    slot: &'a SnapshotSlot,
}

impl<'a> PendingSnapshot<'a> {
    /// The user it is for.
    pub fn user_id(&self) -> UserId {
        self.slot.snapshot().user_id
    }
    /// The snapshot.
    pub fn snapshot(&self) -> &'a Snapshot {
        self.slot.snapshot()
    }
    /// The snapshot wrapped as a datagram, ready for `codec::encode_datagram_into` (no copy).
    pub fn datagram(&self) -> &'a Datagram {
        &self.slot.message
    }
}

/// One user's part of [`VeState`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UserState<S: Space> {
    /// Id.
    pub user_id: UserId,
    /// Role.
    pub role: Role,
    /// Present or leaving.
    pub presence: Presence,
    /// The user's OP in the VE at the last step's evaluation.
    pub op_pose: OpPose<S>,
    /// The wrench the last step applied at the OP (force channel and PD; fade and passivity scale included).
    pub wrench: S::OpVec,
    /// Fade weight of the last step.
    pub weight: f64,
    /// The coupling's K_g per axis as it stands (designed at the join, softened since if the round trip grew).
    pub coupling_stiffness: S::OpVec,
    /// The pose the coupling pulls the OP toward (the user's local model as heard, led).
    pub coupling_target: OpPose<S>,
    /// Constraint count of the user's last snapshot.
    pub constraint_count: u8,
    /// The user's passivity account.
    pub passivity: PassivityObserver,
    /// Client clock of the newest uplink the VE has used (0 before the first): the VE has heard of what the
    /// user did up to then.
    pub heard_until_s: f64,
    /// The client time whose local-model state the VE's coupling aims at (`Snapshot::uplink_time_s`; 0 before
    /// the first uplink): `heard_until_s` plus the coupling's lead (see `Coupling::lead_by`).
    pub answers_s: f64,
}

/// The VE's state after the last tick, for recording and tests.
#[derive(Debug)]
pub struct VeState<'a, S: Space> {
    /// Time of the last tick.
    pub time: Duration,
    /// Steps taken.
    pub step: u64,
    /// Generalized coordinates.
    pub q: &'a DVector<f64>,
    /// Generalized velocities.
    pub qd: &'a DVector<f64>,
    /// Closure multipliers of the last step.
    pub lambda: &'a DVector<f64>,
    /// Closure residual norm at the start of the last step (after the previous projection), m.
    pub closure_error: f64,
    users: &'a [User],
    couplings: &'a [Coupling<S>],
}

impl<S: Space> VeState<'_, S> {
    /// Every user, in join order.
    pub fn users(&self) -> impl ExactSizeIterator<Item = UserState<S>> + '_ {
        self.users.iter().zip(self.couplings).map(|(u, c)| UserState {
            user_id: u.id,
            role: u.role,
            presence: u.presence,
            op_pose: c.op_pose,
            wrench: c.step_wrench,
            weight: c.weight,
            coupling_stiffness: c.stiffness,
            coupling_target: c.target_pose,
            constraint_count: u.constraint_count,
            passivity: u.passivity,
            heard_until_s: c.heard_time_s,
            answers_s: c.target_time_s,
        })
    }
}

/// Reusable buffers of the snapshot build (see `snapshots`).
#[derive(Debug)]
struct SnapshotScratch<S: Space> {
    /// `Ỹ_h` of the user being built (n×k, see `kinloop_linkage::algorithms::op_space`).
    op_y: DMatrix<f64>,
    /// `Ỹ_c n` of a contact (n).
    contact_y: DVector<f64>,
    /// Contacts within the margin, nearest first.
    near: Vec<Contact<S>>,
    /// The op-space terms of the OP whose users are being built (see `snapshots`).
    at_op: snapshots::AtOp<S>,
    /// `P Σ Jᵀ F_h` over every pushing user's hand (n): the hands' share of the probe's accelerations
    /// (see `sharing`).
    hands_qdd: DVector<f64>,
    /// Scratch of `kkt::constrained_response` (2m).
    response: Vec<f64>,
    /// The workspace of the velocity terms b̂ leaves out (`snapshots::VelocityTerms`).
    velocity: snapshots::VelocityTerms<S>,
    /// User indices grouped by OP (then in join order), for `roster_version` `order_version`: the order of
    /// the snapshots and of the couplings' evaluation (`VeCore::refresh_op_order`).
    order: Vec<usize>,
    order_version: u64,
}

/// The virtual environment (see the module documentation).
#[derive(Debug)]
pub struct VeCore<S: Space> {
    model: Model<S>,
    data: Data<S>,
    config: VeConfig,
    step_config: StepConfig,
    shape: SessionShape,
    period: Duration,
    snapshot_period: Duration,
    /// K_g and B_g every user gets when the configuration fixes them (else each user's are designed).
    fixed_gains: Option<(S::OpVec, S::OpVec)>,
    /// Each operational point's surveyed reach, by OP index (`design` fits devices and gains to it).
    reaches: Vec<OpReach<S>>,
    /// A workspace and a state at rest for the loads held for users with gravity compensation (made at the
    /// first such join).
    held: Option<(Data<S>, DVector<f64>)>,
    /// The join's handover of a linkage that waited at rest (`handover`).
    handover: handover::Handover<S>,
    q: DVector<f64>,
    qd: DVector<f64>,
    /// Restore point: q at the start of the last step that began with the loop closed (see `tick`).
    checkpoint_q: DVector<f64>,
    /// The step's energy account (`VeConfig::energy_guard`), reset whenever the state is set from outside.
    energy_guard: EnergyGuard,
    /// q at the start of the current step (after a successful step, the previous restore point: scratch).
    step_start_q: DVector<f64>,
    lambda: DVector<f64>,
    closure_error: f64,
    step: u64,
    last_tick_at: Duration,
    next_tick_at: Duration,
    next_snapshot_at: Duration,
    users: Vec<User>,
    couplings: Vec<Coupling<S>>,
    contacts: Option<PenaltyContacts<S>>,
    next_user_id: UserId,
    roster_version: u64,
    snapshot_cursor: usize,
    scratch: SnapshotScratch<S>,
    events: EventQueue,
    metrics: VeMetrics,
}

impl<S: Space> VeCore<S> {
    /// A VE for `model` at its initial state `(q0, q̇0)`, no users, first tick due one period after the
    /// epoch.
    pub fn new(model: Model<S>, config: VeConfig) -> Result<Self, VeConfigError> {
        config.validate()?;
        let fixed_gains = match (&config.coupling_stiffness, &config.coupling_damping) {
            (None, None) => None,
            (stiffness, damping) => {
                // One given alone: the other is designed... for every user alike it cannot be, so it is the
                // paper's.
                let paper = VeConfig::paper();
                let k = stiffness.as_ref().or(paper.coupling_stiffness.as_ref());
                let b = damping.as_ref().or(paper.coupling_damping.as_ref());
                match (k, b) {
                    (Some(k), Some(b)) => {
                        Some((k.resolve::<S>("coupling_stiffness")?, b.resolve::<S>("coupling_damping")?))
                    }
                    _ => None,
                }
            }
        };
        let reaches = (0..model.ops.len())
            .map(|op| survey_op(&model, op, &SurveyConfig::default()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| VeConfigError::Survey(e.to_string()))?;
        let period = config.ve_period();
        let step_config = StepConfig {
            integrator: config.integrator,
            dt: period.as_secs_f64(),
            project: config.projection,
            implicit_forces: config.implicit_coupling,
        };
        let mut data = Data::new(&model);
        // The implicit coupling mass is added to D at every step, and the state each snapshot probes is the
        // next step's: D formed once per state serves both factorizations and the config-space terms.
        data.keep_mass_matrix = config.implicit_coupling;
        let q = model.q0.clone();
        let qd = model.qd0.clone();
        forward_kinematics(&model, &mut data, &q);
        forward_velocity(&model, &mut data, &qd);
        let contacts = PenaltyContacts::of_obstacles(&model).map(|mut contacts| {
            contacts.stiffness = config.contact_stiffness.unwrap_or(contacts.stiffness);
            contacts.damping = config.contact_damping.unwrap_or(contacts.damping);
            contacts
        });
        let (n, m, k) = (model.nv(), model.nc(), S::DIM);
        let user_room = 2 * config.max_users;
        let scratch = SnapshotScratch {
            op_y: DMatrix::zeros(n, k),
            contact_y: DVector::zeros(n),
            near: Vec::with_capacity(kinloop_linkage::algorithms::contact::contact_capacity(&model)),
            at_op: snapshots::AtOp::none(),
            hands_qdd: DVector::zeros(n),
            response: vec![0.0; 2 * m],
            velocity: snapshots::VelocityTerms::new(&model),
            order: Vec::with_capacity(user_room),
            order_version: u64::MAX,
        };
        Ok(VeCore {
            shape: SessionShape::of_model(&model),
            snapshot_period: config.snapshot_period(),
            period,
            step_config,
            fixed_gains,
            reaches,
            held: None,
            handover: handover::Handover::default(),
            checkpoint_q: q.clone(),
            energy_guard: EnergyGuard::default(),
            step_start_q: q.clone(),
            lambda: DVector::zeros(m),
            q,
            qd,
            closure_error: 0.0,
            step: 0,
            last_tick_at: Duration::ZERO,
            next_tick_at: period,
            next_snapshot_at: period,
            users: Vec::with_capacity(user_room),
            couplings: Vec::with_capacity(user_room),
            contacts,
            next_user_id: 1,
            roster_version: 0,
            snapshot_cursor: 0,
            scratch,
            events: EventQueue::new(),
            metrics: VeMetrics::default(),
            data,
            model,
            config,
        })
    }

    /// The scene.
    pub fn model(&self) -> &Model<S> {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &VeConfig {
        &self.config
    }

    /// The dimensions every session of this VE shares.
    pub fn session_shape(&self) -> SessionShape {
        self.shape
    }

    /// What a client learns before it joins: the scene's space and operational points.
    pub fn scene_info(&self) -> SceneInfo {
        SceneInfo {
            name: self.model.name.clone(),
            kind: S::KIND,
            ops: self.model.ops.iter().map(|o| o.name.clone()).collect(),
        }
    }

    /// The surveyed reach of operational point `op`.
    pub fn reach(&self, op: usize) -> Option<&OpReach<S>> {
        self.reaches.get(op)
    }

    /// Admits a user. Refuses when `max_users` are present, when the scene has no operational point of that
    /// name (an empty name asks for the first), or when the device cannot serve the scene (`design`). Its
    /// mapping and coupling gains are chosen here (`design`).
    ///
    /// A manipulator grasps its OP at the join: its coupling fades in at once, holding the OP where it is
    /// (no hand wrench, the OP's pose as the reference) until the user's first uplink takes over, and fades
    /// out again if none comes within `silent_timeout` of when one could first come: a measured round trip
    /// after the join (the welcome's way down, the first uplink's way up). Otherwise a linkage under gravity
    /// would fall for the network's round trip and the fade-in, and the user's first moments would be spent
    /// catching it; and over a round trip longer than `silent_timeout` the grasp would fade out before any
    /// uplink could arrive, and the linkage fall away from the pose the user's local model starts at (the
    /// grasp's, at rest).
    ///
    /// The user's round trip is not measured here: its coupling gets the default frequency
    /// ([`VeCore::join_measured`] takes the driver's measurement).
    pub fn join(&mut self, now: Duration, request: JoinRequest) -> Result<Joined, RefusalReason> {
        self.join_measured(now, request, None)
    }

    /// [`VeCore::join`] for a user whose network round trip the server measured (the driver's view of the
    /// link, never the client's word): the coupling's frequency follows it (`design::CouplingFrequency`).
    pub fn join_measured(
        &mut self,
        now: Duration,
        request: JoinRequest,
        round_trip: Option<Duration>,
    ) -> Result<Joined, RefusalReason> {
        let present = self.present_users();
        if present >= self.config.max_users {
            self.metrics.joins_refused += 1;
            return Err(RefusalReason::ServerFull { max_users: self.config.max_users as u32 });
        }
        let found = if request.op.is_empty() {
            (!self.model.ops.is_empty()).then_some(0)
        } else {
            self.model.op_index(&request.op)
        };
        let Some(op) = found else {
            self.metrics.joins_refused += 1;
            return Err(RefusalReason::UnknownOp {
                requested: request.op,
                available: self.model.ops.iter().map(|o| o.name.clone()).collect(),
            });
        };
        let reach = &self.reaches[op];
        let manipulator = request.role == Role::Manipulator;
        let designed = match &request.device {
            Some(device) => design::check_request::<S>(device, &request.mapping)
                .and_then(|()| design::choose_mapping(reach, &self.reaches, device, &request.mapping, manipulator))
                .and_then(|mapping| {
                    // Only a manipulator with the mapping the server chose for it: a scale the client asked
                    // for is checked by `choose_mapping` against the peak.
                    let automatic = request.mapping.force_scale.is_none();
                    if manipulator && automatic {
                        design::check_holdable(reach, device, &mapping)?;
                    }
                    Ok(mapping)
                })
                .map(|mapping| {
                    let rigid = mapping.rigid_grasp;
                    (mapping, device.native_rate_hz, rigid)
                }),
            // A user without a device (a view, a test) is mapped one to one and moves its reference as fast as
            // the VE.
            None => Ok((
                Mapping { gravity_compensation: request.mapping.gravity_compensation, ..Mapping::identity() },
                self.config.ve_rate_hz,
                true,
            )),
        };
        let (mapping, device_rate, torque) = match designed {
            Ok(designed) => designed,
            Err(error) => {
                self.metrics.joins_refused += 1;
                return Err(RefusalReason::Device { what: error.to_string() });
            }
        };
        let (frequency, (stiffness, damping)) = match self.fixed_gains {
            Some(gains) => (None, gains),
            None => {
                let trip = round_trip.map(|t| t.as_secs_f64());
                let f = design::CouplingFrequency::designed(self.config.ve_rate_hz, device_rate, trip);
                (Some(f), design::coupling_gains(reach, f.omega, torque))
            }
        };
        let user_id = self.next_user_id;
        self.next_user_id += 1;
        let point = &self.model.ops[op];
        let mut coupling = Coupling::new(point.body, point.point, self.model.nv(), stiffness, damping);
        coupling.brakes = !self.config.passivity_per_axis;
        coupling.evaluate(&self.model, &self.data.kin, true);
        if manipulator {
            coupling.pushes = true;
            coupling.target_pose = coupling.op_pose;
            coupling.heard_pose = coupling.op_pose;
        }
        let welcome = self.welcome(user_id, op, &mapping, &coupling);
        self.users.push(User {
            id: user_id,
            name: request.name,
            role: request.role,
            op,
            form: request.form,
            wrench_limits: guards::wrench_limits_for_device(request.device.as_ref(), &mapping, &self.config.guards),
            thresholds: device_side::user_thresholds::<S>(&self.config, &mapping, &stiffness),
            mapping,
            presence: Presence::Present,
            last_seq: None,
            // The grasp counts as the user's first word, said when the first uplink could be heard at the
            // earliest (see above).
            last_uplink_at: manipulator.then_some(now + round_trip.unwrap_or(Duration::ZERO)),
            silent: !manipulator,
            fade: Fade::off(),
            passivity: PassivityObserver::default(),
            hand_off: false,
            let_go: false,
            round_trip: round_trip::RoundTrip::new(),
            coupling_frequency: frequency,
            rejections: RejectionBurst::default(),
            constraint_count: 0,
            slot: SnapshotSlot::new(&self.model, user_id, request.form),
        });
        self.couplings.push(coupling);
        // The workspace of the static loads: the held ones, and the handover's (`handover`).
        let compensated = self.users.last().is_some_and(|u| u.mapping.gravity_compensation);
        if manipulator && self.held.is_none() && (self.config.rest_unheld || compensated) {
            self.held = Some((Data::new(&self.model), DVector::zeros(self.model.nv())));
        }
        if manipulator && compensated {
            self.update_held_loads();
        }
        self.roster_version += 1;
        self.metrics.users_joined += 1;
        self.metrics.users = self.present_users() as u32;
        self.events.push(VeEvent::UserJoined { user: user_id });
        Ok(Joined { user_id, welcome })
    }

    /// The user leaves: no more snapshots; its coupling fades out and the user is removed once it is off.
    pub fn leave(&mut self, _now: Duration, user: UserId) -> Result<(), UnknownUser> {
        let index = self.index_of(user).ok_or(UnknownUser { user })?;
        let u = &mut self.users[index];
        if u.presence == Presence::Present {
            u.presence = Presence::Leaving;
            u.slot.pending = false;
            self.events.push(VeEvent::FadingOut { user, reason: FadeReason::Left });
            self.metrics.users = self.present_users() as u32;
        }
        Ok(())
    }

    /// Uses an uplink from `user` (see [`UplinkSample`] for the allocation-free form drivers use).
    pub fn handle_uplink(&mut self, now: Duration, user: UserId, uplink: &Uplink) -> Result<(), UplinkRejection> {
        let sample = UplinkSample::from_uplink(uplink);
        match sample {
            Ok(sample) => self.handle_uplink_sample(now, user, &sample),
            Err(rejection) => {
                // A shape error still counts against the user (when there is one).
                if let Some(index) = self.index_of(user) {
                    self.reject(index, now, rejection);
                }
                Err(rejection)
            }
        }
    }

    /// Uses an uplink sample from `user`: stale or duplicate sequence numbers are ignored, physically absurd
    /// values rejected (counted, reported once per burst); either way nothing changes. Observers' uplinks
    /// only keep them alive; their wrenches are ignored.
    pub fn handle_uplink_sample(
        &mut self,
        now: Duration,
        user: UserId,
        sample: &UplinkSample,
    ) -> Result<(), UplinkRejection> {
        let index = self.index_of(user).filter(|&i| self.users[i].presence == Presence::Present);
        let Some(index) = index else {
            return Err(UplinkRejection::UnknownUser { user });
        };
        if let Some(last) = self.users[index].last_seq.filter(|last| sample.seq <= *last) {
            self.metrics.uplinks_stale += 1;
            return Err(UplinkRejection::Stale { seq: sample.seq, last });
        }
        let coupling = &mut self.couplings[index];
        let checked = guards::check_uplink::<S>(
            sample,
            &coupling.op_pose,
            &self.users[index].wrench_limits,
            &self.users[index].thresholds.guards,
            &mut coupling.pose_memo,
        );
        let checked = match checked {
            Ok(checked) => checked,
            Err(rejection) => {
                self.reject(index, now, rejection);
                return Err(rejection);
            }
        };
        self.metrics.uplinks_accepted += 1;
        if checked.clipped {
            self.metrics.uplinks_clipped += 1;
        }
        let u = &mut self.users[index];
        // The gap since the previous uplink (not since the join's grasp, which waits for the client to start).
        let gap_s = u.last_seq.and(u.last_uplink_at).map_or(0.0, |at| now.saturating_sub(at).as_secs_f64());
        u.last_seq = Some(sample.seq);
        u.last_uplink_at = Some(now);
        // A wait that is no duration at all is taken as none: the uplink arrived now.
        let arrived_s = now.as_secs_f64() - if sample.waited_s.is_finite() { sample.waited_s.max(0.0) } else { 0.0 };
        if let Some(trip_s) = u.round_trip.heard(arrived_s, sample.last_snapshot_seq, sample.last_snapshot_age_s) {
            self.metrics.sharing.note_sample(trip_s);
        }
        if let Some(frequency) = &mut u.coupling_frequency {
            let c = &mut self.couplings[index];
            let trip = u.round_trip.estimate_s();
            if design::soften::<S>(frequency, trip, gap_s, &mut c.stiffness, &mut c.damping) {
                u.thresholds = device_side::user_thresholds::<S>(&self.config, &u.mapping, &c.stiffness);
                self.metrics.couplings_softened += 1;
            }
        }
        u.hand_off = sample.flags & kinloop_protocol::uplink_flags::HAND_OFF != 0;
        if u.role == Role::Manipulator {
            let c = &mut self.couplings[index];
            // The wire bounds a client's clock; a direct caller's odd one reads as "no uplink yet", and such an
            // uplink, which says nothing of when it was sent, is followed at once.
            let t = sample.client_time_s;
            let timed = t > 0.0 && t <= kinloop_protocol::codec::limits::MAX_TIME_S;
            let reference = playout::Reference {
                client_time_s: if timed { t } else { 0.0 },
                hand_wrench: checked.hand_wrench,
                pose: checked.model_pose,
                twist: checked.model_twist,
            };
            if self.config.jitter_buffer && timed {
                c.playout.push(now.as_secs_f64(), reference);
            } else {
                c.follow(&reference);
            }
            if self.config.passivity {
                // The client's end of the two-port: booked by the server from what it received, and the
                // client's own books checked against the stream's history (see `passivity`). Only the
                // controller uses them, so without it they are neither booked nor read (40 ns a user a tick).
                u.passivity.observe_client::<S>(t, &checked.hand_wrench, &checked.model_twist);
                let k = S::DIM;
                let limits = &u.wrench_limits;
                let guards = &u.thresholds.guards;
                let max_power_w = limits.max_force_n.max(limits.max_torque_nm)
                    * guards.max_model_speed_m_per_s.max(guards.max_model_angular_speed_rad_per_s);
                let report = u.passivity.client.check(
                    t,
                    &sample.energy_received_j[..k],
                    &sample.energy_emitted_j[..k],
                    max_power_w,
                    u.thresholds.passivity_allowance,
                );
                if report.is_err() {
                    self.metrics.energy_reports_refused += 1;
                }
            }
        }
        Ok(())
    }

    fn reject(&mut self, index: usize, now: Duration, rejection: UplinkRejection) {
        self.metrics.uplinks_rejected += 1;
        let quiet = self.config.guards.rejection_burst_quiet;
        let u = &mut self.users[index];
        let new_burst = u.rejections.last_at.is_none_or(|at| now.saturating_sub(at) > quiet);
        if new_burst {
            let previous_burst = u.rejections.count;
            u.rejections.count = 0;
            self.events.push(VeEvent::UplinkRejected { user: u.id, rejection, previous_burst });
        }
        u.rejections.count += 1;
        u.rejections.last_at = Some(now);
    }

    /// When the next tick is due.
    pub fn poll_timeout(&self) -> Duration {
        self.next_tick_at
    }

    /// The next snapshot not yet polled (one per present user after each snapshot tick).
    pub fn poll_snapshot(&mut self) -> Option<PendingSnapshot<'_>> {
        while self.snapshot_cursor < self.users.len() {
            let index = self.snapshot_cursor;
            self.snapshot_cursor += 1;
            if self.users[index].slot.pending {
                self.users[index].slot.pending = false;
                return Some(PendingSnapshot { slot: &self.users[index].slot });
            }
        }
        self.snapshot_cursor = 0;
        None
    }

    /// The oldest unreported event.
    pub fn poll_event(&mut self) -> Option<VeEvent> {
        self.events.pop()
    }

    /// Counters.
    pub fn metrics(&self) -> VeMetrics {
        // The energy account keeps its own counters; they are read here rather than copied every tick.
        VeMetrics {
            energy_guard_activations: self.energy_guard.activations,
            energy_guard_removed: self.energy_guard.removed,
            ..self.metrics
        }
    }

    /// The state after the last tick.
    pub fn state(&self) -> VeState<'_, S> {
        VeState {
            time: self.last_tick_at,
            step: self.step,
            q: &self.q,
            qd: &self.qd,
            lambda: &self.lambda,
            closure_error: self.closure_error,
            users: &self.users,
            couplings: &self.couplings,
        }
    }

    /// Kinetic and potential (gravity, springs) energy of the linkage at the current state (J). Recomputes
    /// kinematics into the workspace, which every step recomputes anyway.
    pub fn mechanical_energy(&mut self) -> (f64, f64) {
        forward_kinematics(&self.model, &mut self.data, &self.q);
        forward_velocity(&self.model, &mut self.data, &self.qd);
        (
            kinloop_linkage::algorithms::gravity::kinetic_energy(&self.model, &self.data),
            kinloop_linkage::algorithms::gravity::potential_energy(&self.model, &self.data, &self.q),
        )
    }

    /// Ids of the users present (not leaving), in join order.
    pub fn present_user_ids(&self) -> impl Iterator<Item = UserId> + '_ {
        self.users.iter().filter(|u| u.presence == Presence::Present).map(|u| u.id)
    }

    /// A user's name, for logs.
    pub fn user_name(&self, user: UserId) -> Option<&str> {
        self.index_of(user).map(|i| self.users[i].name.as_str())
    }

    fn present_users(&self) -> usize {
        self.users.iter().filter(|u| u.presence == Presence::Present).count()
    }

    /// Ids are handed out in increasing order, users are appended as they join and removed in place, so
    /// `users` is sorted by id: a binary search (every uplink looks its user up; a linear scan made a
    /// 64-user tick's uplinks quadratic).
    fn index_of(&self, user: UserId) -> Option<usize> {
        debug_assert!(self.users.windows(2).all(|w| w[0].id < w[1].id), "users sorted by id");
        self.users.binary_search_by_key(&user, |u| u.id).ok()
    }

    fn welcome(&self, user_id: UserId, op: usize, mapping: &Mapping, coupling: &Coupling<S>) -> Welcome {
        Welcome {
            session_id: splitmix64(self.config.session_seed ^ u64::from(user_id)),
            user_id,
            scene: SceneSummary {
                name: self.model.name.clone(),
                kind: S::KIND,
                n: self.model.nv() as u32,
                m: self.model.nc() as u32,
                ball_rates: ConfigLayout::of(&self.model).ball_rates().iter().map(|&r| r as u32).collect(),
                op_dim: S::DIM as u8,
                op_name: self.model.ops[op].name.clone(),
                length_scale: self.model.length_scale,
            },
            ve_rate_hz: self.config.ve_rate_hz,
            snapshot_rate_hz: self.config.snapshot_rate_hz,
            mapping: mapping.clone(),
            coupling: design::coupling_message::<S>(&coupling.stiffness, &coupling.damping),
            op: OpSummary::from_reach(&self.reaches[op], &coupling.op_pose),
        }
    }
}

/// A well-mixed 64-bit hash (SplitMix64), for session ids that do not reveal the user count.
fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}
