//! The controllers of the paper's section III (Fig 2) as they act on the device in its Fig 4:
//! joint-constraint control along the constrained directions, impedance control with Λ̂⁻¹ in the free
//! directions, and the four-channel teleoperator between device and local model.
//!
//! **Units.** Û and Σ̂ arrive in the unit-consistent coordinates of `constraint_directions`: a twist is
//! `T ẋ = (v, L ω)`, a wrench `T⁻¹ F = (f, τ / L)`, with `T = diag(1 linear, L angular)`. A scaled projector
//! P̃ therefore acts on twists as `T⁻¹ P̃ T`, on wrenches as `T P̃ T⁻¹`, and a scaled stiffness `k P̃` becomes
//! the physical stiffness `T P̃ T k` (N/m along linear, N m/rad along angular directions).
//!
//! **Weights instead of a count.** `P̃_c = Σ wᵢ ũᵢ ũᵢᵀ` with a continuous weight of the relative singular
//! value (see [`ConstraintWeighting`]): a direction crossing the threshold fades in and out, and equal
//! singular values get equal weights, so a swap in the SVD's order changes nothing. The free-direction
//! projector is `I − P̃_c = Σ (1 − wᵢ) ũᵢ ũᵢᵀ`.

use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, scale_op, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::local_model::{ContactTerm, MAX_LOCAL_CONTACTS};
use kinloop_linkage::algorithms::op_path::product;
use kinloop_linkage::math::space::{MatOps, Space, VecOps};

use super::config::ConstraintWeighting;
use super::intake::SnapshotTerms;
use super::safety::smoothstep;

/// The weight of a direction with relative singular value `r = σᵢ / σ₁`: 1 at or below `full_below`, 0 at
/// or above `none_above`, smoothstep between.
pub fn constraint_weight(r: f64, weighting: &ConstraintWeighting) -> f64 {
    let span = weighting.none_above - weighting.full_below;
    if r <= weighting.full_below {
        1.0
    } else if r >= weighting.none_above || span <= 0.0 {
        0.0
    } else {
        smoothstep((weighting.none_above - r) / span)
    }
}

/// The constrained-direction projector, Λ̂⁻¹ and the free-direction pseudo-inverse, filtered so that a new
/// snapshot never steps the force, plus the hysteretic constraint count.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ConstraintFrame<S: Space> {
    target_projector: S::OpMat,
    target_inverse_inertia: S::OpMat,
    target_bias: S::OpVec,
    /// Scaled P̃_c in use (filtered).
    pub projector: S::OpMat,
    /// Λ̂⁻¹ in use (filtered, physical units).
    pub inverse_inertia: S::OpMat,
    /// b̂ in use (filtered): the OP acceleration of everything but this user's hand (other users' hands,
    /// velocity terms, gravity).
    pub bias: S::OpVec,
    /// Λ̂⁺ restricted to the free directions (physical units): maps an OP acceleration to the OP wrench
    /// that causes it; used to express contact forces as wrenches at the OP.
    pub free_inertia: S::OpMat,
    /// `Λ̂` itself in every direction the controllers render (physical units), the smallest singular values
    /// of `Λ̂⁻¹` floored: the local model's kinetic energy is `½ ẋᵀ Λ̂ ẋ`, and along the constrained directions
    /// the model is heavy, not massless.
    pub inertia: S::OpMat,
    counted: [bool; 6],
    /// Directions counted as constrained (with hysteresis).
    pub count: usize,
}

impl<S: Space> ConstraintFrame<S> {
    pub fn new() -> Self {
        ConstraintFrame {
            target_projector: S::OpMat::zero(),
            target_inverse_inertia: S::OpMat::zero(),
            target_bias: S::OpVec::zero(),
            projector: S::OpMat::zero(),
            inverse_inertia: S::OpMat::zero(),
            bias: S::OpVec::zero(),
            free_inertia: S::OpMat::zero(),
            inertia: S::OpMat::zero(),
            counted: [false; 6],
            count: 0,
        }
    }

    /// Takes a snapshot's directions as the new target; `jump` adopts it at once (first snapshot, resume).
    ///
    /// `pinned`: the device renders no torque, so the hand holds the OP as through a pin: it pushes with forces
    /// only and the linkage turns the OP as it must. The directions are then those of the linear block of
    /// Λ⁻¹ (the OP's response to forces), and the angular axes are neither constrained nor free (no
    /// controller acts on them). Taking the snapshot's full-space directions instead would let an angle the
    /// device cannot show leak, through directions that mix turning and moving, into linear forces.
    pub fn set_target(
        &mut self,
        terms: &SnapshotTerms<S>,
        weighting: &ConstraintWeighting,
        length_scale: f64,
        jump: bool,
        pinned: bool,
    ) {
        let (values, vectors) = if pinned {
            let block = force_response::<S>(&terms.inverse_inertia);
            let d = constraint_directions::<S>(&block, length_scale, DEFAULT_THRESHOLD);
            (d.singular_values, d.directions)
        } else {
            (terms.singular_values, terms.directions)
        };
        // A direction with no linear part is one the pinned hand does not render.
        let angular_only = |u: &S::OpVec| pinned && S::op_lin(u).norm() < std::f64::consts::FRAC_1_SQRT_2;
        let column = |i: usize| {
            let mut u = S::OpVec::zero();
            for row in 0..S::DIM {
                u[row] = vectors[(row, i)];
            }
            u
        };
        let sigma_max = (0..S::DIM).filter(|&i| !angular_only(&column(i))).map(|i| values[i]).fold(0.0, f64::max);
        let mut projector = S::OpMat::zero();
        let mut free_scaled = S::OpMat::zero();
        let mut inertia_scaled = S::OpMat::zero();
        let mut count = 0;
        for i in 0..S::DIM {
            let u = column(i);
            if angular_only(&u) {
                self.counted[i] = false;
                continue;
            }
            // An immobile OP (σ₁ = 0) is constrained in every direction.
            let r = if sigma_max > 0.0 { values[i] / sigma_max } else { 0.0 };
            let w = constraint_weight(r, weighting);
            let outer = S::op_outer(&u, &u);
            projector += outer * w;
            if values[i] > 0.0 && w < 1.0 {
                free_scaled += outer * ((1.0 - w) / values[i]);
            }
            // A direction the linkage does not move in at all is as heavy as the lightest measurable one
            // is light, a million times over.
            inertia_scaled += outer * (1.0 / values[i].max(sigma_max * INERTIA_FLOOR));
            if r <= weighting.count_enter {
                self.counted[i] = true;
            } else if r >= weighting.count_exit {
                self.counted[i] = false;
            }
            count += usize::from(self.counted[i]);
        }
        self.count = count;
        self.target_projector = projector;
        self.target_inverse_inertia = terms.inverse_inertia;
        self.target_bias = terms.bias;
        // (Λ⁻¹)⁺ = T Λ̃⁺ T because Λ̃⁻¹ = T Λ⁻¹ T.
        self.free_inertia = scale_both::<S>(&free_scaled, length_scale, length_scale);
        self.inertia = scale_both::<S>(&inertia_scaled, length_scale, length_scale);
        if jump {
            self.projector = projector;
            self.inverse_inertia = terms.inverse_inertia;
            self.bias = terms.bias;
        }
    }

    /// Moves the terms in use a fraction `alpha` ∈ [0, 1] toward the target (first-order filter).
    pub fn filter(&mut self, alpha: f64) {
        self.projector += (self.target_projector - self.projector) * alpha;
        self.inverse_inertia += (self.target_inverse_inertia - self.inverse_inertia) * alpha;
        self.bias += (self.target_bias - self.bias) * alpha;
    }

    /// The terms in use turned by `turn` (a rotation of the unit-consistent coordinates, `op_path::turn_between`)
    /// — the frame carried along a 1-DOF linkage's path from where its snapshot was linearized to where the
    /// model is. Directions and their weights turn (`R P̃ Rᵀ`), Λ̂⁻¹ and b̂ turn as twists do (`Q = T⁻¹ R T`:
    /// `Q Λ̂⁻¹ Qᵀ`, `Q b̂`), the inertias as wrenches do (`Q⁻ᵀ Λ̂ Q⁻¹`, with `Q⁻ᵀ = T R T⁻¹`); the
    /// singular values, so the count, are kept.
    pub fn turned(&self, turn: &S::OpMat, length_scale: f64) -> Self {
        let twist_turn = twist_turn::<S>(turn, length_scale);
        let wrench_turn = scale_both::<S>(turn, length_scale, 1.0 / length_scale);
        let conjugate = |q: &S::OpMat, a: &S::OpMat| product::<S>(&product::<S>(q, a), &q.transpose());
        ConstraintFrame {
            projector: conjugate(turn, &self.projector),
            inverse_inertia: conjugate(&twist_turn, &self.inverse_inertia),
            bias: twist_turn * self.bias,
            free_inertia: conjugate(&wrench_turn, &self.free_inertia),
            inertia: conjugate(&wrench_turn, &self.inertia),
            ..*self
        }
    }
}

/// The linear block of `inverse_inertia` (the OP's motion under forces alone, as through a pin), its angular
/// rows and columns zeroed.
pub(crate) fn force_response<S: Space>(inverse_inertia: &S::OpMat) -> S::OpMat {
    let lin = <S::Point as VecOps>::LEN;
    let mut block = *inverse_inertia;
    for r in 0..S::DIM {
        for c in 0..S::DIM {
            if r >= lin || c >= lin {
                block[(r, c)] = 0.0;
            }
        }
    }
    block
}

/// A rotation `R` of the unit-consistent coordinates as it acts on physical twists: `T⁻¹ R T`.
pub(crate) fn twist_turn<S: Space>(turn: &S::OpMat, length_scale: f64) -> S::OpMat {
    scale_both::<S>(turn, 1.0 / length_scale, length_scale)
}

/// `A` with rows of angular index multiplied by `row_factor` and columns by `column_factor`:
/// `diag(1, row_factor) A diag(1, column_factor)`.
fn scale_both<S: Space>(a: &S::OpMat, row_factor: f64, column_factor: f64) -> S::OpMat {
    let linear = <S::Point as VecOps>::LEN;
    let mut out = *a;
    for c in 0..S::DIM {
        for r in 0..S::DIM {
            let f = (if r >= linear { row_factor } else { 1.0 }) * (if c >= linear { column_factor } else { 1.0 });
            out[(r, c)] *= f;
        }
    }
    out
}

/// `T P̃ T⁻¹ w`: the part of wrench `w` along the directions P̃ selects.
pub fn project_wrench<S: Space>(projector: &S::OpMat, length_scale: f64, w: &S::OpVec) -> S::OpVec {
    scale_op::<S>(&(*projector * scale_op::<S>(w, 1.0 / length_scale)), length_scale)
}

/// What the device is left to feel of the position channels' wrench `w`: softened along the constrained
/// directions by the linearization trust `trust` (the walls of a stale frame push less), and without its
/// constrained part where the acceleration-zeroing controller cancels it (`cancels`).
pub fn channel_felt<S: Space>(
    projector: &S::OpMat,
    length_scale: f64,
    trust: f64,
    cancels: bool,
    w: &S::OpVec,
) -> S::OpVec {
    let softened = if trust < 1.0 { *w - project_wrench::<S>(projector, length_scale, w) * (1.0 - trust) } else { *w };
    if cancels {
        softened - project_wrench::<S>(projector, length_scale, &softened)
    } else {
        softened
    }
}

/// `T⁻¹ P̃ T ẋ`: the part of twist-like `x` along the directions P̃ selects.
pub fn project_twist<S: Space>(projector: &S::OpMat, length_scale: f64, x: &S::OpVec) -> S::OpVec {
    scale_op::<S>(&(*projector * scale_op::<S>(x, length_scale)), 1.0 / length_scale)
}

/// `T P̃ T x`: the scaled projector as a physical stiffness map from a twist-like `x` to a wrench.
pub fn project_as_stiffness<S: Space>(projector: &S::OpMat, length_scale: f64, x: &S::OpVec) -> S::OpVec {
    scale_op::<S>(&(*projector * scale_op::<S>(x, length_scale)), length_scale)
}

/// Component-wise product.
pub fn hadamard<S: Space>(a: &S::OpVec, b: &S::OpVec) -> S::OpVec {
    let mut out = *a;
    for i in 0..S::DIM {
        out[i] *= b[i];
    }
    out
}

/// Position channels of the four-channel teleoperator (Fig 4, `K_pc`, `B_pc`), on the device:
/// `K_pc ⊙ (x_m ⊖ x_d) + B_pc ⊙ (ẋ_m − ẋ_d)` with `error = x_d ⊖ x_m`, `error_rate = ẋ_d − ẋ_m`.
/// The local model receives the opposite, at the end of its step (`channel_reaction`), along the constrained
/// directions only at the walls' gains (`ResolvedGains::wall_stiffness`).
pub fn position_channel<S: Space>(
    stiffness: &S::OpVec,
    damping: &S::OpVec,
    error: &S::OpVec,
    error_rate: &S::OpVec,
) -> S::OpVec {
    -(hadamard::<S>(stiffness, error) + hadamard::<S>(damping, error_rate))
}

/// Joint-constraint control, stiffness mode (Fig 4, first manipulation): a spring-damper along the
/// constrained directions, `−T P̃_c T (k_j e + b_j ė)`.
pub fn joint_constraint_stiffness<S: Space>(
    projector: &S::OpMat,
    length_scale: f64,
    stiffness: f64,
    damping: f64,
    error: &S::OpVec,
    error_rate: &S::OpVec,
) -> S::OpVec {
    -project_as_stiffness::<S>(projector, length_scale, &(*error * stiffness + *error_rate * damping))
}

/// Smallest singular value of `Λ̂⁻¹` counted in `ConstraintFrame::inertia`, relative to the largest.
pub const INERTIA_FLOOR: f64 = 1e-6;

/// Distance, in reaches, within which [`linearization_trust`] is exactly 1.
pub const TRUST_DEAD_ZONE: f64 = 0.05;

/// How much of the constrained directions' stiffness a local model at scaled distance `distance` from the
/// pose its terms were computed at still renders: `1 / (1 + r² − r₀²)` with `r = distance / reach`, and all of it
/// within `r₀ =` [`TRUST_DEAD_ZONE`] (a twentieth of the reach: under a millimetre on the built-in scenes, where
/// a session without delay stays, and the controllers then skip the softening altogether).
///
/// The frozen terms describe the linkage's constraint as a plane through that pose; the linkage's motion
/// curves away from the plane by about `κ d² / 2` at distance `d` (curvature `κ`). Under delay the model
/// runs a round trip of motion ahead of the VE it was linearized at (centimetres at slow hand speeds and long
/// delays), the hand follows the real curve, and a joint stiffness `k` held against the plane pushed back with
/// `k κ d² / 2`: several newtons, enough to saturate a device. Scaled by this trust the push is
/// `k κ d² / (2 (1 + d²/reach²))`, never more than `k κ reach² / 2` however far the model runs; near the
/// linearization point (no delay) the walls keep their full stiffness. The constraint degrades to a softer
/// wall instead of a wrong one: graceful transparency rather than saturation.
pub fn linearization_trust(distance: f64, reach: f64) -> f64 {
    // An infinite reach trusts everywhere (r = 0), a zero reach nowhere off the point (r = ∞ → 0); a
    // non-finite model is the safety layer's business, not this one's.
    let r = distance / reach;
    if r.is_nan() || r <= TRUST_DEAD_ZONE {
        1.0
    } else {
        1.0 / (1.0 + r * r - TRUST_DEAD_ZONE * TRUST_DEAD_ZONE)
    }
}

/// Joint-constraint control, impedance mode (second manipulation: "controlling the acceleration of the
/// end-effector of the haptic device to zero along the directions of cut joint constraint"): cancels, along
/// the constrained directions, the hand wrench and every other wrench the core commands,
/// `−T P̃_c T⁻¹ (F_h + F_other)`, so nothing accelerates the device there. Cancelling the hand wrench alone
/// would leave the position channels pulling along those directions — a stiffness rendering at `K_pc` —
/// and the device would not drift from the OP as in the paper's Fig 7b.
pub fn joint_constraint_impedance<S: Space>(
    projector: &S::OpMat,
    length_scale: f64,
    hand: &S::OpVec,
    other: &S::OpVec,
) -> S::OpVec {
    -project_wrench::<S>(projector, length_scale, &(*hand + *other))
}

/// How much lighter than itself the impedance controller may make the device feel, per axis. Rendering a
/// mass `m` on a device of mass `M` feeds the sensed hand wrench back with gain `M/m − 1`; a sampled force
/// sensor with a hand on it tolerates only a small such gain (the serial arm's hand OP, 0.004 kg m² against
/// the paper device's 0.005 kg m² mapped to 1.6 VE units, asked for a gain of 360 and chattered at the
/// device's torque limit every tick). Past this ratio the OP is rendered as `M / MAX_MASS_REDUCTION`.
pub const MAX_MASS_REDUCTION: f64 = 4.0;

/// Impedance control with Λ̂⁻¹ in the free directions: the device (mass M) under the hand wrench plus this
/// wrench accelerates as the linkage's OP would (eq 5 with the local model's bias, `ẍ = Λ̂⁻¹ F_h + b̂`),
/// `M⁻¹ (F_h + F) = Λ̂⁻¹ F_h + b̂`, i.e. `F = M (Λ̂⁻¹ F_h + b̂) − F_h`, applied only in the free directions:
/// `F_imp = P_f (M (Λ̂⁻¹ F_h + b̂) − F_h)` with the wrench projector `P_f = T (I − P̃_c) T⁻¹`. The bias carries
/// what moves the OP besides this hand (other users' hands above all): without it each device renders the
/// linkage as if its own hand alone pushed it, and the others' pushes reach it only through the position
/// channels, which then drag the device's own mass along. (Exact when M is isotropic within the linear and
/// within the angular axes, as on the paper's device; otherwise the projection mixes a little of M's
/// anisotropy into the constrained directions, where the joint-constraint controller dominates.) Axis by
/// axis, the mass reduction is bounded by [`MAX_MASS_REDUCTION`].
pub fn impedance_free<S: Space>(
    projector: &S::OpMat,
    length_scale: f64,
    device_mass: &S::OpVec,
    inverse_inertia: &S::OpMat,
    bias: &S::OpVec,
    hand: &S::OpVec,
) -> S::OpVec {
    let mut accel = *inverse_inertia * *hand + *bias;
    for i in 0..S::DIM {
        let reduction = device_mass[i] * inverse_inertia[(i, i)];
        if reduction > MAX_MASS_REDUCTION {
            accel[i] *= MAX_MASS_REDUCTION / reduction;
        }
    }
    let shaped = hadamard::<S>(device_mass, &accel) - *hand;
    shaped - project_wrench::<S>(projector, length_scale, &shaped)
}

/// Force channel from the local model to the device: each live contact's penalty force, expressed as the
/// OP wrench that gives the OP the same acceleration, `Λ̂⁺ (Λ⁻¹_hc n) f_c` (free directions only: along
/// constrained directions the joints, not the contact, hold the OP).
pub fn contact_feedforward<S: Space>(
    contacts: &[ContactTerm<S>; MAX_LOCAL_CONTACTS],
    live: usize,
    free_inertia: &S::OpMat,
) -> S::OpVec {
    let mut accel = S::OpVec::zero();
    for c in &contacts[..live.min(MAX_LOCAL_CONTACTS)] {
        accel += c.coupling * c.force();
    }
    *free_inertia * accel
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;

    type V = <Planar as Space>::OpVec;
    type M = <Planar as Space>::OpMat;

    /// `ConstraintFrame::inertia` is `Λ̂ = (Λ̂⁻¹)⁻¹` where that exists (checked against nalgebra's inverse), and
    /// heavy but finite along a direction the OP cannot move in.
    #[test]
    fn the_frame_inertia_inverts_the_inverse_inertia_and_is_heavy_where_the_op_cannot_move() {
        let length_scale = 0.05;
        let frame_of = |inverse_inertia: M| {
            let mut terms = SnapshotTerms::<Planar>::new(None);
            let d = constraint_directions::<Planar>(&inverse_inertia, length_scale, DEFAULT_THRESHOLD);
            terms.inverse_inertia = inverse_inertia;
            terms.singular_values = d.singular_values;
            terms.directions = d.directions;
            let mut frame = ConstraintFrame::<Planar>::new();
            frame.set_target(&terms, &ConstraintWeighting::default(), length_scale, true, false);
            frame
        };
        let a = M::new(2.0, 0.3, -4.0, 0.3, 0.8, 1.0, -4.0, 1.0, 300.0);
        let frame = frame_of(a);
        let expected = a.try_inverse().expect("invertible");
        let error = (frame.inertia - expected).norm() / expected.norm();
        assert!(error < 1e-9, "relative error {error}");
        // The OP cannot move along y: Λ̂⁻¹ is singular there.
        let singular = M::from_diagonal(&V::from_slice(&[2.0, 0.0, 300.0]));
        let frame = frame_of(singular);
        let y = frame.inertia[(1, 1)];
        assert!(y.is_finite() && y > 1e5, "heavy along y: {y}");
        assert!((frame.inertia[(0, 0)] - 0.5).abs() < 1e-9);
    }

    /// A 1-DOF linkage's frame linearized at one pose and carried to another by the turn between their
    /// tangents (`turned`) is the frame linearized at the other (same mobility along the path, a second
    /// formulation built directly from Λ⁻¹ there): projector, Λ̂⁻¹, both inertias, the count, and a bias along
    /// the path moved onto the new tangent.
    #[test]
    fn a_frame_carried_along_a_path_is_the_frame_linearized_where_it_arrives() {
        let length_scale = 0.05;
        let (mass_along, accel_along) = (0.8, 2.5);
        // Unit tangents in unit-consistent coordinates (x, y, L θ).
        let (from, to) = (V::new(0.6, 0.0, 0.8), V::new(0.0, 0.96, -0.28));
        let unscaled = |v: &V| V::new(v[0], v[1], v[2] / length_scale);
        let frame_along = |t: &V, bias: V| {
            let scaled = Planar::op_outer(t, t) * (1.0 / mass_along);
            let inverse_inertia = scale_both::<Planar>(&scaled, 1.0 / length_scale, 1.0 / length_scale);
            let mut terms = SnapshotTerms::<Planar>::new(None);
            let d = constraint_directions::<Planar>(&inverse_inertia, length_scale, DEFAULT_THRESHOLD);
            terms.inverse_inertia = inverse_inertia;
            terms.singular_values = d.singular_values;
            terms.directions = d.directions;
            terms.bias = bias;
            let mut frame = ConstraintFrame::<Planar>::new();
            frame.set_target(&terms, &ConstraintWeighting::default(), length_scale, true, false);
            frame
        };
        let start = frame_along(&from, unscaled(&from) * accel_along);
        let there = frame_along(&to, unscaled(&to) * accel_along);
        let turn = kinloop_linkage::algorithms::op_path::turn_between::<Planar>(&from, &to, 1.0);
        let carried = start.turned(&turn, length_scale);
        let close = |a: &M, b: &M, what: &str| {
            let error = (a - b).norm() / b.norm().max(1e-300);
            assert!(error < 1e-9, "{what}: relative error {error}\n{a}\n{b}");
        };
        close(&carried.projector, &there.projector, "projector");
        close(&carried.inverse_inertia, &there.inverse_inertia, "inverse inertia");
        close(&carried.free_inertia, &there.free_inertia, "free inertia");
        close(&carried.inertia, &there.inertia, "inertia");
        assert!((carried.bias - there.bias).norm() < 1e-9 * there.bias.norm(), "{} vs {}", carried.bias, there.bias);
        assert_eq!((carried.count, there.count), (2, 2));
        // And the turn did something: the start's walls are not the arrival's.
        assert!((start.projector - there.projector).norm() > 0.5);
    }

    #[test]
    fn impedance_control_makes_the_device_accelerate_as_the_op_with_its_bias() {
        // Device of 1 kg per linear axis and 0.005 kg m² in θ; an OP with Λ̂⁻¹ = diag(2, 0.5, 300) and a bias
        // of (0.3, −0.1, 4) (another user's push, say). No constrained direction: the device under the hand
        // plus the controller must accelerate as ẍ = Λ̂⁻¹ F_h + b̂, computed here by hand.
        let mass = V::from_slice(&[1.0, 1.0, 0.005]);
        let inverse_inertia = M::from_diagonal(&V::from_slice(&[2.0, 0.5, 300.0]));
        let bias = V::from_slice(&[0.3, -0.1, 4.0]);
        let hand = V::from_slice(&[-0.5, 0.2, -0.0025]);
        let f = impedance_free::<Planar>(&M::zero(), 0.05, &mass, &inverse_inertia, &bias, &hand);
        let expected = [2.0 * -0.5 + 0.3, 0.5 * 0.2 - 0.1, 300.0 * -0.0025 + 4.0];
        for axis in 0..3 {
            let accel = (hand[axis] + f[axis]) / mass[axis];
            assert!((accel - expected[axis]).abs() < 1e-12, "axis {axis}: {accel} vs {}", expected[axis]);
        }
        // Along a constrained direction (x here) the controller adds nothing: the joints render it.
        let x_constrained = M::from_diagonal(&V::from_slice(&[1.0, 0.0, 0.0]));
        let f = impedance_free::<Planar>(&x_constrained, 0.05, &mass, &inverse_inertia, &bias, &hand);
        assert_eq!(f[0], 0.0);
        assert!((f[1] - (1.0 * (0.5 * 0.2 - 0.1) - 0.2)).abs() < 1e-12);
    }
    #[test]
    fn linearization_trust_bounds_the_push_of_a_stale_tangent_plane() {
        let reach = 0.02;
        assert_eq!(linearization_trust(0.0, reach), 1.0);
        assert_eq!(linearization_trust(TRUST_DEAD_ZONE * reach, reach), 1.0);
        let just_out = linearization_trust(TRUST_DEAD_ZONE * reach * 1.001, reach);
        assert!(just_out < 1.0 && just_out > 0.9999, "continuous at the dead zone's edge: {just_out}");
        assert!((linearization_trust(reach, reach) - 1.0 / (2.0 - TRUST_DEAD_ZONE * TRUST_DEAD_ZONE)).abs() < 1e-15);
        assert_eq!(linearization_trust(0.05, f64::INFINITY), 1.0);
        assert_eq!(linearization_trust(0.05, 0.0), 0.0);
        // A plane through the linearization point misses a curve of curvature κ by κ d² / 2 at distance d:
        // the softened push k κ d² / 2 · trust(d) rises monotonically to its bound k κ reach² / 2 and never
        // passes it, however far the model runs.
        let (k, kappa) = (2000.0, 10.0);
        let bound = k * kappa * reach * reach / 2.0 / (1.0 - TRUST_DEAD_ZONE * TRUST_DEAD_ZONE);
        let mut last = 0.0;
        for i in 1..=2000 {
            let d = i as f64 * 1e-4;
            let push = k * kappa * d * d / 2.0 * linearization_trust(d, reach);
            assert!(push > last && push < bound, "d = {d}: {push} after {last}, bound {bound}");
            last = push;
        }
        assert!(last > 0.98 * bound, "at 10 reaches the push is near its bound: {last} vs {bound}");
    }
}
