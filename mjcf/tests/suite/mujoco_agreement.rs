//! MJCF linkages written for the tests (a planar four-bar with default classes and geom-derived inertia; a
//! planar slider-crank with layered links, a hinge written along −z and armatures; a spatial RSSR loop with a
//! ball joint, explicit inertials and an include; a Delta robot with ball joints, frames, five connects and
//! armatures on its arms (through a default class) and on a ball), imported and compared with MuJoCo itself at closed, moving
//! states: site positions, the mass matrix (`mj_fullM`), the bias and the passive and actuator forces to 1e-9
//! relative, the constraint Jacobian's row space, and kinloop's constrained acceleration against the exact
//! solve from MuJoCo's own M, forces and Jacobian (MuJoCo's `qacc` is soft, so it is not the reference).
//! The planar models import as planar scenes (two equations per pin, not a connect's three); their terms are
//! compared in MuJoCo's coordinates (a hinge along −n negated back, a site's depth along n restored), and
//! their motion and Λ⁻¹ at the sites against their own spatial import, a second formulation.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::configuration::integrate;
use kinloop_linkage::algorithms::dynamics::forward_dynamics;
use kinloop_linkage::algorithms::integrator::{step, Integrator, StepConfig};
use kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian;
use kinloop_linkage::algorithms::mass_matrix::mass_matrix;
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::math::space::{Planar, SceneKind, Space, Spatial, VecOps};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::Attachment;
use kinloop_linkage::Model;
use kinloop_mjcf::import_file;
use kinloop_mjcf::planar::{PlanarReduction, Reduction};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Vector3};

const TOLERANCE: f64 = 1e-9;
/// Each model and the kind its import must have.
const MODELS: &[(&str, SceneKind)] = &[
    ("planar-four-bar.xml", SceneKind::Planar),
    ("planar-slider-crank.xml", SceneKind::Planar),
    ("spatial-rssr.xml", SceneKind::Spatial),
    ("delta.xml", SceneKind::Spatial),
];

/// A closed state near q0: q moved along a fixed direction then assembled, q̇ a fixed direction projected
/// onto the closure's null space (so the loop stays closed to second order and Baumgarte adds nothing).
fn closed_state<S: Space>(model: &Model<S>, seed: usize) -> (DVector<f64>, DVector<f64>) {
    let nv = model.nv();
    let wave = |k: usize| DVector::from_fn(nv, |i, _| ((i * 7 + k * 3 + seed * 11) as f64 * 0.9).sin());
    let mut q = model.q0.clone();
    integrate(model, &mut q, &wave(1), 0.15);
    let q = assemble(model, &q, 1e-13 * model.length_scale).expect("the loop closes near q0").q;
    let mut data = Data::new(model);
    kinloop_linkage::algorithms::kinematics::forward_kinematics(model, &mut data, &q);
    closure_residual_and_jacobian(model, &mut data);
    let w = data.closure_jacobian_t.transpose();
    let v = wave(2) * 2.0;
    let qd = &v - row_space(&w) * &v;
    (q, qd)
}

/// kinloop's terms at one state, in MuJoCo's coordinates.
struct Terms {
    name: &'static str,
    seed: usize,
    nq: usize,
    qpos: DVector<f64>,
    qvel: DVector<f64>,
    sites: Vec<(String, Vector3<f64>)>,
    mass: DMatrix<f64>,
    bias_and_gravity: DVector<f64>,
    joint_force: DVector<f64>,
    jacobian: DMatrix<f64>,
    qdd: DVector<f64>,
}

/// Three closed states of `model` and its terms there; `signs` map its velocities to MuJoCo's (a planar
/// import's hinge along −n runs the other way) and `site` turns an operational point's kinloop position
/// into MuJoCo's world (a planar import's plane and depth).
fn terms_of<S: Space>(
    name: &'static str,
    model: &Model<S>,
    signs: &DVector<f64>,
    site: impl Fn(usize, &[f64]) -> Vector3<f64>,
) -> Vec<Terms> {
    let flip = DMatrix::from_diagonal(signs);
    (0..3)
        .map(|seed| {
            let (q, qd) = closed_state(model, seed);
            let mut data = Data::new(model);
            forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap_or_else(|e| panic!("{name}: {e}"));
            mass_matrix(model, &mut data);
            let sites = model
                .ops
                .iter()
                .enumerate()
                .map(|(k, op)| {
                    let p = data.kin.point(&Attachment { body: Some(op.body), point: op.point });
                    (op.name.clone(), site(k, p.as_slice()))
                })
                .collect();
            // Without ball joints q and q̇ have one entry per joint, so the signs apply to both.
            let qpos = if model.has_balls() { q.clone() } else { q.component_mul(signs) };
            Terms {
                name,
                seed,
                nq: model.nq(),
                qpos,
                qvel: qd.component_mul(signs),
                sites,
                mass: &flip * &data.mass_matrix * &flip,
                bias_and_gravity: (&data.bias + &data.gravity).component_mul(signs),
                joint_force: data.joint_force.component_mul(signs),
                jacobian: data.closure_jacobian_t.transpose() * &flip,
                qdd: data.qdd.component_mul(signs),
            }
        })
        .collect()
}

fn reduction(name: &str, r: &Reduction) -> PlanarReduction {
    match r {
        Reduction::Planar(p) => (**p).clone(),
        Reduction::Spatial { why, .. } => panic!("{name} was kept spatial: {why}"),
    }
}

#[test]
fn imported_linkages_match_mujoco_terms() {
    let mut cases = Vec::new();
    for &(name, kind) in MODELS {
        let import = import_file(&model(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(import.scene.kind, kind, "{name}: {}", import.reduction.describe());
        // The slider-crank's and the Delta's armatures are imported (and so in M below), never warned about.
        let warned = import.warnings.message(name).unwrap_or_default();
        assert!(!warned.contains("armature"), "{name}: {warned}");
        match kind {
            SceneKind::Planar => {
                let r = reduction(name, &import.reduction);
                let m = Model::<Planar>::compile(&import.scene, name).unwrap_or_else(|e| panic!("{e}"));
                let signs = DVector::from_vec(r.signs.clone());
                cases.extend(terms_of(name, &m, &signs, |k, xy| r.plane.to_world([xy[0], xy[1]], r.op_depths[k])));
            }
            SceneKind::Spatial => {
                let m = Model::<Spatial>::compile(&import.scene, name).unwrap_or_else(|e| panic!("{e}"));
                let signs = DVector::from_element(m.nv(), 1.0);
                cases.extend(terms_of(name, &m, &signs, |_, p| Vector3::from_column_slice(p)));
            }
        }
    }
    let checks: Vec<Check> = cases
        .iter()
        .map(|t| Check {
            model: model(t.name),
            qpos: t.qpos.as_slice().to_vec(),
            qvel: t.qvel.as_slice().to_vec(),
            steps: 0,
        })
        .collect();
    let terms = mujoco_terms(&checks);
    println!("| model | state | sites | M | bias | passive + actuator | W row space | constrained q̈ |");
    for (t, mj) in cases.iter().zip(&terms) {
        let (name, seed, nv) = (t.name, t.seed, t.qvel.len());
        assert_eq!(mj["nv"].as_u64(), Some(nv as u64), "{name}: nv");
        assert_eq!(mj["nq"].as_u64(), Some(t.nq as u64), "{name}: nq");
        let mut site_errors = Vec::new();
        for (op, kin) in &t.sites {
            let theirs = vector(&mj["sites"][op]);
            site_errors.push(relative(kin.as_slice(), theirs.as_slice()));
        }
        let sites = site_errors.iter().fold(0.0f64, |a, b| a.max(*b));
        let m_mj = matrix(&mj["mass_matrix"], nv);
        let mass = relative(t.mass.as_slice(), m_mj.as_slice());
        // kinloop: D q̈ + B + G = τ + Wᵀλ with G = gravity + springs; MuJoCo: qfrc_bias = Coriolis + gravity,
        // springs and dampers in qfrc_passive, the position actuator in qfrc_actuator.
        let (bias_mj, spring, damper, actuator) =
            (vector(&mj["bias"]), vector(&mj["spring"]), vector(&mj["damper"]), vector(&mj["actuator"]));
        let bias = relative(t.bias_and_gravity.as_slice(), (&bias_mj - &spring).as_slice());
        let passive = relative(t.joint_force.as_slice(), (&damper + &actuator).as_slice());
        let j = matrix(&mj["constraint_jacobian"], nv);
        let rows = relative(row_space(&t.jacobian).as_slice(), row_space(&j).as_slice());
        let force = &spring + &damper + &actuator - &bias_mj;
        let exact = exact_constrained_acceleration(&m_mj, &force, &j, &vector(&mj["jdot_qdot"]));
        let qdd = relative(t.qdd.as_slice(), exact.as_slice());
        println!(
            "| {name} | {seed} | {sites:.1e} | {mass:.1e} | {bias:.1e} | {passive:.1e} | {rows:.1e} | {qdd:.1e} |"
        );
        for (what, err) in
            [("sites", sites), ("M", mass), ("bias", bias), ("passive", passive), ("W", rows), ("q̈", qdd)]
        {
            assert!(err < TOLERANCE, "{name} at qpos = {}: {what} differs from MuJoCo's by {err:.2e}", t.qpos);
        }
    }
}

/// The in-plane block of a spatial Λ⁻¹ (order v, ω): rows and columns (e1·v, e2·v, n·ω).
fn in_plane(r: &PlanarReduction, lambda_inv: &Matrix6<f64>) -> Matrix3<f64> {
    let mut t = nalgebra::Matrix3x6::zeros();
    t.fixed_view_mut::<1, 3>(0, 0).copy_from(&r.plane.e1.transpose());
    t.fixed_view_mut::<1, 3>(1, 0).copy_from(&r.plane.e2.transpose());
    t.fixed_view_mut::<1, 3>(2, 3).copy_from(&r.plane.normal.transpose());
    t * lambda_inv * t.transpose()
}

/// The planar models' planar scenes move as their spatial imports (same q(t) over 0.5 s of RK4 under
/// gravity, springs and the actuator), and Λ⁻¹ at every site along the way is the spatial one's in-plane
/// block; the connect's row along the normal is the equation dropped, and the spatial model has it redundant.
#[test]
fn planar_imports_move_and_feel_as_their_spatial_import() {
    println!("| model | max |Δq| over 0.5 s | max Λ⁻¹ difference (relative, (v, L ω)) |");
    for &(name, _) in MODELS.iter().filter(|(_, k)| *k == SceneKind::Planar) {
        let import = import_file(&model(name)).unwrap_or_else(|e| panic!("{e}"));
        let r = reduction(name, &import.reduction);
        assert!(r.dropped.iter().any(|d| d.starts_with("connect") && d.contains("1 of 3")), "{name}: {:?}", r.dropped);
        assert!(import.reduction.describe().starts_with("reduced to a planar scene"));
        // The slider-crank's rod hinge is written along −z: its planar angle runs the other way.
        let flipped: Vec<f64> = if name == "planar-slider-crank.xml" { vec![1.0, -1.0, 1.0] } else { vec![1.0; 3] };
        assert_eq!(r.signs, flipped, "{name}");
        let planar = Model::<Planar>::compile(&import.scene, name).unwrap_or_else(|e| panic!("{e}"));
        let spatial = Model::<Spatial>::compile(&r.spatial, name).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(planar.nc(), 2 * spatial.nc() / 3, "{name}: a pin per connect");
        assert_eq!(spatial.closure_rank, planar.closure_rank, "{name}: the dropped row is redundant");
        assert_eq!(planar.closure_rank, planar.nc(), "{name}: the planar closure has no redundant row");
        let signs = DVector::from_vec(r.signs.clone());
        let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-3, project: true, implicit_forces: false };
        let (mut qp, mut qdp) = (planar.q0.clone(), planar.qd0.clone());
        let (mut qs, mut qds) = (spatial.q0.clone(), spatial.qd0.clone());
        let (mut dp, mut ds) = (Data::new(&planar), Data::new(&spatial));
        let (mut worst_q, mut worst_lambda) = (0.0f64, 0.0f64);
        let scale = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, planar.length_scale));
        for k in 0..=500 {
            worst_q = worst_q.max((&qp - qs.component_mul(&signs)).amax());
            if k % 100 == 0 {
                forward_dynamics(&planar, &mut dp, &qp, &qdp, &mut ()).unwrap();
                forward_dynamics(&spatial, &mut ds, &qs, &qds, &mut ()).unwrap();
                for op in 0..planar.ops.len() {
                    op_space_inertia(&planar, &mut dp, op).unwrap();
                    op_space_inertia(&spatial, &mut ds, op).unwrap();
                    let theirs = scale * in_plane(&r, &ds.op.inverse_inertia) * scale;
                    let ours = scale * dp.op.inverse_inertia * scale;
                    worst_lambda = worst_lambda.max(relative(ours.as_slice(), theirs.as_slice()));
                }
            }
            step(&planar, &mut dp, &mut qp, &mut qdp, &mut (), &cfg).unwrap();
            step(&spatial, &mut ds, &mut qs, &mut qds, &mut (), &cfg).unwrap();
        }
        let travel = (&qp - &planar.q0).amax();
        println!("| {name} | {worst_q:.1e} | {worst_lambda:.1e} |");
        assert!(travel > 1e-2, "{name}: the linkage hardly moved ({travel:e}), so the check says little");
        assert!(worst_q < 1e-9, "{name}: the planar and spatial imports move apart by {worst_q:e}");
        assert!(worst_lambda < 1e-9, "{name}: Λ⁻¹ at a site differs by {worst_lambda:e} (relative)");
    }
}
