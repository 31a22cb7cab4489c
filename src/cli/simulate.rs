//! `kinloop simulate`: integrate a scene for a while and report accuracy and cost.

use std::time::Instant;

use anyhow::{ensure, Context, Result};
use kinloop_linkage::algorithms::contact::PenaltyContacts;
use kinloop_linkage::algorithms::dynamics::Forces;
use kinloop_linkage::algorithms::gravity::{kinetic_energy, potential_energy};
use kinloop_linkage::algorithms::kinematics::{forward_kinematics, forward_velocity};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::model::data::Kinematics;
use kinloop_linkage::{
    algorithms::dynamics::OpWrench, algorithms::integrator::step, algorithms::integrator::Integrator,
    algorithms::integrator::StepConfig, math::space::Planar, math::space::SceneKind, math::space::Space,
    math::space::Spatial, math::space::VecOps, model::data::Data, model::Model,
};
use serde_json::json;

use super::inspect::{op_index, parse_wrench};
use crate::scene_arg::load_scene;

/// Arguments of `kinloop simulate`.
#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Scene file or built-in scene name (e.g. paper-testbed, chain50_loops5).
    pub scene: String,
    /// Simulated time, s.
    #[arg(long, default_value_t = 3.0)]
    pub duration: f64,
    /// Time step, s.
    #[arg(long, default_value_t = 1e-3)]
    pub dt: f64,
    /// euler (semi-implicit), explicit-euler or rk4.
    #[arg(long, default_value = "euler")]
    pub integrator: String,
    /// Project q and q̇ onto the constraint manifold after every step.
    #[arg(long)]
    pub project: bool,
    /// Operational point where --wrench acts (default: the scene's first).
    #[arg(long)]
    pub op: Option<String>,
    /// Constant wrench at the OP, world axes (default zero; `paper` for the paper's (−0.5, 0, −0.0025)).
    #[arg(long, allow_hyphen_values = true)]
    pub wrench: Option<String>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Runs `kinloop simulate`.
pub fn run(args: &SimulateArgs) -> Result<()> {
    ensure!(args.dt > 0.0 && args.dt.is_finite() && args.dt <= 1.0, "--dt: must be in (0, 1] s, got {}", args.dt);
    ensure!(args.duration >= 0.0 && args.duration <= 1e5, "--duration: must be in [0, 1e5] s, got {}", args.duration);
    let integrator = Integrator::parse(&args.integrator)
        .with_context(|| format!("--integrator: unknown '{}' (euler, explicit-euler, rk4)", args.integrator))?;
    let loaded = load_scene(&args.scene)?;
    let report = match loaded.scene.kind {
        SceneKind::Planar => simulate::<Planar>(args, integrator, &loaded.scene, &loaded.label)?,
        SceneKind::Spatial => simulate::<Spatial>(args, integrator, &loaded.scene, &loaded.label)?,
    };
    if args.json {
        println!("{report}");
    } else {
        println!(
            "{}: {} steps of {} s with {}{}: max closure error {:.3e} (the scene's length unit), energy error {}, {:.0} \
             ns per step",
            report["scene"].as_str().unwrap_or(""),
            report["steps"],
            args.dt,
            integrator.name(),
            if args.project { " + projection" } else { "" },
            report["max_closure_error"].as_f64().unwrap_or(f64::NAN),
            report["energy_error"].as_f64().map_or("n/a (not conservative)".into(), |e| format!("{e:.3e} (the scene's energy unit)")),
            report["ns_per_step"].as_f64().unwrap_or(f64::NAN),
        );
    }
    Ok(())
}

/// What acts on a simulated scene from outside the linkage: the constant wrench and, when the scene has
/// obstacles, the penalty contacts the VE applies (the same [`PenaltyContacts`], with the scene's
/// `contact` parameters).
struct SceneForces<S: Space> {
    user: OpWrench<S>,
    contacts: Option<PenaltyContacts<S>>,
}

impl<S: Space> Forces<S> for SceneForces<S> {
    fn add_forces(&mut self, model: &Model<S>, kin: &Kinematics<S>, tau: &mut nalgebra::DVector<f64>) {
        self.user.add_forces(model, kin, tau);
        if let Some(contacts) = &mut self.contacts {
            contacts.add_forces(model, kin, tau);
        }
    }
}

fn simulate<S: Space>(
    args: &SimulateArgs,
    integrator: Integrator,
    scene: &kinloop_linkage::model::scene::Scene,
    label: &str,
) -> Result<serde_json::Value> {
    let model: Model<S> = Model::compile(scene, label)?;
    let op = if model.ops.is_empty() && args.wrench.is_none() { 0 } else { op_index(&model, args.op.as_deref())? };
    let wrench = match args.wrench.as_deref() {
        Some("paper") => parse_wrench::<S>(Some("-0.5,0,-0.0025"))?,
        other => parse_wrench::<S>(other)?,
    };
    let mut forces =
        SceneForces::<S> { user: OpWrench { op, wrench }, contacts: PenaltyContacts::of_obstacles(&model) };
    let cfg = StepConfig { integrator, dt: args.dt, project: args.project, implicit_forces: false };
    let steps = (args.duration / args.dt).round() as usize;

    // Pass 1, timed: the steps and nothing else but the closure error each step reports.
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let mut max_closure: f64 = 0.0;
    let start = Instant::now();
    for k in 0..steps {
        let r = step(&model, &mut data, &mut q, &mut qd, &mut forces, &cfg).with_context(|| format!("step {k}"))?;
        max_closure = max_closure.max(r.closure_error);
    }
    let elapsed = start.elapsed();
    forward_kinematics(&model, &mut data, &q);
    kinloop_linkage::algorithms::loop_closure::closure_residual(&model, &mut data);
    max_closure = max_closure.max(data.closure_residual.norm());

    // Pass 2: the same (deterministic) trajectory, checking energy where it is conserved.
    let energy_error = energy_error(&model, &cfg, &mut forces.user, steps)?;
    Ok(json!({
        "scene": model.name,
        "integrator": integrator.name(),
        "dt": args.dt,
        "project": args.project,
        "steps": steps,
        "contacts": !model.obstacles.is_empty(),
        "q": q.as_slice(),
        "qd": qd.as_slice(),
        "max_closure_error": max_closure,
        "energy_error": energy_error,
        "ns_per_step": if steps > 0 { elapsed.as_nanos() as f64 / steps as f64 } else { 0.0 },
    }))
}

/// Largest deviation of `T + V_gravity + V_springs + V_wrench` from its start, where the constant wrench's
/// potential is `-F·p_op - τ·θ_op` (conservative in the plane, or for a pure force in space); `None` when the
/// scene dissipates or drives (damping, actuators, obstacles) or the wrench is not conservative.
fn energy_error<S: Space>(
    model: &Model<S>,
    cfg: &StepConfig,
    user: &mut OpWrench<S>,
    steps: usize,
) -> Result<Option<f64>> {
    let torque = S::op_ang(&user.wrench);
    let conservative = !model.has_joint_forces
        && model.obstacles.is_empty()
        && (S::KIND == SceneKind::Planar || torque.norm() == 0.0)
        && (!model.ops.is_empty() || user.wrench.norm() == 0.0);
    if !conservative {
        return Ok(None);
    }
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let force = S::op_lin(&user.wrench);
    let op = user.op;
    let mut angle = S::Angular::zero();
    let energy = |data: &mut Data<S>, q: &nalgebra::DVector<f64>, qd: &nalgebra::DVector<f64>, angle: &S::Angular| {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, qd);
        let mut e = kinetic_energy(model, data) + potential_energy(model, data, q);
        if !model.ops.is_empty() {
            e -= force.dot(&OpPose::of_op(model, data, op).position) + torque.dot(angle);
        }
        (e, (!model.ops.is_empty()).then(|| OpPose::of_op(model, data, op).rotation))
    };
    let (e0, mut rot) = energy(&mut data, &q, &qd, &angle);
    let mut worst: f64 = 0.0;
    for _ in 0..steps {
        step(model, &mut data, &mut q, &mut qd, user, cfg)?;
        if let Some(prev) = rot {
            forward_kinematics(model, &mut data, &q);
            let now = OpPose::of_op(model, &data, op).rotation;
            // Unwrapped rotation of the OP's body, for the torque's potential.
            angle += S::rot_log(&S::rot_mul(&now, &S::rot_inverse(&prev)));
        }
        let (e, r) = energy(&mut data, &q, &qd, &angle);
        rot = r;
        worst = worst.max((e - e0).abs());
    }
    Ok(Some(worst))
}
