//! MJCF linkages written for the tests (a planar four-bar with default classes and geom-derived inertia; a
//! spatial RSSR loop with a ball joint, explicit inertials and an include), imported and compared with
//! MuJoCo itself at closed, moving states: site positions, the mass matrix (`mj_fullM`), the bias and the
//! passive and actuator forces to 1e-9 relative, the constraint Jacobian's row space, and kinloop's
//! constrained acceleration against the exact solve from MuJoCo's own M, forces and Jacobian (MuJoCo's
//! `qacc` is soft, so it is not the reference).

mod common;

use common::*;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::configuration::integrate;
use kinloop_linkage::algorithms::dynamics::forward_dynamics;
use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::algorithms::mass_matrix::mass_matrix;
use kinloop_linkage::math::space::Spatial;
use kinloop_linkage::model::data::Data;
use kinloop_linkage::Model;
use kinloop_mjcf::import_file;
use nalgebra::DVector;

const TOLERANCE: f64 = 1e-9;
const MODELS: &[&str] = &["planar-four-bar.xml", "spatial-rssr.xml"];

/// A closed state near q0: q moved along a fixed direction then assembled, q̇ a fixed direction projected
/// onto the closure's null space (so the loop stays closed to second order and Baumgarte adds nothing).
fn closed_state(model: &Model<Spatial>, seed: usize) -> (DVector<f64>, DVector<f64>) {
    let nv = model.nv();
    let wave = |k: usize| DVector::from_fn(nv, |i, _| ((i * 7 + k * 3 + seed * 11) as f64 * 0.9).sin());
    let mut q = model.q0.clone();
    integrate(model, &mut q, &wave(1), 0.15);
    let q = assemble(model, &q, 1e-13 * model.length_scale).expect("the loop closes near q0").q;
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, &q);
    closure_residual_and_jacobian(model, &mut data);
    let w = data.closure_jacobian_t.transpose();
    let v = wave(2) * 2.0;
    let qd = &v - row_space(&w) * &v;
    (q, qd)
}

#[test]
fn imported_linkages_match_mujoco_terms() {
    let mut cases = Vec::new();
    let mut checks = Vec::new();
    for name in MODELS {
        let import = import_file(&model(name)).unwrap_or_else(|e| panic!("{e}"));
        let kin_model = Model::<Spatial>::compile(&import.scene, name).unwrap_or_else(|e| panic!("{e}"));
        for seed in 0..3 {
            let (q, qd) = closed_state(&kin_model, seed);
            checks.push(Check {
                model: model(name),
                qpos: q.as_slice().to_vec(),
                qvel: qd.as_slice().to_vec(),
                steps: 0,
            });
            cases.push((name, seed, kin_model.clone(), q, qd));
        }
    }
    let terms = mujoco_terms(&checks);
    println!("| model | state | sites | M | bias | passive + actuator | W row space | constrained q̈ |");
    for ((name, seed, model, q, qd), mj) in cases.iter().zip(&terms) {
        let nv = model.nv();
        assert_eq!(mj["nv"].as_u64(), Some(nv as u64), "{name}: nv");
        assert_eq!(mj["nq"].as_u64(), Some(model.nq() as u64), "{name}: nq");
        let mut data = Data::new(model);
        forward_dynamics(model, &mut data, q, qd, &mut ()).unwrap_or_else(|e| panic!("{name}: {e}"));
        mass_matrix(model, &mut data);

        let mut site_errors = Vec::new();
        for op in &model.ops {
            let kin = data.kin.body_pos[op.body] + data.kin.body_rot[op.body] * op.point;
            let theirs = vector(&mj["sites"][&op.name]);
            site_errors.push(relative(kin.as_slice(), theirs.as_slice()));
        }
        let sites = site_errors.iter().fold(0.0f64, |a, b| a.max(*b));
        let m_mj = matrix(&mj["mass_matrix"], nv);
        let mass = relative(data.mass_matrix.as_slice(), m_mj.as_slice());
        // kinloop: D q̈ + B + G = τ + Wᵀλ with G = gravity + springs; MuJoCo: qfrc_bias = Coriolis + gravity,
        // springs and dampers in qfrc_passive, the position actuator in qfrc_actuator.
        let (bias_mj, spring, damper, actuator) =
            (vector(&mj["bias"]), vector(&mj["spring"]), vector(&mj["damper"]), vector(&mj["actuator"]));
        let bias = relative((&data.bias + &data.gravity).as_slice(), (&bias_mj - &spring).as_slice());
        let passive = relative(data.joint_force.as_slice(), (&damper + &actuator).as_slice());
        let j = matrix(&mj["constraint_jacobian"], nv);
        let rows = relative(row_space(&data.closure_jacobian_t.transpose()).as_slice(), row_space(&j).as_slice());
        let force = &spring + &damper + &actuator - &bias_mj;
        let exact = exact_constrained_acceleration(&m_mj, &force, &j, &vector(&mj["jdot_qdot"]));
        let qdd = relative(data.qdd.as_slice(), exact.as_slice());
        println!(
            "| {name} | {seed} | {sites:.1e} | {mass:.1e} | {bias:.1e} | {passive:.1e} | {rows:.1e} | {qdd:.1e} |"
        );
        for (what, err) in
            [("sites", sites), ("M", mass), ("bias", bias), ("passive", passive), ("W", rows), ("q̈", qdd)]
        {
            assert!(err < TOLERANCE, "{name} at q = {q}: {what} differs from MuJoCo's by {err:.2e} (relative)");
        }
    }
}
