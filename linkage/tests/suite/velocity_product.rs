//! The velocity-product acceleration (`velocity_product`): at every built-in scene's OPs, moving at a
//! velocity the loops allow, it is what finite differences of the OP's twist along integrated motions give,
//! with the parts that are not quadratic in the velocity (gravity, springs, dampers, stabilization) taken out
//! by the same even combination, of trajectories this time: `(a(v) + a(−v)) / 2 − a(0)`.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::constraint_directions::scale_op;
use kinloop_linkage::algorithms::dynamics::{forward_dynamics, OpWrench};
use kinloop_linkage::algorithms::integrator::{step, Integrator, StepConfig};
use kinloop_linkage::algorithms::kkt::constrained_response;
use kinloop_linkage::algorithms::local_model::op_twist;
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::algorithms::velocity_product::velocity_product_acceleration;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_linkage::model::{data::Data, Model};
use nalgebra::DVector;

/// The OP acceleration along the motion from `(q, qd)` with no applied force: the central difference of the
/// OP's twist over RK4 steps of ±h.
fn acceleration_by_differences<S: Space>(model: &Model<S>, q: &DVector<f64>, qd: &DVector<f64>, op: usize) -> S::OpVec {
    // Short: the delta robot's redundant closures make its motion stiff, and RK4 over 1e-4 s leaves it.
    let h = 1e-6;
    let mut data = Data::new(model);
    let mut none = OpWrench::<S> { op, wrench: S::OpVec::zero() };
    let mut twist_after = |dt: f64| {
        let (mut q, mut qd) = (q.clone(), qd.clone());
        let cfg = StepConfig { integrator: Integrator::Rk4, dt, project: false, implicit_forces: false };
        step(model, &mut data, &mut q, &mut qd, &mut none, &cfg).unwrap();
        forward_dynamics(model, &mut data, &q, &qd, &mut none).unwrap();
        op_twist(model, &data, op)
    };
    (twist_after(h) - twist_after(-h)) * (0.5 / h)
}

/// Checks every OP of `model` at q0; returns how many were checked with a nonzero velocity term.
fn check<S: Space>(name: &str, model: &Model<S>, rng: &mut Rng) -> usize {
    let mut data = Data::new(model);
    let mut workspace = Data::new(model);
    let mut signed = DVector::zeros(model.nv());
    let mut checked = 0;
    for op in 0..model.ops.len() {
        let q = model.q0.clone();
        let mut none = OpWrench::<S> { op, wrench: S::OpVec::zero() };
        forward_dynamics(model, &mut data, &q, &DVector::zeros(model.nv()), &mut none).unwrap();
        op_space_inertia(model, &mut data, op).unwrap();
        // A velocity the loops allow (the constrained response to a random generalized force), brisk: the OP
        // a length scale in a tenth of a second.
        let mut qd = DVector::from_fn(model.nv(), |_, _| rng.signed());
        let mut response = vec![0.0; 2 * model.nc()];
        constrained_response(model, &data, qd.as_mut_slice(), &mut response);
        let mut twist = S::OpVec::zero();
        for c in 0..S::DIM {
            twist[c] = data.op.jacobian_t.column(c).dot(&qd);
        }
        let speed = scale_op::<S>(&twist, model.length_scale).norm();
        if speed <= 0.0 {
            continue;
        }
        qd *= 10.0 * model.length_scale / speed;
        let computed = velocity_product_acceleration(model, &mut workspace, &q, &qd, op, &mut signed).unwrap();
        let minus = -qd.clone();
        let measured = (acceleration_by_differences(model, &q, &qd, op)
            + acceleration_by_differences(model, &q, &minus, op))
            * 0.5
            - acceleration_by_differences(model, &q, &DVector::zeros(model.nv()), op);
        let scale = computed.norm().max(measured.norm());
        let error = (computed - measured).norm() / scale.max(1e-300);
        assert!(error < 1e-4, "{name} op {op}: computed {computed:?}, by differences {measured:?} ({error:.2e})");
        if scale > 0.0 {
            checked += 1;
        }
    }
    checked
}

#[test]
fn the_velocity_terms_are_those_of_motions_integrated_from_the_state() {
    let mut rng = Rng(41);
    let mut checked = 0;
    for (name, model) in planar_models() {
        checked += check(&name, &model, &mut rng);
    }
    for (name, model) in spatial_models() {
        checked += check(&name, &model, &mut rng);
    }
    assert!(checked >= 20, "only {checked} OPs with velocity terms");
}
