//! The wrench each user applies to the VE, and how the integrator sees it.
//!
//! For a manipulator at operational point `op` with fade weight `w` (see `fade`), the paper's force channel
//! plus graphics controller (section IV; Fig 3):
//! ```text
//! F = w · [ F_h + β ⊙ (K_g ⊙ (x_lm ⊖ x_op) + B_g ⊙ (ẋ_lm − ẋ_op)) − (1 − β) ⊙ B_g ⊙ ẋ_op ]
//! ```
//! with `x_lm, ẋ_lm` the client's local-model OP pose and twist (from its newest uplink), `x_op, ẋ_op` the
//! VE's, `⊖` the pose difference (linear, rotation vector) and `β ∈ [0, 1]` per axis the passivity
//! controller's scale on the PD (one unless the controller finds the coupling generating energy, see
//! `passivity`). What it takes off the PD becomes a brake on the OP, which only dissipates. The wrench
//! enters eq 4 as `Jᵀ F`.
//!
//! **Linearly implicit coupling.** The paper's gains (K_g up to 10⁴, B_g up to 10⁴ on a link with
//! I = 0.0021 kg m²) are far too stiff for an explicit step at 1 kHz. Under semi-implicit Euler the PD is
//! evaluated at the end of the step, linearized: `x_op⁺ ≈ x_op + h J q̇⁺`, `ẋ_op⁺ = J q̇⁺`, `q̇⁺ = q̇ + h q̈`,
//! which moves `Jᵀ (w(hB + βh²K)) J` to the left of eq 4 (the PD's damper and the brake together: hB) and
//! adds `−h Jᵀ (wβK ⊙ ẋ_op)` on the right ([`Forces::add_implicit`]). The step is then stable for any gains;
//! the wrench it effectively applied is `F − h wβK ⊙ ẋ_op − w(hB + βh²K) ⊙ J q̈`
//! ([`Coupling::implicit_correction`]).

use kinloop_linkage::algorithms::jacobian::{frame_jacobian_t, frame_velocity, support};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::model::data::Kinematics;
use kinloop_linkage::{math::space::Space, math::space::VecOps, model::Model};
use nalgebra::{DMatrix, DVector};

use super::playout::{Playout, Reference};

/// One user's coupling to the VE: its reference (the newest checked uplink), gains, weight, and what it
/// computed at the last evaluation.
#[derive(Clone, Debug)]
pub struct Coupling<S: Space> {
    /// Body carrying the user's operational point.
    pub body: usize,
    /// The operational point in the body's frame.
    pub point: S::Point,
    /// False for observers and for manipulators before their first uplink: no wrench at all.
    pub pushes: bool,
    /// Fade weight w ∈ [0, 1] for the current tick.
    pub weight: f64,
    /// F_h from the newest uplink.
    pub hand_wrench: S::OpVec,
    /// The PD's target: x_lm from the newest uplink, led along its twist by the coupling's lead (see
    /// [`Coupling::lead_by`]).
    pub target_pose: OpPose<S>,
    /// x_lm exactly as the newest uplink carried it.
    pub heard_pose: OpPose<S>,
    /// ẋ_lm from the newest uplink.
    pub target_twist: S::OpVec,
    /// The static load the VE holds at this OP for its user (gravity compensation; zero otherwise): it joins
    /// the force channel, so the user's local model, whose bias carries every hand but the user's own, is
    /// weightless too.
    pub held_load: S::OpVec,
    /// The linkage's load the VE holds at this OP while this coupling takes over a linkage that waited at
    /// rest (σ L, see `handover`; zero otherwise). Not faded, and in neither the hand's nor the controller's
    /// books: it is the VE's own force.
    pub hold: S::OpVec,
    /// The client time the PD's target stands for (s; 0 before the first uplink): the newest uplink's client
    /// clock plus the lead. Snapshots tell the client which of its local model's states the VE is answering
    /// (`Snapshot::uplink_time_s`).
    pub target_time_s: f64,
    /// The newest uplink's client clock (s; 0 before the first).
    pub heard_time_s: f64,
    /// The first uplink's client clock (s; 0 before it): a lead waits until the envelope below has seen
    /// [`LEAD_RATE_MEMORY_S`] of the hand.
    pub first_heard_s: f64,
    /// Per axis, the largest rate of change of the heard twist lately (|Δẋ_lm| / Δt between consecutive
    /// uplinks, Δt at most [`LEAD_RATE_GAP_S`], decaying by e over [`LEAD_RATE_MEMORY_S`] of client time): what
    /// bounds a lead's guess.
    pub twist_rate_envelope: S::OpVec,
    /// The lead the target has now (s, before rounding to whole ticks; see [`Coupling::steer_lead`]).
    pub lead_s: f64,
    /// K_g per axis.
    pub stiffness: S::OpVec,
    /// B_g per axis.
    pub damping: S::OpVec,
    /// β per axis, the passivity controller's scale on the PD for the current tick (ones when it is off).
    pub pd_scale: S::OpVec,
    /// The passivity controller's scale on the force channel for the current tick, per axis (ones unless the
    /// port's deficit outgrows what scaling the PD can stop, see `passivity`).
    pub hand_scale: S::OpVec,
    /// Whether what β takes off the PD becomes a brake on the OP (the port controller's way; the per-axis
    /// controller leaves the axis free).
    pub brakes: bool,
    /// Jᵀ at the OP (n×k) at the last evaluation that needed it (see [`Coupling::evaluate`]).
    pub jacobian_t: DMatrix<f64>,
    /// x_op at the last evaluation.
    pub op_pose: OpPose<S>,
    /// ẋ_op at the last evaluation.
    pub op_twist: S::OpVec,
    /// F at the last evaluation (explicit form).
    pub wrench: S::OpVec,
    /// The wrench the last step applied: the stage-weighted mean over the step's evaluations, plus the
    /// implicit correction under semi-implicit Euler.
    pub step_wrench: S::OpVec,
    /// Anchors for this user's orientations on the wire, read from its uplinks and written to its
    /// snapshots: both move a little each tick, so a short series replaces a library atan2 and sin_cos,
    /// which with the fade's cosine are a noticeable share of a many-user tick.
    pub pose_memo: S::RotParamsMemo,
    /// The user's uplinks waiting for their turn (the jitter buffer, see `playout`).
    pub playout: Playout<S>,
}

impl<S: Space> Coupling<S> {
    /// A coupling at `(body, point)` that does not push yet; `nq` sizes the Jacobian.
    pub fn new(body: usize, point: S::Point, nq: usize, stiffness: S::OpVec, damping: S::OpVec) -> Self {
        Coupling {
            body,
            point,
            pushes: false,
            weight: 0.0,
            hand_wrench: S::OpVec::zero(),
            target_pose: OpPose::identity(),
            heard_pose: OpPose::identity(),
            target_twist: S::OpVec::zero(),
            target_time_s: 0.0,
            heard_time_s: 0.0,
            first_heard_s: 0.0,
            twist_rate_envelope: S::OpVec::zero(),
            lead_s: 0.0,
            held_load: S::OpVec::zero(),
            hold: S::OpVec::zero(),
            stiffness,
            damping,
            pd_scale: full_scale::<S>(),
            hand_scale: full_scale::<S>(),
            brakes: true,
            jacobian_t: DMatrix::zeros(nq, S::DIM),
            op_pose: OpPose::identity(),
            op_twist: S::OpVec::zero(),
            wrench: S::OpVec::zero(),
            step_wrench: S::OpVec::zero(),
            pose_memo: S::RotParamsMemo::default(),
            playout: Playout::new(),
        }
    }

    /// Makes an uplink's reference the coupling's: the PD's target and the force channel's hand wrench, and
    /// the client time snapshots will say the VE answers. The coupling pushes from the first one on.
    pub fn follow(&mut self, reference: &Reference<S>) {
        if self.first_heard_s <= 0.0 {
            self.first_heard_s = reference.client_time_s;
        }
        self.pushes = true;
        self.hand_wrench = reference.hand_wrench;
        self.target_pose = reference.pose;
        self.heard_pose = reference.pose;
        self.target_twist = reference.twist;
        self.target_time_s = reference.client_time_s;
        self.heard_time_s = reference.client_time_s;
    }

    /// Leads the PD's target by `lead_s` (≥ 0) of the client's time: the heard pose moved along the heard
    /// twist, standing for the local model's state that much after the uplink was sent. A VE that only follows
    /// what it has heard trails the hand by the uplink's delay; leading by that delay puts the OP where the
    /// hand is now, to first order. The target's time moves with it, so a snapshot names the model state the VE
    /// aimed at. The energy a wrong guess puts
    /// into the linkage goes through the PD, which the passivity controller books; but its account holds
    /// credit for all the hand ever put in at the client, so an overshoot is paid from it rather than stopped
    /// (led blindly by 100 ms, a poke's jab gave the linkage twice its kinetic energy): [`Coupling::steer_lead`]
    /// picks a lead the heard motion supports.
    pub fn lead_by(&mut self, lead_s: f64) {
        let lead_s = if lead_s.is_finite() { lead_s.max(0.0) } else { 0.0 };
        self.target_pose = self.heard_pose;
        self.target_pose.integrate(&self.target_twist, lead_s);
        self.target_time_s = if self.heard_time_s > 0.0 { self.heard_time_s + lead_s } else { 0.0 };
    }

    /// Folds a newer uplink's twist into [`Coupling::twist_rate_envelope`], before [`Coupling::follow`] makes
    /// it the coupling's: per axis, the rate of change since the previous uplink, or the envelope decayed over
    /// the client time between them, whichever is larger. Uplinks out of order, repeated, or non-finite leave
    /// it as it was. Only a VE that leads needs it (`update_couplings` skips it otherwise).
    pub fn track_twist_rate(&mut self, reference: &Reference<S>) {
        let dt = reference.client_time_s - self.heard_time_s;
        if !(self.heard_time_s > 0.0 && dt > 0.0 && dt.is_finite()) {
            return;
        }
        // Across a gap (lost uplinks) the VE does not know when the hand changed its motion: the change is
        // taken as if made within LEAD_RATE_GAP_S rather than spread over the gap.
        let rate = (reference.twist - self.target_twist) * (1.0 / dt.min(LEAD_RATE_GAP_S));
        if !rate.is_finite() {
            return;
        }
        let decay = (-dt / LEAD_RATE_MEMORY_S).exp();
        for (envelope, rate) in self.twist_rate_envelope.as_mut_slice().iter_mut().zip(rate.as_slice()) {
            *envelope = rate.abs().max(*envelope * decay);
        }
    }

    /// The longest lead (s) whose guess the heard motion supports: leading by `L` along the heard twist
    /// misses a hand that accelerates at `a_i` on axis `i` by up to `½ a_i L²`, which the PD's spring turns
    /// into `Σ ½ K_i (½ a_i L²)²` of energy nobody put in; that is held to `guess_energy_j`, with the
    /// envelope's rates for `a_i`:
    /// ```text
    /// L ≤ (8 E / Σ K_i a_i²)^¼
    /// ```
    /// A tour's smooth segments keep their lead; a jab, a let-go or a wobble cuts it for as long as the
    /// envelope remembers them. None until the envelope has heard [`LEAD_RATE_MEMORY_S`] of the hand.
    pub fn trusted_lead_s(&self, guess_energy_j: f64) -> f64 {
        if self.first_heard_s <= 0.0 || self.heard_time_s - self.first_heard_s < LEAD_RATE_MEMORY_S {
            return 0.0;
        }
        let spring: f64 =
            self.stiffness.as_slice().iter().zip(self.twist_rate_envelope.as_slice()).map(|(k, a)| k * a * a).sum();
        if !(guess_energy_j.is_finite() && guess_energy_j > 0.0) {
            return 0.0;
        }
        match spring {
            // No acceleration heard (or no spring): nothing bounds the guess but the caller's cap.
            0.0 => f64::INFINITY,
            spring if spring > 0.0 && spring.is_finite() => (8.0 * guess_energy_j / spring).powf(0.25),
            // Negative stiffness or a rate beyond f64: no guess.
            _ => 0.0,
        }
    }

    /// Leads the target by up to `wanted_s` (the network's one-way delay, capped: [`target_lead_s`]), no
    /// further than [`Coupling::trusted_lead_s`] allows, changing the lead by at most [`LEAD_GROWTH_PER_S`]
    /// of a second per second as it grows and by one as it shrinks (so the client time the VE aims at never
    /// goes back), in whole ticks of `dt`. A lead that steps (when the envelope's warm-up ends, or when it
    /// forgets a jab) jerks the target by the twist times the step, and that jerk alone makes energy.
    pub fn steer_lead(&mut self, wanted_s: f64, guess_energy_j: f64, dt: f64) {
        let wanted_s = if wanted_s.is_finite() { wanted_s.max(0.0) } else { 0.0 };
        let goal = wanted_s.min(self.trusted_lead_s(guess_energy_j));
        let (slowest, fastest) = ((self.lead_s - dt).max(0.0), self.lead_s + LEAD_GROWTH_PER_S * dt);
        self.lead_s = goal.clamp(slowest, fastest);
        let ticks = if dt > 0.0 { (self.lead_s / dt + 1e-9).floor() * dt } else { 0.0 };
        self.lead_by(ticks);
    }

    /// True when the coupling adds anything to the dynamics.
    pub fn is_active(&self) -> bool {
        self.pushes && self.weight > 0.0
    }

    /// Updates pose, twist and wrench at the kinematic state `kin` (positions and velocities), and the
    /// Jacobian when `with_jacobian`: a step needs it (implicit mass, the passivity books after the step),
    /// the snapshot probe does not (it applies hand wrenches through `apply_wrench`, and the next step
    /// evaluates again at the same state). The Jacobian is computed even for a coupling that does not push,
    /// so that the users after it on the same OP can copy it ([`Coupling::evaluate_as`]).
    pub fn evaluate(&mut self, model: &Model<S>, kin: &Kinematics<S>, with_jacobian: bool) {
        let rotation = kin.body_rot[self.body];
        let position = kin.body_pos[self.body] + S::rotate(&rotation, &self.point);
        self.op_pose = OpPose { position, rotation };
        self.op_twist = frame_velocity(kin, self.body, &position);
        if with_jacobian {
            frame_jacobian_t(model, kin, self.body, &position, &mut self.jacobian_t);
        }
        self.wrench = self.explicit_wrench();
    }

    /// As [`Coupling::evaluate`], taking the OP's pose, twist and (`with_jacobian`) Jacobian from `first`,
    /// a coupling at the same body and point just evaluated at the same state with the same flag.
    pub fn evaluate_as(&mut self, first: &Coupling<S>, with_jacobian: bool) {
        debug_assert!(self.at_same_point(first));
        self.op_pose = first.op_pose;
        self.op_twist = first.op_twist;
        if with_jacobian && self.is_active() {
            self.jacobian_t.copy_from(&first.jacobian_t);
        }
        self.wrench = self.explicit_wrench();
    }

    /// True when `other` holds the same point of the same body.
    pub fn at_same_point(&self, other: &Coupling<S>) -> bool {
        self.body == other.body && self.point == other.point
    }

    /// `F` of the module documentation at the last evaluated pose and twist.
    #[inline(always)]
    fn explicit_wrench(&self) -> S::OpVec {
        let mut f = S::OpVec::zero();
        if !self.pushes {
            return f;
        }
        let pd = self.pd_wrench();
        let hand = self.hand_part();
        for a in 0..S::DIM {
            // What the passivity controller takes off the PD is replaced by a brake on the OP (the PD's own
            // damping against the OP's velocity), which only dissipates: a PD scaled to zero leaves the VE damped
            // rather than free, and what the brake absorbs lets the account recover (see `passivity`).
            let beta = self.pd_scale[a];
            let brake = if self.brakes { -(1.0 - beta) * self.damping[a] * self.op_twist[a] } else { 0.0 };
            f[a] = hand[a] + self.weight * (beta * pd[a] + brake) + self.hold[a];
        }
        f
    }

    /// The unscaled, unfaded PD `K_g ⊙ (x_lm ⊖ x_op) + B_g ⊙ (ẋ_lm − ẋ_op)` at the last evaluated pose and
    /// twist and the newest reference.
    pub fn pd_wrench(&self) -> S::OpVec {
        let offset = self.target_pose.difference(&self.op_pose);
        let mut f = S::OpVec::zero();
        for a in 0..S::DIM {
            f[a] = self.stiffness[a] * offset[a] + self.damping[a] * (self.target_twist[a] - self.op_twist[a]);
        }
        f
    }

    /// What the PD's spring holds per unit of its scale β, per axis, at the last evaluated pose and the newest
    /// reference: `½ w K_a e_a²` (J), the price the passivity controller puts on raising β.
    pub fn spring_energy(&self) -> S::OpVec {
        let stretch = self.target_pose.difference(&self.op_pose);
        let mut energy = S::OpVec::zero();
        for a in 0..S::DIM {
            energy[a] = 0.5 * self.weight * self.stiffness[a] * stretch[a] * stretch[a];
        }
        energy
    }

    /// Per-axis weight `wβ` of the PD in the wrench.
    pub(super) fn pd_weight(&self, axis: usize) -> f64 {
        self.weight * self.pd_scale[axis]
    }

    /// Per-axis coefficient `w(hB + βh²K)` moved to the mass side by the implicit treatment.
    pub(super) fn implicit_coefficient(&self, dt: f64) -> S::OpVec {
        let mut c = S::OpVec::zero();
        for a in 0..S::DIM {
            let damping = if self.brakes { self.weight } else { self.pd_weight(a) } * dt * self.damping[a];
            c[a] = damping + self.pd_weight(a) * dt * dt * self.stiffness[a];
        }
        c
    }

    /// `h wβK ⊙ ẋ_op`: the spring's response to a step's motion at the current velocity, which the implicit
    /// treatment adds to eq 4's right side as `−Jᵀ` of it.
    pub(super) fn implicit_spring(&self, dt: f64) -> S::OpVec {
        let mut spring = S::OpVec::zero();
        for a in 0..S::DIM {
            spring[a] = dt * self.pd_weight(a) * self.stiffness[a] * self.op_twist[a];
        }
        spring
    }

    /// `J v` for a joint-space vector `v`, touching only the joints that move the OP.
    pub fn op_space_image(&self, model: &Model<S>, v: &DVector<f64>) -> S::OpVec {
        let mut out = S::OpVec::zero();
        for j in support(model, Some(self.body)) {
            for a in 0..S::DIM {
                out[a] += self.jacobian_t[(j, a)] * v[j];
            }
        }
        out
    }

    /// What the implicit treatment added to the explicit wrench in a step of `dt` that produced `qdd`:
    /// `−h wβK ⊙ ẋ_op − w(hB + βh²K) ⊙ J q̈`.
    pub fn implicit_correction(&self, model: &Model<S>, qdd: &DVector<f64>, dt: f64) -> S::OpVec {
        let coefficient = self.implicit_coefficient(dt);
        let accel = self.op_space_image(model, qdd);
        let spring = self.implicit_spring(dt);
        let mut out = S::OpVec::zero();
        for a in 0..S::DIM {
            out[a] = -spring[a] - coefficient[a] * accel[a];
        }
        out
    }

    /// The force channel as the VE applies it: the human's own force and any load held for the user (fade
    /// included; zero for observers). The handover's hold (`hold`) is not part of it.
    pub fn hand_part(&self) -> S::OpVec {
        if !self.pushes {
            return S::OpVec::zero();
        }
        let mut part = S::OpVec::zero();
        for a in 0..S::DIM {
            part[a] = self.weight * self.hand_scale[a] * (self.hand_wrench[a] + self.held_load[a]);
        }
        part
    }

    /// The part of the applied wrench that is neither the force channel nor the VE's hold (`hold`): the
    /// (scaled) PD and its brake.
    pub fn controller_part(&self, wrench: &S::OpVec) -> S::OpVec {
        if !self.pushes {
            return S::OpVec::zero();
        }
        *wrench - self.hand_part() - self.hold
    }
}

/// How long the twist-rate envelope remembers a rate (s of client time, decaying by e): longer than a poke's
/// jab (0.2 s), so its rebound is not led, shorter than a tour's segments (at least 0.6 s), so a tour is.
pub const LEAD_RATE_MEMORY_S: f64 = 0.5;
/// The longest span over which a change of the heard twist counts as spread out (s): uplinks come every
/// millisecond or two, and a change heard across a longer gap (a burst of lost uplinks) is counted as made
/// within this: spread over a long burst, a jab's rebound would look gentle enough to lead.
pub const LEAD_RATE_GAP_S: f64 = 0.005;
/// How fast a lead may grow (s per s): the target runs at most 1.5 times the hand's speed while it does.
pub const LEAD_GROWTH_PER_S: f64 = 0.5;

/// How far ahead of its newest heard uplink a coupling's target is led (s): the network's one-way delay, half
/// the shortest round trip heard (`shortest_round_trip_s`; the clocks are not synchronised, and the shortest
/// trip leaves out the jitter, over which a guess overshoots), at most `max_s`, in whole VE ticks of `dt`
/// (the client keeps its model's states by tick, and a snapshot names the state the VE aimed at); none when
/// that delay is outside `[from, until]` (`VeConfig::coupling_lead_delays_s`).
pub fn target_lead_s(shortest_round_trip_s: Option<f64>, max_s: f64, [from, until]: [f64; 2], dt: f64) -> f64 {
    let one_way = shortest_round_trip_s.map_or(0.0, |rtt| 0.5 * rtt);
    if !(one_way.is_finite() && max_s > 0.0 && dt > 0.0) || one_way < from || one_way > until {
        return 0.0;
    }
    (one_way.min(max_s) / dt).floor() * dt
}

/// β = 1 on every axis: the PD at full strength.
pub fn full_scale<S: Space>() -> S::OpVec {
    let mut scale = S::OpVec::zero();
    scale.as_mut_slice().fill(1.0);
    scale
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
    use kinloop_linkage::testing::{paper_testbed, random_state};
    use kinloop_linkage::{math::space::Planar, model::data::Data};
    use nalgebra::Vector3;

    /// The testbed at random state `seed`, with its kinematics (positions and velocities) evaluated.
    pub(crate) fn testbed_in_motion(seed: u64) -> (Model<Planar>, Data<Planar>, DVector<f64>) {
        let model = paper_testbed();
        let mut data = Data::new(&model);
        let (q, qd) = random_state(&model, seed);
        forward_kinematics(&model, &mut data, &q);
        forward_velocity(&model, &mut data, &qd);
        (model, data, qd)
    }

    #[test]
    fn a_led_target_is_the_heard_pose_moved_along_its_twist_and_names_its_client_time() {
        let mut c = Coupling::<Planar>::new(1, nalgebra::Vector2::new(0.1, 0.0), 3, Vector3::zeros(), Vector3::zeros());
        let mut pose = OpPose::<Planar>::identity();
        pose.position = nalgebra::Vector2::new(0.02, -0.01);
        let twist = Vector3::new(0.05, 0.1, 2.0);
        c.follow(&Reference { client_time_s: 3.0, hand_wrench: Vector3::zeros(), pose, twist });
        c.lead_by(0.1);
        // 0.1 s along (0.05, 0.1) m/s and 2 rad/s: 5 and 10 mm, 0.2 rad.
        let moved = c.target_pose.difference(&pose);
        assert!((moved - Vector3::new(0.005, 0.010, 0.2)).norm() < 1e-12, "{moved}");
        assert!((c.target_time_s - 3.1).abs() < 1e-12);
        assert_eq!((c.heard_pose, c.heard_time_s), (pose, 3.0));
        // Leads do not accumulate: each is taken from the heard pose; a bad lead is none.
        c.lead_by(0.05);
        assert!((c.target_pose.difference(&pose) - Vector3::new(0.0025, 0.005, 0.1)).norm() < 1e-12);
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            c.lead_by(bad);
            assert_eq!((c.target_pose, c.target_time_s), (pose, 3.0), "{bad}");
        }
    }

    /// What `update_couplings` does with an uplink when the VE leads: tracks its twist's rate, then follows it.
    fn hear(c: &mut Coupling<Planar>, reference: Reference<Planar>) {
        c.track_twist_rate(&reference);
        c.follow(&reference);
    }

    /// A planar coupling with the testbed's default-like gains, having heard a hand that started at the
    /// identity pose with twist (0.04 m/s, −0.02 m/s, 0.3 rad/s) and accelerates steadily at `accel` (linear
    /// m/s², angular rad/s²), from client time 1 s for `heard_s`, one uplink per millisecond. Returns the
    /// coupling and the hand's last pose and twist.
    fn heard_accelerating(accel: Vector3<f64>, heard_s: f64) -> (Coupling<Planar>, OpPose<Planar>, Vector3<f64>) {
        let stiffness = Vector3::new(9500.0, 9500.0, 12.5);
        let mut c = Coupling::<Planar>::new(1, nalgebra::Vector2::zeros(), 3, stiffness, Vector3::zeros());
        let (mut pose, mut twist) = (OpPose::<Planar>::identity(), Vector3::new(0.04, -0.02, 0.3));
        let dt = 1e-3;
        for k in 0..=(heard_s / dt).round() as usize {
            if k > 0 {
                // Exact for steady acceleration: x += v dt + ½ a dt², v += a dt.
                pose.integrate(&(twist + accel * (0.5 * dt)), dt);
                twist += accel * dt;
            }
            let reference =
                Reference { client_time_s: 1.0 + k as f64 * dt, hand_wrench: Vector3::zeros(), pose, twist };
            hear(&mut c, reference);
        }
        (c, pose, twist)
    }

    /// The envelope holds each axis's rate of change of the heard twist, and forgets it by e over
    /// `LEAD_RATE_MEMORY_S` once the hand moves steadily; an uplink repeated leaves it alone; a change heard
    /// across a gap counts as made within `LEAD_RATE_GAP_S`.
    #[test]
    fn the_twist_rate_envelope_holds_the_largest_rate_and_forgets_it_slowly() {
        let accel = Vector3::new(2.0, -1.0, 30.0);
        let (mut c, mut pose, twist) = heard_accelerating(accel, 0.1);
        let envelope = c.twist_rate_envelope;
        assert!((envelope - accel.abs()).amax() < 1e-9 * accel.amax(), "{envelope} vs {accel}");
        let last = c.heard_time_s;
        // The jitter buffer hands uplinks over in order, but may repeat one.
        hear(&mut c, Reference { client_time_s: last, hand_wrench: Vector3::zeros(), pose, twist });
        assert_eq!(c.twist_rate_envelope, envelope);
        let dt = 1e-3;
        for k in 1..=(LEAD_RATE_MEMORY_S / dt).round() as usize {
            pose.integrate(&twist, dt);
            hear(&mut c, Reference { client_time_s: last + k as f64 * dt, hand_wrench: Vector3::zeros(), pose, twist });
        }
        let forgotten = accel.abs() * (-1.0f64).exp();
        assert!((c.twist_rate_envelope - forgotten).amax() < 1e-9 * accel.amax(), "{}", c.twist_rate_envelope);
        // Heard across a 20 ms gap, a change of the twist counts as made within LEAD_RATE_GAP_S: the rate it
        // shows is the change over 5 ms, four times what it would be spread over the gap.
        let (gap, change) = (0.02, Vector3::new(0.5, 0.0, 0.0));
        let (before, at) = (c.twist_rate_envelope, c.heard_time_s + gap);
        hear(&mut c, Reference { client_time_s: at, hand_wrench: Vector3::zeros(), pose, twist: twist + change });
        assert!((c.twist_rate_envelope[0] - change[0] / LEAD_RATE_GAP_S).abs() < 1e-9, "{}", c.twist_rate_envelope);
        let decayed = before[2] * (-gap / LEAD_RATE_MEMORY_S).exp();
        assert!((c.twist_rate_envelope[2] - decayed).abs() < 1e-9, "{}", c.twist_rate_envelope);
    }

    /// The trusted lead is the longest whose miss, on a hand that keeps accelerating as the envelope says,
    /// holds the guess energy in the PD's spring: computed here from where the hand really is after the lead
    /// (integrated, not the formula) and where the led target put it. Before the envelope has heard
    /// `LEAD_RATE_MEMORY_S` of the hand there is no lead; a steady hand is not bounded (the cap rules); no
    /// energy or a nonsense one allows none.
    #[test]
    fn a_trusted_lead_misses_an_accelerating_hand_by_the_guess_energy() {
        let energy = 1e-3;
        for accel in [Vector3::new(0.3, -0.2, 1.0), Vector3::new(2.5, 0.0, 12.0), Vector3::new(0.0, 0.05, 0.0)] {
            let (mut c, pose, twist) = heard_accelerating(accel, LEAD_RATE_MEMORY_S + 0.1);
            let lead = c.trusted_lead_s(energy);
            assert!(lead > 0.0 && lead.is_finite(), "{accel}: {lead}");
            let mut truth = pose;
            truth.integrate(&(twist + accel * (0.5 * lead)), lead);
            c.lead_by(lead);
            let miss = truth.difference(&c.target_pose);
            let spring = 0.5 * miss.component_mul(&miss).dot(&c.stiffness);
            assert!((spring - energy).abs() < 1e-6 * energy, "{accel}: lead {lead} s leaves {spring} J");
            // A harder hand, a shorter lead.
            let (harder, _, _) = heard_accelerating(accel * 4.0, LEAD_RATE_MEMORY_S + 0.1);
            assert!((harder.trusted_lead_s(energy) - 0.5 * lead).abs() < 1e-9, "{accel}");
            for bad in [0.0, -1.0, f64::NAN] {
                assert_eq!(c.trusted_lead_s(bad), 0.0, "{bad}");
            }
        }
        let (young, _, _) = heard_accelerating(Vector3::new(0.3, 0.0, 0.0), LEAD_RATE_MEMORY_S - 0.01);
        assert_eq!(young.trusted_lead_s(energy), 0.0);
        let (steady, _, _) = heard_accelerating(Vector3::zeros(), LEAD_RATE_MEMORY_S + 0.1);
        assert_eq!(steady.trusted_lead_s(energy), f64::INFINITY);
    }

    /// A lead grows by half a tick per tick, shrinks by at most a tick per tick (the client time the VE aims
    /// at never goes back while the uplinks keep coming), stays in whole ticks, and stops at what is wanted
    /// and what the heard motion supports.
    #[test]
    fn a_lead_grows_by_half_a_second_per_second_and_never_aims_back_in_time() {
        let dt = 1e-3;
        let (mut c, mut pose, twist) = heard_accelerating(Vector3::zeros(), LEAD_RATE_MEMORY_S + 0.1);
        let mut heard = c.heard_time_s;
        let mut aimed = Vec::new();
        for tick in 0..500 {
            // Want 100 ms for 300 ticks, then none.
            let wanted = if tick < 300 { 0.1 } else { 0.0 };
            c.steer_lead(wanted, 1e-3, dt);
            let lead = c.target_time_s - heard;
            assert!(((lead / dt).round() * dt - lead).abs() < 1e-9, "whole ticks: {lead}");
            aimed.push(c.target_time_s);
            if tick == 9 {
                assert!((c.lead_s - 10.0 * 0.5 * dt).abs() < 1e-12, "{}", c.lead_s);
            }
            if tick == 299 {
                assert!((c.lead_s - 0.1).abs() < 1e-12, "{}", c.lead_s);
            }
            pose.integrate(&twist, dt);
            heard += dt;
            hear(&mut c, Reference { client_time_s: heard, hand_wrench: Vector3::zeros(), pose, twist });
        }
        assert!(aimed.windows(2).all(|w| w[1] >= w[0] - 1e-12), "the aimed time went back");
        assert_eq!(c.lead_s, 0.0);
        // A jab the envelope has heard cuts a lead that was allowed to grow on a steady hand.
        let (mut jabbed, _, _) = heard_accelerating(Vector3::new(3.0, 0.0, 0.0), LEAD_RATE_MEMORY_S + 0.1);
        jabbed.lead_s = 0.1;
        let trusted = jabbed.trusted_lead_s(1e-3);
        for _ in 0..200 {
            jabbed.steer_lead(0.1, 1e-3, dt);
        }
        assert!(jabbed.lead_s <= trusted && jabbed.lead_s > trusted - dt, "{} vs {trusted}", jabbed.lead_s);
    }

    #[test]
    fn the_lead_is_half_the_shortest_round_trip_capped_in_whole_ticks() {
        let dt = 1e-3;
        // 2 x 100 ms: 100 ms, or the cap; 0.2005 s round trip: 100 ms (floored to the tick).
        let everywhere = [0.0, f64::INFINITY];
        assert!((target_lead_s(Some(0.2), 1.0, everywhere, dt) - 0.1).abs() < 1e-12);
        assert!((target_lead_s(Some(0.2), 0.05, everywhere, dt) - 0.05).abs() < 1e-12);
        assert!((target_lead_s(Some(0.2015), 1.0, everywhere, dt) - 0.1).abs() < 1e-12);
        // No round trip heard yet, no lead allowed, or nonsense: no lead.
        assert_eq!(target_lead_s(None, 1.0, everywhere, dt), 0.0);
        assert_eq!(target_lead_s(Some(0.2), 0.0, everywhere, dt), 0.0);
        assert_eq!(target_lead_s(Some(f64::NAN), 1.0, everywhere, dt), 0.0);
        assert_eq!(target_lead_s(Some(f64::INFINITY), 1.0, everywhere, dt), 0.0);
        // Outside the delays it leads over, none; at their edges, all (inclusive).
        let window = [0.075, 0.4];
        assert_eq!(target_lead_s(Some(0.1), 1.0, window, dt), 0.0);
        assert_eq!(target_lead_s(Some(1.0), 1.0, window, dt), 0.0);
        assert!(target_lead_s(Some(0.15), 1.0, window, dt) > 0.07);
        assert!(target_lead_s(Some(0.8), 1.0, window, dt) > 0.39);
        assert!((target_lead_s(Some(0.6), 1.0, window, dt) - 0.3).abs() < 1e-12);
        assert!((target_lead_s(Some(0.6), 0.1, window, dt) - 0.1).abs() < 1e-12);
    }

    /// What the passivity controller takes off the PD becomes a brake on the OP: at β = 0 the coupling applies
    /// the hand's force and `−wB ⊙ ẋ_op`, which takes power from the moving OP on every axis; in between, the
    /// PD's share and the brake's add up to the whole PD's damping, which the implicit treatment keeps whole.
    /// The force channel's own scale (`hand_scale`) takes its share off the hand's part and nothing else.
    #[test]
    fn what_the_controller_takes_off_the_pd_brakes_the_op() {
        let (model, data, _) = testbed_in_motion(5);
        let stiffness = Vector3::new(800.0, 900.0, 2.0);
        let mut c =
            Coupling::<Planar>::new(1, nalgebra::Vector2::new(0.01, -0.002), model.nv(), stiffness, stiffness * 0.05);
        c.pushes = true;
        c.weight = 0.8;
        c.hand_wrench = Vector3::new(0.3, -0.2, 0.001);
        c.target_pose = OpPose { position: nalgebra::Point2::new(0.02, 0.03).coords, ..OpPose::identity() };
        c.evaluate(&model, &data.kin, true);
        assert!(c.op_twist.norm() > 0.0, "the testbed is moving");
        let dt = 1e-3;
        let full = c.implicit_coefficient(dt);
        for beta in [0.0, 0.5] {
            c.pd_scale = Vector3::repeat(beta);
            let controller = c.controller_part(&c.explicit_wrench());
            let pd = c.pd_wrench();
            for a in 0..3 {
                let brake = -c.weight * c.damping[a] * c.op_twist[a];
                let expected = c.weight * beta * pd[a] + (1.0 - beta) * brake;
                assert!((controller[a] - expected).abs() <= 1e-12 * (1.0 + expected.abs()), "β {beta} axis {a}");
                if beta == 0.0 {
                    assert!(controller[a] * c.op_twist[a] <= 0.0, "at β = 0 the controller takes power on axis {a}");
                }
                let coefficient = c.implicit_coefficient(dt)[a];
                let damping_part = c.weight * dt * c.damping[a];
                assert!((coefficient - damping_part - beta * (full[a] - damping_part)).abs() <= 1e-15 * full[a]);
            }
        }
        // The force channel's scale takes its share off the hand's part alone; the controller's is unchanged.
        c.pd_scale = Vector3::repeat(0.5);
        let (whole_hand, whole) = (c.hand_part(), c.explicit_wrench());
        c.hand_scale = Vector3::new(0.25, 1.0, 0.0);
        let scaled = c.explicit_wrench();
        for a in 0..3 {
            let hand = c.weight * c.hand_scale[a] * c.hand_wrench[a];
            assert!((c.hand_part()[a] - hand).abs() <= 1e-15, "axis {a}");
            assert!((scaled[a] - (whole[a] - whole_hand[a] + hand)).abs() <= 1e-12, "axis {a}");
        }
        assert!((c.controller_part(&scaled) - (whole - whole_hand)).norm() <= 1e-12);
    }
}
