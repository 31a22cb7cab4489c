//! The part of an operational point's free acceleration that is quadratic in the linkage's velocity: the
//! centripetal and Coriolis terms of every link, the closures' `Ẇ q̇` and the OP's own `J̇ q̇` as the loops
//! pass them to the OP.
//!
//! b̂ (eq 11, 13) holds `J q̈ + J̇q̇` at the VE's state, these terms included. Along the OP's free directions
//! they are the other half of the inertia's change along the motion: for one freedom with kinetic energy
//! `½ m(s) ṡ²` and no force, `m s̈ = −½ m'(s) ṡ²`, the acceleration that keeps the energy as the mass changes
//! under it. A local model steps with its inertia frozen at the snapshot's, so it has the acceleration
//! without the change it pairs with, and does work on it that no one put in; under delay the terms are also
//! the VE's velocity, not the model's. Near a pose where the OP barely moves while other links swing (a
//! six-bar's output dyad at its dead centre), they are large, turn with the VE's own swing, and a model fed
//! them runs off against the hand. Along the constrained directions they are the curvature of the OP's path,
//! which holds a model on it.
//!
//! **By the even part.** With `a(v)` the OP acceleration `J q̈ + J̇q̇` of a forward-dynamics solve at `(q, v)`
//! with no applied force, `E(v) = (a(v) + a(−v)) / 2 − a(0)` is the quadratic part alone: gravity, springs
//! and the closures' position terms cancel in the difference, joint dampers and the Baumgarte velocity term
//! (linear in v) in the sum. Three solves at one configuration, in a workspace of its own.

use nalgebra::DVector;

use crate::algorithms::dynamics::{forward_dynamics, OpWrench};
use crate::algorithms::jacobian::{frame_bias_acceleration, frame_jacobian_t};
use crate::algorithms::local_model::op_acceleration;
use crate::error::DynamicsError;
use crate::math::space::{OpPose, Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// The velocity-product acceleration `E(q̇)` of OP `op` at `(q, qd)` (see the module documentation). `data`
/// is a workspace of its own, every solve overwrites it; `signed` holds n numbers of scratch.
pub fn velocity_product_acceleration<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    op: usize,
    signed: &mut DVector<f64>,
) -> Result<S::OpVec, DynamicsError> {
    let mut no_force = OpWrench::<S> { op, wrench: S::OpVec::zero() };
    let body = model.ops.get(op).ok_or(DynamicsError::UnknownOp { index: op, count: model.ops.len() })?.body;
    let mut sum = S::OpVec::zero();
    // The OP's point and Jacobian depend on q alone: taken after the first solve, kept for the others.
    let mut point = None;
    for (sign, weight) in [(1.0, 0.5), (-1.0, 0.5), (0.0, -1.0)] {
        signed.copy_from(qd);
        *signed *= sign;
        forward_dynamics(model, data, q, signed, &mut no_force)?;
        let p = match point {
            Some(p) => p,
            None => {
                let p = OpPose::<S>::of_op(model, data, op).position;
                frame_jacobian_t(model, &data.kin, body, &p, &mut data.op.jacobian_t);
                *point.insert(p)
            }
        };
        // J̇q̇ changes with the velocity.
        data.op.jdot_qdot = frame_bias_acceleration(&data.kin, body, &p);
        sum += op_acceleration(data) * weight;
    }
    Ok(sum)
}
