//! The local model of interaction (eq 11, 13): its two forms agree, and it predicts the full dynamics over
//! the short horizons between VE updates.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, algorithms::integrator::step,
    algorithms::integrator::Integrator, algorithms::integrator::StepConfig, math::space::Planar, math::space::Space,
    math::space::VecOps, model::data::Data, model::Model,
};
use kinloop_linkage::{
    algorithms::local_model::{
        op_space_terms, op_twist, ConfigSpaceLocalModel, ConfigSpaceTerms, LocalModelTerms, OpSpaceLocalModel,
    },
    math::space::OpPose,
};
use nalgebra::Vector3;

fn local_models<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &nalgebra::DVector<f64>,
    qd: &nalgebra::DVector<f64>,
    user: &mut OpWrench<S>,
    terms: LocalModelTerms,
) -> (OpSpaceLocalModel<S>, ConfigSpaceLocalModel<S>) {
    forward_dynamics(model, data, q, qd, user).unwrap();
    op_space_inertia(model, data, user.op).unwrap();
    let pose = OpPose::of_op(model, data, user.op);
    let mut reduced = OpSpaceLocalModel::new(op_space_terms(data, &user.wrench, terms), pose);
    reduced.twist = op_twist(model, data, user.op);
    let mut cterms = ConfigSpaceTerms::zeros(model.nv(), model.nc(), S::DIM);
    cterms.fill_from(model, data, q, qd, &user.wrench, terms);
    let mut config = ConfigSpaceLocalModel::new(model.nv(), model.nc());
    assert!(config.update(&cterms, pose));
    (reduced, config)
}

/// Fed the same VE state and the same (varying) wrench, the configuration-space form of eq 11 and the
/// reduced operational-space form move the OP identically (to round-off), with and without bias terms,
/// on the testbed, a two-loop six-bar and the spatial four-bar with redundant closures.
#[test]
fn both_local_model_forms_give_the_same_op_motion() {
    for name in ["paper-testbed", "watt-six-bar", "slider-crank"] {
        check_forms::<Planar>(&compile(&builtin_scene(name)), name);
    }
    check_forms(
        &compile::<kinloop_linkage::math::space::Spatial>(&builtin_scene("spherical-four-bar")),
        "spherical-four-bar",
    );
}

fn check_forms<S: Space>(model: &Model<S>, name: &str) {
    let mut data = Data::new(model);
    let (q, qd) = (model.q0.clone(), model.qd0.clone() * 0.0);
    for terms in [LocalModelTerms::full(), LocalModelTerms::paper()] {
        let mut user = OpWrench::<S> { op: 0, wrench: S::OpVec::zero() };
        let (mut reduced, mut config) = local_models(model, &mut data, &q, &qd, &mut user, terms);
        let a = reduced.terms.inverse_inertia;
        let b = config.inverse_inertia();
        for r in 0..S::DIM {
            for c in 0..S::DIM {
                assert!((a[(r, c)] - b[(r, c)]).abs() < 1e-9 * (1.0 + a[(r, c)].abs()), "{name}: Λ̂⁻¹ differs");
            }
        }
        for k in 0..200 {
            let mut f = S::OpVec::zero();
            for i in 0..S::DIM {
                f[i] = 0.3 * ((k as f64 * 0.05 + i as f64).sin());
            }
            reduced.step(1e-3, &f);
            // The acceleration the configuration form predicts for a wrench without stepping is the one its
            // step then takes.
            let predicted = config.free_op_acceleration() + config.inverse_inertia() * f;
            let taken = config.step(1e-3, &f);
            for i in 0..S::DIM {
                assert!((predicted[i] - taken[i]).abs() < 1e-9 * (1.0 + taken[i].abs()), "{name}: {predicted:?}");
            }
        }
        let diff = reduced.pose.difference(&config.pose);
        for i in 0..S::DIM {
            assert!(diff[i].abs() < 1e-12, "{name} {terms:?}: OP poses differ by {diff:?}");
        }
    }
}

/// Between updates the local model tracks the full simulation: over 10 ms (a slow VE update) of the paper's
/// manipulation the OP position error is second order in the horizon, and drops about 4x when the horizon
/// halves.
#[test]
fn local_model_predicts_the_full_dynamics_over_short_horizons() {
    let model = testbed();
    let mut data = Data::new(&model);
    let mut user = OpWrench::<Planar> { op: 0, wrench: Vector3::from(PAPER_WRENCH) };
    let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-4, project: true, implicit_forces: false };
    // Start mid-motion (0.5 s into the manipulation).
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    for _ in 0..5000 {
        step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
    }
    let mut errors = Vec::new();
    for horizon_ms in [10usize, 5] {
        let (mut reduced, _) = local_models(&model, &mut data, &q, &qd, &mut user, LocalModelTerms::full());
        let (mut qf, mut qdf) = (q.clone(), qd.clone());
        for _ in 0..horizon_ms * 10 {
            step(&model, &mut data, &mut qf, &mut qdf, &mut user, &cfg).unwrap();
            reduced.step(1e-4, &user.wrench);
        }
        forward_dynamics(&model, &mut data, &qf, &qdf, &mut user).unwrap();
        let truth = OpPose::of_op(&model, &data, 0);
        let e = reduced.pose.difference(&truth);
        errors.push((e[0] * e[0] + e[1] * e[1]).sqrt());
    }
    assert!(errors[0] < 1e-4, "10 ms prediction error {:.3e} m", errors[0]);
    let ratio = errors[0] / errors[1];
    assert!(ratio > 3.0, "error should shrink ~4x (second order+): {errors:?}");
}

/// Poses written and read with a memo (a stream that moves a little each tick, as the client's uplink and
/// snapshot intake do) agree with the plain conversions, planar and spatial, including a wrap through ±π
/// and a jump.
#[test]
fn memoized_pose_conversions_match_the_plain_ones() {
    fn check<S: Space>(poses: impl Iterator<Item = OpPose<S>>) {
        let mut write_memo = S::RotParamsMemo::default();
        let mut read_memo = S::RotParamsMemo::default();
        let (mut plain, mut memo) = (vec![0.0; OpPose::<S>::wire_len()], vec![0.0; OpPose::<S>::wire_len()]);
        for pose in poses {
            pose.to_slice(&mut plain);
            pose.to_slice_memo(&mut memo, &mut write_memo);
            for (a, b) in plain.iter().zip(&memo) {
                assert!((a - b).abs() <= 1e-15, "written {memo:?} vs {plain:?}");
            }
            let read = OpPose::<S>::from_slice(&plain).expect("a valid pose");
            let read_memo_pose = OpPose::<S>::from_slice_memo(&plain, &mut read_memo).expect("a valid pose");
            let d = read.difference(&read_memo_pose);
            assert!(d.norm() <= 1e-15, "read {d:?}");
        }
        assert!(OpPose::<S>::from_slice_memo(&vec![f64::NAN; OpPose::<S>::wire_len()], &mut read_memo).is_none());
    }
    let angles = (0..20_000).map(|i| 3.0 + i as f64 * 4e-4).chain([-1.0, 2.5, -3.1]);
    check::<Planar>(angles.clone().map(|a| {
        let mut p = OpPose::<Planar>::identity();
        p.integrate(&Vector3::new(0.1, -0.2, a), 1.0);
        p
    }));
    check::<kinloop_linkage::math::space::Spatial>(angles.step_by(100).map(|a| {
        let mut p = OpPose::<kinloop_linkage::math::space::Spatial>::identity();
        p.integrate(&nalgebra::Vector6::new(0.1, -0.2, 0.3, a, 0.5 * a, -0.2), 1.0);
        p
    }));
}
