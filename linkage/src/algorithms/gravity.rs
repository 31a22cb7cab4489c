//! G(q) of eq 1: gravity and joint and cut springs ("joint flexibility and gravitational effects").

use nalgebra::DVector;

use crate::algorithms::cut_forces::{add_cut_springs, cut_spring_energy};
use crate::algorithms::joint_limits::limit_wall_energy;
use crate::algorithms::tree::subtree_sums;
use crate::math::space::{Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// Fills `data.gravity` with G(q) (so that `D q̈ + B + G = τ`). Needs `forward_kinematics`.
pub fn gravity_forces<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>) {
    let n = model.nv();
    if model.has_gravity {
        for i in 0..n {
            // The weight m g acting at the COM, as a spatial force about the world origin.
            let weight = model.gravity * model.bodies[i].mass;
            data.body_force[i] = S::spatial(S::point_cross_point(&data.kin.com[i], &weight), weight);
        }
        let (g, s) = (data.gravity.as_mut_slice(), &data.kin.motion_subspace);
        subtree_sums(model, &mut data.body_force, |i, f| g[i] = -s[i].dot(f));
    } else {
        data.gravity.as_mut_slice().fill(0.0);
    }
    if model.has_springs {
        for (i, joint) in model.joints.iter().enumerate() {
            if let Some(spring) = joint.spring {
                data.gravity[i] += spring.stiffness * (q[joint.q_index] - spring.rest);
            }
        }
        add_cut_springs(model, &data.kin, &mut data.gravity);
    }
}

/// Potential energy of gravity, springs and the range walls at the configuration of the last
/// `forward_kinematics`.
pub fn potential_energy<S: Space>(model: &Model<S>, data: &Data<S>, q: &DVector<f64>) -> f64 {
    field_energy(model, data, q) + limit_wall_energy(model, &data.kin, q)
}

/// The potential whose gradient is G (gravity, joint and cut springs) at the configuration of the last
/// `forward_kinematics`: [`potential_energy`] without the range walls, whose forces are joint forces.
pub fn field_energy<S: Space>(model: &Model<S>, data: &Data<S>, q: &DVector<f64>) -> f64 {
    let mut e = 0.0;
    for (i, body) in model.bodies.iter().enumerate() {
        e -= body.mass * model.gravity.dot(&data.kin.com[i]);
    }
    for joint in &model.joints {
        if let Some(s) = joint.spring {
            e += 0.5 * s.stiffness * (q[joint.q_index] - s.rest).powi(2);
        }
    }
    e + cut_spring_energy(model, &data.kin)
}

/// Kinetic energy `½ Σ vᵢᵀ Iᵢ vᵢ + ½ Σ aᵢ q̇ᵢ²` (bodies, then armatures: `½ q̇ᵀ D q̇`) at the state of the last
/// `forward_velocity`.
pub fn kinetic_energy<S: Space>(model: &Model<S>, data: &Data<S>) -> f64 {
    (0..model.nv())
        .map(|i| {
            let v = &data.kin.body_velocity[i];
            let rate = data.kin.joint_rate[i];
            0.5 * v.dot(&S::inertia_mul(&data.kin.body_inertia[i], v)) + 0.5 * model.joints[i].armature * rate * rate
        })
        .sum()
}
