//! Each user's local model of interaction (paper Fig 3), built after a tick at the snapshot rate.
//!
//! **State.** A snapshot describes the VE state *after* the tick. `forward_dynamics` is evaluated once at
//! that state with every user's *hand* wrench (force channel) and the contacts, but without the
//! graphics-controller PDs and passivity dampers (`Evaluation::ProbeHands`): it leaves the kinematics, D, W,
//! the KKT factor of D *without* the implicit coupling mass (what eq 9 needs), that q̈ and every coupling's
//! full wrench at that state. All users share it.
//!
//! **Per operational point**, shared by every user holding it (users are visited grouped by OP): Λ̂⁻¹, the
//! OP's acceleration `J q̈ + J̇q̇`, the SVD, the OP's pose and twist. Only b̂'s own-wrench part and the lists
//! are a user's own, so a session of many users on few OPs (the testbed has one) pays the op-space algebra
//! once per OP, not per user. Contacts overwrite the op-space workspace, so a user with contact terms ends
//! the sharing and the next user on that OP computes afresh.
//!
//! **Per user** at its operational point h:
//! - Λ̂⁻¹ with the loops closed (eq 9), `op_space_inertia`; sent as its upper triangle, row-major;
//! - b̂ = J q̈ + J̇q̇ − Λ̂⁻¹ F_u, the OP acceleration minus the effect of the user's own hand wrench F_u (the
//!   client's local model applies it itself); contacts, gravity and the closure's velocity terms stay in b̂
//!   (the velocity terms along the OP's free directions only as far as the user's round trip leaves its
//!   model's velocity the VE's: `VelocityTerms`, `decoupled`), and so do the other users' hand wrenches,
//!   weighted by how long the round trip is (`sharing`: under delay their exchange is a loop). Their share,
//!   `J P Σ Jᵢᵀ F_h,i − Λ̂⁻¹ F_u` over every pushing user, comes from one solve a round with the probe's
//!   factors (`kkt::constrained_response`). No user's PD coupling stays in b̂: it is a numerical tie between
//!   the VE and one local model, and in another user's frozen b̂ it would act as a stiff spring seen one
//!   snapshot late without its stiffness — two users on one OP went unstable that way. A user feels the
//!   others through their hands (in b̂) and through the VE, which its own local model is blended toward;
//! - the SVD of the unit-consistent Λ̃⁻¹ (eq 10, 12): directions in `(v, L ω)` coordinates, singular values,
//!   the constraint count;
//! - OP pose and twist, how many other manipulators there are (the local model needs only that), and the
//!   configuration-space terms of eq 11 when the user asked for them.
//!
//! **Contacts** within `contact_margin` length scales (the nearest `MAX_LOCAL_CONTACTS`, wherever on the linkage: the
//! loops carry a contact's force to any OP) enter the local model along their normal n. With
//! `P = D⁻¹ − D⁻¹Wᵀ S⁺ W D⁻¹` (the KKT inverse's top-left block) and the factors of eq 9 (`Ỹ`: `U⁻¹ Jᵀ`
//! with the kept closures' directions projected out, see `kinloop_linkage::algorithms::op_space`), the cross inertia
//! between the OP frame h and the contact point c is `Λ⁻¹_hc = J_h P J_cᵀ = Ỹ_hᵀ Ỹ_c`. The user's `Ỹ_h` is
//! kept, `frame_point_inertia` at the contact point gives `Ỹ_c` and `Λ⁻¹_cc`, and:
//! - `op_coupling = Λ⁻¹_hc n = Ỹ_hᵀ (Ỹ_c n)`: the OP acceleration per unit normal force and,
//!   by symmetry of P, the gap acceleration per unit OP wrench;
//! - `mobility = nᵀ Λ⁻¹_cc n`;
//! - `bias_accel = nᵀ (J_c q̈ + J̇_c q̇) − op_coupling · F_u − mobility · f_c`, the gap acceleration with
//!   neither the user's wrench nor this contact's own penalty force f_c (both of which the local model adds);
//! - and the user's b̂ loses `op_coupling f_c` for every contact sent, for the same reason. The other sent
//!   contacts' forces stay frozen in each contact's `bias_accel` (the local model has no contact-contact
//!   cross inertia); contacts beyond the nearest `MAX_LOCAL_CONTACTS` stay frozen in b̂.

use kinloop_linkage::algorithms::constraint_directions::{
    constraint_directions_from, ConstraintDirections, DEFAULT_THRESHOLD,
};
use kinloop_linkage::algorithms::contact::detect_contacts;
use kinloop_linkage::algorithms::jacobian::apply_wrench;
use kinloop_linkage::algorithms::kkt::constrained_response;
use kinloop_linkage::algorithms::op_space::{frame_point_inertia, op_space_inertia};
use kinloop_linkage::algorithms::velocity_product::velocity_product_acceleration;
use kinloop_linkage::error::DynamicsError;
use kinloop_linkage::model::data::Data;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, math::space::MatOps, math::space::Space, math::space::VecOps, model::Model,
};
use kinloop_linkage::{
    algorithms::local_model::{op_acceleration, op_twist, LocalModelTerms, MAX_LOCAL_CONTACTS},
    math::space::OpPose,
};
use kinloop_protocol::codec::validate;
use kinloop_protocol::{ConfigTerms, ContactTerm, Role};
use nalgebra::{DMatrix, DVector};

use super::events::VeEvent;
use super::metrics::{self, SharingMetrics};
use super::sharing::{inertial_weight, others_weight, shared_bias};
use super::users::{Presence, User};
use super::ve_forces::{Evaluation, VeForces};
use super::{Coupling, SnapshotScratch, VeCore};

impl<S: Space> VeCore<S> {
    /// Builds every present user's snapshot at the current state (see the module documentation).
    pub(super) fn build_snapshots(&mut self) {
        self.metrics.snapshot_ticks += 1;
        // The step may have removed users since the tick began.
        self.refresh_op_order();
        let mut forces = VeForces {
            couplings: &mut self.couplings,
            order: &self.scratch.order,
            contacts: self.contacts.as_mut(),
            evaluation: Evaluation::ProbeHands,
            stage: 0,
        };
        // `forward_dynamics` drops the last step's implicit coupling mass itself (eq 9 needs D alone).
        if let Err(error) = forward_dynamics(&self.model, &mut self.data, &self.q, &self.qd, &mut forces) {
            self.metrics.snapshots_withheld += self.present_users() as u64;
            self.events.push(VeEvent::SnapshotsWithheld { step: self.step, error });
            return;
        }
        let scratch = &mut self.scratch;
        // A new state: nothing computed at any OP yet.
        scratch.at_op.forget();
        let exchange = hands_share(&self.model, &self.data, &self.users, &self.couplings, scratch);
        note_exchange(&mut self.metrics.sharing, &self.users, &self.couplings, &exchange, self.config.exchange_delay_s);
        if self.contacts.is_some() {
            detect_contacts(
                &self.model,
                &self.data.kin,
                self.config.contact_margin * self.model.length_scale,
                &mut scratch.near,
            );
            scratch.near.sort_unstable_by(|a, b| a.gap.total_cmp(&b.gap));
            scratch.near.truncate(MAX_LOCAL_CONTACTS);
        }
        let time_s = self.last_tick_at.as_secs_f64();
        // Each snapshot counts the other manipulators (its own user aside): all its local model needs of them.
        let manipulators = self.users.iter().filter(|user| user.role == Role::Manipulator).count();
        for position in 0..self.scratch.order.len() {
            let index = self.scratch.order[position];
            if self.users[index].presence != Presence::Present {
                continue;
            }
            let mut pose_memo = self.couplings[index].pose_memo;
            let built = build_one(
                &self.model,
                &mut self.data,
                &self.q,
                &self.qd,
                &mut self.users,
                &self.couplings,
                index,
                &mut self.scratch,
                self.contacts.as_ref().map(|c| (c.stiffness, c.damping)),
                manipulators,
                &mut pose_memo,
                &exchange,
                self.config.exchange_delay_s,
            );
            self.couplings[index].pose_memo = pose_memo;
            let user = &mut self.users[index];
            let at_op = &mut self.scratch.at_op;
            let outcome = built.map_err(SnapshotFailure::Dynamics).and_then(|()| {
                let snapshot = user.slot.snapshot_mut();
                snapshot.seq += 1;
                snapshot.server_time_s = time_s;
                user.round_trip.built(snapshot.seq, time_s);
                snapshot.uplink_time_s = self.couplings[index].target_time_s;
                let (books, k) = (&user.passivity.port, snapshot.energy.received_j.len());
                snapshot.energy.received_j.copy_from_slice(&books.received_j[..k]);
                snapshot.energy.emitted_j.copy_from_slice(&books.emitted_j[..k]);
                snapshot.ve_step = self.step;
                // The OP's terms are the same numbers in every snapshot built from `at_op`: checked once.
                let checked = if at_op.checked {
                    validate::snapshot_user_terms(snapshot, &self.shape)
                } else {
                    let op_terms = validate::snapshot_op_terms(snapshot, &self.shape);
                    at_op.checked = op_terms.is_ok() && at_op.op.is_some();
                    op_terms.and_then(|()| validate::snapshot_user_terms(snapshot, &self.shape))
                };
                checked.map_err(SnapshotFailure::Wire)
            });
            match outcome {
                Ok(()) => {
                    user.slot.pending = true;
                    user.constraint_count = user.slot.snapshot().constraint_count;
                    self.metrics.snapshots_built += 1;
                }
                Err(failure) => {
                    user.slot.pending = false;
                    self.metrics.snapshots_withheld += 1;
                    self.events.push(match failure {
                        SnapshotFailure::Dynamics(error) => VeEvent::SnapshotsWithheld { step: self.step, error },
                        SnapshotFailure::Wire(error) => VeEvent::SnapshotInvalid { user: user.id, error },
                    });
                }
            }
        }
        self.snapshot_cursor = 0;
    }

    /// Brings `scratch.order` (every user's index, grouped by OP, then in join order) up to the roster: the
    /// order the snapshots are built in and the couplings evaluated in (see `coupling`).
    pub(super) fn refresh_op_order(&mut self) {
        let scratch = &mut self.scratch;
        if scratch.order_version != self.roster_version {
            scratch.order.clear();
            scratch.order.extend(0..self.users.len());
            let users = &self.users;
            scratch.order.sort_unstable_by_key(|&index| (users[index].op, index));
            scratch.order_version = self.roster_version;
        }
    }
}

/// What a snapshot round computed at one operational point, for every user holding it (see the module
/// documentation). Valid while `data.op` holds that OP's op-space factors.
#[derive(Clone, Copy, Debug)]
pub(super) struct AtOp<S: Space> {
    /// Index of the OP in the model; `None` when nothing valid is held.
    op: Option<usize>,
    /// The terms passed the wire checks (`validate::snapshot_op_terms`) in a snapshot built from them.
    checked: bool,
    /// Λ̂⁻¹ with the loops closed (eq 9).
    inverse_inertia: S::OpMat,
    /// `J q̈ + J̇q̇` under the probe's forces.
    acceleration: S::OpVec,
    /// The part of its velocity terms along the OP's free directions (`VelocityTerms`), once a user of the OP
    /// needed it.
    velocity_free: Option<S::OpVec>,
    /// `J P Σ Jᵢᵀ F_h,i`: the part of `acceleration` that every pushing user's hand makes.
    hands: S::OpVec,
    /// The SVD of the unit-consistent Λ̃⁻¹ (eq 10, 12).
    directions: ConstraintDirections<S>,
    pose: OpPose<S>,
    twist: S::OpVec,
}

impl<S: Space> AtOp<S> {
    /// Nothing held.
    pub(super) fn none() -> Self {
        AtOp {
            op: None,
            checked: false,
            inverse_inertia: S::OpMat::zero(),
            acceleration: S::OpVec::zero(),
            velocity_free: None,
            hands: S::OpVec::zero(),
            directions: ConstraintDirections {
                singular_values: S::OpVec::zero(),
                directions: S::OpMat::zero(),
                count: 0,
                length_scale: 1.0,
            },
            pose: OpPose::identity(),
            twist: S::OpVec::zero(),
        }
    }

    /// Forgets what is held (a new state, or `data.op` overwritten).
    pub(super) fn forget(&mut self) {
        self.op = None;
        self.checked = false;
    }
}

/// The op-space terms at `user`'s OP: those held in `shared` when they are that OP's, else computed there
/// (warm-started from this user's last directions: Λ⁻¹ moves little between snapshots) for the next user.
fn at_op<'a, S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    user: &User,
    shared: &'a mut AtOp<S>,
    hands_qdd: &DVector<f64>,
) -> Result<&'a AtOp<S>, DynamicsError> {
    let op = user.op;
    if shared.op == Some(op) {
        return Ok(shared);
    }
    // `data.op` is about to change: whatever happens, it no longer holds the kept OP's factors.
    shared.forget();
    op_space_inertia(model, data, op)?;
    let inverse_inertia = data.op.inverse_inertia;
    let mut previous = S::OpMat::zero();
    let last = &user.slot.snapshot().directions;
    let warm = (last.len() == S::DIM * S::DIM).then(|| {
        previous.as_mut_slice().copy_from_slice(last);
        &previous
    });
    shared.inverse_inertia = inverse_inertia;
    shared.acceleration = op_acceleration(data);
    for c in 0..S::DIM {
        shared.hands[c] = data.op.jacobian_t.column(c).dot(hands_qdd);
    }
    shared.directions = constraint_directions_from::<S>(&inverse_inertia, model.length_scale, DEFAULT_THRESHOLD, warm);
    shared.velocity_free = None;
    shared.pose = OpPose::of_op(model, data, op);
    shared.twist = op_twist(model, data, op);
    shared.op = Some(op);
    Ok(shared)
}

/// The part of the OP's velocity terms (`kinloop_linkage::algorithms::velocity_product`) along its free
/// directions, which b̂ leaves out: the local model steps with its inertia frozen at the snapshot's, and
/// those terms are the other half of the inertia's change along the motion, work on a frozen model that no
/// one put in. Along the constrained directions (the curvature of the OP's path, which holds the model on
/// it) b̂ keeps them. A workspace of its own: its solves at other velocities leave the probe's factors, which
/// the other users' terms still need, as they were.
#[derive(Clone, Debug)]
pub(super) struct VelocityTerms<S: Space> {
    data: Data<S>,
    signed: DVector<f64>,
}

impl<S: Space> VelocityTerms<S> {
    pub fn new(model: &Model<S>) -> Self {
        VelocityTerms { data: Data::new(model), signed: DVector::zeros(model.nv()) }
    }

    /// The velocity terms of OP `op` at `(q, qd)` projected on the free directions of `directions` (the OP's
    /// own, unit-consistent coordinates); zero when the solves fail (b̂ then keeps them whole).
    fn free_part(
        &mut self,
        model: &Model<S>,
        q: &DVector<f64>,
        qd: &DVector<f64>,
        op: usize,
        directions: &ConstraintDirections<S>,
    ) -> S::OpVec {
        let Ok(terms) = velocity_product_acceleration(model, &mut self.data, q, qd, op, &mut self.signed) else {
            return S::OpVec::zero();
        };
        let scaled = directions.to_scaled(&terms);
        let mut free = S::OpVec::zero();
        for i in 0..S::DIM - directions.count.min(S::DIM) {
            let direction = directions.direction(i);
            free += direction * direction.dot(&scaled);
        }
        let free = directions.twist_from_scaled(&free);
        if free.as_slice().iter().all(|x| x.is_finite()) {
            free
        } else {
            S::OpVec::zero()
        }
    }
}

/// How far `user`'s round trip decouples its local model's velocity from the VE's: the round trip in periods
/// of the user's coupling, at most 1. The VE follows the model through the coupling, so over a round trip
/// much shorter than the coupling's period they move together, and the VE's velocity terms are the model's;
/// over a period or more the model runs a round trip of its own motion ahead. Below [`DECOUPLED_FROM`] (and
/// before a round trip is measured) 0: b̂ as the paper sends it, and the three solves the terms cost are not
/// made.
fn decoupled(user: &User) -> f64 {
    match (user.round_trip.estimate_s(), user.coupling_frequency) {
        (Some(trip), Some(frequency)) if trip.is_finite() && trip > 0.0 => {
            let periods = (trip * frequency.omega / std::f64::consts::TAU).min(1.0);
            if periods >= DECOUPLED_FROM {
                periods
            } else {
                0.0
            }
        }
        _ => 0.0,
    }
}

/// The shortest round trip, in periods of the user's coupling, over which b̂ leaves out the velocity terms
/// along the free directions (`decoupled`): a tenth of a period, 12.5 ms at the coupling's 8 Hz floor. On a
/// local network (a round trip of a few milliseconds against a coupling of 20 Hz) the terms stay whole.
pub const DECOUPLED_FROM: f64 = 0.1;

/// Who pushes and over what round trip: what each user's weight of the others' hands depends on (`sharing`).
struct Exchange {
    /// Manipulators whose hands push.
    pushing: usize,
    /// The longest of their round trips; `None` while one is unmeasured.
    round_trip_s: Option<f64>,
}

/// Fills `scratch.hands_qdd` with the hands' share of the probe's accelerations, `P Σ Jᵢᵀ F_h,i` over every
/// pushing user, at the state in `data` (just solved, so its factors are in place), and says who pushes.
fn hands_share<S: Space>(
    model: &Model<S>,
    data: &Data<S>,
    users: &[User],
    couplings: &[Coupling<S>],
    scratch: &mut SnapshotScratch<S>,
) -> Exchange {
    let mut exchange = Exchange { pushing: 0, round_trip_s: Some(0.0) };
    for (user, c) in users.iter().zip(couplings).filter(|(_, c)| c.is_active()) {
        exchange.pushing += 1;
        let trip = user.round_trip.estimate_s().map(|t| t + held_s(c));
        exchange.round_trip_s = exchange.round_trip_s.zip(trip).map(|(a, b)| a.max(b));
    }
    let hands = &mut scratch.hands_qdd;
    hands.fill(0.0);
    // Only a user with another pushing user to weight needs it (an observer's snapshot weights every pusher's
    // hand, so one pusher and anyone else is enough); alone, the round skips it.
    if exchange.pushing == 0 || users.len() < 2 {
        return exchange;
    }
    // Users are visited grouped by OP: one `Jᵀ Σ F` per run of users at the same point.
    let mut run: Option<(usize, S::OpVec)> = None;
    for &i in &scratch.order {
        let c = &couplings[i];
        if !c.is_active() {
            continue;
        }
        match run.as_mut().filter(|(first, _)| couplings[*first].at_same_point(c)) {
            Some((_, sum)) => *sum += c.hand_part(),
            None => {
                if let Some((first, sum)) = run.take() {
                    let f = &couplings[first];
                    apply_wrench(model, &data.kin, f.body, &f.op_pose.position, &sum, hands);
                }
                run = Some((i, c.hand_part()));
            }
        }
    }
    if let Some((first, sum)) = run {
        let f = &couplings[first];
        apply_wrench(model, &data.kin, f.body, &f.op_pose.position, &sum, hands);
    }
    constrained_response(model, data, hands.as_mut_slice(), &mut scratch.response);
    exchange
}

/// What the jitter buffer holds a user's uplinks (s), which lengthens every exchange through that user.
fn held_s<S: Space>(coupling: &Coupling<S>) -> f64 {
    if coupling.playout.holding() {
        coupling.playout.buffer_s()
    } else {
        0.0
    }
}

/// Counts what the round's weight of the others' hands was judged by (`metrics::SharingMetrics`).
fn note_exchange<S: Space>(
    sharing: &mut SharingMetrics,
    users: &[User],
    couplings: &[Coupling<S>],
    exchange: &Exchange,
    exchange_delay_s: f64,
) {
    if exchange.pushing < 2 {
        return;
    }
    let others = exchange.pushing - 1;
    let below_whole = |trip_s: Option<f64>| others_weight(others, trip_s, exchange_delay_s) < 1.0;
    sharing.rounds += 1;
    let (mut held, mut longest_estimate_s) = (false, Some(0.0f64));
    for (user, c) in users.iter().zip(couplings).filter(|(_, c)| c.is_active()) {
        held |= c.playout.holding();
        let estimate_s = user.round_trip.estimate_s();
        longest_estimate_s = longest_estimate_s.zip(estimate_s).map(|(a, b)| a.max(b));
        sharing.users_over += u64::from(below_whole(estimate_s.map(|t| t + held_s(c))));
    }
    sharing.rounds_held += u64::from(held);
    sharing.rounds_unmeasured += u64::from(exchange.round_trip_s.is_none());
    sharing.rounds_weighted += u64::from(below_whole(exchange.round_trip_s));
    sharing.rounds_over_by_estimate += u64::from(below_whole(longest_estimate_s));
    if let Some(trip_s) = exchange.round_trip_s {
        sharing.trip_bins[metrics::bin(trip_s)] += 1;
    }
}

enum SnapshotFailure {
    Dynamics(DynamicsError),
    Wire(kinloop_protocol::codec::DecodeError),
}

/// Fills user `index`'s snapshot from the evaluated state in `data` (`pose_memo`: that user's
/// `Coupling::pose_memo`).
#[allow(clippy::too_many_arguments)]
fn build_one<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    users: &mut [User],
    couplings: &[Coupling<S>],
    index: usize,
    scratch: &mut SnapshotScratch<S>,
    contact_gains: Option<(f64, f64)>,
    manipulators: usize,
    pose_memo: &mut S::RotParamsMemo,
    exchange: &Exchange,
    exchange_delay_s: f64,
) -> Result<(), DynamicsError> {
    // What of this user's wrench the probe applied: its hand (see the module documentation).
    let own_wrench = couplings[index].hand_part();
    let at = at_op(model, data, &users[index], &mut scratch.at_op, &scratch.hands_qdd)?;
    // The velocity terms along the free directions, as far as this user's round trip decouples its local
    // model's velocity from the VE's (`VelocityTerms`), computed once per OP and round, in a workspace of its
    // own (`data` keeps the probe's factors).
    let decoupled = decoupled(&users[index]);
    let velocity_free = match (decoupled > 0.0, at.velocity_free) {
        (false, _) => S::OpVec::zero(),
        (true, Some(free)) => free,
        (true, None) => {
            let free = scratch.velocity.free_part(model, q, qd, users[index].op, &at.directions);
            scratch.at_op.velocity_free = Some(free);
            free
        }
    };
    let shared = &scratch.at_op;
    // b̂ (`op_space_terms`): the OP's acceleration without this user's own hand, with only the weighted share
    // of the other users' hands and this user's share of the load they no longer carry (`sharing`).
    let own = shared.inverse_inertia * own_wrench;
    let others = exchange.pushing - usize::from(couplings[index].is_active());
    let weight = if others == 0 {
        1.0
    } else {
        let mapping = &users[index].mapping;
        let mut linear_mobility = 0.0f64;
        for a in 0..<S::Point as VecOps>::LEN {
            linear_mobility = linear_mobility.max(shared.inverse_inertia[(a, a)]);
        }
        let inertial = inertial_weight(others, linear_mobility, mapping.position_scale, mapping.force_scale);
        others_weight(others, exchange.round_trip_s, exchange_delay_s).min(inertial)
    };
    let acceleration = shared.acceleration - velocity_free * decoupled;
    let bias = shared_bias(&acceleration, &shared.hands, &own, others, weight);

    let other_manipulators = manipulators - usize::from(users[index].role == Role::Manipulator);
    let slot = &mut users[index].slot;
    if let Some(scratch_terms) = slot.config_scratch.as_mut() {
        scratch_terms.fill_from(model, data, q, qd, &own_wrench, LocalModelTerms::full());
    }
    let config_scratch = slot.config_scratch.as_ref();
    let (snapshot, spare) = match &mut slot.message {
        kinloop_protocol::Datagram::Snapshot(s) => (s, &mut slot.spare_contacts),
        kinloop_protocol::Datagram::Uplink(_) => unreachable!("a snapshot slot holds a snapshot"),
    };
    set_from(&mut snapshot.op_pose, OpPose::<S>::wire_len(), |out| shared.pose.to_slice_memo(out, pose_memo));
    set(&mut snapshot.op_twist, shared.twist.as_slice());
    set_upper_triangle::<S>(&mut snapshot.inverse_inertia, &shared.inverse_inertia);
    set(&mut snapshot.bias_accel, bias.as_slice());
    set(&mut snapshot.directions, shared.directions.directions.as_slice());
    set(&mut snapshot.singular_values, shared.directions.singular_values.as_slice());
    snapshot.constraint_count = shared.directions.count as u8;
    if let (Some(wire), Some(terms)) = (snapshot.config.as_mut(), config_scratch) {
        write_config_terms(wire, terms);
    }
    snapshot.other_manipulators = u16::try_from(other_manipulators).unwrap_or(u16::MAX);

    // Contacts last: frame_point_inertia overwrites data.op.
    spare.append(&mut snapshot.contacts);
    if let Some((stiffness, damping)) = contact_gains.filter(|_| !scratch.near.is_empty()) {
        scratch.op_y.copy_from(&data.op.y_closed);
        // `frame_point_inertia` at the contacts overwrites `data.op`.
        scratch.at_op.forget();
        for near_index in 0..scratch.near.len() {
            let Some(mut term) = spare.pop() else { break };
            let contact = scratch.near[near_index];
            let penalty =
                fill_contact_term(model, data, scratch, &contact, &own_wrench, (stiffness, damping), &mut term)?;
            // The probe applied this contact's penalty, so b̂ holds its effect on the OP; the local model adds
            // the live penalty itself, so take the frozen one out of b̂ (else the contact pushes twice).
            for (b, g) in snapshot.bias_accel.iter_mut().zip(&term.op_coupling) {
                *b -= g * penalty;
            }
            snapshot.contacts.push(term);
        }
    }
    Ok(())
}

/// `out ← values`, within `out`'s capacity once warmed up; in place when the length is already right (every
/// snapshot after a user's first: no capacity checks, which cost more than the copy of a few numbers).
fn set(out: &mut Vec<f64>, values: &[f64]) {
    if out.len() == values.len() {
        for (o, v) in out.iter_mut().zip(values) {
            *o = *v;
        }
    } else {
        out.clear();
        out.extend_from_slice(values);
    }
}

/// `out ← len` numbers written by `write`.
fn set_from(out: &mut Vec<f64>, len: usize, write: impl FnOnce(&mut [f64])) {
    out.clear();
    out.resize(len, 0.0);
    write(out);
}

/// Upper triangle of a symmetric operational matrix, row-major.
fn set_upper_triangle<S: Space>(out: &mut Vec<f64>, m: &S::OpMat) {
    set_upper_triangle_of(out, S::DIM, |r, c| m[(r, c)]);
}

/// Upper triangle of a dynamic symmetric matrix, row-major.
fn set_upper_triangle_dyn(out: &mut Vec<f64>, m: &DMatrix<f64>) {
    set_upper_triangle_of(out, m.nrows(), |r, c| m[(r, c)]);
}

/// `out ←` the upper triangle, row-major, of the k×k matrix with entries `at(r, c)`; in place when the length
/// is already right (as [`set`]).
#[inline(always)]
fn set_upper_triangle_of(out: &mut Vec<f64>, k: usize, at: impl Fn(usize, usize) -> f64) {
    let entries = (0..k).flat_map(|r| (r..k).map(move |c| (r, c)));
    if out.len() == k * (k + 1) / 2 {
        for (o, (r, c)) in out.iter_mut().zip(entries) {
            *o = at(r, c);
        }
    } else {
        out.clear();
        out.extend(entries.map(|(r, c)| at(r, c)));
    }
}

fn write_config_terms(wire: &mut ConfigTerms, terms: &kinloop_linkage::algorithms::local_model::ConfigSpaceTerms) {
    set(&mut wire.q, terms.q.as_slice());
    set(&mut wire.qd, terms.qd.as_slice());
    set_upper_triangle_dyn(&mut wire.mass_matrix, &terms.mass_matrix);
    set(&mut wire.closure_jacobian, terms.closure_jacobian.as_slice());
    set(&mut wire.closure_bias_stab, terms.closure_bias_stab.as_slice());
    set(&mut wire.generalized_bias, terms.generalized_bias.as_slice());
    set(&mut wire.op_jacobian, terms.op_jacobian.as_slice());
    set(&mut wire.op_bias, terms.op_bias.as_slice());
}

/// One contact's local-model term (formulas in the module documentation). Overwrites `data.op`. Returns
/// the penalty force the probe applied at this contact.
fn fill_contact_term<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    scratch: &mut SnapshotScratch<S>,
    contact: &kinloop_linkage::algorithms::contact::Contact<S>,
    own_wrench: &S::OpVec,
    (stiffness, damping): (f64, f64),
    term: &mut ContactTerm,
) -> Result<f64, DynamicsError> {
    frame_point_inertia(model, data, contact.body, &contact.point)?;
    let normal = contact.normal.as_slice();
    let lin = normal.len();
    let ws = &data.op;
    for i in 0..model.nv() {
        scratch.contact_y[i] = (0..lin).map(|a| ws.y_closed[(i, a)] * normal[a]).sum();
    }
    let mut coupling = S::OpVec::zero();
    for j in 0..S::DIM {
        coupling[j] = scratch.op_y.column(j).dot(&scratch.contact_y);
    }
    let mut mobility = 0.0;
    let mut gap_accel = 0.0;
    for a in 0..lin {
        for b in 0..lin {
            mobility += normal[a] * ws.inverse_inertia[(a, b)] * normal[b];
        }
        let accel_a = ws.jdot_qdot[a] + ws.jacobian_t.column(a).dot(&data.qdd);
        gap_accel += normal[a] * accel_a;
    }
    let gap_rate = contact.normal.dot(&data.kin.point_velocity(Some(contact.body), &contact.point));
    let penalty = if contact.gap < 0.0 { (-stiffness * contact.gap - damping * gap_rate).max(0.0) } else { 0.0 };
    set(&mut term.point, contact.point.as_slice());
    set(&mut term.normal, normal);
    term.depth = -contact.gap;
    term.normal_velocity = gap_rate;
    set(&mut term.op_coupling, coupling.as_slice());
    term.mobility = mobility.max(0.0);
    term.bias_accel = gap_accel - coupling.dot(own_wrench) - mobility * penalty;
    term.stiffness = stiffness;
    term.damping = damping;
    Ok(penalty)
}
