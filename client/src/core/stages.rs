//! The stages of a tick other than the model's pull (`pull`): taking the newest snapshot and reading the
//! device (intake), stepping the local model, the controllers, the safety envelope, the uplink and the
//! report. `HapticCore::tick` conducts them in that order (see the module documentation of `core`).

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{clip_wrench_parts, Space, VecOps};
use kinloop_protocol::codec::limits::MAX_WRENCH;
use kinloop_protocol::passivity::MAX_AXES;
use kinloop_protocol::uplink_flags;

use super::bias_trust::paid_bias;
use super::channel_reaction::end_of_step_reaction;
use super::config::{LOAD_FEEDFORWARD_RISE_S, LOAD_FEEDFORWARD_SHARE};
use super::controllers::{
    channel_felt, contact_feedforward, hadamard, impedance_free, joint_constraint_impedance,
    joint_constraint_stiffness, position_channel, project_wrench,
};
use super::index::DeviceIndex;
use super::passive_update::damper_dissipation;
use super::safety::{brake, force_ratio, limit_wrench_parts, mask_unactuated, usable_model_state, within};
use super::{ConstraintMode, ControllerWrenches, HapticCore, TickOutput, TickReport};
use crate::device::DeviceState;

/// What the intake read this tick: the device mapped into the VE, the active snapshot's age, and the flags
/// known so far.
pub(super) struct Intake<S: Space> {
    /// Device pose in the VE.
    pub device_pose: OpPose<S>,
    /// Device twist in the VE.
    pub device_twist: S::OpVec,
    /// How long ago the active snapshot arrived.
    pub age: Duration,
    /// The active snapshot is older than `SafetyConfig::max_snapshot_age`.
    pub stale: bool,
    /// No hand holds the handle (the presence sensor says so).
    pub hand_off: bool,
    /// Uplink flags so far.
    pub flags: u32,
}

/// The hand's wrench as the model step used it (VE units).
pub(super) struct HandWrenches<S: Space> {
    /// Measured by a force sensor, within range and the device's peaks.
    pub sensed: Option<S::OpVec>,
    /// The observer's estimate.
    pub estimate: S::OpVec,
    /// What the acceleration-zeroing controller cancels: the measured wrench, else the estimate when the
    /// observer runs.
    pub for_constraint: Option<S::OpVec>,
    /// What drove the local model (and goes up in the uplink).
    pub model: S::OpVec,
}

/// What the controllers ask for this tick (VE units).
pub(super) struct Requests<S: Space> {
    /// Model pose after the step.
    pub model_pose: OpPose<S>,
    /// `x_d ⊖ x_m` on the controlled axes.
    pub error: S::OpVec,
    /// Its rate.
    pub error_rate: S::OpVec,
    /// Position channels.
    pub position_channel: S::OpVec,
    /// Joint-constraint controller.
    pub joint_constraint: S::OpVec,
    /// Impedance controller.
    pub impedance: S::OpVec,
    /// The part of it that renders b̂ (`M b̂` in the free directions, as weighted; on a device without a sensor
    /// the load `Λ̂ b̂`, see `CoreConfig::load_feedforward`), which `pay_bias` prices.
    pub bias_feedforward: S::OpVec,
    /// The share of b̂ that may be stale (`BiasTrust::assess`): the part of its work the tank pays.
    pub bias_at_risk: f64,
    /// Contact force channel.
    pub contact: S::OpVec,
    /// Their sum.
    pub requested: S::OpVec,
    /// What the device receives from the position channels' dampers once the joint-constraint controller has
    /// acted, the joint-constraint controller's damper included (what fills the update's tank).
    pub damping_felt: S::OpVec,
}

/// What the safety envelope let through.
pub(super) struct Commanded<S: Space> {
    /// Device units.
    pub command: S::OpVec,
    /// Output gate gain.
    pub gain: f64,
    /// Smaller of the limits' scales (1 = not clamped).
    pub clamp_scale: f64,
    /// Flags the envelope raised.
    pub flags: u32,
}

impl<S: Space> HapticCore<S> {
    /// The tick's step in seconds (the period on the first tick, at most `MAX_STEP_S` after a stall).
    pub(super) fn advance_clock(&mut self, now: Duration) -> f64 {
        let dt_s = match self.last_now {
            Some(last) => now.saturating_sub(last).as_secs_f64().min(super::MAX_STEP_S),
            None => self.config.period.as_secs_f64(),
        };
        self.last_now = Some(now);
        self.stats.ticks += 1;
        dt_s
    }

    /// Stage 1: the device reading mapped into the VE, the active snapshot's age, and the flags they raise.
    ///
    /// No hand on the handle (a presence sensor says so): a free device must not be driven, so the output
    /// fades as for stale data while a damper brakes the handle, and the local model parks where it is (no
    /// one drives it), so the VE's coupling holds the linkage where the hand left it rather than letting it
    /// fall. When the hand returns, the model restarts on the VE and the output ramps in again.
    pub(super) fn intake(&mut self, now: Duration, device: &DeviceState<S>, hand_off: bool) -> Intake<S> {
        self.stats.active_ticks += 1;
        let mut flags = 0;
        if self.config.constraint_mode == ConstraintMode::Impedance {
            flags |= uplink_flags::IMPEDANCE_MODE;
        }
        let device_pose = self.index.apply(&device.pose);
        let device_twist = self.scales.twist_to_ve::<S>(&device.twist);
        let age = now.saturating_sub(self.active.received_at);
        let stale = age > self.stale_after(now);
        if hand_off {
            flags |= uplink_flags::HAND_OFF;
            self.stats.hand_off_ticks += 1;
        }
        if stale {
            flags |= uplink_flags::STALE_SNAPSHOT | uplink_flags::FADING;
            self.stats.stale_ticks += 1;
        }
        Intake { device_pose, device_twist, age, stale, hand_off, flags }
    }

    /// The VE's OP predicted to `now`: the snapshot's pose moved along its twist for its age plus the one-way
    /// delay (at most the staleness limit).
    pub(super) fn predicted_op(&self, now: Duration) -> OpPose<S> {
        let mut pose = self.active.op_pose;
        pose.integrate(&self.active.op_twist, self.horizon(now).as_secs_f64());
        pose
    }

    /// How long the active snapshot's terms are held for at `now`: its age plus the one-way delay, at most
    /// the staleness limit.
    pub(super) fn horizon(&self, now: Duration) -> Duration {
        (now.saturating_sub(self.active.received_at) + self.one_way_delay).min(self.config.safety.max_snapshot_age)
    }

    /// How far behind the VE the b̂ the impedance controller renders is at `now`: the snapshot's horizon plus
    /// the lag of the first-order filter the controllers' terms pass through (`terms_time_constant` τ: a
    /// filtered ramp trails its input by τ). Near a dead centre b̂ turns within a few milliseconds, so at 0 ms
    /// one way the filter's lag is most of what `bias_trust` must weigh.
    pub(super) fn bias_horizon(&self, now: Duration) -> Duration {
        self.horizon(now) + self.config.terms_time_constant
    }

    /// Makes the pending snapshot the active one.
    pub(super) fn apply_pending(&mut self, now: Duration, device: &OpPose<S>, hand_off: bool) {
        std::mem::swap(&mut self.pending, &mut self.active);
        self.pending_fresh = false;
        let first = !self.has_snapshot;
        // With the output fully faded (start, or a link that came back) nothing is felt, so the model may jump
        // onto the VE instead of being pulled there; not while the hand is off, when the model stays parked
        // where the VE holds it (jumping onto a VE that follows the model would walk both away).
        let restart = first || (self.gate.gain() == 0.0 && !hand_off);
        self.model.update(&self.active);
        if restart {
            self.bias_trust.reset();
        }
        let keep_s = self.config.safety.max_snapshot_age.as_secs_f64();
        self.bias_trust.observe(self.active.server_time_s, &self.active.bias, self.length_scale, keep_s);
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
            // indexed (extrapolating a linkage that was moving at the join would put the model ahead of the
            // device by its speed times the delay, and both loops would fight over the gap). Later restarts
            // (a link that came back) find a VE that moves by itself: the model starts where it is now.
            if self.active.uplink_time_s > 0.0 {
                self.model.set_state(self.predicted_op(now), self.active.op_twist);
            } else {
                self.model.set_state(self.active.op_pose, S::OpVec::zero());
            }
            self.model.set_inverse_inertia(&self.frame.inverse_inertia);
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

    /// Stage 3: steps the local model (eq 11/13) under the user's wrench and books the power into it. The
    /// position channels' reaction is taken at the end of the step (`channel_reaction`): whole in the free
    /// directions, and along the constrained ones (where the device feels them as part of the wall) only up
    /// to the walls' gains (`ResolvedGains::wall_stiffness`).
    pub(super) fn step_model(&mut self, dt_s: f64, device: &DeviceState<S>, intake: &Intake<S>) -> HandWrenches<S> {
        // A sensed wrench past the protocol's range is no reading (the server would refuse the uplink).
        // The sensor saturates at the device's peaks (a hand can push harder than the motors, but the
        // linkage feels what the device can answer); a pin passes no torque (its limit is 0).
        let sensed = device.hand_wrench.filter(|w| within(w.as_slice(), MAX_WRENCH)).map(|w| {
            let (in_range, _) = clip_wrench_parts::<S>(&w, self.limits.max_force_n, self.limits.max_torque_nm);
            self.scales.wrench_to_ve::<S>(&in_range)
        });
        let estimate = self.observer.update(dt_s, &intake.device_twist, &self.last_command);
        let for_constraint = sensed.or((self.config.hand_observer_bandwidth > 0.0).then_some(estimate));
        let model = if intake.hand_off {
            self.model.set_state(self.model.pose(), S::OpVec::zero());
            S::OpVec::zero()
        } else {
            // Without a sensor the model is held up by the load the device rendered last tick
            // (`CoreConfig::load_feedforward`): the pair's two ends cancel, and the channels carry no load.
            let own = sensed.unwrap_or(-self.load_held);
            // The acceleration-zeroing controller cancels the channels along the constrained directions.
            let walls = !(self.config.constraint_mode == ConstraintMode::Impedance && for_constraint.is_some());
            let wrench = own + self.channels_at_end_of_step(dt_s, intake, &own, walls);
            self.model.step(dt_s, &wrench);
            if self.pinned() {
                self.model.turn_as_pinned();
            }
            wrench
        };
        let mut power_out = [0.0; MAX_AXES];
        let model_twist_after = self.model.twist();
        for (a, p) in power_out.iter_mut().enumerate().take(S::DIM) {
            // Power into the local model is energy this end of the two-port received.
            *p = -model[a] * model_twist_after[a];
        }
        self.port.book(&power_out[..S::DIM], dt_s);
        // Only for a user alone on the linkage: with others on it, this user's coupling passes on energy
        // between their hands and the linkage that this end never sees (`port_passivity`).
        if self.config.port_passivity && !self.active.shared {
            let (remote, own) = (&self.server_energy.accepted, &self.port);
            let braked = self.port_passivity.brake::<S>(remote, own, &self.local.inertia, &model_twist_after);
            if braked != model_twist_after {
                self.model.set_state(self.model.pose(), braked);
            }
        }
        HandWrenches { sensed, estimate, for_constraint, model }
    }

    /// The position channels' reaction at the end of the model's step under `own` (`channel_reaction`), as
    /// the device renders it under the gate's gain and the limits' scales of the last tick: whole in the free
    /// directions, at the walls' gains along the constrained ones where `walls` (softened as the controllers
    /// soften them). Zero when it cannot be solved.
    fn channels_at_end_of_step(&self, dt_s: f64, intake: &Intake<S>, own: &S::OpVec, walls: bool) -> S::OpVec {
        let (l, p) = (self.length_scale, &self.local.projector);
        let (gain, scales) = (self.gate.gain(), self.last_scales);
        let trust = if walls { self.linearization_trust() } else { 0.0 };
        let error = self.controlled(intake.device_pose.difference(&self.model.pose()));
        let (inverse_inertia, free) = self.model.step_response(dt_s, own);
        let g = &self.gains;
        let rendered = |whole: &S::OpVec, wall: &S::OpVec| {
            let taken = channel_felt::<S>(p, l, 1.0, true, whole) + project_wrench::<S>(p, l, wall) * trust;
            scales.apply::<S>(&mask_unactuated::<S>(&taken, &self.limits)) * gain
        };
        end_of_step_reaction::<S>(
            dt_s,
            &inverse_inertia,
            &free,
            &error,
            &intake.device_twist,
            |v| self.controlled(v),
            |e| rendered(&hadamard::<S>(&g.position_stiffness, e), &hadamard::<S>(&g.wall_stiffness, e)),
            |r| rendered(&hadamard::<S>(&g.position_damping, r), &hadamard::<S>(&g.wall_damping, r)),
        )
        .unwrap_or_else(S::OpVec::zero)
    }

    /// Stage 4: the controllers (section III, Fig 4), with `e = x_d ⊖ x_m`: joint constraint (stiffness or
    /// impedance mode), impedance with Λ̂⁻¹ in the free directions, position channels, contact force channel.
    ///
    /// The impedance controller's b̂ is weighted by how little it changes over the horizon it is held for
    /// (`bias_trust`, over `bias_horizon`: the snapshot's age, the one-way delay and the terms filter's lag),
    /// while this user holds the linkage alone. With others on it, b̂ carries their hands too, which is how
    /// the users feel each other, and the server already weighs those by the measured round trip
    /// (`server::core::sharing`): weighed again here, sixteen users sharing a push on one OP moved it half as
    /// far as one user does.
    pub(super) fn controllers(&self, now: Duration, intake: &Intake<S>, hand: &HandWrenches<S>) -> Requests<S> {
        let model_pose = self.model.pose();
        let model_twist = self.model.twist();
        let error = self.controlled(intake.device_pose.difference(&model_pose));
        let error_rate = self.controlled(intake.device_twist - model_twist);
        let g = &self.gains;
        let (l, p) = (self.length_scale, &self.local.projector);
        // The constrained directions soften as the model runs away from where its terms were computed
        // (`linearization_trust`): the joint-constraint controller and the position channels' constrained part.
        let trust = self.linearization_trust();
        let soften = |w: S::OpVec| channel_felt::<S>(p, l, trust, false, &w);
        let pc = soften(position_channel::<S>(&g.position_stiffness, &g.position_damping, &error, &error_rate));
        // The dampers' part of it, which with the joint-constraint controller's fills the update's tank
        // (`passive_update`).
        let zero = S::OpVec::zero();
        let pc_damping = soften(position_channel::<S>(&zero, &g.position_damping, &zero, &error_rate));
        // The controller is linear in (b̂, F_h): its b̂ part is taken apart for `pay_bias` to price.
        let horizon = self.bias_horizon(now).as_secs_f64();
        let (trusted, bias_at_risk) = self.bias_trust.assess(horizon, self.one_way_delay.as_secs_f64());
        let (imp, bias_feedforward) = match hand.sensed {
            Some(hand) => {
                let weight = if self.active.shared { 1.0 } else { trusted };
                let bias = self.local.bias * weight;
                let (mass, inverse_inertia) = (&self.device_mass, &self.local.inverse_inertia);
                let fed = impedance_free::<S>(p, l, mass, inverse_inertia, &bias, &zero);
                let imp = impedance_free::<S>(p, l, mass, inverse_inertia, &zero, &hand) + fed;
                if trust < 1.0 {
                    (imp * trust, fed * trust)
                } else {
                    (imp, fed)
                }
            }
            // Without a sensor the position channels would carry the load: the model sags `Λ̂ b̂ / K_pc` off the
            // device under it (centimetres for a heavy link on a soft channel), and the VE, which follows the
            // model, with it. The device renders the load itself instead, in the free directions (along the
            // constrained ones the walls hold the OP), and the model is held up by as much (`hold_load`).
            None if self.config.load_feedforward && !self.active.shared => {
                let fed = self.within_share(&(self.local.free_inertia * (self.local.bias * trusted)), 1.0);
                if trust < 1.0 {
                    (fed * trust, fed * trust)
                } else {
                    (fed, fed)
                }
            }
            None => (zero, zero),
        };
        let (contacts, live) = self.model.contacts();
        let contact = contact_feedforward::<S>(contacts, live, &self.local.free_inertia);
        let (jc, damping_felt) = match (self.config.constraint_mode, hand.for_constraint) {
            (ConstraintMode::Impedance, Some(hand)) => (
                joint_constraint_impedance::<S>(p, l, &hand, &(pc + imp + contact)),
                // The acceleration-zeroing controller cancels the channels along the constrained directions:
                // the device feels only their free part (Fig 7b).
                channel_felt::<S>(p, l, 1.0, true, &pc_damping),
            ),
            // Without a hand wrench to cancel, the acceleration-zeroing mode cannot work: keep the joints stiff.
            _ => (
                joint_constraint_stiffness::<S>(p, l, g.joint_stiffness, g.joint_damping, &error, &error_rate),
                pc_damping + joint_constraint_stiffness::<S>(p, l, 0.0, g.joint_damping, &zero, &error_rate) * trust,
            ),
        };
        let jc = if trust < 1.0 { jc * trust } else { jc };
        Requests {
            model_pose,
            error,
            error_rate,
            position_channel: pc,
            joint_constraint: jc,
            impedance: imp,
            bias_feedforward,
            bias_at_risk,
            contact,
            requested: pc + jc + imp + contact,
            damping_felt,
        }
    }

    /// Stage 4a: a device without a sensor has its load feedforward (`CoreConfig::load_feedforward`) change by
    /// at most [`LOAD_FEEDFORWARD_RISE_S`]'s rate from what it asked for last tick; what is held back stays
    /// with the position channels.
    pub(super) fn ramp_load(&mut self, dt_s: f64, hand: &HandWrenches<S>, asked: &mut Requests<S>) {
        if hand.sensed.is_some() {
            return;
        }
        let rise = (dt_s / LOAD_FEEDFORWARD_RISE_S).min(1.0);
        let fed = self.load_fed + self.within_share(&(asked.bias_feedforward - self.load_fed), rise);
        let held_back = asked.bias_feedforward - fed;
        asked.bias_feedforward = fed;
        asked.impedance -= held_back;
        asked.requested -= held_back;
        self.load_fed = fed;
    }

    /// Stage 4b: b̂'s feedforward paid from its tank (`bias_trust`), while this user holds the linkage alone:
    /// the share at risk of the work `M b̂` would do on the device this tick, `F_b · ẋ_d dt`, is drawn from the
    /// tank, and what the tank cannot pay is taken out of the request. Work the hand does against it fills
    /// the tank.
    pub(super) fn pay_bias(&mut self, dt_s: f64, intake: &Intake<S>, asked: &mut Requests<S>) {
        if self.active.shared {
            return;
        }
        let fed = asked.bias_feedforward;
        let paid = paid_bias::<S>(&mut self.bias_tank, &fed, asked.bias_at_risk, &intake.device_twist, dt_s);
        if paid != fed {
            let withheld = fed - paid;
            asked.bias_feedforward = paid;
            asked.impedance -= withheld;
            asked.requested -= withheld;
        }
    }

    /// `wrench` (VE units) clipped on the device, force and torque apart, to `fraction` of the load
    /// feedforward's share of the device's limits ([`LOAD_FEEDFORWARD_SHARE`]).
    fn within_share(&self, wrench: &S::OpVec, fraction: f64) -> S::OpVec {
        let share = LOAD_FEEDFORWARD_SHARE * fraction;
        let on_device = self.scales.wrench_to_device::<S>(wrench);
        let (clipped, _) =
            clip_wrench_parts::<S>(&on_device, self.limits.max_force_n * share, self.limits.max_torque_nm * share);
        self.scales.wrench_to_ve::<S>(&clipped)
    }

    /// After the safety envelope: the load feedforward as the device rendered it (`CoreConfig::load_feedforward`;
    /// under the gate's gain and the limits' scales), which holds the model up on its next step. A sensed
    /// device's b̂ feedforward shapes the device's acceleration instead and is not the model's.
    pub(super) fn hold_load(&mut self, hand: &HandWrenches<S>, asked: &Requests<S>) {
        self.load_held = if hand.sensed.is_none() {
            let rendered = mask_unactuated::<S>(&asked.bias_feedforward, &self.limits);
            self.last_scales.apply::<S>(&rendered) * self.gate.gain()
        } else {
            S::OpVec::zero()
        };
    }

    /// Stage 5: the safety envelope: non-finite check, output gate (ramp in, fade out on stale snapshots or
    /// a released handle, which is braked), device limits; then the position channels' reaction for the
    /// next step, the update tank's fill and the counters.
    pub(super) fn safety(
        &mut self,
        now: Duration,
        dt_s: f64,
        device_twist: &S::OpVec,
        intake: &Intake<S>,
        asked: &Requests<S>,
    ) -> Commanded<S> {
        // The command the device held since the last tick, on the twist it moved at.
        let held = self.scales.wrench_to_device::<S>(&self.last_command);
        self.device_port.book::<S>(&held, device_twist, dt_s);
        let mut command = S::OpVec::zero();
        let mut clamp_scale = 1.0;
        let mut flags = 0;
        let gain;
        if !asked.requested.is_finite() || !usable_model_state::<S>(&self.model.pose(), &self.model.twist()) {
            self.recover_from_non_finite(now);
            flags |= uplink_flags::SAFETY_STOP;
            gain = 0.0;
        } else {
            gain = self.gate.update(dt_s, !intake.stale && !intake.hand_off);
            let mut on_device = self.scales.wrench_to_device::<S>(&(asked.requested * gain));
            if self.config.device_port_passivity && !self.active.shared {
                let remote = &self.server_energy.accepted;
                let damping =
                    self.device_port.damping::<S>(remote, self.scales.torque, &self.config.device, device_twist, dt_s);
                on_device += super::device_port::within_headroom::<S>(&on_device, &damping, &self.limits);
            }
            if intake.hand_off {
                // A released handle is braked, not left to coast (as a dead-man switch engages a device's
                // brakes): a damper is passive, and it comes in as the rendering fades.
                on_device += brake::<S>(&self.config.device, device_twist) * (1.0 - gain);
            }
            let scales;
            (command, scales) = limit_wrench_parts::<S>(&on_device, &self.limits);
            clamp_scale = scales.min();
            self.last_scales = scales;
        }
        self.tank.fill(damper_dissipation::<S>(&asked.error_rate, &asked.damping_felt, gain * clamp_scale, dt_s));
        if clamp_scale < 1.0 {
            flags |= uplink_flags::CLAMPED;
            self.stats.clamped_ticks += 1;
        }
        // The observer and the report work on the VE side.
        self.last_command = self.scales.wrench_to_ve::<S>(&command);
        self.stats.max_force_ratio = self.stats.max_force_ratio.max(force_ratio::<S>(&command, &self.limits));
        // Tracking as the hand feels it: in device space.
        let distance = S::op_lin(&asked.error).norm() * self.scales.position;
        if distance.is_finite() {
            self.stats.tracking_error_sum_sq += distance * distance;
            self.stats.tracking_error_max = self.stats.tracking_error_max.max(distance);
        }
        Commanded { command, gain, clamp_scale, flags }
    }

    /// Stage 6: the uplink, every tick or through the perceptual deadband. Adds `DEADBAND_SKIPPED` to
    /// `flags` when the last one was held back; returns whether one leaves this tick.
    pub(super) fn uplink(
        &mut self,
        now: Duration,
        intake: &Intake<S>,
        flags: &mut u32,
        model_wrench: &S::OpVec,
        model_pose: &OpPose<S>,
    ) -> bool {
        self.stats.uplinks_built += 1;
        if self.deadband.skipped {
            *flags |= uplink_flags::DEADBAND_SKIPPED;
        }
        let send = self.deadband.admit(now, model_wrench, model_pose, *flags, self.length_scale);
        if send {
            self.fill_uplink(now, intake, *flags, model_wrench);
            self.deadband.skipped = false;
            self.stats.uplinks_sent += 1;
        } else {
            self.deadband.skipped = true;
        }
        send
    }

    fn fill_uplink(&mut self, now: Duration, intake: &Intake<S>, flags: u32, model_wrench: &S::OpVec) {
        let u = &mut self.uplink;
        u.seq += 1;
        u.client_time_s = now.as_secs_f64();
        u.last_snapshot_seq = self.active.seq;
        u.last_snapshot_age_s = intake.age.as_secs_f64();
        u.hand_wrench.copy_from_slice(model_wrench.as_slice());
        intake.device_pose.to_slice_memo(&mut u.device_pose, &mut self.pose_memos.uplink_device);
        u.device_twist.copy_from_slice(intake.device_twist.as_slice());
        self.model.pose().to_slice_memo(&mut u.model_pose, &mut self.pose_memos.uplink_model);
        u.model_twist.copy_from_slice(self.model.twist().as_slice());
        u.flags = flags;
        u.energy.received_j.copy_from_slice(&self.port.received_j[..S::DIM]);
        u.energy.emitted_j.copy_from_slice(&self.port.emitted_j[..S::DIM]);
    }

    /// The report of an active tick.
    pub(super) fn record(
        &mut self,
        now: Duration,
        intake: &Intake<S>,
        hand: &HandWrenches<S>,
        asked: &Requests<S>,
        out: &Commanded<S>,
        flags: u32,
    ) {
        self.report = TickReport {
            time: now,
            active: true,
            device_pose: intake.device_pose,
            device_twist: intake.device_twist,
            model_pose: self.model.pose(),
            model_twist: self.model.twist(),
            hand_wrench: hand.sensed.unwrap_or(hand.estimate),
            model_wrench: hand.model,
            wrenches: ControllerWrenches {
                position_channel: asked.position_channel,
                joint_constraint: asked.joint_constraint,
                impedance: asked.impedance,
                contact: asked.contact,
                requested: asked.requested,
                command: out.command,
            },
            gain: out.gain,
            clamp_scale: out.clamp_scale,
            constraint_count: self.frame.count,
            snapshot_constraint_count: self.active.constraint_count,
            snapshot_seq: self.active.seq,
            snapshot_age: Some(intake.age),
            tracking_error: asked.error,
            flags,
        };
    }

    /// Zero output before the first snapshot or with an unusable device reading.
    pub(super) fn idle_tick(&mut self, now: Duration, device_usable: bool) -> TickOutput<'_, S> {
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
        self.observer.reset();
        self.gate.close();
    }

    /// `error` with the axes no controller acts on zeroed: held as through a pin (see
    /// `ConstraintFrame::set_target`), no controller acts on angles the device can neither show nor push.
    pub(super) fn controlled(&self, mut error: S::OpVec) -> S::OpVec {
        if self.pinned() {
            for i in <S::Point as VecOps>::LEN..S::DIM {
                error[i] = 0.0;
            }
        }
        error
    }
}
