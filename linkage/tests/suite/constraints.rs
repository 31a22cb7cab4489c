//! Loop closure over time, redundant closures, the plain path for loop-free scenes, and the unit
//! consistency of constraint counting.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::integrator::{project, CHORD_TOLERANCE};
use kinloop_linkage::algorithms::kinematics::forward_poses;
use kinloop_linkage::algorithms::loop_closure::closure_residual;
use kinloop_linkage::algorithms::op_space::{op_space_inertia, open_inverse_inertia};
use kinloop_linkage::bench::Case;
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, algorithms::integrator::step,
    algorithms::integrator::Integrator, algorithms::integrator::StepConfig, math::space::Planar, math::space::Spatial,
    model::builtin, model::data::Data, model::Model,
};
use nalgebra::{DVector, Vector3};

fn paper_run(integrator: Integrator, project: bool, seconds: f64) -> (f64, Vec<usize>) {
    let model = testbed();
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let mut user = OpWrench::<Planar> { op: 0, wrench: Vector3::from(PAPER_WRENCH) };
    let cfg = StepConfig { integrator, dt: 1e-3, project, implicit_forces: false };
    let mut max_err: f64 = 0.0;
    let mut counts = Vec::new();
    for k in 0..(seconds * 1000.0) as usize {
        max_err = max_err.max(step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap().closure_error);
        if k % 10 == 0 {
            forward_dynamics(&model, &mut data, &q, &qd, &mut user).unwrap();
            op_space_inertia(&model, &mut data, 0).unwrap();
            counts.push(
                constraint_directions::<Planar>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD).count,
            );
        }
    }
    (max_err, counts)
}

/// The paper's manipulation at 1 kHz keeps the loop closed to 1e-9 m over 3 s with projection, for both
/// integrators; without projection Baumgarte alone keeps the drift bounded (but much larger).
#[test]
fn closure_error_stays_below_a_nanometre_in_the_paper_manipulation() {
    for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
        let (err, _) = paper_run(integrator, true, 3.0);
        assert!(err <= 1e-9, "{integrator:?} with projection: {err:.3e} m");
    }
    let (err, _) = paper_run(Integrator::SemiImplicitEuler, false, 3.0);
    assert!(err < 1e-4, "Baumgarte alone should bound the drift: {err:.3e} m");
    assert!(err > 1e-9, "without projection the drift is visible ({err:.3e} m), so the test above means something");
}

/// On the benchmark chains, moving fast after half a second of the paper's push (3 s of it), the residual
/// the projection predicts is the one a fresh evaluation finds (to the second-order term), and the chord
/// iterations alone take it below the tolerance: no refactorization.
#[test]
fn predicted_residual_is_the_evaluated_one() {
    for scene in ["chain20_loops5", "chain50_loops5"] {
        let mut case = Case::new(scene).unwrap();
        let (model, data) = (&case.model, &mut case.data);
        let mut check = Data::new(model);
        let cfg = StepConfig { project: false, ..StepConfig::euler(1e-3) };
        let (mut refactored, mut iterations, mut worst, mut max_actual) = (0, 0, 0.0f64, 0.0f64);
        for _ in 0..3000 {
            step(model, data, &mut case.q, &mut case.qd, &mut case.user, &cfg).unwrap();
            let p = project(model, data, &mut case.q, &mut case.qd);
            forward_poses(model, &mut check, &case.q);
            closure_residual(model, &mut check);
            let actual = check.closure_residual.norm();
            refactored += p.refactored as usize;
            iterations += p.chord_iterations;
            worst = worst.max((actual - p.predicted_residual).abs());
            max_actual = max_actual.max(actual);
        }
        // Measured: worst difference 1.7e-12 m, largest residual 9.18e-11 m (the tolerance is 9.17e-11 m:
        // the prediction is compared with it), 1.4 and 1.6 iterations a step on average.
        let tolerance = CHORD_TOLERANCE * model.length_scale;
        assert!(worst <= 0.05 * tolerance, "{scene}: prediction off by {worst:.3e} m");
        assert!(max_actual <= 1.1 * tolerance, "{scene}: left {max_actual:.3e} m");
        assert_eq!(refactored, 0, "{scene}: {iterations} chord iterations");
        assert!(iterations > 3000, "{scene}: the chain should move fast enough to need a second iteration");
    }
}

/// As in the paper's Fig 6a: at least one constraint on the OP throughout (the OP's link has too few DOF),
/// and two when the loop closure binds near the singular configurations (≈1 s and ≈2.9 s).
#[test]
fn constraint_count_follows_the_paper_fig_6a() {
    let (_, counts) = paper_run(Integrator::SemiImplicitEuler, true, 3.0);
    assert!(counts.iter().all(|&c| c >= 1), "{counts:?}");
    let twos: Vec<usize> = counts.iter().enumerate().filter(|(_, c)| **c == 2).map(|(i, _)| i * 10).collect();
    assert!(twos.iter().any(|&ms| (900..=1150).contains(&ms)), "no 2 near 1 s: {twos:?}");
    assert!(twos.iter().any(|&ms| ms >= 2800), "no 2 near 2.9 s: {twos:?}");
    assert!(counts[..50].iter().all(|&c| c == 1), "one constraint at the start: {:?}", &counts[..50]);
}

/// Redundant closures (one in the parallelogram, three in the spherical four-bar) are detected, solved
/// without NaN, and the loops stay closed during 2 s of free motion under gravity.
#[test]
fn redundant_closures_are_solved_without_nan() {
    let parallelogram: Model<Planar> = compile(&builtin_scene("parallelogram"));
    assert_eq!((parallelogram.nc(), parallelogram.closure_rank), (4, 3));
    run_free(&parallelogram, "parallelogram");
    let spherical: Model<Spatial> = compile(&builtin_scene("spherical-four-bar"));
    assert_eq!((spherical.nc(), spherical.closure_rank), (5, 2));
    run_free(&spherical, "spherical-four-bar");
}

/// A Bennett linkage (five closure rows of generic rank 2) swung by gravity through its folds stays on its
/// own motion. At a fold (θ1 = 0, θ2 = π) one of its cut's point rows vanishes: a factorization that keeps that
/// row and one other holds the loop with a single equation there, and the step leaves along a branch the other
/// rows forbid (with rows chosen relative to their own size, 16 L open after 3 s at 5 rad/s). Checked against
/// the Bennett's closed form rather than the code's own residual alone: θ3 = −θ1 and
/// `tan(θ1/2) tan(θ2/2) = sin((β+α)/2) / sin((β−α)/2) = 1 + √3` (the scene file's comment), written as
/// `sin(θ1/2) sin(θ2/2) − (1 + √3) cos(θ1/2) cos(θ2/2) = 0` to stay bounded at the fold.
#[test]
fn a_bennett_linkage_swings_through_its_folds_on_its_own_motion() {
    let model: Model<Spatial> = compile(&builtin_scene("bennett-linkage"));
    assert_eq!((model.nc(), model.closure_rank), (5, 2));
    let k = 1.0 + 3f64.sqrt();
    for speed in [0.5, 2.0, 5.0] {
        let mut data = Data::new(&model);
        let (mut q, mut qd) = (model.q0.clone(), DVector::from_vec(vec![speed, 0.0, -speed]));
        forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
        project(&model, &mut data, &mut q, &mut qd);
        let cfg = StepConfig::euler(1e-3);
        let (mut worst_rows, mut worst_form, mut folds_passed) = (0.0f64, 0.0f64, 0);
        let mut side = q[0].sin() > 0.0;
        for _ in 0..3000 {
            step(&model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap();
            forward_poses(&model, &mut data, &q);
            closure_residual(&model, &mut data);
            worst_rows = worst_rows.max(data.closure_residual.amax() / model.length_scale);
            let (h1, h2) = (q[0] / 2.0, q[1] / 2.0);
            let relation = h1.sin() * h2.sin() - k * h1.cos() * h2.cos();
            let opposite = (q[2] + q[0]).sin().abs();
            worst_form = worst_form.max(relation.abs()).max(opposite);
            if (q[0].sin() > 0.0) != side {
                side = !side;
                folds_passed += 1;
            }
        }
        assert!(folds_passed >= 2, "speed {speed}: the swing passed {folds_passed} folds (the test needs some)");
        assert!(worst_rows <= 1e-8, "speed {speed}: the loop opened by {worst_rows:.3e} of L on some row");
        assert!(worst_form <= 1e-6, "speed {speed}: {worst_form:.3e} off the Bennett's closed-form motion");
    }
}

fn run_free<S: kinloop_linkage::math::space::Space>(model: &Model<S>, name: &str) {
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), DVector::zeros(model.nv()));
    for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
        let cfg = StepConfig { integrator, dt: 1e-3, project: true, implicit_forces: false };
        let mut max_err: f64 = 0.0;
        for _ in 0..2000 {
            let r = step(model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{name}: {e}"));
            max_err = max_err.max(r.closure_error);
            assert!(data.lambda.iter().all(|x| x.is_finite()), "{name}: λ not finite");
        }
        assert!(qd.amax() > 0.1, "{name} should swing under gravity");
        assert!(
            max_err < 1e-9 * model.length_scale.max(1.0) * 100.0,
            "{name} {integrator:?}: closure error {max_err:.3e}"
        );
    }
}

/// A scene without loops takes the plain path: no closure rows, no multipliers, and the accelerations are
/// D⁻¹ τ (compared with nalgebra's LU).
#[test]
fn loop_free_scene_takes_the_plain_path() {
    let model: Model<Planar> = compile(&builtin_scene("serial-arm"));
    assert_eq!((model.nc(), model.closure_rank), (0, 0));
    let mut data = Data::new(&model);
    assert_eq!(data.lambda.len(), 0);
    let (q, qd) = random_state(&model, 5);
    forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
    kinloop_linkage::algorithms::mass_matrix::mass_matrix(&model, &mut data);
    let tau = &data.applied + &data.joint_force - &data.bias - &data.gravity;
    let expected = data.mass_matrix.clone().lu().solve(&tau).unwrap();
    assert!((&data.qdd - expected).amax() < 1e-10);
}

/// The classic serial-chain result: without loops Λ⁻¹ = J D⁻¹ Jᵀ (and the closed and open forms agree).
#[test]
fn serial_chain_gives_the_classic_inverse_inertia() {
    let model: Model<Planar> = compile(&builtin_scene("serial-arm"));
    let mut data = Data::new(&model);
    let (q, qd) = random_state(&model, 2);
    forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
    op_space_inertia(&model, &mut data, 0).unwrap();
    kinloop_linkage::algorithms::mass_matrix::mass_matrix(&model, &mut data);
    let j = data.op.jacobian_t.transpose();
    let classic = &j * data.mass_matrix.clone().try_inverse().unwrap() * j.transpose();
    for r in 0..3 {
        for c in 0..3 {
            assert!((data.op.inverse_inertia[(r, c)] - classic[(r, c)]).abs() < 1e-10);
            assert_eq!(data.op.inverse_inertia[(r, c)], open_inverse_inertia(&model, &data)[(r, c)]);
        }
    }
}

/// The same testbed written in millimetres (lengths ×1000, inertias ×10⁶, wrench force ×1000 and torque
/// ×10⁶) gives the same constraint count, the same directions (in unit-consistent coordinates) and
/// singular values scaled by one common factor (here 1), along the whole manipulation.
#[test]
fn constraint_count_and_directions_do_not_depend_on_units() {
    let metres = builtin_scene("paper-testbed");
    let millimetres = metres.scaled_lengths(1000.0);
    let (m1, m2): (Model<Planar>, Model<Planar>) = (compile(&metres), compile(&millimetres));
    assert!((m2.length_scale / m1.length_scale - 1000.0).abs() < 1e-9);
    let (mut d1, mut d2) = (Data::new(&m1), Data::new(&m2));
    let (mut q1, mut qd1) = (m1.q0.clone(), m1.qd0.clone());
    let (mut q2, mut qd2) = (m2.q0.clone(), m2.qd0.clone());
    let w = Vector3::from(PAPER_WRENCH);
    let mut u1 = OpWrench::<Planar> { op: 0, wrench: w };
    let mut u2 = OpWrench::<Planar> { op: 0, wrench: Vector3::new(w.x * 1e3, w.y * 1e3, w.z * 1e6) };
    let cfg = StepConfig { integrator: Integrator::SemiImplicitEuler, dt: 1e-3, project: true, implicit_forces: false };
    let mut compared_twos = 0;
    let mut raw_counts_differ = false;
    for k in 0..3000 {
        step(&m1, &mut d1, &mut q1, &mut qd1, &mut u1, &cfg).unwrap();
        step(&m2, &mut d2, &mut q2, &mut qd2, &mut u2, &cfg).unwrap();
        if k % 25 != 0 {
            continue;
        }
        assert!((&q1 - &q2).amax() < 1e-6, "the motion itself is unit-independent (joint angles)");
        let mut cd = Vec::new();
        for (model, data, q, qd, user) in [(&m1, &mut d1, &q1, &qd1, &mut u1), (&m2, &mut d2, &q2, &qd2, &mut u2)] {
            forward_dynamics(model, data, q, qd, user).unwrap();
            op_space_inertia(model, data, 0).unwrap();
            cd.push(constraint_directions::<Planar>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD));
        }
        assert_eq!(cd[0].count, cd[1].count, "count at step {k}");
        // Control: without the length scale (L = 1 in each unit system) the counts disagree somewhere.
        let raw =
            |d: &Data<Planar>| constraint_directions::<Planar>(&d.op.inverse_inertia, 1.0, DEFAULT_THRESHOLD).count;
        raw_counts_differ |= raw(&d1) != raw(&d2);
        compared_twos += usize::from(cd[0].count == 2);
        // Mass keeps its unit, so accelerations and forces both scale by 1000 and the common factor is 1.
        let common = cd[1].singular_values[0] / cd[0].singular_values[0];
        assert!((common - 1.0).abs() < 1e-9, "common factor {common}");
        for i in 0..3 {
            let ratio = cd[1].singular_values[i] / cd[0].singular_values[i];
            if cd[0].singular_values[i] > 1e-9 * cd[0].singular_values[0] {
                assert!((ratio / common - 1.0).abs() < 1e-6, "σ{i} scales by the common factor: {ratio}");
                let (a, b) = (cd[0].direction(i), cd[1].direction(i));
                assert!(a.dot(&b).abs() > 1.0 - 1e-9, "direction {i} at step {k}: {a} vs {b}");
            }
        }
    }
    assert!(compared_twos > 0, "the comparison should cover the binding loop closure");
    assert!(raw_counts_differ, "unscaled Λ⁻¹ should give unit-dependent counts (else this test proves nothing)");
}

/// The benchmark chains keep their loops closed and their constraint structure: chainN_loopsL has 2L rows.
#[test]
fn benchmark_chains_compile_closed() {
    for (n, l) in [(20, 1), (20, 5), (50, 1), (50, 5)] {
        let model: Model<Planar> = compile(&builtin::chain(n, l));
        assert_eq!((model.nv(), model.nc(), model.closure_rank), (n, 2 * l, 2 * l));
        let mut data = Data::new(&model);
        forward_dynamics(&model, &mut data, &model.q0, &model.qd0, &mut ()).unwrap();
        assert!(data.closure_residual.amax() < 1e-15);
    }
}

/// A step with linearly-implicit forces, then a plain `forward_dynamics`, then a step again: the second
/// step must not see the first step's implicit terms (they are cleared whenever the flag drops).
#[test]
fn implicit_mass_never_leaks_between_solves() {
    use kinloop_linkage::algorithms::dynamics::Forces;
    use kinloop_linkage::model::data::Kinematics;
    struct Stiff;
    impl Forces<Planar> for Stiff {
        fn add_forces(&mut self, _: &Model<Planar>, _: &Kinematics<Planar>, _: &mut nalgebra::DVector<f64>) {}
        fn add_implicit(
            &mut self,
            _: &Model<Planar>,
            _: &Kinematics<Planar>,
            _: f64,
            _: &nalgebra::DVector<f64>,
            m: &mut nalgebra::DMatrix<f64>,
            _: &mut nalgebra::DVector<f64>,
        ) -> bool {
            for i in 0..m.nrows() {
                m[(i, i)] += 1.0;
            }
            true
        }
    }
    let model = testbed();
    let cfg = StepConfig::euler(1e-3);
    let run = |interleave: bool| {
        let mut data = Data::new(&model);
        let (mut q, mut qd) = (model.q0.clone(), nalgebra::DVector::from_element(4, 0.1));
        for _ in 0..5 {
            step(&model, &mut data, &mut q, &mut qd, &mut Stiff, &cfg).unwrap();
            if interleave {
                forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
            }
        }
        (q, data.implicit_mass.amax())
    };
    let (plain, _) = run(false);
    let (interleaved, implicit) = run(true);
    assert_eq!(plain, interleaved, "a forward_dynamics between steps must not change the steps");
    assert_eq!(implicit, 0.0, "forward_dynamics leaves no implicit mass behind");
}
