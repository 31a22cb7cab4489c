//! The VE's tick (the paper's sections II and IV in order): each user's fade and passivity scale are
//! updated, then one [`kinloop_linkage::algorithms::integrator::step`] integrates eq 4 with every user's coupling and the penalty
//! contacts; a failed step restores the last good state; after the last tick due, snapshots if one is due.

use std::time::Duration;

use kinloop_linkage::algorithms::dynamics::dynamics_terms;
use kinloop_linkage::algorithms::integrator::{Integrator, StepReport};

use super::closing::close_loops;
use super::*;

impl<S: Space> VeCore<S> {
    /// Runs every tick due at or before `now` at the fixed VE period (at most `max_catch_up_ticks`; beyond
    /// that the schedule skips ahead and the skip is counted), then builds snapshots if one is due.
    pub fn handle_timeout(&mut self, now: Duration) {
        if self.run_due_ticks(now) {
            self.build_due_snapshots();
        }
    }

    /// The first half of [`Self::handle_timeout`]: runs every tick due at or before `now`; true when a
    /// snapshot round is due after them ([`Self::build_due_snapshots`]). A driver that times the two halves
    /// apart calls them in turn.
    pub fn run_due_ticks(&mut self, now: Duration) -> bool {
        let mut ran = 0;
        while self.next_tick_at <= now {
            if ran == self.config.max_catch_up_ticks {
                let behind = (now - self.next_tick_at).as_nanos() / self.period.as_nanos().max(1) + 1;
                let behind = u32::try_from(behind).unwrap_or(u32::MAX);
                self.next_tick_at += self.period * behind;
                self.metrics.skipped_ticks += u64::from(behind);
                self.events.push(VeEvent::TicksSkipped { count: u64::from(behind) });
                break;
            }
            let at = self.next_tick_at;
            self.tick(at);
            self.next_tick_at += self.period;
            ran += 1;
        }
        self.metrics.events_dropped = self.events.dropped;
        ran > 0 && self.last_tick_at >= self.next_snapshot_at
    }

    /// The second half of [`Self::handle_timeout`]: every present user's snapshot terms at the current state,
    /// when [`Self::run_due_ticks`] said a round is due (a call when none is due does nothing).
    pub fn build_due_snapshots(&mut self) {
        if self.last_tick_at < self.next_snapshot_at {
            return;
        }
        self.build_snapshots();
        self.update_held_loads();
        while self.next_snapshot_at <= self.last_tick_at {
            self.next_snapshot_at += self.snapshot_period;
        }
        self.metrics.events_dropped = self.events.dropped;
    }

    /// One VE step at time `at`.
    ///
    /// **Restore point.** A diverging linkage stays finite for a few steps while its loop tears open (the
    /// 60 s demo, whose constant push spins the testbed up to 30 rad/s, went from 4e-11 m to a non-finite
    /// step in a few ms and was restored to a configuration 4.8 cm open, where it then stayed). So the
    /// restore point is the start of the last step that began with the loop closed (residual at most
    /// [`BROKEN_CLOSURE_PER_LENGTH`] times the scene's length scale), and a step that begins torn open
    /// counts as failed even if it is finite.
    fn tick(&mut self, at: Duration) {
        let dt = self.step_config.dt;
        self.update_couplings(at, dt);
        if self.config.rest_unheld && self.couplings.iter().all(|c| c.weight <= 0.0) {
            // No one holds the linkage: it waits for its users at rest (`VeConfig::rest_unheld`). The
            // couplings' step wrenches were cleared by `update_couplings`.
            self.qd.fill(0.0);
            self.energy_guard.reset();
            self.finish_tick(at);
            return;
        }
        self.step_start_q.as_mut_slice().copy_from_slice(self.q.as_slice());
        self.refresh_op_order();
        let mut forces = VeForces {
            couplings: &mut self.couplings,
            order: &self.scratch.order,
            contacts: self.contacts.as_mut(),
            evaluation: Evaluation::Step(stage_weights(self.step_config.integrator)),
            stage: 0,
        };
        let broken = BROKEN_CLOSURE_PER_LENGTH * self.model.length_scale;
        let guard = self.config.energy_guard.then_some(&mut self.energy_guard);
        let stepped =
            step_guarded(&self.model, &mut self.data, &mut self.q, &mut self.qd, &mut forces, &self.step_config, guard)
                .and_then(|report| {
                    if report.closure_error <= broken {
                        Ok(report)
                    } else {
                        Err(DynamicsError::ClosureBroken { residual: report.closure_error, limit: broken })
                    }
                })
                .and_then(|report| self.close_if_open(report));
        match stepped {
            Ok(report) => {
                // The step began closed: its start is the new restore point (a swap, not a second copy).
                std::mem::swap(&mut self.checkpoint_q, &mut self.step_start_q);
                self.closure_error = report.closure_error;
                self.metrics.closure_error = report.closure_error;
                self.metrics.max_closure_error = self.metrics.max_closure_error.max(report.closure_error);
                self.lambda.as_mut_slice().copy_from_slice(self.data.lambda.as_slice());
                self.book_step_wrenches(dt);
                self.settle_energy();
            }
            Err(error) => {
                // Restoring the velocity too would replay the same divergence: restore at rest. A restore
                // point began a step closed to `BROKEN_CLOSURE_PER_LENGTH`, which in violent motion is far
                // above what a projected step leaves: it is assembled onto the loops (and stays the restore
                // point, closed), so the VE goes on from a closed state.
                if let Ok(closed) = close_loops(&self.model, &mut self.data, &self.checkpoint_q) {
                    self.checkpoint_q.copy_from(&closed.q);
                    self.closure_error = closed.residual;
                    self.metrics.closure_error = closed.residual;
                }
                self.q.copy_from(&self.checkpoint_q);
                self.qd.fill(0.0);
                self.energy_guard.reset();
                for c in &mut self.couplings {
                    c.step_wrench = S::OpVec::zero();
                }
                self.metrics.state_restores += 1;
                self.events.push(VeEvent::StateRestored { step: self.step, error });
            }
        }
        self.finish_tick(at);
    }

    /// After a booked step: the energy account settles the step at once (`EnergyGuard::settle`) rather than at
    /// the next step's open, so what the step made is out of the velocity before the snapshots, the couplings
    /// and the recordings read it. The passivity books keep the velocity the step moved with: they book the
    /// couplings' work on the motion the linkage made.
    ///
    /// **Why.** Near a jam a step can make energy that its projection hands on. Taken out at the next step's
    /// open, it had already reached the snapshot and the couplings, which passed it on to the client and the
    /// hand (docs/robustness.md, "A step's energy settled where it is made").
    fn settle_energy(&mut self) {
        if !(self.config.energy_guard && self.step_config.integrator == Integrator::SemiImplicitEuler) {
            return;
        }
        // The end state's terms, kinematics included: the snapshots' probe and the next step find them in the
        // workspace's memo at this state, so they are computed once a tick, here.
        dynamics_terms(&self.model, &mut self.data, &self.q, &self.qd, &mut ());
        self.energy_guard.settle(&self.model, &self.data, &self.q, &mut self.qd);
    }

    /// A projected step's end re-assembled onto the loops when it left them open beyond
    /// [`OPEN_CLOSURE_PER_LENGTH`] (rare: the assembly allocates its own workspace); a failed step when the
    /// assembly fails. The velocity stays the step's: it was projected at a configuration within that
    /// residual, and the next step's Baumgarte term and projection take up the rest. Without projection
    /// (`VeConfig::projection` off) Baumgarte's drift is what the VE was asked for, and it is left alone.
    fn close_if_open(&mut self, mut report: StepReport) -> Result<StepReport, DynamicsError> {
        let open = OPEN_CLOSURE_PER_LENGTH * self.model.length_scale;
        if !self.step_config.project || report.closure_error <= open {
            return Ok(report);
        }
        match close_loops(&self.model, &mut self.data, &self.q) {
            Ok(closed) if closed.residual <= open => {
                self.q.copy_from(&closed.q);
                report.closure_error = closed.residual;
                Ok(report)
            }
            Ok(closed) => Err(DynamicsError::ClosureBroken { residual: closed.residual, limit: open }),
            Err(residual) => Err(DynamicsError::ClosureBroken { residual, limit: open }),
        }
    }

    /// The bookkeeping that ends every tick, stepped or at rest.
    fn finish_tick(&mut self, at: Duration) {
        self.remove_faded_users();
        self.step += 1;
        self.metrics.ticks += 1;
        self.last_tick_at = at;
    }

    /// The static loads the VE holds for users with gravity compensation, at the current state (the OP wrench
    /// that cancels gravity's acceleration in the OP's free directions, `kinloop_linkage::algorithms::reach`), until the
    /// next snapshot round. Allocates nothing.
    pub(super) fn update_held_loads(&mut self) {
        let Some((data, at_rest)) = self.held.as_mut() else { return };
        for (u, c) in self.users.iter().zip(&mut self.couplings) {
            if !(u.mapping.gravity_compensation && u.role == Role::Manipulator) {
                continue;
            }
            c.held_load = static_load(&self.model, data, at_rest, &self.q, u.op);
        }
    }

    /// Fade weights (join, silence, letting go, leave) and passivity scales for the coming step.
    ///
    /// A user whose hand is off its handle (`uplink_flags::HAND_OFF`, from a presence sensor) parks its local
    /// model where the hand left it, and its coupling holds the linkage there: alone, the linkage stays put
    /// rather than falling. With another user's hand on the linkage that hold would fight them (the others
    /// would pull against it at their devices' limits), so then it fades out like a silent user's, and fades
    /// back in when the hand returns (its model restarts on the VE).
    ///
    /// Then the join's handover (`handover`): the hold at the coupling furthest into its fade-in.
    fn update_couplings(&mut self, at: Duration, dt: f64) {
        let fade_s = self.config.fade_time.as_secs_f64();
        // The potential energy from the static loads' workspace, so the step's own stays as the step left it.
        let (model, q, held) = (&self.model, &self.q, &mut self.held);
        let potential = || match held.as_mut() {
            Some((data, _)) => {
                forward_kinematics(model, data, q);
                kinloop_linkage::algorithms::gravity::potential_energy(model, data, q)
            }
            None => 0.0,
        };
        let before = handover::before_tick(&self.handover, &self.couplings, self.model.length_scale, potential);
        let mut activations = 0;
        let holding =
            |u: &User, c: &Coupling<S>| u.presence == Presence::Present && c.pushes && !u.silent && !u.hand_off;
        let holders = self.users.iter().zip(&self.couplings).filter(|(u, c)| holding(u, c)).count();
        let (lead_max_s, lead_delays_s) = (self.config.coupling_lead_max_s, self.config.coupling_lead_delays_s);
        for (u, c) in self.users.iter_mut().zip(&mut self.couplings) {
            if let Some(reference) = c.playout.due(at.as_secs_f64()) {
                if lead_max_s > 0.0 {
                    c.track_twist_rate(&reference);
                }
                c.follow(&reference);
            }
            if lead_max_s > 0.0 && c.heard_time_s > 0.0 {
                let wanted = coupling::target_lead_s(u.round_trip.shortest_s(), lead_max_s, lead_delays_s, dt);
                c.steer_lead(wanted, u.thresholds.lead_guess_energy, dt);
            }
            let silent = u.is_silent(at, self.config.silent_timeout);
            let let_go = u.hand_off && holders > usize::from(holding(u, c));
            let (faded, was_faded) = (silent || let_go, u.silent || u.let_go);
            if faded != was_faded && u.presence == Presence::Present && c.pushes {
                let reason = if silent { FadeReason::Silent } else { FadeReason::LetGo };
                self.events.push(if faded {
                    VeEvent::FadingOut { user: u.id, reason }
                } else {
                    VeEvent::Resumed { user: u.id }
                });
            }
            u.silent = silent;
            u.let_go = let_go;
            u.fade.advance(u.presence == Presence::Present && c.pushes && !silent && !let_go, dt, fade_s);
            c.weight = u.fade.weight();
            c.step_wrench = S::OpVec::zero();
            c.hand_scale = coupling::full_scale::<S>();
            c.pd_scale = if self.config.passivity && c.pushes {
                // The power the full PD would deliver, from the OP twist of the previous evaluation (one tick
                // old at most) and the newest reference.
                let pd = c.pd_wrench();
                let mut power = S::OpVec::zero();
                for a in 0..S::DIM {
                    power[a] = c.weight * pd[a] * c.op_twist[a];
                }
                let before = u.passivity.activations;
                let allowance = u.thresholds.passivity_allowance;
                let scale = if self.config.passivity_per_axis {
                    u.passivity.pd_scale_per_axis::<S>(&power, allowance)
                } else {
                    // The power the whole force channel would deliver (its scale is still full here), as the PD's
                    // above.
                    let hand = c.hand_part();
                    let mut hand_power = S::OpVec::zero();
                    for a in 0..S::DIM {
                        hand_power[a] = hand[a] * c.op_twist[a];
                    }
                    c.hand_scale = u.passivity.hand_scale::<S>(&hand_power, allowance);
                    u.passivity.pd_scale::<S>(&power, &c.spring_energy(), &c.pd_scale, allowance)
                };
                activations += u.passivity.activations - before;
                scale
            } else {
                coupling::full_scale::<S>()
            };
        }
        if activations > 0 {
            self.metrics.passivity_activations += 1;
        }
        if self.config.rest_unheld {
            let (model, q, users) = (&self.model, &self.q, &self.users);
            let held = &mut self.held;
            self.handover.update(before, &mut self.couplings, [dt, fade_s], |i| match held.as_mut() {
                Some((data, at_rest)) => static_load(model, data, at_rest, q, users[i].op),
                None => S::OpVec::zero(),
            });
        }
    }

    /// After a successful step: the wrench each coupling effectively applied, and the passivity books.
    fn book_step_wrenches(&mut self, dt: f64) {
        let implicit = self.data.use_implicit_mass;
        for (u, c) in self.users.iter_mut().zip(&mut self.couplings) {
            if !c.is_active() {
                continue;
            }
            if implicit {
                c.step_wrench += c.implicit_correction(&self.model, &self.data.qdd, dt);
            }
            if self.config.passivity {
                // ẋ_op after the step, J q̇⁺: the velocity semi-implicit Euler moved the OP with. (Without the
                // controller the books stay at zero, and the snapshots say so.)
                let velocity_after = c.op_space_image(&self.model, &self.qd);
                u.passivity.observe::<S>(&c.controller_part(&c.step_wrench), &c.hand_part(), &velocity_after, dt);
            }
        }
    }

    fn remove_faded_users(&mut self) {
        let mut index = 0;
        while index < self.users.len() {
            if self.users[index].presence == Presence::Leaving && self.users[index].fade.is_off() {
                let user = self.users.remove(index);
                self.couplings.remove(index);
                self.handover.removed(index);
                self.roster_version += 1;
                self.metrics.users_left += 1;
                self.events.push(VeEvent::UserRemoved { user: user.id });
            } else {
                index += 1;
            }
        }
    }
}

/// The static load at OP `op` in state `q` at rest (`kinloop_linkage::algorithms::reach::static_op_load`),
/// zero when it cannot be had.
fn static_load<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    at_rest: &DVector<f64>,
    q: &DVector<f64>,
    op: usize,
) -> S::OpVec {
    match kinloop_linkage::algorithms::reach::static_op_load(model, data, q, at_rest, op) {
        Ok((load, _)) if load.is_finite() => load,
        _ => S::OpVec::zero(),
    }
}
