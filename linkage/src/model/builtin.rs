//! Scenes that ship with kinloop (the files in `scenes/`, compiled in) and the generated benchmark chains
//! `chainN_loopsL`.

use crate::error::SceneError;
use crate::math::space::SceneKind;
use crate::model::scene::{
    BodySpec, CutKindSpec, CutSpec, GeometrySpec, JointKindSpec, JointSpec, Numbers, OpSpec, Scene,
};

/// The scene files in `scenes/`, by name.
pub const SCENE_FILES: &[(&str, &str)] = &[
    ("paper-testbed", include_str!("../../../scenes/paper-testbed.toml")),
    ("fourbar-crank-rocker", include_str!("../../../scenes/fourbar-crank-rocker.toml")),
    ("slider-crank", include_str!("../../../scenes/slider-crank.toml")),
    ("watt-six-bar", include_str!("../../../scenes/watt-six-bar.toml")),
    ("parallelogram", include_str!("../../../scenes/parallelogram.toml")),
    ("serial-arm", include_str!("../../../scenes/serial-arm.toml")),
    ("spherical-four-bar", include_str!("../../../scenes/spherical-four-bar.toml")),
    ("stephenson-six-bar", include_str!("../../../scenes/stephenson-six-bar.toml")),
    ("five-bar-robot", include_str!("../../../scenes/five-bar-robot.toml")),
    ("bennett-linkage", include_str!("../../../scenes/bennett-linkage.toml")),
    ("rssr-four-bar", include_str!("../../../scenes/rssr-four-bar.toml")),
    ("guided-slider-crank", include_str!("../../../scenes/guided-slider-crank.toml")),
    ("delta", include_str!("../../../scenes/delta.toml")),
];

/// The paper's user wrench on the testbed: (−0.5 N, 0 N, −0.0025 N m) at the COM of link 2.
pub const PAPER_WRENCH: [f64; 3] = [-0.5, 0.0, -0.0025];

/// A built-in scene by name: one of [`SCENE_FILES`] or `chainN_loopsL` (see [`chain`]).
pub fn scene(name: &str) -> Option<Result<Scene, SceneError>> {
    if let Some((_, text)) = SCENE_FILES.iter().find(|(n, _)| *n == name) {
        return Some(Scene::from_toml_str(text, &format!("scenes/{name}.toml")));
    }
    parse_chain_name(name).map(|(n, l)| Ok(chain(n, l)))
}

/// A scene named on a command line: a file when `arg` exists or looks like a path (ends in `.toml` or
/// holds a `/`), else a built-in scene by name. Returns the scene and the label its messages carry: the
/// path, or `builtin:NAME`. One rule for every command (`kinloop`, `kinloop-server`), so a name means the
/// same thing everywhere.
pub fn load(arg: &str) -> Result<(Scene, String), SceneError> {
    let path = std::path::Path::new(arg);
    if path.exists() || arg.ends_with(".toml") || arg.contains('/') {
        return Ok((Scene::from_file(path)?, arg.to_string()));
    }
    match scene(arg) {
        Some(scene) => Ok((scene?, format!("builtin:{arg}"))),
        None => {
            let names: Vec<&str> = SCENE_FILES.iter().map(|(n, _)| *n).collect();
            Err(SceneError::Io {
                file: arg.to_string(),
                message: format!(
                    "no such file, and no built-in scene of that name (built in: {}, chainN_loopsL)",
                    names.join(", ")
                ),
            })
        }
    }
}

/// Parses `chainN_loopsL` into `(N, L)`.
pub fn parse_chain_name(name: &str) -> Option<(usize, usize)> {
    let rest = name.strip_prefix("chain")?;
    let (n, l) = rest.split_once("_loops")?;
    let (n, l) = (n.parse().ok()?, l.parse().ok()?);
    ((2..=1000).contains(&n) && l <= n).then_some((n, l))
}

/// The benchmark chain `chainN_loopsL`: planar, no gravity, N links of length 0.05 m, mass 1 kg, inertia
/// 0.0021 kg m², COM at midpoints; q0[0] = 0.3, then 0.6 for even and −0.9 for odd joint indices; for
/// j = 1..L the tip of link k = N·j/L (1-based) is pinned to ground where it lies at q0. Operational point
/// `link2` at the COM of link 2 (where the testbed wrench acts).
pub fn chain(links: usize, loops: usize) -> Scene {
    const LENGTH: f64 = 0.05;
    let name = |i: usize| format!("link{}", i + 1);
    let bodies = (0..links)
        .map(|i| BodySpec {
            name: name(i),
            mass: 1.0,
            com: vec![LENGTH / 2.0, 0.0],
            inertia: Numbers::One(0.0021),
            geometry: vec![GeometrySpec::Capsule { from: vec![0.0, 0.0], to: vec![LENGTH, 0.0], radius: 0.003 }],
        })
        .collect();
    let joints = (0..links)
        .map(|i| JointSpec {
            name: format!("j{}", i + 1),
            kind: JointKindSpec::Revolute,
            parent: if i == 0 { "ground".into() } else { name(i - 1) },
            child: name(i),
            origin: if i == 0 { vec![0.0, 0.0] } else { vec![LENGTH, 0.0] },
            rotation: None,
            axis: None,
            axes: None,
            q0: if i == 0 {
                0.3
            } else if i % 2 == 0 {
                0.6
            } else {
                -0.9
            },
            qd0: 0.0,
            spring: None,
            damping: 0.0,
            armature: 0.0,
            actuator: None,
            range: None,
        })
        .collect();
    let cuts = (1..=loops)
        .map(|j| {
            let k = links * j / loops;
            CutSpec::between(format!("pin{j}"), CutKindSpec::Pin, name(k - 1), vec![LENGTH, 0.0], "ground".into())
        })
        .collect();
    Scene {
        name: format!("chain{links}_loops{loops}"),
        kind: SceneKind::Planar,
        gravity: vec![0.0, 0.0],
        length_scale: None,
        baumgarte: Default::default(),
        contact: Default::default(),
        closure_tolerance: None,
        bodies,
        joints,
        cuts,
        ops: vec![OpSpec { name: "link2".into(), body: name(1.min(links - 1)), point: vec![LENGTH / 2.0, 0.0] }],
        obstacles: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_scene_parses() {
        for (name, _) in SCENE_FILES {
            scene(name).expect("listed").unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }

    #[test]
    fn chain_names_parse_and_reject_nonsense() {
        assert_eq!(parse_chain_name("chain50_loops5"), Some((50, 5)));
        assert_eq!(parse_chain_name("chain4_loops0"), Some((4, 0)));
        assert_eq!(parse_chain_name("chain3_loops4"), None);
        assert_eq!(parse_chain_name("chainx_loops1"), None);
        assert_eq!(parse_chain_name("chain1_loops0"), None);
    }

    /// A command-line scene argument: built-in names and chains by name, paths as files (even missing
    /// ones, whose error names the path), and an unknown name gets the list of what is built in.
    #[test]
    fn scene_arguments_resolve_to_files_or_builtins() {
        let (scene, label) = load("paper-testbed").unwrap();
        assert_eq!((scene.name.as_str(), label.as_str()), ("paper-testbed", "builtin:paper-testbed"));
        assert_eq!(load("chain6_loops2").unwrap().1, "builtin:chain6_loops2");
        let file = format!("{}/../scenes/slider-crank.toml", env!("CARGO_MANIFEST_DIR"));
        assert_eq!(load(&file).unwrap(), (scene_named("slider-crank", &file), file.clone()));
        for missing in ["no/such/dir/x.toml", "nothing.toml"] {
            let message = load(missing).unwrap_err().to_string();
            assert!(message.starts_with(missing) && message.contains("cannot read"), "{message}");
        }
        let message = load("paper-tesbed").unwrap_err().to_string();
        assert!(message.contains("paper-tesbed") && message.contains("paper-testbed, fourbar"), "{message}");
    }

    /// The built-in scene `name` as parsed from `file` (the label in its errors is the only difference).
    fn scene_named(name: &str, file: &str) -> Scene {
        let text = SCENE_FILES.iter().find(|(n, _)| *n == name).unwrap().1;
        Scene::from_toml_str(text, file).unwrap()
    }
}
