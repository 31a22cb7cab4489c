//! Every shipped scene exports to MJCF that MuJoCo loads closed at qpos0 and simulates (finite after a
//! second of its own steps), and re-imports to the same closed-loop motion: q(t) of the shared joints over
//! 0.3 s of RK4 matches the original scene's, less what the export does not carry (cut springs, dampers and
//! ranges, obstacles, actuator targets, initial velocities). A slider cut's guide body (10⁻⁶ of the mass)
//! is the one difference the encoding adds. Every joint is given an armature first, so the motion shows
//! whether the export carries it.

use crate::common;

use common::*;
use kinloop_linkage::algorithms::integrator::{step, Integrator, StepConfig};
use kinloop_linkage::math::space::SceneKind;
use kinloop_linkage::math::space::{Planar, Space, Spatial};
use kinloop_linkage::model::builtin::{scene, SCENE_FILES};
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::scene::{JointKindSpec, Scene};
use kinloop_linkage::model::JointKind;
use kinloop_linkage::Model;
use kinloop_mjcf::planar::Reduction;
use kinloop_mjcf::{export, import_file};
use nalgebra::DVector;

/// The armature every joint of a shipped scene is given: of the order of its links' inertias about their
/// joints (a tenth of 0.1 kg at 0.1 m), so a dropped armature shows in the motion.
const ARMATURE_KG_M2: f64 = 1e-4;
/// The same for prismatic joints (a tenth of a 0.1 kg slider).
const ARMATURE_KG: f64 = 1e-2;

/// The scene less what the export drops.
fn carried(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    s.obstacles.clear();
    for c in &mut s.cuts {
        c.spring = None;
        c.damping = 0.0;
        c.range = None;
    }
    for j in &mut s.joints {
        j.qd0 = 0.0;
        if let Some(a) = &mut j.actuator {
            a.target = 0.0;
        }
    }
    s
}

/// q of each named joint (a ball's four quaternion entries, a universal's two angles) after each step.
fn motion<S: Space>(scene: &Scene, file: &str, steps: usize) -> Vec<Vec<(String, Vec<f64>)>> {
    let model = Model::<S>::compile(scene, file).unwrap_or_else(|e| panic!("{e}"));
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let cfg = StepConfig { integrator: Integrator::Rk4, dt: 1e-3, project: true, implicit_forces: false };
    let named = |q: &DVector<f64>| {
        let mut out: Vec<(String, Vec<f64>)> = Vec::new();
        for j in &model.joints {
            let width = if matches!(j.kind, JointKind::Ball { .. }) { 4 } else { 1 };
            let values = q.as_slice()[j.q_index..j.q_index + width].to_vec();
            match out.iter_mut().find(|(n, _)| *n == j.name) {
                Some((_, v)) if width == 1 => v.extend(values),
                Some(_) => {}
                None => out.push((j.name.clone(), values)),
            }
        }
        out
    };
    let mut trace = vec![named(&q)];
    for _ in 0..steps {
        step(&model, &mut data, &mut q, &mut qd, &mut (), &cfg).unwrap_or_else(|e| panic!("{file}: {e}"));
        trace.push(named(&q));
    }
    trace
}

#[test]
fn shipped_scenes_export_load_in_mujoco_and_reimport_to_the_same_motion() {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for (name, _) in SCENE_FILES {
        let mut original = scene(name).unwrap().unwrap();
        for j in &mut original.joints {
            j.armature = if j.kind == JointKindSpec::Prismatic { ARMATURE_KG } else { ARMATURE_KG_M2 };
        }
        let export = export(&original, name).unwrap_or_else(|e| panic!("{name}: {e}"));
        let path = dir.path().join(format!("{name}.xml"));
        std::fs::write(&path, &export.xml).unwrap();
        files.push((name, original, path));
    }
    let checks: Vec<Check> = files
        .iter()
        .map(|(_, _, path)| Check { model: path.clone(), qpos: vec![], qvel: vec![], steps: 1000 })
        .collect();
    let terms = mujoco_terms(&checks);
    println!("| scene | MuJoCo closure at qpos0 | max |Δq| over 0.3 s |");
    for ((name, original, path), mj) in files.iter().zip(&terms) {
        let closure = mj["closure"].as_f64().unwrap();
        assert!(closure < 1e-9, "{name}: MuJoCo finds the exported loops open by {closure:e} at qpos0");
        assert_eq!(mj["stepped_finite"].as_bool(), Some(true), "{name}: MuJoCo's simulation went non-finite");
        let import = import_file(path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let steps = 300;
        // A planar scene exported re-imports as planar (its hinges along +z keep their sign); a spatial one
        // stays spatial.
        let mut theirs = match import.scene.kind {
            SceneKind::Planar => motion::<Planar>(&import.scene, name, steps),
            SceneKind::Spatial => motion::<Spatial>(&import.scene, name, steps),
        };
        assert_eq!(import.scene.kind, original.kind, "{name}: {}", import.reduction.describe());
        if let Reduction::Planar(r) = &import.reduction {
            for (joint, sign) in import.scene.joints.iter().zip(&r.signs) {
                for (n, q) in theirs.iter_mut().flatten() {
                    if *n == joint.name {
                        q.iter_mut().for_each(|x| *x *= sign);
                    }
                }
            }
        }
        let carried = carried(original);
        let ours = match original.kind {
            SceneKind::Planar => motion::<Planar>(&carried, name, steps),
            SceneKind::Spatial => motion::<Spatial>(&carried, name, steps),
        };
        let mut worst = 0.0f64;
        for (a, b) in ours.iter().zip(&theirs) {
            for (joint, qa) in a {
                let (_, qb) =
                    b.iter().find(|(n, _)| n == joint).unwrap_or_else(|| panic!("{name}: joint {joint} lost"));
                worst = qa.iter().zip(qb).fold(worst, |w, (x, y)| w.max((x - y).abs()));
            }
        }
        println!("| {name} | {closure:.1e} | {worst:.1e} |");
        assert!(worst < 1e-6, "{name}: the re-imported motion departs by {worst:e}");
    }
}
