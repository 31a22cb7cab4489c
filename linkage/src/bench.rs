//! Benchmark cases for `kinloop bench` and criterion: each returns the median time per call over several
//! batches, measured in one run (medians resist the noise of a shared machine).

use std::hint::black_box;
use std::time::{Duration, Instant};

use nalgebra::{DVector, Vector3};

use crate::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use crate::algorithms::dynamics::{forward_dynamics, OpWrench};
use crate::algorithms::integrator::{step, Integrator, StepConfig};
use crate::algorithms::local_model::{op_space_terms, LocalModelTerms, OpSpaceLocalModel};
use crate::algorithms::op_space::op_space_inertia;
use crate::math::space::OpPose;
use crate::math::space::Planar;
use crate::math::space::Spatial;
use crate::model::builtin::{self, PAPER_WRENCH};
use crate::model::data::Data;
use crate::model::revolute_built::revolute_built;
use crate::model::scene::Scene;
use crate::Model;

/// Timing of one benchmark case.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Median over batches of the mean time per call, ns.
    pub median_ns: f64,
    /// 10th percentile over batches, ns.
    pub p10_ns: f64,
    /// 90th percentile over batches, ns.
    pub p90_ns: f64,
    /// Calls measured in total.
    pub calls: u64,
}

/// Runs `f` in batches for about `budget` and reports per-call statistics over the batches.
pub fn measure(budget: Duration, mut f: impl FnMut()) -> Timing {
    let batch = |calls: u64| {
        let t = Instant::now();
        for _ in 0..calls {
            f();
        }
        Ok::<_, std::convert::Infallible>(t.elapsed().as_nanos() as f64 / calls as f64)
    };
    match measure_batches(budget, batch) {
        Ok(timing) => timing,
        Err(never) => match never {},
    }
}

/// Like [`measure`] for code that times its own batches (it sets up state it must not count):
/// `batch(calls)` runs `calls` calls and returns the mean ns per call. Batches are calibrated to about
/// 0.5 ms of measured work; the first error stops the measurement.
pub fn measure_batches<E>(budget: Duration, mut batch: impl FnMut(u64) -> Result<f64, E>) -> Result<Timing, E> {
    let mut calls = 1u64;
    while batch(calls)? * (calls as f64) < 500_000.0 && calls <= 1 << 30 {
        calls *= 2;
    }
    let mut samples = Vec::new();
    let start = Instant::now();
    while start.elapsed() < budget || samples.len() < 5 {
        samples.push(batch(calls)?);
    }
    samples.sort_by(|a, b| a.total_cmp(b));
    let at = |q: f64| quantile(&samples, q);
    Ok(Timing { median_ns: at(0.5), p10_ns: at(0.1), p90_ns: at(0.9), calls: calls * samples.len() as u64 })
}

/// The `q`-quantile (0 to 1) of sorted, non-empty `sorted`, by nearest rank.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// A compiled planar benchmark scene with its state and the paper's user wrench.
pub struct Case {
    /// The model.
    pub model: Model<Planar>,
    /// Its workspace.
    pub data: Data<Planar>,
    /// Configuration.
    pub q: DVector<f64>,
    /// Velocity.
    pub qd: DVector<f64>,
    /// The paper's user: a constant wrench at the first OP.
    pub user: OpWrench<Planar>,
    /// The state 0.5 s into the manipulation, where every window of [`WINDOW_STEPS`] steps starts.
    start: (DVector<f64>, DVector<f64>),
    /// Steps taken in the current window.
    steps_in_window: usize,
}

/// Steps of one benchmark window: the paper's 3 s manipulation at 1 kHz. A constant wrench pumps energy into
/// a conservative linkage without bound, so after a minute or two of simulated time the velocities outgrow
/// the 1 ms step and the state diverges; a timing
/// taken there measures failing steps. Rewinding every window keeps every measured step a valid one.
pub const WINDOW_STEPS: usize = 3000;

impl Case {
    /// `paper-testbed` or `chainN_loopsL`, started 0.5 s into the paper's manipulation so it is moving.
    pub fn new(scene: &str) -> Option<Case> {
        let scene = builtin::scene(scene)?.ok()?;
        let model: Model<Planar> = Model::compile(&scene, &scene.name).ok()?;
        let data = Data::new(&model);
        let (q, qd) = (model.q0.clone(), model.qd0.clone());
        let user = OpWrench { op: 0, wrench: Vector3::from(PAPER_WRENCH) };
        let start = (q.clone(), qd.clone());
        let mut case = Case { model, data, q, qd, user, start, steps_in_window: 0 };
        let cfg = StepConfig::euler(1e-3);
        for _ in 0..500 {
            step(&case.model, &mut case.data, &mut case.q, &mut case.qd, &mut case.user, &cfg).ok()?;
        }
        case.start = (case.q.clone(), case.qd.clone());
        Some(case)
    }

    /// One VE step: semi-implicit Euler with projection at 1 kHz. The state keeps moving between calls and
    /// rewinds to the start of the window every [`WINDOW_STEPS`] calls.
    pub fn ve_step(&mut self, integrator: Integrator) {
        if self.steps_in_window == WINDOW_STEPS {
            self.q.copy_from(&self.start.0);
            self.qd.copy_from(&self.start.1);
            self.steps_in_window = 0;
        }
        self.steps_in_window += 1;
        let cfg = StepConfig { integrator, dt: 1e-3, project: true, implicit_forces: true };
        let r = step(&self.model, &mut self.data, &mut self.q, &mut self.qd, &mut self.user, &cfg);
        black_box(r.ok());
    }

    /// Λ⁻¹ at the OP, its SVD and the constraint count (after the dynamics terms and factors of one solve).
    pub fn op_space(&mut self) -> usize {
        let _ = op_space_inertia(&self.model, &mut self.data, 0);
        constraint_directions::<Planar>(&self.data.op.inverse_inertia, self.model.length_scale, DEFAULT_THRESHOLD).count
    }

    /// Prepares the factors `op_space` needs at the current state.
    pub fn prepare_op_space(&mut self) {
        let _ = forward_dynamics(&self.model, &mut self.data, &self.q, &self.qd, &mut self.user);
    }

    /// A reduced local model built from the current state.
    pub fn local_model(&mut self) -> OpSpaceLocalModel<Planar> {
        self.prepare_op_space();
        let _ = op_space_inertia(&self.model, &mut self.data, 0);
        let terms = op_space_terms(&self.data, &self.user.wrench, LocalModelTerms::full());
        OpSpaceLocalModel::new(terms, OpPose::of_op(&self.model, &self.data, 0))
    }
}

/// The paper's wrench as an operational vector.
pub fn paper_wrench() -> Vector3<f64> {
    Vector3::from(PAPER_WRENCH)
}

/// The Delta robot written with ball joints (the linkage tests' scene).
const DELTA_BALL: &str = include_str!("../../scenes/delta.toml");

/// Mass of each gimbal in the Delta's revolute-built version: what a user had to write before ball joints.
pub const DELTA_GIMBAL_MASS: f64 = 0.005;

/// The Delta robot falling under gravity from q0 (damped arms), with ball joints or revolute-built (three
/// revolutes and two 5 g gimbals per ball), for the VE step's cost beside each other.
pub struct DeltaCase {
    /// The model.
    pub model: Model<Spatial>,
    data: Data<Spatial>,
    q: DVector<f64>,
    qd: DVector<f64>,
    steps_in_window: usize,
}

impl DeltaCase {
    /// The ball-jointed Delta, or its revolute-built version.
    pub fn new(balls: bool) -> Option<DeltaCase> {
        let scene = Scene::from_toml_str(DELTA_BALL, "scenes/delta.toml").ok()?;
        let scene = if balls { scene } else { revolute_built(&scene, DELTA_GIMBAL_MASS) };
        let model: Model<Spatial> = Model::compile(&scene, &scene.name).ok()?;
        let data = Data::new(&model);
        let (q, qd) = (model.q0.clone(), model.qd0.clone());
        Some(DeltaCase { model, data, q, qd, steps_in_window: 0 })
    }

    /// One VE step (semi-implicit Euler with projection at 1 kHz); rewinds to q0 every [`WINDOW_STEPS`].
    pub fn ve_step(&mut self) {
        if self.steps_in_window == WINDOW_STEPS {
            self.q.copy_from(&self.model.q0);
            self.qd.copy_from(&self.model.qd0);
            self.steps_in_window = 0;
        }
        self.steps_in_window += 1;
        let cfg = StepConfig::euler(1e-3);
        let r = step(&self.model, &mut self.data, &mut self.q, &mut self.qd, &mut (), &cfg);
        black_box(r.ok());
    }
}
