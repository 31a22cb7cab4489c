//! Forward kinematics: body poses, world-frame motion subspaces and spatial inertias (position level), and
//! body velocities with their velocity-product accelerations (velocity level).

use nalgebra::DVector;

use crate::algorithms::tree::follows_parent;
use crate::math::space::{OpPose, Space, VecOps};
use crate::model::data::Data;
use crate::model::{JointKind, Model, NO_PARENT};

/// Computes body poses, the motion subspace S_i of every joint and every body's spatial inertia, all in the
/// world frame, at configuration `q`.
pub fn forward_kinematics<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>) {
    forward_poses(model, data, q);
    let kin = &mut data.kin;
    for (i, body) in model.bodies.iter().enumerate() {
        kin.com[i] = kin.body_pos[i] + S::rotate(&kin.body_rot[i], &body.com);
        kin.body_inertia[i] = S::inertia_world(body.mass, &kin.com[i], &body.inertia, &kin.body_rot[i]);
    }
}

/// The geometric part of [`forward_kinematics`]: body poses and motion subspaces, what the loop closure's h
/// and W need, but not the centres of mass and spatial inertias, which keep their values from the last full
/// evaluation (the projection after a step evaluates the closure this way; the next step's dynamics redo it
/// all). Poses already evaluated at exactly this q are kept (`Data::poses_at`): they depend on q alone, so
/// the result is the same bits either way, and the next step's dynamics start at the q the projection last
/// evaluated.
pub fn forward_poses<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>) {
    data.terms_at.clear();
    data.mass_matrix_fresh = false;
    if data.poses_at.holds(q) {
        return;
    }
    data.poses_at.record(q);
    let kin = &mut data.kin;
    let q = q.as_slice();
    // The pose of joint i - 1's body, kept in registers for a child that follows its parent (as in a chain):
    // reading it back from memory just after storing it would put a store-to-load wait on the path.
    let mut previous = (S::rot_identity(), S::Point::zero());
    for (i, joint) in model.joints.iter().enumerate() {
        let (parent_rot, parent_pos) = if follows_parent(joint.parent, i) {
            previous
        } else if joint.parent == NO_PARENT {
            (S::rot_identity(), S::Point::zero())
        } else {
            (kin.body_rot[joint.parent], kin.body_pos[joint.parent])
        };
        let frame_rot = S::rot_mul(&parent_rot, &joint.placement_rot);
        let origin = parent_pos + S::rotate(&parent_rot, &joint.placement_pos);
        match joint.kind {
            JointKind::Revolute => {
                let axis_world = S::rotate(&frame_rot, &joint.axis);
                let (sin, cos) = kin.sin_cos[i].eval(q[joint.q_index]);
                let rot = S::rot_mul(&frame_rot, &S::rot_about_axis(&joint.axis, cos, sin));
                kin.body_rot[i] = rot;
                kin.body_pos[i] = origin;
                previous = (rot, origin);
                // A unit rotation about an axis through `origin` moves the world origin at -ω × origin.
                let w = S::axis_as_angular(&axis_world);
                kin.motion_subspace[i] = S::spatial(w, -S::ang_cross_point(&w, &origin));
            }
            JointKind::Prismatic => {
                let axis_world = S::rotate(&frame_rot, &joint.axis);
                let pos = origin + axis_world * q[joint.q_index];
                kin.body_rot[i] = frame_rot;
                kin.body_pos[i] = pos;
                previous = (frame_rot, pos);
                kin.motion_subspace[i] = S::spatial(S::Angular::zero(), axis_world);
            }
            JointKind::Ball { slot } => {
                // Slot 0 turns the joint frame by the quaternion; slots 1 and 2 hang from it with an identity
                // placement and share its pose. Rate k turns the body about its own axis k, through the centre.
                let rot = if slot == 0 {
                    S::rot_mul(&frame_rot, &S::rot_from_quaternion(&q[joint.q_index..joint.q_index + 4]))
                } else {
                    frame_rot
                };
                kin.body_rot[i] = rot;
                kin.body_pos[i] = origin;
                previous = (rot, origin);
                let w = S::axis_as_angular(&S::rotate(&rot, &joint.axis));
                kin.motion_subspace[i] = S::spatial(w, -S::ang_cross_point(&w, &origin));
            }
        }
    }
}

/// Computes every body's spatial velocity `v_i = v_λ(i) + S_i q̇_i` and velocity-product acceleration
/// `a_i = a_λ(i) + v_i × S_i q̇_i` (the body's acceleration when q̈ = 0). Needs [`forward_kinematics`].
pub fn forward_velocity<S: Space>(model: &Model<S>, data: &mut Data<S>, qd: &DVector<f64>) {
    data.terms_at.clear();
    let kin = &mut data.kin;
    let qd = qd.as_slice();
    kin.joint_rate.copy_from_slice(qd);
    // Joint i - 1's values in registers for a child that follows its parent (see `forward_poses`).
    let mut previous = (S::Spatial::zero(), S::Spatial::zero());
    // The velocity of the body a ball joint hangs from, set at its slot 0 (slots 1 and 2 follow at once).
    let mut ball_parent_velocity = S::Spatial::zero();
    for (i, joint) in model.joints.iter().enumerate() {
        let (v_parent, a_parent) = if follows_parent(joint.parent, i) {
            previous
        } else if joint.parent == NO_PARENT {
            (S::Spatial::zero(), S::Spatial::zero())
        } else {
            (kin.body_velocity[joint.parent], kin.bias_acceleration[joint.parent])
        };
        let s_qd = kin.motion_subspace[i] * qd[i];
        let v = v_parent + s_qd;
        // In the world frame Ṡ_i = v_i × S_i (the axis moves with the body that carries it). A ball joint's
        // three axes are all fixed in its child: Σ_k Ṡ_k q̇_k = v_child × ω_rel = v_parent × ω_rel, as
        // ω_rel × ω_rel = 0; so each slot adds v_parent × S_k q̇_k (not its internal body's partial velocity).
        let carrier = match joint.kind {
            JointKind::Revolute | JointKind::Prismatic => v,
            JointKind::Ball { slot: 0 } => {
                ball_parent_velocity = v_parent;
                v
            }
            JointKind::Ball { .. } => ball_parent_velocity,
        };
        let a = a_parent + S::cross_motion(&carrier, &s_qd);
        kin.body_velocity[i] = v;
        kin.bias_acceleration[i] = a;
        previous = (v, a);
    }
}

impl<S: Space> OpPose<S> {
    /// Pose of operational point `op` at the last `forward_kinematics`.
    pub fn of_op(model: &Model<S>, data: &Data<S>, op: usize) -> Self {
        let o = &model.ops[op];
        let rot = data.kin.body_rot[o.body];
        OpPose { position: data.kin.body_pos[o.body] + S::rotate(&rot, &o.point), rotation: rot }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::space::Planar;
    use crate::testing::{paper_testbed, random_state};

    /// The velocity of every COM equals the finite difference of its position.
    #[test]
    fn com_velocity_matches_finite_difference() {
        let model = paper_testbed();
        let mut data = Data::new(&model);
        let (q, qd) = random_state(&model, 7);
        forward_kinematics(&model, &mut data, &q);
        forward_velocity(&model, &mut data, &qd);
        let coms = data.kin.com.clone();
        let velocities: Vec<_> = (0..model.nv()).map(|i| data.kin.point_velocity(Some(i), &coms[i])).collect();
        let h = 1e-7;
        forward_kinematics(&model, &mut data, &(&q + &qd * h));
        let plus = data.kin.com.clone();
        forward_kinematics(&model, &mut data, &(&q - &qd * h));
        for i in 0..model.nv() {
            let fd = (plus[i] - data.kin.com[i]) / (2.0 * h);
            assert!((fd - velocities[i]).norm() < 1e-7, "body {i}: {fd} vs {}", velocities[i]);
        }
    }

    /// The testbed's tip lands at q0 where the paper's testbed, reconstructed by hand, puts it (≈ (0.000645,
    /// 0.008528) m).
    #[test]
    fn testbed_tip_at_q0_matches_the_reconstruction() {
        let model = paper_testbed();
        let mut data = Data::new(&model);
        forward_kinematics(&model, &mut data, &model.q0);
        let tip = data
            .kin
            .point(&crate::model::Attachment::<Planar> { body: Some(3), point: nalgebra::Vector2::new(0.06, 0.0) });
        assert!((tip.x - 0.000645).abs() < 5e-7 && (tip.y - 0.008528).abs() < 5e-7, "{tip}");
    }

    /// Poses already evaluated at exactly the q asked for are kept, and they are bit for bit what a fresh
    /// workspace evaluates; another q is evaluated afresh, also after a detour.
    #[test]
    fn poses_are_kept_exactly_when_q_is_the_same() {
        let model = paper_testbed();
        let (q, _) = random_state(&model, 3);
        let mut q2 = q.clone();
        q2[1] += 1e-9;
        let poses =
            |data: &Data<Planar>| format!("{:?}", (&data.kin.body_rot, &data.kin.body_pos, &data.kin.motion_subspace));
        let fresh = |q: &DVector<f64>| {
            let mut data = Data::new(&model);
            forward_kinematics(&model, &mut data, q);
            poses(&data)
        };
        let mut data = Data::new(&model);
        for at in [&q, &q, &q2, &q, &q2, &q2] {
            forward_kinematics(&model, &mut data, at);
            assert_eq!(poses(&data), fresh(at));
        }
        assert_ne!(fresh(&q), fresh(&q2));
        // Kept, not evaluated again: a pose written over survives an evaluation at the same q, not at another.
        data.kin.body_pos[0].x = 7.0;
        forward_poses(&model, &mut data, &q2);
        assert_eq!(data.kin.body_pos[0].x, 7.0);
        forward_poses(&model, &mut data, &q);
        assert_eq!(poses(&data), fresh(&q));
    }
}
