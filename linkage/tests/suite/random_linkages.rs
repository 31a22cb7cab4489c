//! Property tests on random linkages: random trees of revolute and prismatic joints, closed by random pins
//! (some of them degenerate or redundant), in the plane and in space.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::model::scene::{BodySpec, CutKindSpec, CutSpec, JointKindSpec, JointSpec, Numbers, OpSpec};
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, math::space::MatOps, math::space::Planar,
    math::space::SceneKind, math::space::Space, math::space::Spatial, math::space::VecOps, model::data::Data,
    model::scene::Scene, model::Model,
};
use nalgebra::DMatrix;
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct Spec {
    bodies: Vec<(usize, bool, f64, f64, f64, f64)>, // (parent choice, prismatic, length, mass, inertia, q0)
    cuts: Vec<(usize, usize, f64)>,                 // (body a, body b choice, point along a)
    seed: u64,
}

fn spec() -> impl Strategy<Value = Spec> {
    (
        prop::collection::vec(
            (0usize..100, prop::bool::weighted(0.2), 0.05f64..0.3, 0.1f64..2.0, 1e-4f64..1e-2, -1.5f64..1.5),
            2..7,
        ),
        prop::collection::vec((0usize..100, 0usize..100, 0.2f64..1.0), 0..3),
        any::<u64>(),
    )
        .prop_map(|(bodies, cuts, seed)| Spec { bodies, cuts, seed })
}

fn build(spec: &Spec, kind: SceneKind) -> Scene {
    let d = kind.point_dim();
    let v = |x: f64, y: f64| if d == 2 { vec![x, y] } else { vec![x, y, 0.1 * x] };
    let n = spec.bodies.len();
    let name = |i: usize| format!("b{i}");
    let bodies = spec
        .bodies
        .iter()
        .enumerate()
        .map(|(i, &(_, _, len, mass, inertia, _))| BodySpec {
            name: name(i),
            mass,
            com: v(len / 2.0, 0.01),
            inertia: if d == 2 {
                Numbers::One(inertia)
            } else {
                Numbers::Many(vec![inertia, inertia * 1.3, inertia * 0.7])
            },
            geometry: vec![],
        })
        .collect();
    let joints = spec
        .bodies
        .iter()
        .enumerate()
        .map(|(i, &(p, prismatic, _, _, _, q0))| {
            let parent = if i == 0 || p % (i + 1) == i { None } else { Some(p % i) };
            let parent_len = parent.map_or(0.0, |p| spec.bodies[p].2);
            JointSpec {
                name: format!("j{i}"),
                kind: if prismatic { JointKindSpec::Prismatic } else { JointKindSpec::Revolute },
                parent: parent.map_or("ground".into(), name),
                child: name(i),
                origin: v(parent_len, 0.02 * i as f64),
                rotation: if d == 2 { None } else { Some(Numbers::Many(vec![0.3 * i as f64, -0.2, 0.1])) },
                axis: if d == 3 { Some(vec![0.1 * i as f64, 0.5, 1.0]) } else { None },
                axes: None,
                q0: if prismatic { 0.1 * q0 } else { q0 },
                qd0: 0.0,
                spring: None,
                damping: 0.0,
                armature: 0.0,
                actuator: None,
                range: None,
            }
        })
        .collect();
    let cuts = spec
        .cuts
        .iter()
        .enumerate()
        .map(|(k, &(a, b, along))| {
            let a = a % n;
            let b = b % (n + 1);
            CutSpec::between(
                format!("c{k}"),
                if d == 2 { CutKindSpec::Pin } else { CutKindSpec::Spherical },
                name(a),
                v(along * spec.bodies[a].2, 0.0),
                if b == n || b == a { "ground".into() } else { name(b) },
            )
        })
        .collect();
    Scene {
        name: format!("random-{}", spec.seed),
        kind,
        gravity: if d == 2 { vec![0.0, -9.81] } else { vec![0.0, 0.0, -9.81] },
        length_scale: None,
        baumgarte: Default::default(),
        contact: Default::default(),
        closure_tolerance: None,
        bodies,
        joints,
        cuts,
        ops: vec![OpSpec { name: "op".into(), body: name(n - 1), point: v(0.03, 0.01) }],
        obstacles: vec![],
    }
}

fn check<S: Space>(scene: &Scene, seed: u64) -> Result<(), TestCaseError> {
    let model: Model<S> = Model::compile(scene, "random").map_err(|e| TestCaseError::fail(e.to_string()))?;
    let mut data = Data::new(&model);
    let mut rng = Rng(seed);
    // A velocity consistent with the closures (W q̇ = 0), as every real state has: with an inconsistent one,
    // redundant rows would be contradictory at acceleration level.
    let random = nalgebra::DVector::from_fn(model.nv(), |_, _| rng.signed());
    let qd = if model.nc() == 0 {
        random
    } else {
        kinloop_linkage::algorithms::kinematics::forward_kinematics(&model, &mut data, &model.q0);
        kinloop_linkage::algorithms::loop_closure::closure_residual_and_jacobian(&model, &mut data);
        let n = null_space(&data.closure_jacobian(), model.nv());
        &n * (n.transpose() * random)
    };
    let mut user = OpWrench::<S> { op: 0, wrench: S::OpVec::zero() };
    for x in user.wrench.as_mut_slice() {
        *x = rng.signed();
    }
    forward_dynamics(&model, &mut data, &model.q0, &qd, &mut user).map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert!(data.qdd.iter().chain(data.lambda.iter()).all(|x| x.is_finite()));
    // D by composite rigid bodies: the dynamics factored it from articulated inertias without forming it.
    kinloop_linkage::algorithms::mass_matrix::mass_matrix(&model, &mut data);
    let tau = &data.applied + &data.joint_force - &data.bias - &data.gravity;
    let residual = &data.mass_matrix * &data.qdd + &data.closure_jacobian_t * &data.lambda - &tau;
    prop_assert!(residual.amax() < 1e-8 * (1.0 + tau.amax() + data.lambda.amax()), "eq 4 residual {}", residual.amax());
    // At q0 the closures hold (h = 0). W q̈ + w_stab = 0 on the rows the pivoting kept, always; on the
    // dependent rows too whenever the system is consistent (w_stab in the range of W), as a structural
    // redundancy makes it (the parallelogram's). A random linkage may be built at a shaky configuration
    // (links aligned, where W drops rank only at that point): a q̇ in W's null space there is not a real
    // motion and no q̈ satisfies every row (seen: residual 2.7e-4 on the dropped row, w_stab not in the
    // range of W); the documented answer is then the basic solution on the kept rows.
    let closure = data.closure_jacobian() * &data.qdd + &data.closure_bias_stab;
    let scale = 1.0 + data.closure_bias_stab.amax() + data.qdd.amax();
    let consistent = model.nc() == 0 || {
        let left_null = null_space(&data.closure_jacobian().transpose(), model.nc());
        (left_null.transpose() * &data.closure_bias_stab).amax() <= 1e-9 * scale
    };
    let rank = data.kkt.schur_rank;
    let rows: Vec<usize> = if consistent { (0..model.nc()).collect() } else { data.kkt.schur_perm[..rank].to_vec() };
    let worst = rows.iter().map(|&r| closure[r].abs()).fold(0.0, f64::max);
    prop_assert!(
        worst < 1e-7 * scale,
        "acceleration closure {worst} on rows {rows:?} (rank {rank}/{}, consistent {consistent})",
        model.nc()
    );

    op_space_inertia(&model, &mut data, 0).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let li = DMatrix::from_column_slice(S::DIM, S::DIM, data.op.inverse_inertia.as_slice());
    prop_assert!((&li - li.transpose()).amax() < 1e-12 * (1.0 + li.amax()), "Λ⁻¹ symmetric");
    let eig = li.clone().symmetric_eigen().eigenvalues;
    prop_assert!(eig.min() > -1e-9 * (1.0 + eig.amax()), "Λ⁻¹ positive semi-definite: {eig}");
    if data.kkt.schur_rank == model.closure_rank {
        let expected =
            null_space_inverse_inertia(&data.mass_matrix, &data.closure_jacobian(), &data.op.jacobian_t.transpose());
        prop_assert!((&li - &expected).amax() < 1e-7 * (1.0 + li.amax()), "Λ⁻¹ vs null-space formula");
    }
    Ok(())
}

/// 200 cases from a fixed seed, so that a CI run is reproducible; `PROPTEST_RNG_SEED=<u64>` explores
/// others. Linkages generated at a shaky configuration once gave a Λ⁻¹ with an eigenvalue of -1.7e-6 (seed
/// 6, and about 1 random run in 15): the difference `Yᵀ Y - Gᵀ G` lost the small eigenvalues to
/// round-off; the Gram form of `op_space` fixed it (seeds 1 to 40 pass, 16,000 cases).
fn config() -> ProptestConfig {
    let mut config = ProptestConfig { cases: 200, ..ProptestConfig::default() };
    if std::env::var_os("PROPTEST_RNG_SEED").is_none() {
        config.rng_seed = proptest::test_runner::RngSeed::Fixed(20261123);
    }
    config
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn random_planar_linkages_satisfy_eq_4_and_eq_9(s in spec()) {
        check::<Planar>(&build(&s, SceneKind::Planar), s.seed)?;
    }

    #[test]
    fn random_spatial_linkages_satisfy_eq_4_and_eq_9(s in spec()) {
        check::<Spatial>(&build(&s, SceneKind::Spatial), s.seed)?;
    }
}
