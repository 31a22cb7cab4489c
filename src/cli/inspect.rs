//! `kinloop inspect`: everything the linkage core knows at one configuration.

use anyhow::{bail, ensure, Context, Result};
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::configuration;
use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::idle_freedoms::idle_freedoms;
use kinloop_linkage::algorithms::op_space::{op_space_inertia, open_inverse_inertia};
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::dynamics::OpWrench, math::space::MatOps, math::space::Planar,
    math::space::SceneKind, math::space::Space, math::space::Spatial, math::space::VecOps, model::data::Data,
    model::Model,
};
use nalgebra::DVector;
use serde_json::json;

use crate::scene_arg::{load_scene, parse_numbers};

/// Arguments of `kinloop inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Scene file or built-in scene name.
    pub scene: String,
    /// Operational point (default: the scene's first).
    #[arg(long)]
    pub op: Option<String>,
    /// Configuration q (comma-separated; default the scene's q0).
    #[arg(long, allow_hyphen_values = true)]
    pub q: Option<String>,
    /// Velocity q̇ (comma-separated; default zero).
    #[arg(long, allow_hyphen_values = true)]
    pub qd: Option<String>,
    /// Wrench at the OP, world axes (planar fx,fy,tz; spatial fx,fy,fz,tx,ty,tz; default zero).
    #[arg(long, allow_hyphen_values = true)]
    pub wrench: Option<String>,
    /// Solve q to the nearest closed configuration first (Newton steps).
    #[arg(long)]
    pub assemble: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Runs `kinloop inspect`.
pub fn run(args: &InspectArgs) -> Result<()> {
    let loaded = load_scene(&args.scene)?;
    let mut report = match loaded.scene.kind {
        SceneKind::Planar => inspect::<Planar>(args, &loaded.scene, &loaded.label)?,
        SceneKind::Spatial => inspect::<Spatial>(args, &loaded.scene, &loaded.label)?,
    };
    // An MJCF model says what its import reduced (or why it stayed spatial).
    report["import"] = json!(loaded.reduction);
    if args.json {
        println!("{report}");
    } else {
        print_human(&report);
    }
    Ok(())
}

/// Resolves `--op` (or the first OP) to an index.
pub fn op_index<S: Space>(model: &Model<S>, op: Option<&str>) -> Result<usize> {
    match op {
        Some(name) => model.op_index(name).with_context(|| {
            let names: Vec<&str> = model.ops.iter().map(|o| o.name.as_str()).collect();
            format!("--op: no operational point '{name}' (the scene has: {})", names.join(", "))
        }),
        None if model.ops.is_empty() => bail!("the scene defines no operational point ([[op]])"),
        None => Ok(0),
    }
}

/// Parses `--wrench` into an operational vector.
pub fn parse_wrench<S: Space>(text: Option<&str>) -> Result<S::OpVec> {
    let mut w = S::OpVec::zero();
    if let Some(text) = text {
        let v = parse_numbers("--wrench", text)?;
        ensure!(v.len() == S::DIM, "--wrench: expected {} numbers for a {:?} scene, got {}", S::DIM, S::KIND, v.len());
        w.as_mut_slice().copy_from_slice(&v);
    }
    Ok(w)
}

fn vector(flag: &str, text: Option<&str>, n: usize, default: &DVector<f64>) -> Result<DVector<f64>> {
    match text {
        None => Ok(default.clone()),
        Some(t) => {
            let v = parse_numbers(flag, t)?;
            ensure!(
                v.len() == n,
                "{flag}: expected {n} numbers (one per coordinate; a ball joint has 4 positions, 3 rates), got {}",
                v.len()
            );
            Ok(DVector::from_vec(v))
        }
    }
}

fn rows<M: MatOps>(m: &M) -> Vec<Vec<f64>> {
    (0..M::DIM).map(|r| (0..M::DIM).map(|c| m[(r, c)]).collect()).collect()
}

fn inspect<S: Space>(
    args: &InspectArgs,
    scene: &kinloop_linkage::model::scene::Scene,
    label: &str,
) -> Result<serde_json::Value> {
    let model: Model<S> =
        if args.assemble { Model::compile_unclosed(scene, label)? } else { Model::compile(scene, label)? };
    let (n, nq) = (model.nv(), model.nq());
    let mut q = vector("--q", args.q.as_deref(), nq, &model.q0)?;
    if let Err(problem) = configuration::check(&model, q.as_slice()) {
        bail!("--q: {problem}");
    }
    let qd = vector("--qd", args.qd.as_deref(), n, &DVector::zeros(n))?;
    let op = op_index(&model, args.op.as_deref())?;
    let mut assembly = serde_json::Value::Null;
    if args.assemble {
        let a = assemble(&model, &q, 1e-12 * model.length_scale)?;
        assembly = json!({ "initial_residual": a.initial_residual, "residual": a.residual, "iterations": a.iterations, "q": a.q.as_slice() });
        q = a.q;
    }
    let mut user = OpWrench::<S> { op, wrench: parse_wrench::<S>(args.wrench.as_deref())? };
    let mut data = Data::new(&model);
    forward_dynamics(&model, &mut data, &q, &qd, &mut user)?;
    op_space_inertia(&model, &mut data, op)?;
    let cd = constraint_directions::<S>(&data.op.inverse_inertia, model.length_scale, DEFAULT_THRESHOLD);
    let idle: Vec<serde_json::Value> = idle_freedoms(&model, &q)
        .iter()
        .map(|f| json!({ "body": model.bodies[f.body].name, "axis": f.axis.as_slice(), "through": f.point.as_slice() }))
        .collect();
    Ok(json!({
        "scene": model.name,
        "kind": S::KIND,
        "n": n,
        "nq": nq,
        "m": model.nc(),
        "closure_rank": model.closure_rank,
        "dof": n - model.closure_rank,
        "idle_freedoms": idle,
        "op": model.ops[op].name,
        "length_scale": model.length_scale,
        "q": q.as_slice(),
        "closure_residual": data.closure_residual.norm(),
        "qdd": data.qdd.as_slice(),
        "lambda": data.lambda.as_slice(),
        "inverse_inertia": rows(&data.op.inverse_inertia),
        "inverse_inertia_open": rows(&open_inverse_inertia(&model, &data)),
        "singular_values": cd.singular_values.as_slice(),
        "directions": rows(&cd.directions),
        "constraint_count": cd.count,
        "constraint_threshold": DEFAULT_THRESHOLD,
        "assembly": assembly,
    }))
}

fn print_human(r: &serde_json::Value) {
    let fmt_row = |v: &serde_json::Value| {
        v.as_array()
            .map(|a| {
                a.iter().map(|x| format!("{:>12.5e}", x.as_f64().unwrap_or(f64::NAN))).collect::<Vec<_>>().join(" ")
            })
            .unwrap_or_default()
    };
    let text = |v: &serde_json::Value| v.as_str().unwrap_or("").to_string();
    let idle = r["idle_freedoms"].as_array().cloned().unwrap_or_default();
    let nq = if r["nq"] == r["n"] { String::new() } else { format!(" (nq = {})", r["nq"]) };
    let idle_count = if idle.is_empty() { String::new() } else { format!(", {} of them idle", idle.len()) };
    println!(
        "scene {} ({}), n = {}{nq}, m = {} (rank {}), {} DOF{idle_count}; OP '{}'",
        text(&r["scene"]),
        text(&r["kind"]),
        r["n"],
        r["m"],
        r["closure_rank"],
        r["dof"],
        text(&r["op"])
    );
    if let Some(reduction) = r["import"].as_str() {
        println!("MJCF import: {reduction}");
    }
    for f in &idle {
        println!(
            "idle freedom: body '{}' spins about [{}] through [{}], moving nothing else (kept in the model, with the body's own inertia about it)",
            text(&f["body"]),
            fmt_row(&f["axis"]).trim(),
            fmt_row(&f["through"]).trim()
        );
    }
    if !r["assembly"].is_null() {
        println!(
            "assembled in {} Newton steps: residual {} -> {}",
            r["assembly"]["iterations"], r["assembly"]["initial_residual"], r["assembly"]["residual"]
        );
    }
    println!("q                {}", fmt_row(&r["q"]));
    println!("closure residual {:.3e}", r["closure_residual"].as_f64().unwrap_or(f64::NAN));
    println!("q̈                {}", fmt_row(&r["qdd"]));
    println!("λ                {}", fmt_row(&r["lambda"]));
    println!("Λ⁻¹ (loops closed):");
    for row in r["inverse_inertia"].as_array().into_iter().flatten() {
        println!("  {}", fmt_row(row));
    }
    println!("Λ⁻¹ (loops open):");
    for row in r["inverse_inertia_open"].as_array().into_iter().flatten() {
        println!("  {}", fmt_row(row));
    }
    println!(
        "singular values  {}   (scaled, L = {:.4} in the scene's length unit)",
        fmt_row(&r["singular_values"]),
        r["length_scale"].as_f64().unwrap_or(0.0)
    );
    println!("directions (columns, (v, L ω)):");
    for row in r["directions"].as_array().into_iter().flatten() {
        println!("  {}", fmt_row(row));
    }
    println!("constraints on the OP: {}", r["constraint_count"]);
}
