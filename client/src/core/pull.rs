//! Stage 2 of a tick (paper Fig 3): the frame the controllers use and the local model's pull toward the VE.
//!
//! Λ̂⁻¹ and the constrained-direction projector are filtered (`terms_time_constant`); on a linkage of one
//! degree of freedom they are carried along the OP's path to where the model is (`place_frame`), the model
//! steps with the snapshot's b̂ turned as they are, with its own acceleration across the path (the path's
//! curvature at its speed, square to its velocity: `turning_only`) in place of the VE's, and with the change
//! of the forces at rest along the path where that change holds it toward the VE, and it is held at a swing's
//! limits, where the OP turns back while the linkage goes on (`PathFollower::stop_at_limit`). The model's OP
//! is pulled toward the VE's OP predicted to now, fast along the constrained directions (onto the path when
//! there is one), slowly in the free ones (`CoreConfig::free_blend_time_constant`), no faster than the
//! device-model coupling's dampers allow when `CoreConfig::passive_update` is on.

use std::time::Duration;

use kinloop_linkage::algorithms::constraint_directions::scale_op;
use kinloop_linkage::algorithms::op_path::{turn_between, PathShape};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};

use super::controllers::{linearization_trust, project_twist, twist_turn};
use super::passive_update::{energy_change, CouplingSprings};
use super::stages::Intake;
use super::{model, ConstraintMode, HapticCore};

impl<S: Space> HapticCore<S> {
    /// Filters the snapshot's terms over `dt_s`, places the frame, and pulls the model toward the VE (not on a
    /// stale snapshot, nor while the hand is off, when the model stays parked); `sensed`: the device measures
    /// the hand's wrench.
    pub(super) fn pull_model(&mut self, now: Duration, dt_s: f64, intake: &Intake<S>, sensed: bool) {
        let fraction = |tau: Duration| if tau.is_zero() { 1.0 } else { (dt_s / tau.as_secs_f64()).min(1.0) };
        self.frame.filter(fraction(self.config.terms_time_constant));
        // The VE's OP predicted to now: where the pull aims, and what the forces at rest's change is measured
        // against (`place_frame`).
        let predicted = self.predicted_op(now);
        let on_path = self.place_frame(&predicted, dt_s);
        if !intake.stale && !intake.hand_off {
            let (constrained, free) =
                (fraction(self.config.blend_time_constant), fraction(self.free_blend_time_constant()));
            let (p, l) = (&self.local.projector, self.length_scale);
            // The model is pulled toward the VE's state predicted to now: along the constrained directions
            // fast, where the frozen terms let it drift off the linkage's curve; along the free ones over
            // round trips, as the VE follows the model there. Not toward the model's own state that the VE
            // answered (a Smith predictor): that takes the delay out of the loop but puts the model's own
            // corrections in it, which made the lighter outputs saturate and gain energy.
            let (own, own_twist) = (self.model.pose(), self.model.twist());
            let mut pose = predicted.difference(&own);
            let mut ve_twist = self.active.op_twist;
            if let Some(placed) = &on_path {
                // On a path the model belongs, along the constrained directions, on the path where it is
                // (where the joints hold the OP), not on the tangent line through the VE's pose; and the
                // VE's twist, along the path where the VE was, is turned to where the model is (both as far
                // as `place_frame` carries the frame).
                pose += project_twist::<S>(p, l, &(placed.point.difference(&own) - pose)) * placed.along;
                ve_twist = placed.twist_turn * ve_twist;
            }
            let twist = ve_twist - own_twist;
            let (mut moved, mut sped) = model::split_correction::<S>(&pose, &twist, p, l, constrained, free);
            if self.config.passive_update {
                let fraction = self.tank.admit(self.update_cost(&intake.device_pose, sensed, &moved, &sped));
                if fraction < 1.0 {
                    self.stats.updates_limited += 1;
                }
                moved = moved * fraction;
                sped = sped * fraction;
            }
            self.model.apply_correction(&moved, &sped);
        }
        if on_path.is_some() {
            // A swing's limits hold the model where the OP turns back (`PathFollower::stop_at_limit`).
            let held = self
                .path
                .as_ref()
                .and_then(|f| f.stop_at_limit(&self.model.pose(), &self.model.twist(), self.length_scale));
            if let Some((moved, sped)) = held {
                self.model.apply_correction(&moved, &sped);
            }
        }
        self.model.set_inverse_inertia(&self.local.inverse_inertia);
        // On a path the model steps with the snapshot's b̂ turned as the frame is. At a regular point of a
        // one-freedom path b̂ lies along the tangent where the VE was (its curvature's part aside); left
        // unturned, a part |b̂| sin Δ of it pushes the model along the walls where it is, Δ the angle the
        // frame turned, and the constrained pull (`blend_time_constant` τ) answers it only by holding the
        // model |b̂| sin Δ τ² off the path, where the linkage cannot follow. To it the model adds the change of
        // the forces at rest between the VE's point and its own where that change holds it toward the VE
        // (`PlacedFrame::model_rest`). Across the path the model takes its own acceleration
        // (`PlacedFrame::across`) in place of what of b̂ its frame finds there, as far as the frame was
        // carried.
        let bias = match &on_path {
            Some(placed) => {
                let turned = placed.twist_turn * self.active.bias + placed.model_rest;
                let ve_across = project_twist::<S>(&self.local.projector, self.length_scale, &turned);
                turned + (placed.across - ve_across) * placed.along
            }
            None => self.active.bias,
        };
        self.model.set_bias(&bias);
    }

    /// How far the local model's constraint geometry is still trusted where the model is now, as this tick's
    /// `place_frame` found it.
    pub(super) fn linearization_trust(&self) -> f64 {
        self.trust
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
        // `HapticCore::controllers`); without one the joints are held stiff.
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
    /// its pose (followed whole, the path would pull such a model back to its end).
    ///
    /// Only for a user alone on the linkage: with others on it each local model runs ahead along its own OP's
    /// path by its own hand, and models that disagree about the linkage's one coordinate pull the VE apart;
    /// the snapshots' own tangents keep them together.
    ///
    /// `predicted` is the VE's OP predicted to now. Returns where the frame was placed, or `None` when the
    /// snapshot's frame is used as it is.
    fn place_frame(&mut self, predicted: &OpPose<S>, dt_s: f64) -> Option<PlacedFrame<S>> {
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
        // the path counts as little there as a tangent that far from its pose. A swing's ends are limits the
        // OP does not pass: the path counts whole there (`pull_model` holds the model at them).
        let reach = self.config.linearization_reach * l;
        let past_end = if follower.path.shape() == PathShape::Swing { 0.0 } else { on.past_end };
        let along = (1.0 - self.trust) * linearization_trust(past_end, reach);
        let turn = turn_between::<S>(&from, &on.tangent, along);
        let twist_turn = twist_turn::<S>(&turn, l);
        self.local = self.frame.turned(&turn, l);
        let mut model_rest = S::OpVec::zero();
        if let (true, Some(here), Some(there)) =
            (follower.rest_where_model_is, on.rest_acceleration, follower.snapshot_rest)
        {
            // b̂ holds the forces at rest where the snapshot was taken; the model feels them where it is.
            // Carried along unchanged they are a spring felt a round trip late, which makes energy. A swing
            // carries none (its pose is two configurations): b̂ stays the snapshot's, turned.
            //
            // The change moves the OP along the path, never across it: only its part along the frame's free
            // directions is kept. `here` lies along the path's tangent where the model is, and the frame is
            // turned only `along` of the way there, so the rest of the turn leaves `|here| sin((1 − w) Δ)` of
            // it across the frame's walls, where the model's acceleration is the path's own (`across`). On a
            // light OP under a heavy load the forces at rest dwarf `κ v²`, so a few milliradians of turn push
            // the model off the path, and the constrained pull and the joint-constraint controller drag the
            // device after it: energy the hand absorbs and the VE never gave.
            let change = (here - twist_turn * there) * along;
            let change = change - project_twist::<S>(&self.local.projector, l, &change);
            self.local.bias += change;
            // The model steps with the change only where it pulls the model along the path toward the VE's
            // pose predicted to now (where `pull_model` pulls it). Where the change pushes the model away
            // from there (the load falling ahead of where the VE holds it, or dragging the model after a VE
            // that has run ahead), the hand follows the model and the VE the hand a round trip later, so the
            // gap feeds itself.
            let (ahead, pull) = (scale_op::<S>(&pose.difference(predicted), l), scale_op::<S>(&change, l));
            if ahead.dot(&on.tangent) * pull.dot(&on.tangent) < 0.0 {
                model_rest = change;
            }
        }
        // The walls are right as far as the tangent or the path is.
        self.trust = 1.0 - (1.0 - self.trust) * (1.0 - along);
        // The model's velocity as the path measures it: on a pinned grasp's path (positions alone), its linear
        // part (`controlled`). Its turning, which the pin ties to its motion, can be fast where the OP's path
        // has a cusp and would hide the linear velocity `turning_only` keeps κ v² square to.
        let twist = scale_op::<S>(&self.controlled(self.model.twist()), l);
        let speed = on.tangent.dot(&twist);
        let across =
            project_twist::<S>(&self.local.projector, l, &scale_op::<S>(&(on.curvature * (speed * speed)), 1.0 / l));
        let across = scale_op::<S>(&turning_only::<S>(&scale_op::<S>(&across, l), &twist, dt_s), 1.0 / l);
        Some(PlacedFrame { point: on.pose, along, twist_turn, model_rest, across })
    }
}

/// Largest angle (rad) by which the model's own acceleration across its path may turn the model's velocity in
/// one step ([`turning_only`]).
pub const MAX_TURN_PER_STEP_RAD: f64 = 0.05;

/// The acceleration across the path `across` as the model steps with it (`across` and the model's twist
/// `twist` in scaled coordinates): only its part square to the twist, which turns the model's velocity and
/// does no work on it, and of that no more than turns the velocity by [`MAX_TURN_PER_STEP_RAD`] in a step of
/// `dt_s`.
///
/// `κ v²` holds a point to its curve while the point moves along the curve. The frame is carried only part of
/// the way along the path (`along`), so its walls are not square to the tangent, and the model does not move
/// exactly along the path: `κ v²` as the walls take it then has a part along the model's velocity, which speeds
/// the model up, and a faster model asks for more `κ v²`. Near a cusp of the OP's path, where κ grows without
/// bound (the linkage's OP slows to a stop there, the model following the hand does not), that loop runs the
/// model off to non-finite speeds within tens of ticks. Square to the velocity, an explicit step still lengthens
/// it by a factor `√(1 + (κ v dt)²)`: a path that turns further than a few hundredths of a radian within one
/// step's travel is a corner at the model's rate, and the model turns no faster than that.
pub(crate) fn turning_only<S: Space>(across: &S::OpVec, twist: &S::OpVec, dt_s: f64) -> S::OpVec {
    let speed = twist.norm();
    if !speed.is_finite() || speed <= 0.0 {
        return S::OpVec::zero();
    }
    let heading = *twist * (1.0 / speed);
    let square = *across - heading * heading.dot(across);
    let (size, most) = (square.norm(), MAX_TURN_PER_STEP_RAD * speed / dt_s);
    if size > most {
        square * (most / size)
    } else {
        square
    }
}

/// Where `place_frame` placed the frame on a path.
struct PlacedFrame<S: Space> {
    /// The model's point on the path.
    point: OpPose<S>,
    /// How far the frame was carried along the path toward it (`w`).
    along: f64,
    /// The frame's turn as it acts on twists (and on accelerations, which turn as twists do).
    twist_turn: S::OpMat,
    /// The change of the forces at rest between the VE's point and the model's that the model steps with:
    /// the whole change where it pulls the model along the path toward the VE's pose predicted to now, else
    /// none.
    model_rest: S::OpVec,
    /// The model's own acceleration across the path where it is (along the frame's constrained directions):
    /// `κ v²`, the path's curvature there at the model's speed along it. A point that keeps to a curve has
    /// that acceleration across it whatever the forces. What the frame finds of b̂ there is the VE's `κ v²`
    /// at the VE's speed, and the part of b̂'s push along the path that the filtered, turned frame does not
    /// line up with; with either the model is pushed off the path (a VE swinging back fast under a model at
    /// rest pulls it toward the circle's centre), and the constrained pull holds it off by that push.
    across: S::OpVec,
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::Vector3;

    /// A point on a circle of radius r at speed v needs `v² / r` toward the centre, square to its velocity:
    /// taken whole while it turns the velocity by less than the bound in a step.
    #[test]
    fn a_gentle_turn_square_to_the_velocity_is_taken_whole() {
        let (r, v, dt) = (0.05, 0.2, 1e-3);
        let across = Vector3::new(-v * v / r, 0.0, 0.0);
        let twist = Vector3::new(0.0, v, 0.0);
        assert!((v / r) * dt < MAX_TURN_PER_STEP_RAD);
        assert_eq!(turning_only::<Planar>(&across, &twist, dt), across);
    }

    /// The part along the velocity, which would speed the model up or slow it down, is left out; what is kept
    /// does no work on the model's motion.
    #[test]
    fn the_part_along_the_velocity_is_left_out() {
        let twist = Vector3::new(0.3, -0.1, 0.2);
        let across = Vector3::new(1.0, 2.0, 0.5);
        let kept = turning_only::<Planar>(&across, &twist, 1e-3);
        assert!(kept.dot(&twist).abs() < 1e-12 * across.norm() * twist.norm(), "power {}", kept.dot(&twist));
        // What is left out lies along the velocity.
        let dropped = across - kept;
        assert!(dropped.cross(&twist).norm() < 1e-12 * dropped.norm() * twist.norm(), "{dropped:?}");
    }

    /// Near a cusp, κ v² outgrows what a step can follow: the velocity turns by the bound per step, and
    /// a step with it lengthens the velocity by no more than `√(1 + θ²)`; a model at rest is not pushed.
    #[test]
    fn a_corner_turns_the_velocity_by_the_bound_per_step() {
        let (v, dt) = (0.3, 1e-3);
        let twist = Vector3::new(v, 0.0, 0.0);
        let cusp = Vector3::new(0.0, 1e6, 0.0);
        let kept = turning_only::<Planar>(&cusp, &twist, dt);
        let stepped = twist + kept * dt;
        let turned = (stepped.y / stepped.x).atan();
        assert!((turned - MAX_TURN_PER_STEP_RAD.atan()).abs() < 1e-12, "turned {turned} rad");
        assert!(stepped.norm() <= v * (1.0 + MAX_TURN_PER_STEP_RAD.powi(2)).sqrt() * (1.0 + 1e-12));
        assert_eq!(turning_only::<Planar>(&cusp, &Vector3::zeros(), dt), Vector3::zeros());
    }
}
