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
//!    plus the position channels' reaction, taken at the end of the step (`channel_reaction`);
//! 4. the controllers, with `e = x_d ⊖ x_m`: joint constraint (stiffness or impedance mode), impedance with
//!    Λ̂⁻¹ in the free directions, position channels, contact force channel;
//! 5. safety: non-finite check, output gate (ramp in, fade out on stale snapshots), the device port's passivity
//!    damper (`device_port`), device limits;
//! 6. the uplink (every tick, or through the perceptual deadband).
//!
//! **What drives the local model.** The hand wrench F_h (only when a sensor measures it: without one, feeding
//! an estimate forward would make the user feel the device's mass instead of the linkage's, because the
//! impedance controller that reshapes the device needs the same measurement) plus the reaction of the
//! position channels, equal and opposite to what the device receives in the free directions, so the
//! teleoperator exchanges no net energy of its own there. It is taken at the end of the model's step
//! (`channel_reaction`), so the channels are as stiff as the device renders however light the OP is. Along
//! the constrained directions the device feels the channels as part of the wall, and the model takes their
//! reaction only at the walls' gains (`ResolvedGains::wall_stiffness`), which a step at its start would
//! hold: taken whole, it would drag the model through the walls. Other users' wrenches are not added: the
//! server's b̂ already contains their effect. The uplink's
//! `hand_wrench` is exactly this driving wrench, so the VE's force channel pushes the VE's OP as the hand
//! pushes the model.

pub mod config;
pub mod controllers;
pub mod design;
pub mod safety;

mod bias_trust;
mod channel_reaction;

mod deadband;
pub mod device_port;
mod error;
mod gains;
mod index;
mod intake;
mod model;
mod observer;
mod passive_update;
mod path_follower;
pub mod port_passivity;
mod pose_memos;
mod pull;
mod report;
mod scales;
mod stages;

use std::time::Duration;

use kinloop_linkage::algorithms::configuration::ConfigLayout;
use kinloop_linkage::algorithms::local_model::ConfigSpaceLocalModel;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::arrival_gaps::ArrivalGaps;
use kinloop_protocol::codec::limits::{MAX_SCENE_SPEED, MAX_SCENE_WRENCH};
use kinloop_protocol::passivity::{EnergyReports, PortBooks};
use kinloop_protocol::{SessionShape, Snapshot, Uplink, Welcome};

pub use config::{
    ConstraintMode, ConstraintWeighting, ControllerGains, CoreConfig, GainChoice, ModelForm, SafetyConfig,
    UplinkDeadband, FREE_BLEND_PER_ROUND_TRIP, LONGEST_STALE_AGE, STALE_GAP_MARGIN,
};
pub use error::CoreError;
pub use gains::ResolvedGains;
pub use intake::SnapshotRejection;
pub use passive_update::TANK_CAPACITY_J as UPDATE_TANK_CAPACITY_J;
pub use report::{ControllerWrenches, CoreStats, TickOutput, TickReport};
pub use scales::Scales;

use bias_trust::BiasTrust;
use controllers::ConstraintFrame;
use deadband::Deadband;
use index::{Boxes, DeviceIndex};
use intake::SnapshotTerms;
use model::LocalModel;
use observer::HandObserver;
use passive_update::EnergyTank;
use path_follower::PathFollower;
use pose_memos::PoseMemos;
use safety::{usable_device_state, OutputGate, PartScales, WrenchLimits};

/// Longest step a late tick may take (a stalled loop must not integrate a huge step).
const MAX_STEP_S: f64 = 0.02;

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
    /// b̂'s rate on the VE's clock, which weighs it as the impedance controller's feedforward (`bias_trust`).
    bias_trust: Box<BiasTrust<S>>,
    index: DeviceIndex<S>,
    gate: OutputGate,
    observer: HandObserver<S>,
    /// The limits' scales on the last command (what the channels' reaction at the end of a step assumes).
    last_scales: PartScales,
    last_command: S::OpVec,
    last_now: Option<Duration>,
    one_way_delay: Duration,
    deadband: Deadband<S>,
    /// The energy the model's updates may still put into the coupling (`passive_update`).
    tank: EnergyTank,
    /// The energy b̂'s feedforward may still put into the device (`bias_trust::BIAS_TANK_CAPACITY_J`).
    bias_tank: EnergyTank,
    /// The load feedforward the device rendered last tick (`CoreConfig::load_feedforward`, VE units, after
    /// the gate and the limits): the local model is held up by as much on its next step.
    load_held: S::OpVec,
    /// The load feedforward asked for last tick, before the gate and the limits (`HapticCore::ramp_load`).
    load_fed: S::OpVec,
    /// Gaps between the snapshots taken as newest: what a silence is judged against (`stale_after`).
    snapshot_gaps: ArrivalGaps,
    /// This end of the two-port: the local model's port, where the user's wrench (hand and device
    /// reaction) drives the model (`kinloop_protocol::passivity`); its books go up in every uplink.
    port: PortBooks,
    /// The VE coupling's books, as the snapshots report them (checked).
    server_energy: EnergyReports,
    port_passivity: port_passivity::PortPassivity,
    /// The device's port: the motors' work on the device, checked against the VE's books (`device_port`).
    device_port: device_port::DevicePort,
    uplink: Uplink,
    /// Trigonometric anchors for the three pose streams converted every tick or snapshot.
    pose_memos: PoseMemos<S>,
    stats: CoreStats,
    report: TickReport<S>,
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
        let gains = gains::resolve_gains::<S>(&config, welcome, &scales)?;
        let shape = scene.shape();
        let rates = scene.ball_rates.iter().map(|&r| r as usize).collect();
        let layout = ConfigLayout::new(shape.n, rates)?;
        let config_shape = (config.form == ModelForm::Config).then_some((layout, shape.m));
        let pose_len = OpPose::<S>::wire_len();
        let k = S::DIM;
        let uplink = Uplink::at_rest(0, k, pose_len);
        // A pinned grasp renders no torque, whatever the device could (`Mapping::rigid_grasp`).
        let limits = WrenchLimits {
            max_torque_nm: if welcome.mapping.rigid_grasp { device.wrench_limits().max_torque_nm } else { 0.0 },
            ..device.wrench_limits()
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
            incoming: Box::new(SnapshotTerms::new(config_shape.as_ref())),
            pending: Box::new(SnapshotTerms::new(config_shape.as_ref())),
            pending_fresh: false,
            newest_seq: None,
            active: Box::new(SnapshotTerms::new(config_shape.as_ref())),
            has_snapshot: false,
            model: LocalModel::new(config_shape),
            frame: ConstraintFrame::new(),
            local: ConstraintFrame::new(),
            path,
            trust: 1.0,
            bias_trust: Box::new(BiasTrust::new()),
            index: DeviceIndex::identity(scales.position),
            gate: OutputGate::new(&config.safety, config.period),
            observer: HandObserver::new(config.hand_observer_bandwidth, device_mass),
            last_scales: PartScales { force: 1.0, torque: 1.0 },
            last_command: S::OpVec::zero(),
            last_now: None,
            one_way_delay: Duration::ZERO,
            deadband: Deadband::new(config.deadband.map(|d| d.in_ve_units(&scales))),
            tank: EnergyTank::new(passive_update::TANK_CAPACITY_J, scales.torque),
            bias_tank: EnergyTank::new(bias_trust::BIAS_TANK_CAPACITY_J, scales.torque),
            load_held: S::OpVec::zero(),
            load_fed: S::OpVec::zero(),
            snapshot_gaps: ArrivalGaps::new(),
            port: PortBooks::default(),
            server_energy: EnergyReports::default(),
            port_passivity: port_passivity::PortPassivity::new(port_passivity::PORT_ALLOWANCE_J, scales.torque),
            device_port: device_port::DevicePort::new(device_port::DEVICE_PORT_ALLOWANCE_J),
            uplink,
            pose_memos: PoseMemos::default(),
            stats: CoreStats::default(),
            report: TickReport::idle(Duration::ZERO),
            config,
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

    /// The output gate's gain now, in [0, 1] (0: the core commands no force).
    pub fn output_gain(&self) -> f64 {
        self.gate.gain()
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

    /// The configuration-space local model (its q, q̇ and frozen terms) while it steps the model.
    pub fn config_local_model(&self) -> Option<&ConfigSpaceLocalModel<S>> {
        self.model.config_in_use()
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

    /// How old the active snapshot may grow at `now` before it is stale and the output fades:
    /// `SafetyConfig::max_snapshot_age`, or on a link whose snapshots have lately come with longer gaps
    /// ([`kinloop_protocol::arrival_gaps`]: a jittery path delivers in bunches) [`STALE_GAP_MARGIN`] times
    /// the longest of them, never more than [`LONGEST_STALE_AGE`]. A silence the link has been making all
    /// along is not a link gone: faded there, the force went out and came back every few seconds, and each
    /// return released the stretched device-model coupling into the hand.
    pub fn stale_after(&self, now: Duration) -> Duration {
        let link = self.snapshot_gaps.longest(now).mul_f64(STALE_GAP_MARGIN).min(LONGEST_STALE_AGE);
        self.config.safety.max_snapshot_age.max(link)
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
        let _ = self.server_energy.check(
            snapshot.server_time_s,
            &e.received_j,
            &e.emitted_j,
            MAX_SCENE_WRENCH * MAX_SCENE_SPEED,
            0.0,
        );
        std::mem::swap(&mut self.incoming, &mut self.pending);
        self.pending_fresh = true;
        self.newest_seq = Some(snapshot.seq);
        self.snapshot_gaps.arrived(now);
        self.stats.snapshots_accepted += 1;
        Ok(true)
    }

    /// One haptic tick at `now` with the device reading `device`: the stages in the order of the module
    /// documentation.
    pub fn tick(&mut self, now: Duration, device: &crate::device::DeviceState<S>) -> TickOutput<'_, S> {
        let dt_s = self.advance_clock(now);
        let device_usable = usable_device_state::<S>(&device.pose, &device.twist);
        let hand_off = device.grasped == Some(false);
        if self.pending_fresh && device_usable {
            self.apply_pending(now, &device.pose, hand_off);
        }
        if !self.has_snapshot || !device_usable {
            return self.idle_tick(now, device_usable);
        }
        let intake = self.intake(now, device, hand_off);
        self.pull_model(now, dt_s, &intake, device.hand_wrench.is_some());
        let hand = self.step_model(dt_s, device, &intake);
        let mut asked = self.controllers(now, &intake, &hand);
        self.ramp_load(dt_s, &hand, &mut asked);
        self.pay_bias(dt_s, &intake, &mut asked);
        let out = self.safety(now, dt_s, &device.twist, &intake, &asked);
        self.hold_load(&hand, &asked);
        let mut flags = intake.flags | out.flags;
        let send = self.uplink(now, &intake, &mut flags, &hand.model, &asked.model_pose);
        self.record(now, &intake, &hand, &asked, &out, flags);
        TickOutput { command: out.command, uplink: send.then_some(&self.uplink), report: &self.report }
    }
}
