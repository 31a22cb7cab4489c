//! Loop closure (eq 2, 3): the residual h(q), its Jacobian W = ∂h/∂q and the velocity-product term
//! w = Ẇ q̇, all analytic, and the Baumgarte-stabilized right-hand side w_stab.
//!
//! Each cut joint is a list of primitives (see [`ClosurePrimitive`]); each primitive's h, W and w are
//! derived by hand below from the body poses, velocities and velocity-product accelerations.

use nalgebra::{DMatrix, DVector};

use crate::algorithms::jacobian::{point_column, support};
use crate::math::dense::{dot, mul_add};
use crate::math::space::{Space, VecOps};
use crate::model::data::{Data, Kinematics};
use crate::model::{Attachment, ClosurePrimitive, Model};

/// Fills `closure_residual` (h), `closure_jacobian_t` (Wᵀ) and `closure_bias` (w). Needs
/// `forward_kinematics` and `forward_velocity`.
pub fn loop_closure<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    evaluate(model, data, Outputs::JacobianAndBias);
}

/// Fills only `closure_residual` (h). Needs `forward_kinematics`.
pub fn closure_residual<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    evaluate(model, data, Outputs::Residual);
}

/// Fills h and Wᵀ, not w (which needs velocities). Needs `forward_kinematics`.
pub fn closure_residual_and_jacobian<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    evaluate(model, data, Outputs::Jacobian);
}

/// What to compute besides h.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Outputs {
    Residual,
    Jacobian,
    JacobianAndBias,
}

fn evaluate<S: Space>(model: &Model<S>, data: &mut Data<S>, outputs: Outputs) {
    if !model.has_loops() {
        return;
    }
    let kin = &data.kin;
    let wt = &mut data.closure_jacobian_t;
    let h = &mut data.closure_residual;
    let w = &mut data.closure_bias;
    if outputs != Outputs::Residual {
        crate::math::dense::zero(wt.as_mut_slice());
    }
    for cut in &model.cuts {
        let mut row = cut.row;
        for prim in &cut.primitives {
            match prim {
                ClosurePrimitive::Coincident { a, b } => {
                    coincident(model, kin, a, b, row, h, derivatives(outputs, wt, w))
                }
                ClosurePrimitive::OnPlane { a, normal_a, b } => {
                    on_plane(model, kin, a, normal_a, b, row, h, derivatives(outputs, wt, w))
                }
                ClosurePrimitive::Perpendicular { body_a, dir_a, body_b, dir_b } => {
                    perpendicular(model, kin, *body_a, dir_a, *body_b, dir_b, row, h, derivatives(outputs, wt, w))
                }
                ClosurePrimitive::SameAngle { body_a, body_b, offset } => {
                    same_angle(model, kin, *body_a, *body_b, offset, row, h, derivatives(outputs, wt, w))
                }
            }
            row += prim.rows();
        }
    }
}

/// The optional outputs of a primitive: Wᵀ (unless only h is wanted) and w (when wanted too).
fn derivatives<'a>(
    outputs: Outputs,
    wt: &'a mut DMatrix<f64>,
    w: &'a mut DVector<f64>,
) -> Option<(&'a mut DMatrix<f64>, Option<&'a mut DVector<f64>>)> {
    match outputs {
        Outputs::Residual => None,
        Outputs::Jacobian => Some((wt, None)),
        Outputs::JacobianAndBias => Some((wt, Some(w))),
    }
}

/// Baumgarte stabilization (eq 3): `w_stab = w + 2αβ W q̇ + α² h`, so that the solved accelerations give
/// `ḧ + 2αβ ḣ + α² h = 0`. Needs [`loop_closure`].
pub fn stabilize<S: Space>(model: &Model<S>, data: &mut Data<S>, qd: &DVector<f64>) {
    if !model.has_loops() {
        return;
    }
    let (alpha, beta) = (model.baumgarte.alpha, model.baumgarte.beta);
    // ḣ = W q̇, one contiguous column of Wᵀ per closure row.
    let n = data.closure_jacobian_t.nrows();
    let wt = data.closure_jacobian_t.as_slice();
    let out = data.closure_bias_stab.as_mut_slice().iter_mut();
    let out = out.zip(data.closure_bias.as_slice()).zip(data.closure_residual.as_slice());
    for (((s, w), h), col) in out.zip(wt.chunks_exact(n)) {
        *s = mul_add(alpha * alpha, *h, mul_add(2.0 * alpha * beta, dot(col, qd.as_slice()), *w));
    }
}

/// Adds `sign · (c · J_v(p))` for body-fixed point `p` on `body` into column `row` of Wᵀ, where c selects a
/// component (`Some(k)`) or projects on a direction.
#[allow(clippy::too_many_arguments)]
fn add_point_rows<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body: Option<usize>,
    p: &S::Point,
    sign: f64,
    direction: Option<&S::Point>,
    row: usize,
    wt: &mut DMatrix<f64>,
) {
    let n = wt.nrows();
    let cols = &mut wt.as_mut_slice()[row * n..];
    for j in support(model, body) {
        let col = point_column(kin, j, p);
        match direction {
            Some(d) => cols[j] += sign * d.dot(&col),
            None => {
                for (k, x) in col.as_slice().iter().enumerate() {
                    cols[k * n + j] += sign * x;
                }
            }
        }
    }
}

/// Adds `sign · (c · ω_j)` (angular Jacobian projected on `c`, or all components when `c` is `None`).
fn add_angular_rows<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body: Option<usize>,
    sign: f64,
    c: Option<&S::Angular>,
    row: usize,
    wt: &mut DMatrix<f64>,
) {
    let n = wt.nrows();
    let cols = &mut wt.as_mut_slice()[row * n..];
    for j in support(model, body) {
        let w = S::spatial_ang(&kin.motion_subspace[j]);
        match c {
            Some(c) => cols[j] += sign * c.dot(&w),
            None => {
                for (k, x) in w.as_slice().iter().enumerate() {
                    cols[k * n + j] += sign * x;
                }
            }
        }
    }
}

/// `h = p_a - p_b`; `W = J_v(p_a) - J_v(p_b)`; `w = (J̇q̇)_a - (J̇q̇)_b` (classical point accelerations).
#[allow(clippy::too_many_arguments)]
fn coincident<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    a: &Attachment<S>,
    b: &Attachment<S>,
    row: usize,
    h: &mut DVector<f64>,
    derivatives: Option<(&mut DMatrix<f64>, Option<&mut DVector<f64>>)>,
) {
    let pa = kin.point(a);
    let pb = kin.point(b);
    let gap = pa - pb;
    for k in 0..<S::Point as VecOps>::LEN {
        h[row + k] = gap.as_slice()[k];
    }
    let Some((wt, w)) = derivatives else { return };
    add_point_rows(model, kin, a.body, &pa, 1.0, None, row, wt);
    add_point_rows(model, kin, b.body, &pb, -1.0, None, row, wt);
    let Some(w) = w else { return };
    let acc = kin.point_bias_acceleration(a.body, &pa) - kin.point_bias_acceleration(b.body, &pb);
    for k in 0..<S::Point as VecOps>::LEN {
        w[row + k] = acc.as_slice()[k];
    }
}

/// `h = n·d` with `n` fixed in a and `d = p_b - p_a`.
/// `ḣ = (ω_a × n)·d + n·ḋ = (n × d)·ω_a + n·(v_b(p_b) - v_a(p_a))`;
/// `ḧ = (n × d)·α_a + (ω_a × (ω_a × n))·d + 2 (ω_a × n)·ḋ + n·d̈`.
#[allow(clippy::too_many_arguments)]
fn on_plane<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    a: &Attachment<S>,
    normal_a: &S::Point,
    b: &Attachment<S>,
    row: usize,
    h: &mut DVector<f64>,
    derivatives: Option<(&mut DMatrix<f64>, Option<&mut DVector<f64>>)>,
) {
    let pa = kin.point(a);
    let pb = kin.point(b);
    let n = kin.direction(a.body, normal_a);
    let d = pb - pa;
    h[row] = n.dot(&d);
    let Some((wt, w)) = derivatives else { return };
    let n_cross_d = S::point_cross_point(&n, &d);
    add_angular_rows(model, kin, a.body, 1.0, Some(&n_cross_d), row, wt);
    add_point_rows(model, kin, a.body, &pa, -1.0, Some(&n), row, wt);
    add_point_rows(model, kin, b.body, &pb, 1.0, Some(&n), row, wt);
    let Some(w) = w else { return };
    let omega_a = S::spatial_ang(&kin.velocity(a.body));
    let alpha_a = S::spatial_ang(&kin.bias_accel(a.body));
    let n_dot = S::ang_cross_point(&omega_a, &n);
    let d_dot = kin.point_velocity(b.body, &pb) - kin.point_velocity(a.body, &pa);
    let d_ddot = kin.point_bias_acceleration(b.body, &pb) - kin.point_bias_acceleration(a.body, &pa);
    w[row] = n_cross_d.dot(&alpha_a)
        + S::ang_cross_point(&omega_a, &n_dot).dot(&d)
        + 2.0 * n_dot.dot(&d_dot)
        + n.dot(&d_ddot);
}

/// `h = d·e` with `d` fixed in a and `e` fixed in b. `ḣ = (ω_a - ω_b)·(d × e)`;
/// `ḧ = (α_a - α_b)·(d × e) + (ω_a - ω_b)·((ω_a × d) × e + d × (ω_b × e))`.
#[allow(clippy::too_many_arguments)]
fn perpendicular<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body_a: Option<usize>,
    dir_a: &S::Point,
    body_b: Option<usize>,
    dir_b: &S::Point,
    row: usize,
    h: &mut DVector<f64>,
    derivatives: Option<(&mut DMatrix<f64>, Option<&mut DVector<f64>>)>,
) {
    let d = kin.direction(body_a, dir_a);
    let e = kin.direction(body_b, dir_b);
    h[row] = d.dot(&e);
    let Some((wt, w)) = derivatives else { return };
    let c = S::point_cross_point(&d, &e);
    add_angular_rows(model, kin, body_a, 1.0, Some(&c), row, wt);
    add_angular_rows(model, kin, body_b, -1.0, Some(&c), row, wt);
    let Some(w) = w else { return };
    let (omega_a, omega_b) = (S::spatial_ang(&kin.velocity(body_a)), S::spatial_ang(&kin.velocity(body_b)));
    let (alpha_a, alpha_b) = (S::spatial_ang(&kin.bias_accel(body_a)), S::spatial_ang(&kin.bias_accel(body_b)));
    let c_dot = S::point_cross_point(&S::ang_cross_point(&omega_a, &d), &e)
        + S::point_cross_point(&d, &S::ang_cross_point(&omega_b, &e));
    w[row] = (alpha_a - alpha_b).dot(&c) + (omega_a - omega_b).dot(&c_dot);
}

/// Planar: `h = θ_a - θ_b - offset` (wrapped); `W = J_ω,a - J_ω,b`; `w = α_a - α_b` (velocity products).
#[allow(clippy::too_many_arguments)]
fn same_angle<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body_a: Option<usize>,
    body_b: Option<usize>,
    offset: &S::Rot,
    row: usize,
    h: &mut DVector<f64>,
    derivatives: Option<(&mut DMatrix<f64>, Option<&mut DVector<f64>>)>,
) {
    let relative = S::rot_mul(&S::rot_inverse(&kin.rot(body_b)), &kin.rot(body_a));
    let err = S::rot_log(&S::rot_mul(&S::rot_inverse(offset), &relative));
    for k in 0..<S::Angular as VecOps>::LEN {
        h[row + k] = err.as_slice()[k];
    }
    let Some((wt, w)) = derivatives else { return };
    add_angular_rows(model, kin, body_a, 1.0, None, row, wt);
    add_angular_rows(model, kin, body_b, -1.0, None, row, wt);
    let Some(w) = w else { return };
    let acc = S::spatial_ang(&kin.bias_accel(body_a)) - S::spatial_ang(&kin.bias_accel(body_b));
    for k in 0..<S::Angular as VecOps>::LEN {
        w[row + k] = acc.as_slice()[k];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
    use crate::testing::{displaced, for_each_model, random_state};

    /// W is the derivative of h (central differences along random directions) and w = Ẇ q̇ the derivative
    /// of W q̇ along q̇, for every closure primitive of every test scene, away from q0 (h ≠ 0).
    #[test]
    fn closure_jacobian_and_bias_match_finite_differences() {
        for_each_model!(name, model => { check(name, model) });
    }

    fn check<S: Space>(name: &str, model: &Model<S>) {
        if !model.has_loops() {
            return;
        }
        let mut data = Data::new(model);
        for seed in 0..4 {
            let (q, qd) = random_state(model, seed);
            let eval = |data: &mut Data<S>, q: &DVector<f64>| {
                forward_kinematics(model, data, q);
                forward_velocity(model, data, &qd);
                loop_closure(model, data);
                (data.closure_residual.clone(), data.closure_jacobian(), data.closure_bias.clone())
            };
            let (_, wmat, wbias) = eval(&mut data, &q);
            let hstep = 1e-6;
            let (hp, wp, _) = eval(&mut data, &displaced(model, &q, &qd, hstep));
            let (hm, wm, _) = eval(&mut data, &displaced(model, &q, &qd, -hstep));
            let hdot_fd = (&hp - &hm) / (2.0 * hstep);
            let hdot = &wmat * &qd;
            let wdot_fd = (&wp * &qd - &wm * &qd) / (2.0 * hstep);
            for r in 0..model.nc() {
                assert!((hdot_fd[r] - hdot[r]).abs() < 1e-6 * (1.0 + hdot[r].abs()), "{name}: W row {r}");
                assert!(
                    (wdot_fd[r] - wbias[r]).abs() < 1e-5 * (1.0 + wbias[r].abs()),
                    "{name}: w row {r}: fd {} vs {}",
                    wdot_fd[r],
                    wbias[r]
                );
            }
            // Column by column too (catches errors that cancel along q̇).
            for j in 0..model.nv() {
                let mut e = DVector::zeros(model.nv());
                e[j] = hstep;
                let (hp, _, _) = eval(&mut data, &displaced(model, &q, &e, 1.0));
                let (hm, _, _) = eval(&mut data, &displaced(model, &q, &e, -1.0));
                for r in 0..model.nc() {
                    let fd = (hp[r] - hm[r]) / (2.0 * hstep);
                    assert!((fd - wmat[(r, j)]).abs() < 1e-6, "{name}: W[{r},{j}] fd {fd} vs {}", wmat[(r, j)]);
                }
            }
        }
    }
}
