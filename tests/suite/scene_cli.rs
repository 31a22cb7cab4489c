//! `kinloop simulate` applies a scene's obstacles as the VE does, a kinloop program whose stdout is closed
//! early (`kinloop inspect … | head`) ends quietly with success, and an MJCF model is a scene argument like a
//! scene file (`kinloop import` writes the same scene, and `inspect` says what its import reduced), through real
//! processes.

use std::process::{Command, Stdio};

fn kinloop(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kinloop")).args(args).output().expect("kinloop runs")
}

/// `kinloop simulate FILE --json`'s final q.
fn simulated_q(scene: &std::path::Path) -> Vec<f64> {
    let out = kinloop(&["simulate", scene.to_str().unwrap(), "--duration", "1", "--integrator", "rk4", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    report["q"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

/// The slider-crank's slider starts at x = 0.181 m and its spring pulls it toward 0.15 m, so it swings
/// through x < 0.19 m: a wall far away (x = 0.5 m) changes nothing, bit for bit, against no wall at all; the
/// wall moved into the slider's path (x = 0.185 m, the ball of radius 0.01 m already touching it) changes q.
#[test]
fn simulate_applies_the_obstacles() {
    let dir = tempfile::tempdir().unwrap();
    let original = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/slider-crank.toml")).unwrap();
    assert!(original.contains("offset = -0.205"));
    let write = |name: &str, text: String| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let wall_at = |x: f64| original.replace("offset = -0.205", &format!("offset = {}", -x));
    let without = original[..original.find("[[obstacle]]").unwrap()].to_string();
    let far = simulated_q(&write("far.toml", wall_at(0.5)));
    let none = simulated_q(&write("none.toml", without));
    let near = simulated_q(&write("near.toml", wall_at(0.185)));
    assert_eq!(far, none, "a wall out of reach changes nothing");
    let moved = far.iter().zip(&near).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(moved > 1e-3, "the wall in the slider's path must change q: {far:?} vs {near:?}");
}

/// stdout already closed when `kinloop inspect` first prints (its reader gone, as `| head` leaves it): no
/// panic, no message, success.
#[test]
fn a_closed_stdout_ends_the_program_quietly() {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_kinloop"))
        .args(["inspect", "paper-testbed"])
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .expect("kinloop runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit {:?}: {stderr}", out.status);
    assert!(stderr.is_empty(), "nothing on stderr, got: {stderr}");
}

/// `kinloop simulate MODEL.xml` and `kinloop simulate` of the scene `kinloop import MODEL.xml -o` wrote move
/// the same, bit for bit; `kinloop export --mjcf` of that scene writes a model the same reader takes.
#[test]
fn an_mjcf_model_is_a_scene_argument() {
    for model in ["spatial-rssr.xml", "planar-four-bar.xml"] {
        a_model_moves_as_its_import(&format!("{}/mjcf/tests/models/{model}", env!("CARGO_MANIFEST_DIR")));
    }
}

fn a_model_moves_as_its_import(model: &str) {
    let dir = tempfile::tempdir().unwrap();
    let toml = dir.path().join("rssr.toml");
    let out = kinloop(&["import", model, "-o", toml.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let from_model = simulated_q(std::path::Path::new(model));
    assert_eq!(from_model, simulated_q(&toml));
    let xml = dir.path().join("again.xml");
    let out = kinloop(&["export", toml.to_str().unwrap(), "--mjcf", "-o", xml.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let again = simulated_q(&xml);
    let gap = from_model.iter().zip(&again).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(gap < 1e-9, "exported and re-read, q departs by {gap:e}");
}

/// `kinloop inspect MODEL.xml` says what the import reduced: a planar four-bar written with hinges along y is a
/// planar scene with a pin's two equations, the connect's third dropped and named; a spatial loop says why it
/// stayed spatial.
#[test]
fn inspect_says_what_an_mjcf_import_reduced() {
    let models = concat!(env!("CARGO_MANIFEST_DIR"), "/mjcf/tests/models/");
    let out = kinloop(&["inspect", &format!("{models}planar-four-bar.xml"), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["kind"], "planar");
    assert_eq!((report["m"].as_u64(), report["dof"].as_u64()), (Some(2), Some(1)), "a pin's two equations");
    let reduction = report["import"].as_str().unwrap();
    assert!(reduction.starts_with("reduced to a planar scene: hinges along [0.0000, 1.0000, 0.0000]"), "{reduction}");
    assert!(reduction.contains("dropped as redundant: connect 'coupler-rocker': 1 of 3"), "{reduction}");
    let out = kinloop(&["inspect", &format!("{models}spatial-rssr.xml")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().any(|l| l.starts_with("MJCF import: kept spatial: ")), "{text}");
    let out = kinloop(&["inspect", "paper-testbed", "--json"]);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report["import"].is_null(), "a scene file has no import to speak of");
}
