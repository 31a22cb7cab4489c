//! The configuration space: q (nq coordinates) moved by a velocity-space displacement (nv coordinates).
//! Revolute and prismatic joints add, `q_i ← q_i + h v_i`; a ball joint turns its unit quaternion by the
//! body-axes rotation vector `h (v_k, v_k+1, v_k+2)` (`math::quaternion::integrate`), so q stays on the
//! manifold of valid configurations whatever the step. As Pinocchio's `integrate` / `difference`: every
//! update of q by q̇, a Newton correction or a finite difference goes through here; models without ball
//! joints take a plain `axpy`.

use nalgebra::{DVector, Vector3};

use crate::math::quaternion;
use crate::math::space::Space;
use crate::model::{JointKind, Model};

/// `q ← q ⊕ h v`. Allocation-free.
pub fn integrate<S: Space>(model: &Model<S>, q: &mut DVector<f64>, v: &DVector<f64>, h: f64) {
    integrate_slice(model, q.as_mut_slice(), v.as_slice(), h);
}

/// [`integrate`] on slices (q of length nq, v of length nv).
pub fn integrate_slice<S: Space>(model: &Model<S>, q: &mut [f64], v: &[f64], h: f64) {
    if !model.has_balls() {
        for (x, d) in q.iter_mut().zip(v) {
            *x += h * d;
        }
        return;
    }
    for (i, joint) in model.joints.iter().enumerate() {
        match joint.kind {
            JointKind::Ball { slot: 0 } => {
                let theta = Vector3::new(v[i], v[i + 1], v[i + 2]) * h;
                quaternion::integrate(&mut q[joint.q_index..joint.q_index + 4], &theta);
            }
            JointKind::Ball { .. } => {}
            _ => q[joint.q_index] += h * v[i],
        }
    }
}

/// The displacement `d` (nv) with `b = a ⊕ d`: the inverse of [`integrate`] (ball joints: the short way round).
pub fn difference<S: Space>(model: &Model<S>, a: &DVector<f64>, b: &DVector<f64>, d: &mut DVector<f64>) {
    for (i, joint) in model.joints.iter().enumerate() {
        let k = joint.q_index;
        match joint.kind {
            JointKind::Ball { slot: 0 } => {
                let theta = quaternion::difference(&a.as_slice()[k..k + 4], &b.as_slice()[k..k + 4]);
                d.as_mut_slice()[i..i + 3].copy_from_slice(theta.as_slice());
            }
            JointKind::Ball { .. } => {}
            _ => d[i] = b[k] - a[k],
        }
    }
}

/// Checks q's length and that every number is finite and every ball joint's quaternion a unit one (to
/// 1e-6, the wire's tolerance for orientations); the message names the first coordinate at fault.
pub fn check<S: Space>(model: &Model<S>, q: &[f64]) -> Result<(), String> {
    if q.len() != model.nq() {
        return Err(format!("expected {} configuration coordinates, got {}", model.nq(), q.len()));
    }
    if let Some(i) = q.iter().position(|x| !x.is_finite()) {
        return Err(format!("q[{i}] is {}", q[i]));
    }
    for joint in model.joints.iter().filter(|j| j.kind == JointKind::Ball { slot: 0 }) {
        let k = joint.q_index;
        let norm = q[k..k + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-6 {
            return Err(format!(
                "ball joint '{}': q[{k}..{}] has norm {norm}, not a unit quaternion",
                joint.name,
                k + 4
            ));
        }
    }
    Ok(())
}
