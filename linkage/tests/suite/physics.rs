//! Physics checked against independent computations: energy identities, finite differences of the
//! Lagrangian, null-space (independent-coordinates) dynamics, conservation laws and closed forms.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::bias::bias_forces;
use kinloop_linkage::algorithms::gravity::{gravity_forces, kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::algorithms::mass_matrix::mass_matrix;
use kinloop_linkage::algorithms::op_space::{op_space_inertia, open_inverse_inertia};
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, algorithms::integrator::step,
    algorithms::integrator::Integrator, algorithms::integrator::StepConfig, math::space::Space, model::data::Data,
    model::Model,
};
use nalgebra::{DMatrix, DVector};

macro_rules! for_each_model {
    ($name:ident, $model:ident => $body:block) => {{
        for (n, m) in planar_models().iter() {
            let ($name, $model) = (n.as_str(), m);
            $body
        }
        for (n, m) in spatial_models().iter() {
            let ($name, $model) = (n.as_str(), m);
            $body
        }
    }};
}

fn energy<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>, qd: &DVector<f64>) -> (f64, f64) {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, qd);
    (kinetic_energy(model, data), potential_energy(model, data, q))
}

/// D is symmetric positive definite and equals the Hessian of the kinetic energy in q̇ (the kinetic energy is
/// summed body by body, not through D).
#[test]
fn mass_matrix_is_spd_and_the_hessian_of_kinetic_energy() {
    for_each_model!(name, model => { check_mass_matrix(name, model) });
}

fn check_mass_matrix<S: Space>(name: &str, model: &Model<S>) {
    let mut data = Data::new(model);
    let n = model.nv();
    for seed in 0..3 {
        let (q, _) = random_state(model, seed);
        forward_kinematics(model, &mut data, &q);
        mass_matrix(model, &mut data);
        let d = data.mass_matrix.clone();
        assert_close(&format!("{name}: D symmetric"), &d, &d.transpose(), 1e-14);
        assert!(d.clone().cholesky().is_some(), "{name}: D not positive definite");
        let ke = |data: &mut Data<S>, v: &DVector<f64>| energy(model, data, &q, v).0;
        let mut hessian = DMatrix::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                let (mut ei, mut ej) = (DVector::zeros(n), DVector::zeros(n));
                ei[i] = 1.0;
                ej[j] = 1.0;
                // Polarization: D_ij = T(e_i + e_j) - T(e_i) - T(e_j) for the quadratic form T = ½ q̇ᵀ D q̇.
                hessian[(i, j)] = ke(&mut data, &(&ei + &ej)) - ke(&mut data, &ei) - ke(&mut data, &ej);
            }
        }
        assert_close(&format!("{name}: D vs Hessian of T"), &d, &hessian, 1e-12);
    }
}

/// B(q, q̇) = Ḋ q̇ - ∂T/∂q (Lagrange's equations), both terms by central differences of D and T.
#[test]
fn coriolis_terms_match_lagrange_equations() {
    for_each_model!(name, model => { check_bias(name, model) });
}

fn check_bias<S: Space>(name: &str, model: &Model<S>) {
    // Written for additive configurations (q ± h q̇, one body per tree joint); ball-jointed models
    // (nq ≠ nv, internal bodies per ball) have these checks along the configuration update in
    // tests/suite/ball_joints.rs.
    if model.has_balls() {
        return;
    }
    let mut data = Data::new(model);
    let n = model.nv();
    for seed in 0..3 {
        let (q, qd) = random_state(model, seed);
        forward_kinematics(model, &mut data, &q);
        forward_velocity(model, &mut data, &qd);
        bias_forces(model, &mut data);
        let b = data.bias.clone();
        let h = 1e-6;
        let d_at = |data: &mut Data<S>, q: &DVector<f64>| {
            forward_kinematics(model, data, q);
            mass_matrix(model, data);
            data.mass_matrix.clone()
        };
        let d_dot = (d_at(&mut data, &(&q + &qd * h)) - d_at(&mut data, &(&q - &qd * h))) / (2.0 * h);
        let mut dt_dq = DVector::zeros(n);
        for i in 0..n {
            let mut e = DVector::zeros(n);
            e[i] = h;
            dt_dq[i] =
                (energy(model, &mut data, &(&q + &e), &qd).0 - energy(model, &mut data, &(&q - &e), &qd).0) / (2.0 * h);
        }
        let expected = d_dot * &qd - dt_dq;
        let err = (&b - &expected).amax();
        assert!(err < 1e-6 * (1.0 + b.amax()), "{name}: B {b} vs Lagrange {expected}");
    }
}

/// G(q) is the gradient of the potential energy (gravity and springs).
#[test]
fn gravity_and_springs_are_the_gradient_of_potential_energy() {
    for_each_model!(name, model => { check_gravity(name, model) });
}

fn check_gravity<S: Space>(name: &str, model: &Model<S>) {
    let mut data = Data::new(model);
    let n = model.nv();
    let (q, qd) = random_state(model, 11);
    forward_kinematics(model, &mut data, &q);
    gravity_forces(model, &mut data, &q);
    let g = data.gravity.clone();
    for i in 0..n {
        // Along the configuration update, so a ball joint's quaternion stays on its manifold and G reads in
        // the velocity basis (nq ≠ nv).
        let mut e = DVector::zeros(n);
        e[i] = 1.0;
        let (plus, minus) = (displaced(model, &q, &e, 1e-6), displaced(model, &q, &e, -1e-6));
        let fd = (energy(model, &mut data, &plus, &qd).1 - energy(model, &mut data, &minus, &qd).1) / 2e-6;
        assert!((fd - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()), "{name}: G[{i}] = {} vs dV/dq = {fd}", g[i]);
    }
}

/// The KKT solution of eq 4 equals the null-space (independent coordinates) solution, including for
/// redundant closures (parallelogram, spherical four-bar), and satisfies the stabilized closure.
#[test]
fn kkt_accelerations_match_null_space_dynamics() {
    for_each_model!(name, model => { check_kkt(name, model) });
}

fn check_kkt<S: Space>(name: &str, model: &Model<S>) {
    let mut data = Data::new(model);
    for seed in 0..3 {
        let (q, qd) = random_state(model, seed);
        // Project q onto the manifold first: the null-space method needs consistent w_stab rows when W is
        // rank deficient.
        let q = kinloop_linkage::algorithms::assemble::assemble(model, &q, 1e-13).map(|a| a.q).unwrap_or(q);
        let mut wrench = OpWrench::<S> { op: 0, wrench: S::OpVec::zero() };
        for (i, x) in wrench.wrench.as_mut_slice().iter_mut().enumerate() {
            *x = 0.3 * (i as f64 + 1.0) * if seed % 2 == 0 { 1.0 } else { -1.0 };
        }
        forward_dynamics(model, &mut data, &q, &qd, &mut wrench).unwrap_or_else(|e| panic!("{name}: {e}"));
        // D by composite rigid bodies: the dynamics factored it from articulated inertias without forming it.
        mass_matrix(model, &mut data);
        let tau = &data.applied + &data.joint_force - &data.bias - &data.gravity;
        let w = data.closure_jacobian();
        // Make the velocity consistent too, so w_stab is in the range of W.
        let expected = null_space_accelerations(&data.mass_matrix, &w, &data.closure_bias_stab, &tau);
        let qdd = DMatrix::from_column_slice(model.nv(), 1, data.qdd.as_slice());
        let exp = DMatrix::from_column_slice(model.nv(), 1, expected.as_slice());
        if model.nc() == 0 || data.kkt.schur_rank == model.nc() {
            assert_close(&format!("{name}: q̈ (seed {seed})"), &qdd, &exp, 1e-8);
        }
        // D q̈ + Wᵀ λ = τ holds whatever the rank.
        let residual = &data.mass_matrix * &data.qdd + &data.closure_jacobian_t * &data.lambda - &tau;
        assert!(residual.amax() < 1e-9 * (1.0 + tau.amax()), "{name}: eq 4 residual {residual}");
    }
}

use kinloop_linkage::{math::space::MatOps, math::space::VecOps};

/// Λ⁻¹ (eq 9, through the rank-revealing KKT factors) equals the null-space formula J N (NᵀDN)⁻¹ NᵀJᵀ, and
/// the open-chain Λ⁻¹ equals J D⁻¹ Jᵀ computed with nalgebra's inverse.
#[test]
fn inverse_inertia_matches_the_null_space_formula() {
    for_each_model!(name, model => { check_op_space(name, model) });
}

fn check_op_space<S: Space>(name: &str, model: &Model<S>) {
    let mut data = Data::new(model);
    for seed in 0..3 {
        let (q, qd) = random_state(model, seed);
        let q = kinloop_linkage::algorithms::assemble::assemble(model, &q, 1e-13).map(|a| a.q).unwrap_or(q);
        forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
        mass_matrix(model, &mut data);
        for op in 0..model.ops.len() {
            op_space_inertia(model, &mut data, op).unwrap();
            let j = data.op.jacobian_t.transpose();
            let closed = DMatrix::from_column_slice(S::DIM, S::DIM, data.op.inverse_inertia.as_slice());
            let open = DMatrix::from_column_slice(S::DIM, S::DIM, open_inverse_inertia(model, &data).as_slice());
            let d_inv = data.mass_matrix.clone().try_inverse().unwrap();
            assert_close(&format!("{name} op {op}: open Λ⁻¹"), &open, &(&j * d_inv * j.transpose()), 1e-10);
            let w = data.closure_jacobian();
            let expected = null_space_inverse_inertia(&data.mass_matrix, &w, &j);
            // Both formulations lose about ε κ² near a configuration where a kept closure row is almost
            // redundant (κ: W's condition over its kept rows); random states do land near one (the
            // parallelogram at seed 1 has σ = 1.9e-6 beside 0.74), so the tolerance follows κ.
            let kappa = kept_condition(&w);
            let tolerance = 1e-8 + 16.0 * f64::EPSILON * kappa * kappa;
            assert_close(&format!("{name} op {op}: closed Λ⁻¹ (κ {kappa:.1e})"), &closed, &expected, tolerance);
        }
    }
}

/// RK4 conserves the mechanical energy of free conservative linkages (no damping, no actuators): the drift is
/// small, and it is truncation error — halving the step shrinks it by about 2⁴.
#[test]
fn rk4_conserves_energy_of_conservative_linkages() {
    for name in ["fourbar-crank-rocker", "watt-six-bar", "parallelogram", "paper-testbed"] {
        let model = compile::<kinloop_linkage::math::space::Planar>(&builtin_scene(name));
        check_energy(name, &model);
    }
    check_energy(
        "spherical-four-bar",
        &compile::<kinloop_linkage::math::space::Spatial>(&builtin_scene("spherical-four-bar")),
    );
}

fn check_energy<S: Space>(name: &str, model: &Model<S>) {
    let (drift, ke) = energy_drift(model, 1e-3, 1.0);
    let (drift_half, _) = energy_drift(model, 5e-4, 1.0);
    assert!(ke > 1e-4, "{name}: the linkage should move (max kinetic energy {ke})");
    assert!(drift < 1e-5 * ke, "{name}: energy drift {drift:.3e} J vs kinetic energy {ke:.3e} J");
    // Fourth order: expect a ratio near 16; allow for round-off floors on the slow scenes.
    assert!(
        drift_half < drift / 8.0 || drift < 1e-12 * ke.max(1.0),
        "{name}: drift {drift:.3e} at dt, {drift_half:.3e} at dt/2"
    );
}

/// Largest |ΔE| and largest kinetic energy over `duration` seconds of RK4 with projection.
fn energy_drift<S: Space>(model: &Model<S>, dt: f64, duration: f64) -> (f64, f64) {
    let mut data = Data::new(model);
    let mut q = model.q0.clone();
    let mut qd = DVector::zeros(model.nv());
    if model.gravity.norm() == 0.0 {
        // No gravity: start with a velocity made consistent with the closures instead.
        qd = DVector::from_fn(model.nv(), |i, _| 0.5 + 0.1 * i as f64);
        forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
        kinloop_linkage::algorithms::integrator::project(model, &mut data, &mut q.clone(), &mut qd);
    }
    let (t0, v0) = energy(model, &mut data, &q, &qd);
    let cfg = StepConfig { integrator: Integrator::Rk4, dt, project: true, implicit_forces: false };
    let (mut drift, mut ke): (f64, f64) = (0.0, t0);
    for _ in 0..(duration / dt).round() as usize {
        step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap();
        let (t, v) = energy(model, &mut data, &q, &qd);
        drift = drift.max((t + v - t0 - v0).abs());
        ke = ke.max(t);
    }
    (drift, ke)
}
