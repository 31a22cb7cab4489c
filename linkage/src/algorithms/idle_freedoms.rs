//! Idle freedoms: motions the closed linkage allows that turn one body about a line through two of its
//! connection points and move nothing else, such as a rod between two ball joints spinning about its own
//! axis (Gruebler-Kutzbach counts one per such rod). They are found, as redundant closures are, from W: for
//! each body b, the motions in the null space of `[W; J_c for every other body c]` (J_c the spatial
//! velocity Jacobian, so c stays still), kept when two of b's connection points (its joint's centre, its
//! children's joint centres, its cut points) stay at rest.
//!
//! **What the model does with them: keeps them.** They are true freedoms of the equations (n − rank W counts
//! them) with a positive inertia (every body's rotational inertia is positive definite), so D, the KKT
//! solve and Λ⁻¹ (eq 9) stay finite; they lie in the null space of every operational point's Jacobian
//! that is not on the spinning body, so they change neither Λ⁻¹ there nor its constraint count (eq 10, 12).
//! `inspect` names them and reports the mobility both with and without them.

use nalgebra::{DMatrix, DVector};

use crate::algorithms::jacobian::support;
use crate::algorithms::kinematics::forward_kinematics;
use crate::algorithms::loop_closure::closure_residual_and_jacobian;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::{Attachment, ClosurePrimitive, JointKind, Model};

/// One idle freedom: `body` turns about the line through `point` along `axis` (world frame, unit).
#[derive(Clone, Debug, PartialEq)]
pub struct IdleFreedom<S: Space> {
    /// The body that turns (never an internal body).
    pub body: usize,
    /// Unit direction of the line, world frame.
    pub axis: S::Angular,
    /// A point on the line, world frame.
    pub point: S::Point,
}

/// Relative tolerance of the null spaces (singular values below it times the largest) and of "at rest"
/// (speeds below it times |ω| L).
const TOLERANCE: f64 = 1e-8;

/// The idle freedoms of `model` at the closed configuration `q`.
pub fn idle_freedoms<S: Space>(model: &Model<S>, q: &DVector<f64>) -> Vec<IdleFreedom<S>> {
    let n = model.nv();
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    closure_residual_and_jacobian(model, &mut data);
    let w = data.closure_jacobian();
    let real: Vec<usize> = (0..n).filter(|&b| !model.is_internal_body(b)).collect();
    let len = <S::Spatial as VecOps>::LEN;
    let mut found = Vec::new();
    for &b in &real {
        let others: Vec<usize> = real.iter().copied().filter(|&c| c != b).collect();
        let rows = w.nrows() + others.len() * len;
        let mut a = DMatrix::zeros(rows.max(n), n);
        a.view_mut((0, 0), (w.nrows(), n)).copy_from(&w);
        for (k, &c) in others.iter().enumerate() {
            for j in support(model, Some(c)) {
                for (r, x) in data.kin.motion_subspace[j].as_slice().iter().enumerate() {
                    a[(w.nrows() + k * len + r, j)] = *x;
                }
            }
        }
        for v in null_space(a, n) {
            let velocity =
                support(model, Some(b)).fold(S::Spatial::zero(), |acc, j| acc + data.kin.motion_subspace[j] * v[j]);
            if let Some(freedom) = as_idle_turn(model, &data, b, &velocity) {
                found.push(freedom);
            }
        }
    }
    found
}

/// The unit vectors spanning the null space of `a` (rows ≥ n), by SVD.
fn null_space(a: DMatrix<f64>, n: usize) -> Vec<DVector<f64>> {
    let svd = a.svd(false, true);
    let Some(v_t) = svd.v_t else { return Vec::new() };
    let max = svd.singular_values.max();
    (0..n).filter(|&i| svd.singular_values[i] <= TOLERANCE * max).map(|i| v_t.row(i).transpose()).collect()
}

/// `Some` when the spatial velocity `velocity` of body b is a turn leaving two of b's connection points at
/// rest.
fn as_idle_turn<S: Space>(model: &Model<S>, data: &Data<S>, b: usize, velocity: &S::Spatial) -> Option<IdleFreedom<S>> {
    let omega = S::spatial_ang(velocity);
    let speed = omega.norm();
    if speed == 0.0 {
        return None;
    }
    let lin = S::spatial_lin(velocity);
    let still = |p: &S::Point| (lin + S::ang_cross_point(&omega, p)).norm() <= TOLERANCE * speed * model.length_scale;
    let mut at_rest: Vec<S::Point> = Vec::new();
    for p in connection_points(model, data, b) {
        if still(&p) && at_rest.iter().all(|r| (*r - p).norm() > TOLERANCE * model.length_scale) {
            at_rest.push(p);
        }
    }
    (at_rest.len() >= 2).then(|| IdleFreedom { body: b, axis: omega * (1.0 / speed), point: at_rest[0] })
}

/// World positions of the points where body b meets the rest of the linkage: its carrying joint's centre
/// (revolute and ball joints), its children's joint centres, and its cuts' coincident points.
fn connection_points<S: Space>(model: &Model<S>, data: &Data<S>, b: usize) -> Vec<S::Point> {
    let kin = &data.kin;
    let mut points = Vec::new();
    if model.joints[b].kind != JointKind::Prismatic {
        points.push(kin.body_pos[b]);
    }
    for (c, joint) in model.joints.iter().enumerate() {
        if model.parent(c) == Some(b) && joint.kind != JointKind::Prismatic {
            points.push(kin.body_pos[c]);
        }
    }
    for cut in &model.cuts {
        for prim in &cut.primitives {
            if let ClosurePrimitive::Coincident { a, b: other } = prim {
                for end in [a, other] {
                    if end.body == Some(b) {
                        points.push(kin.point(&Attachment { body: Some(b), point: end.point }));
                    }
                }
            }
        }
    }
    points
}
