//! Malformed scenes never panic: every built-in scene file, mutated a thousand ways (numbers swapped for NaN,
//! infinities, zero, negatives, huge and tiny values; lines deleted or doubled; names swapped; vectors cut
//! short or lengthened), is either rejected with an error naming the file, or compiles into a model whose
//! dynamics, steps, operational-space inertia and assembly return typed errors or finite numbers, and a step
//! that fails leaves the state as it was.

use crate::common;

use std::panic::{catch_unwind, AssertUnwindSafe};

use common::Rng;
use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::model::builtin::SCENE_FILES;
use kinloop_linkage::{
    algorithms::dynamics::forward_dynamics, algorithms::integrator::step, algorithms::integrator::Integrator,
    algorithms::integrator::StepConfig, math::space::MatOps, math::space::Planar, math::space::Space,
    math::space::Spatial, model::data::Data, model::scene::Scene, model::Model,
};
use nalgebra::DVector;

const FILE: &str = "mutant.toml";
const MUTANTS_PER_SCENE: usize = 1000;
const ODD_NUMBERS: &[&str] =
    &["nan", "inf", "-inf", "0.0", "-0.0", "-1.0", "1e308", "1e-308", "1e20", "1e-20", "3", "-5", "99999999999", "0.5"];

/// What became of one mutant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Outcome {
    NotParsed,
    NotCompiled,
    Simulated,
}

/// The byte ranges of the number literals on a line.
fn numbers(line: &str) -> Vec<(usize, usize)> {
    let b = line.as_bytes();
    let mut out = vec![];
    let mut k = 0;
    while k < b.len() {
        let starts = b[k].is_ascii_digit() || (b[k] == b'-' && b.get(k + 1).is_some_and(u8::is_ascii_digit));
        if starts {
            let start = k;
            k += 1;
            while k < b.len() && (b[k].is_ascii_digit() || matches!(b[k], b'.' | b'e' | b'-')) {
                k += 1;
            }
            out.push((start, k));
        } else {
            k += 1;
        }
    }
    out
}

/// One to three random edits of `text`.
fn mutate(text: &str, rng: &mut Rng) -> String {
    let names: Vec<&str> = text.split('"').skip(1).step_by(2).collect();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for _ in 0..1 + rng.below(3) {
        let i = rng.below(lines.len());
        let line = lines[i].clone();
        match rng.below(6) {
            0 => drop(lines.remove(i)),
            1 => lines.insert(i, line),
            2 | 3 => {
                let spans = numbers(&line);
                if !spans.is_empty() {
                    let (start, end) = spans[rng.below(spans.len())];
                    let odd = ODD_NUMBERS[rng.below(ODD_NUMBERS.len())];
                    lines[i] = format!("{}{odd}{}", &line[..start], &line[end..]);
                }
            }
            4 => {
                if let (Some(name), false) = (line.split('"').nth(1), names.is_empty()) {
                    lines[i] = line.replacen(name, names[rng.below(names.len())], 1);
                }
            }
            _ => {
                // A vector one element shorter (from its second element to the bracket) or longer.
                if let Some(comma) = line.find(", ") {
                    let close = line[comma..].find(']').map_or(line.len(), |x| comma + x);
                    lines[i] = if rng.below(2) == 0 {
                        format!("{}{}", &line[..comma], &line[close..])
                    } else {
                        format!("{}, 0.1{}", &line[..comma], &line[comma..])
                    };
                }
            }
        }
    }
    lines.join("\n")
}

/// Steps, inertias and assembly of a compiled mutant: each returns a typed error or finite numbers.
fn exercise<S: Space>(model: &Model<S>) -> Result<(), String> {
    let mut data = Data::new(model);
    let (mut q, mut qd) = (model.q0.clone(), DVector::zeros(model.nv()));
    if forward_dynamics(model, &mut data, &q, &qd, &mut ()).is_ok() && !data.qdd.iter().all(|x| x.is_finite()) {
        return Err(format!("forward dynamics returned Ok with q̈ = {}", data.qdd));
    }
    for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
        let cfg = StepConfig { integrator, ..StepConfig::euler(1e-3) };
        for k in 0..20 {
            let before = (q.clone(), qd.clone());
            if let Err(e) = step(model, &mut data, &mut q, &mut qd, &mut (), &cfg) {
                if (&q, &qd) != (&before.0, &before.1) {
                    return Err(format!("{integrator:?} step {k} failed ({e}) and changed the state"));
                }
                break;
            }
        }
    }
    for op in 0..model.ops.len() {
        if op_space_inertia(model, &mut data, op).is_ok() && !MatOps::is_finite(&data.op.inverse_inertia) {
            return Err(format!("Λ⁻¹ at op {op} returned Ok and is not finite"));
        }
    }
    if let Ok(assembly) = assemble(model, &model.q0, 1e-10) {
        if !assembly.q.iter().all(|x| x.is_finite()) {
            return Err("assembly returned Ok with a non-finite q".into());
        }
    }
    Ok(())
}

fn try_mutant(text: &str) -> Result<Outcome, String> {
    let named = |e: &dyn std::fmt::Display| {
        let message = e.to_string();
        if message.contains(FILE) {
            Ok(())
        } else {
            Err(format!("error without the file's name: {message}"))
        }
    };
    let scene = match Scene::from_toml_str(text, FILE) {
        Ok(scene) => scene,
        Err(e) => return named(&e).map(|()| Outcome::NotParsed),
    };
    fn compiled<S: Space>(scene: &Scene) -> Result<Result<Model<S>, String>, String> {
        Ok(Model::<S>::compile(scene, FILE).map_err(|e| e.to_string()))
    }
    let spatial = text.contains("kind = \"spatial\"");
    let result = if spatial {
        compiled::<Spatial>(&scene)?.map(|m| exercise(&m))
    } else {
        compiled::<Planar>(&scene)?.map(|m| exercise(&m))
    };
    match result {
        Ok(exercised) => exercised.map(|()| Outcome::Simulated),
        Err(message) => named(&message).map(|()| Outcome::NotCompiled),
    }
}

#[test]
fn mutated_scenes_are_rejected_by_name_or_simulate_without_panicking() {
    let mut rng = Rng(0x5EED_5CE4E);
    for (name, text) in SCENE_FILES {
        let mut counts = std::collections::BTreeMap::new();
        for _ in 0..MUTANTS_PER_SCENE {
            let mutant = mutate(text, &mut rng);
            let outcome = catch_unwind(AssertUnwindSafe(|| try_mutant(&mutant)))
                .unwrap_or_else(|_| panic!("{name}: panicked on the mutant\n{mutant}"))
                .unwrap_or_else(|why| panic!("{name}: {why}, on the mutant\n{mutant}"));
            *counts.entry(outcome).or_insert(0) += 1;
        }
        // Every path was taken: the mutations neither all break the syntax nor all leave the scene valid.
        for outcome in [Outcome::NotParsed, Outcome::NotCompiled, Outcome::Simulated] {
            assert!(counts.get(&outcome).copied().unwrap_or(0) >= MUTANTS_PER_SCENE / 20, "{name}: {counts:?}");
        }
    }
}
