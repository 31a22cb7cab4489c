//! Point and frame Jacobians (world axes, operational order: linear part first) and J̇ q̇.

use nalgebra::DMatrix;

use crate::math::space::{Space, VecOps};
use crate::model::data::Kinematics;
use crate::model::{Model, NO_PARENT};

/// The joints that move `body`: the body's own joint and its ancestors', from the body down to the root.
pub fn support<S: Space>(model: &Model<S>, body: Option<usize>) -> Support<'_, S> {
    Support { model, next: body.unwrap_or(NO_PARENT) }
}

/// Iterator over the supporting joints of a body (see [`support`]).
pub struct Support<'a, S: Space> {
    model: &'a Model<S>,
    next: usize,
}

impl<S: Space> Iterator for Support<'_, S> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        if self.next == NO_PARENT {
            return None;
        }
        let j = self.next;
        self.next = self.model.joints[j].parent;
        Some(j)
    }
}

/// Linear velocity that a unit rate of joint `j` gives the body-fixed point at world position `p`.
#[inline]
pub fn point_column<S: Space>(kin: &Kinematics<S>, j: usize, p: &S::Point) -> S::Point {
    let s = &kin.motion_subspace[j];
    S::spatial_lin(s) + S::ang_cross_point(&S::spatial_ang(s), p)
}

/// Fills `jt` (n×k) with the transpose of the frame Jacobian of the point at world position `p` fixed to
/// `body`: row j holds the operational velocity (linear, then angular) that a unit rate of joint j gives.
pub fn frame_jacobian_t<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body: usize,
    p: &S::Point,
    jt: &mut DMatrix<f64>,
) {
    let n = jt.nrows();
    let jt = jt.as_mut_slice();
    jt.fill(0.0);
    let lin_len = <S::Point as VecOps>::LEN;
    for j in support(model, Some(body)) {
        let lin = point_column(kin, j, p);
        let ang = S::spatial_ang(&kin.motion_subspace[j]);
        // Two loops, not one over a chained iterator (whose per-item branch cost half the Jacobian).
        for (c, x) in lin.as_slice().iter().enumerate() {
            jt[c * n + j] = *x;
        }
        for (c, x) in ang.as_slice().iter().enumerate() {
            jt[(lin_len + c) * n + j] = *x;
        }
    }
    debug_assert_eq!(lin_len + <S::Angular as VecOps>::LEN, S::DIM);
}

/// J̇ q̇ of the frame at world position `p` fixed to `body`: its operational acceleration when q̈ = 0.
/// Needs `forward_velocity`.
pub fn frame_bias_acceleration<S: Space>(kin: &Kinematics<S>, body: usize, p: &S::Point) -> S::OpVec {
    let lin = kin.point_bias_acceleration(Some(body), p);
    let ang = S::spatial_ang(&kin.bias_acceleration[body]);
    S::op(lin, ang)
}

/// Operational velocity (linear, then angular) of the frame at world position `p` fixed to `body`.
pub fn frame_velocity<S: Space>(kin: &Kinematics<S>, body: usize, p: &S::Point) -> S::OpVec {
    let lin = kin.point_velocity(Some(body), p);
    S::op(lin, S::spatial_ang(&kin.body_velocity[body]))
}

/// Adds `Jᵀ F` to the generalized forces `tau` for an operational wrench `wrench` (force, then torque; world
/// axes) applied at world position `p` on `body`. Allocation-free; touches only the supporting joints.
pub fn apply_wrench<S: Space>(
    model: &Model<S>,
    kin: &Kinematics<S>,
    body: usize,
    p: &S::Point,
    wrench: &S::OpVec,
    tau: &mut nalgebra::DVector<f64>,
) {
    let force = S::op_lin(wrench);
    let torque = S::op_ang(wrench);
    let tau = tau.as_mut_slice();
    for j in support(model, Some(body)) {
        tau[j] += point_column(kin, j, p).dot(&force) + S::spatial_ang(&kin.motion_subspace[j]).dot(&torque);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
    use crate::model::data::Data;
    use crate::testing::{displaced, for_each_model, random_state};
    use nalgebra::DVector;

    /// J q̇ equals the finite difference of the operational pose, and J̇ q̇ the finite difference of J q̇
    /// along the motion, for every OP of every test scene.
    #[test]
    fn jacobian_and_jdot_qdot_match_finite_differences() {
        for_each_model!(name, model => { check_frame_jacobian(name, model) });
    }

    fn check_frame_jacobian<S: Space>(name: &str, model: &Model<S>) {
        // Written for additive configurations (q ± h q̇, one body per tree joint); ball-jointed models
        // (nq ≠ nv, internal bodies per ball) have these checks along the configuration update in
        // tests/ball_joints.rs.
        if model.has_balls() {
            return;
        }
        let mut data = Data::new(model);
        let n = model.nv();
        for seed in 0..3 {
            let (q, qd) = random_state(model, seed);
            for body in 0..n {
                let local = model.bodies[body].com + S::Point::from_slice(&[0.013, -0.007, 0.004]);
                let eval = |data: &mut Data<S>, q: &DVector<f64>| {
                    forward_kinematics(model, data, q);
                    forward_velocity(model, data, &qd);
                    let p = data.kin.body_pos[body] + S::rotate(&data.kin.body_rot[body], &local);
                    let mut jt = DMatrix::zeros(n, S::DIM);
                    frame_jacobian_t(model, &data.kin, body, &p, &mut jt);
                    (p, data.kin.body_rot[body], jt.transpose() * &qd, frame_bias_acceleration(&data.kin, body, &p))
                };
                let (_, _, v, jdqd) = eval(&mut data, &q);
                let h = 1e-6;
                let (pp, rp, vp, _) = eval(&mut data, &displaced(model, &q, &qd, h));
                let (pm, rm, vm, _) = eval(&mut data, &displaced(model, &q, &qd, -h));
                let lin_fd = (pp - pm) * (0.5 / h);
                let ang_fd = S::rot_log(&S::rot_mul(&rp, &S::rot_inverse(&rm))) * (0.5 / h);
                let fd = S::op(lin_fd, ang_fd);
                for r in 0..S::DIM {
                    assert!(
                        (fd[r] - v[r]).abs() < 1e-6 * (1.0 + v[r].abs()),
                        "{name} body {body}: J q̇ row {r}: fd {} vs {}",
                        fd[r],
                        v[r]
                    );
                    let acc_fd = (vp[r] - vm[r]) / (2.0 * h);
                    assert!(
                        (acc_fd - jdqd[r]).abs() < 1e-5 * (1.0 + jdqd[r].abs()),
                        "{name} body {body}: J̇q̇ row {r}: fd {acc_fd} vs {}",
                        jdqd[r]
                    );
                }
            }
        }
    }
}
