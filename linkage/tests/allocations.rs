//! The hot paths allocate nothing: a counting global allocator watches a VE step (both integrators, with
//! projection and external forces), the operational-space inertia with its SVD, and both local models.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::math::space::Spatial;
use kinloop_linkage::model::builtin::{self, PAPER_WRENCH};
use kinloop_linkage::model::scene::Scene;
use kinloop_linkage::{
    algorithms::configuration::ConfigLayout,
    algorithms::local_model::{
        op_space_terms, ConfigSpaceLocalModel, ConfigSpaceTerms, LocalModelTerms, OpSpaceLocalModel,
    },
    math::space::OpPose,
};
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, algorithms::integrator::step,
    algorithms::integrator::Integrator, algorithms::integrator::StepConfig, math::space::Planar, model::data::Data,
    model::Model,
};
use nalgebra::{Vector3, Vector6};

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Set on the thread that runs the measured code. Counting every thread's allocations made this test
    /// flaky: libtest's main thread inserts the running test into a HashMap (and allocates) after spawning
    /// the test's thread, racing with the first measurement (captured backtrace; about half the runs on a
    /// loaded two-core machine). The hot paths spawn no threads, and a spawn would itself allocate here.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

fn count() {
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f` on this thread.
fn allocations_during(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.load(Ordering::SeqCst) - before
}

// One test function only: the counter is global, and tests in one binary run on parallel threads.
#[test]
fn hot_paths_allocate_nothing() {
    for name in ["paper-testbed", "chain20_loops5", "serial-arm", "slider-crank"] {
        let scene = builtin::scene(name).unwrap().unwrap();
        let model: Model<Planar> = Model::compile(&scene, name).unwrap();
        let mut data = Data::new(&model);
        let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
        let mut user = OpWrench::<Planar> { op: 0, wrench: Vector3::from(PAPER_WRENCH) };
        let mut contacts = kinloop_linkage::algorithms::contact::PenaltyContacts::new(&model);
        let mut terms = ConfigSpaceTerms::zeros(model.nv(), model.nc(), 3);
        let mut config = ConfigSpaceLocalModel::<Planar>::new(model.nv(), model.nc());
        let mut reduced =
            OpSpaceLocalModel::new(op_space_terms(&data, &user.wrench, LocalModelTerms::full()), OpPose::identity());
        for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
            let cfg = StepConfig { integrator, dt: 1e-3, project: true, implicit_forces: true };
            // Warm up once (nothing should be lazily allocated, but be fair).
            step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
            let n = allocations_during(|| {
                for _ in 0..100 {
                    step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
                    step(&model, &mut data, &mut q, &mut qd, &mut contacts, &cfg).unwrap();
                }
            });
            assert_eq!(n, 0, "{name}: {integrator:?} step allocated {n} times");
        }
        let n = allocations_during(|| {
            forward_dynamics(&model, &mut data, &q, &qd, &mut user).unwrap();
            op_space_inertia(&model, &mut data, 0).unwrap();
            let cd = constraint_directions::<Planar>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD);
            assert!(cd.count >= 1 || model.nc() == 0);
            reduced.terms = op_space_terms(&data, &user.wrench, LocalModelTerms::full());
            terms.fill_from(&model, &mut data, &q, &qd, &user.wrench, LocalModelTerms::full());
            assert!(config.update(&terms, OpPose::of_op(&model, &data, 0)));
            for _ in 0..100 {
                reduced.step(1e-3, &user.wrench);
                config.step(1e-3, &user.wrench);
            }
        });
        assert_eq!(n, 0, "{name}: op space, SVD and local models allocated {n} times");
    }
    ball_joints_allocate_nothing();
}

/// The same with ball joints (nq ≠ nv: the configuration update on the manifold, RKMK, the projection's
/// correction through a displacement): the Delta robot of `tests/scenes`.
fn ball_joints_allocate_nothing() {
    let scene = Scene::from_toml_str(include_str!("../../scenes/delta.toml"), "scenes/delta.toml").unwrap();
    let model: Model<Spatial> = Model::compile(&scene, "delta-ball").unwrap();
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let mut user = OpWrench::<Spatial> { op: 0, wrench: Vector6::new(0.5, -0.2, 1.0, 0.0, 0.0, 0.0) };
    let mut terms = ConfigSpaceTerms::zeros_nq(model.nq(), model.nv(), model.nc(), 6);
    let mut config = ConfigSpaceLocalModel::<Spatial>::with_layout(ConfigLayout::of(&model), model.nc());
    for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
        let cfg = StepConfig { integrator, dt: 1e-3, project: true, implicit_forces: true };
        step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
        let n = allocations_during(|| {
            for _ in 0..100 {
                step(&model, &mut data, &mut q, &mut qd, &mut user, &cfg).unwrap();
            }
        });
        assert_eq!(n, 0, "delta-ball: {integrator:?} step allocated {n} times");
    }
    let n = allocations_during(|| {
        forward_dynamics(&model, &mut data, &q, &qd, &mut user).unwrap();
        op_space_inertia(&model, &mut data, 0).unwrap();
        constraint_directions::<Spatial>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD);
        terms.fill_from(&model, &mut data, &q, &qd, &user.wrench, LocalModelTerms::full());
        assert!(config.update(&terms, OpPose::of_op(&model, &data, 0)));
        for _ in 0..100 {
            config.step(1e-3, &user.wrench);
        }
    });
    assert_eq!(n, 0, "delta-ball: op space, SVD and local model allocated {n} times");
}
