//! Springs and dampers on cut joints: generalized forces `Wᵀ`-like, through the cut's own freedom (the
//! right-hand side of eq 1, beside the tree joints' springs in G and damping in τ).
//!
//! A cut leaves a relative motion free ([`CutFreedom`]): a slide `s` along an axis fixed in body a, a hinge
//! angle `θ` about such an axis, or a free rotation. A force `f` along that freedom acts on body b and,
//! equal and opposite, on body a at the same world point (a force along the slide at point b's position; a
//! torque about the hinge axis), so its generalized force is `f ∂s/∂q` — the cut's Jacobian row for its
//! freedom. For a slide this is exact: `ṡ = u·(v_b(p_b) − v_a(p_b))` with `v_a(p_b)` the velocity of the point
//! of body a at `p_b`, which accounts for the turning of `u` with body a. For a hinge it is exact on the
//! constraint manifold (where b turns relative to a about the axis only); for a free rotation the torque
//! `−k φ` of the rotation vector `φ` is exactly the gradient of `½ k |φ|²`.
//!
//! The spring's potential `½ k (s − rest)²` enters G (so G stays the gradient of the potential energy),
//! the damper `−c ṡ` enters the joint forces, dissipating exactly `c ṡ²`.

use nalgebra::DVector;

use crate::algorithms::jacobian::apply_wrench;
use crate::math::space::{Space, VecOps};
use crate::model::data::Kinematics;
use crate::model::{CutFreedom, Model};

/// A cut freedom's position and rate: metres (slide) or radians (hinge), per second for the rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FreedomState {
    /// Slide length or hinge angle (the angle from q0's pose, in (−π, π]).
    pub position: f64,
    /// Its time derivative.
    pub rate: f64,
}

/// The world rotation from where body b would be, carried rigidly by body a from q0, to where it is:
/// `R_b R₀⁻¹ R_a⁻¹`, whose rotation vector is the freedom of a hinge or free rotation.
fn rotation_from_q0<S: Space>(
    kin: &Kinematics<S>,
    body_a: Option<usize>,
    body_b: Option<usize>,
    relative: &S::Rot,
) -> S::Angular {
    let carried = S::rot_mul(&kin.rot(body_a), relative);
    S::rot_log(&S::rot_mul(&kin.rot(body_b), &S::rot_inverse(&carried)))
}

/// Angular velocity of body b relative to body a, world axes.
fn relative_angular_velocity<S: Space>(
    kin: &Kinematics<S>,
    body_a: Option<usize>,
    body_b: Option<usize>,
) -> S::Angular {
    S::spatial_ang(&kin.velocity(body_b)) - S::spatial_ang(&kin.velocity(body_a))
}

/// Position and rate of a one-dimensional cut freedom (slide or hinge) at the kinematic state `kin`
/// (positions and velocities); `None` for a locked cut or a free rotation.
pub fn freedom_state<S: Space>(freedom: &CutFreedom<S>, kin: &Kinematics<S>) -> Option<FreedomState> {
    match freedom {
        CutFreedom::Slide { a, b, axis_a } => {
            let u = kin.direction(a.body, axis_a);
            let p_b = kin.point(b);
            let position = u.dot(&(p_b - kin.point(a)));
            let rate = u.dot(&(kin.point_velocity(b.body, &p_b) - kin.point_velocity(a.body, &p_b)));
            Some(FreedomState { position, rate })
        }
        CutFreedom::Hinge { body_a, body_b, axis_a, relative } => {
            let axis = S::axis_as_angular(&kin.direction(*body_a, axis_a));
            let position = axis.dot(&rotation_from_q0(kin, *body_a, *body_b, relative));
            let rate = axis.dot(&relative_angular_velocity(kin, *body_a, *body_b));
            Some(FreedomState { position, rate })
        }
        CutFreedom::Locked | CutFreedom::Rotation { .. } => None,
    }
}

/// Adds to `tau` the generalized force of a pair of equal and opposite wrenches: `wrench` on body b at
/// world point `p`, its opposite on body a at the same point (ground takes no generalized force).
fn apply_pair<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body_a: Option<usize>,
    body_b: Option<usize>,
    p: &S::Point,
    wrench: &S::OpVec,
    tau: &mut DVector<f64>,
) {
    if let Some(b) = body_b {
        apply_wrench(model, kin, b, p, wrench, tau);
    }
    if let Some(a) = body_a {
        apply_wrench(model, kin, a, p, &(*wrench * -1.0), tau);
    }
}

/// Adds to `tau` the generalized force of a force `f` along a slide or hinge freedom (N or N m; positive
/// pushes the position up): `f ∂s/∂q`.
pub fn apply_along<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    freedom: &CutFreedom<S>,
    f: f64,
    tau: &mut DVector<f64>,
) {
    match freedom {
        CutFreedom::Slide { a, b, axis_a } => {
            let u = kin.direction(a.body, axis_a);
            let wrench = S::op(u * f, S::Angular::zero());
            apply_pair(model, kin, a.body, b.body, &kin.point(b), &wrench, tau);
        }
        CutFreedom::Hinge { body_a, body_b, axis_a, .. } => {
            let axis = S::axis_as_angular(&kin.direction(*body_a, axis_a));
            let wrench = S::op(S::Point::zero(), axis * f);
            apply_pair(model, kin, *body_a, *body_b, &S::Point::zero(), &wrench, tau);
        }
        CutFreedom::Locked | CutFreedom::Rotation { .. } => {}
    }
}

/// Adds the cut springs' part of G(q) (`+∂V/∂q`) to `gravity`. Needs `forward_kinematics`.
pub fn add_cut_springs<S: Space>(model: &Model<S>, kin: &Kinematics<S>, gravity: &mut DVector<f64>) {
    for cut in &model.cuts {
        let Some(spring) = cut.spring else { continue };
        match &cut.freedom {
            CutFreedom::Rotation { body_a, body_b, relative } => {
                let phi = rotation_from_q0(kin, *body_a, *body_b, relative);
                let wrench = S::op(S::Point::zero(), phi * spring.stiffness);
                apply_pair(model, kin, *body_a, *body_b, &S::Point::zero(), &wrench, gravity);
            }
            freedom => {
                if let Some(s) = freedom_state(freedom, kin) {
                    apply_along(model, kin, freedom, spring.stiffness * (s.position - spring.rest), gravity);
                }
            }
        }
    }
}

/// Adds the cut dampers' forces `−c ṡ` to the joint forces `tau`. Needs `forward_velocity`.
pub fn add_cut_dampers<S: Space>(model: &Model<S>, kin: &Kinematics<S>, tau: &mut DVector<f64>) {
    for cut in model.cuts.iter().filter(|c| c.damping > 0.0) {
        match &cut.freedom {
            CutFreedom::Rotation { body_a, body_b, .. } => {
                let omega = relative_angular_velocity(kin, *body_a, *body_b);
                let wrench = S::op(S::Point::zero(), omega * -cut.damping);
                apply_pair(model, kin, *body_a, *body_b, &S::Point::zero(), &wrench, tau);
            }
            freedom => {
                if let Some(s) = freedom_state(freedom, kin) {
                    apply_along(model, kin, freedom, -cut.damping * s.rate, tau);
                }
            }
        }
    }
}

/// Potential energy of the cut springs at the configuration of the last `forward_kinematics`.
pub fn cut_spring_energy<S: Space>(model: &Model<S>, kin: &Kinematics<S>) -> f64 {
    let mut e = 0.0;
    for cut in &model.cuts {
        let Some(spring) = cut.spring else { continue };
        let stretch = match &cut.freedom {
            CutFreedom::Rotation { body_a, body_b, relative } => {
                rotation_from_q0(kin, *body_a, *body_b, relative).norm()
            }
            freedom => freedom_state(freedom, kin).map_or(0.0, |s| s.position - spring.rest),
        };
        e += 0.5 * spring.stiffness * stretch * stretch;
    }
    e
}
