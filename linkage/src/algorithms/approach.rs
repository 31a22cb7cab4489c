//! Moving a closed configuration so that an operational point approaches a target pose, on the loops: where
//! the linkage would be if its OP were led to the target. A VE uses it to evaluate a user's local-model terms
//! (eq 9, 10) where that user's local model will be when the snapshot reaches it, not where the VE is: under a
//! network delay the model runs a round trip of motion ahead of the VE, and on a curved path the VE's tangent
//! plane is the wrong one there.
//!
//! **The step.** At `q`, the OP wrench that would accelerate the OP along the free part of the pose error
//! `e = target ⊖ x(q)` is `F = (Λ⁻¹)⁺ e` (over the free directions of eq 10, as `reach::static_wrench`), and
//! the joint motion it starts is `Δq = P Jᵀ F` (`kkt::constrained_response`; `P` as in eq 9), which moves the
//! OP by `J P Jᵀ F = Λ⁻¹ F = e_free` to first order. The step is mass-weighted, as a push would move the
//! linkage, and never asks anything of the constrained directions, which no motion of the linkage reaches.
//! `integrator::project` then pulls `q` back onto the loops (eq 2). A few such Newton steps converge
//! quadratically to the closed configuration whose OP is nearest the target along the free directions.
//!
//! Allocation-free given an [`ApproachScratch`] (a VE runs it per user per snapshot).

use nalgebra::DVector;

use crate::algorithms::constraint_directions::{constraint_directions, ConstraintDirections, DEFAULT_THRESHOLD};
use crate::algorithms::dynamics::forward_dynamics;
use crate::algorithms::integrator::project;
use crate::algorithms::kkt::constrained_response;
use crate::algorithms::local_model::OpPose;
use crate::algorithms::op_space::op_space_inertia;
use crate::algorithms::reach::static_wrench;
use crate::error::DynamicsError;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// Newton steps [`approach_op`] takes at most.
pub const MAX_STEPS: usize = 4;

/// A pose error whose free part is below this fraction of the length scale (scaled norm `|(Δp, L Δθ)|`) is
/// reached: 1e-6 L is a few hundredths of a millimetre on the built-in scenes, far below what a device shows.
pub const REACHED: f64 = 1e-6;

/// Buffers of [`approach_op`], sized for one model.
#[derive(Clone, Debug)]
pub struct ApproachScratch {
    /// Zero joint velocities (the approach is at rest: only positions matter).
    at_rest: DVector<f64>,
    /// `Jᵀ F`, then `Δq` (n).
    step: DVector<f64>,
    /// `constrained_response`'s scratch (2m).
    response: Vec<f64>,
    /// Velocities `project` corrects along with `q` (kept zero).
    velocity: DVector<f64>,
    /// `q` before a step, to go back to.
    before: DVector<f64>,
}

impl ApproachScratch {
    /// Buffers for `model`.
    pub fn new<S: Space>(model: &Model<S>) -> Self {
        let n = model.nq();
        ApproachScratch {
            at_rest: DVector::zeros(n),
            step: DVector::zeros(n),
            response: vec![0.0; 2 * model.nc()],
            velocity: DVector::zeros(n),
            before: DVector::zeros(n),
        }
    }
}

/// What [`approach_op`] reached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Approach<S: Space> {
    /// The OP's pose at the final `q`.
    pub pose: OpPose<S>,
    /// Eq 10 at the final `q` (`data.op` holds Λ⁻¹ there).
    pub directions: ConstraintDirections<S>,
    /// Scaled norm of the free part of the error left (`|(Δp, L Δθ)|` over the free directions).
    pub free_error: f64,
    /// Newton steps taken.
    pub steps: usize,
}

/// Moves `q` (closed on entry) toward the closed configuration whose operational point `op` is at `target`
/// (see the module documentation), at most [`MAX_STEPS`] steps. On return `data` holds the dynamics and
/// `data.op` the operational-space terms at the final `q` (at rest), which is closed to the projection's
/// tolerance. A step that would not reduce the error (a dead point in the way, a target off the branch) is
/// not taken: `q` stays where the error was smallest.
pub fn approach_op<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &mut DVector<f64>,
    op: usize,
    target: &OpPose<S>,
    scratch: &mut ApproachScratch,
) -> Result<Approach<S>, DynamicsError> {
    let mut at = evaluate(model, data, q, op, target, scratch)?;
    while at.steps < MAX_STEPS && at.free_error > REACHED * model.length_scale {
        // F = (Λ⁻¹)⁺ e over the free directions (`static_wrench` gives −(Λ̃⁻¹)⁺ ã).
        let wrench = -static_wrench(&at.directions, &target.difference(&at.pose));
        let jt = &data.op.jacobian_t;
        for (i, tau) in scratch.step.iter_mut().enumerate() {
            *tau = (0..S::DIM).map(|c| jt[(i, c)] * wrench[c]).sum();
        }
        constrained_response(model, data, scratch.step.as_mut_slice(), &mut scratch.response);
        scratch.before.copy_from(q);
        *q += &scratch.step;
        scratch.velocity.fill(0.0);
        project(model, data, q, &mut scratch.velocity);
        let next = evaluate(model, data, q, op, target, scratch)?;
        if !(next.free_error < at.free_error) {
            // Not closer (or not finite): back to the best, with its terms in `data`.
            q.copy_from(&scratch.before);
            at = Approach { steps: at.steps + 1, ..evaluate(model, data, q, op, target, scratch)? };
            break;
        }
        at = Approach { steps: at.steps + 1, ..next };
    }
    Ok(at)
}

/// The dynamics at rest, the OP's terms and its pose at `q`, and the free part of the error to `target`.
fn evaluate<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    op: usize,
    target: &OpPose<S>,
    scratch: &ApproachScratch,
) -> Result<Approach<S>, DynamicsError> {
    forward_dynamics(model, data, q, &scratch.at_rest, &mut ())?;
    op_space_inertia(model, data, op)?;
    let directions = constraint_directions::<S>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD);
    let pose = OpPose::of_op(model, data, op);
    let error = directions.to_scaled(&target.difference(&pose));
    let mut free_sq = 0.0;
    for i in 0..S::DIM - directions.count {
        free_sq += directions.direction(i).dot(&error).powi(2);
    }
    Ok(Approach { pose, directions, free_error: free_sq.sqrt(), steps: 0 })
}
