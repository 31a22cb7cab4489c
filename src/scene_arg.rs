//! Reading the SCENE argument of the CLI: a file path, or the name of a built-in scene
//! (`paper-testbed`, `chain50_loops5`, ...).

use std::path::Path;

use anyhow::{Context, Result};
use kinloop_linkage::{builtin, Scene};

/// A scene and the label its errors should carry.
pub struct LoadedScene {
    /// The parsed scene.
    pub scene: Scene,
    /// The file it came from, or `builtin:NAME`.
    pub label: String,
}

/// Loads `arg` as a file if it exists (or looks like a path), else as a built-in scene name.
pub fn load_scene(arg: &str) -> Result<LoadedScene> {
    let path = Path::new(arg);
    if path.exists() || arg.ends_with(".toml") || arg.contains('/') {
        let scene = Scene::from_file(path)?;
        return Ok(LoadedScene { scene, label: arg.to_string() });
    }
    let scene = builtin::scene(arg)
        .with_context(|| {
            let names: Vec<&str> = builtin::SCENE_FILES.iter().map(|(n, _)| *n).collect();
            format!(
                "no scene file '{arg}' and no built-in scene of that name (built in: {}, chainN_loopsL)",
                names.join(", ")
            )
        })?
        .with_context(|| format!("built-in scene {arg}"))?;
    Ok(LoadedScene { scene, label: format!("builtin:{arg}") })
}

/// Parses a comma-separated list of numbers (`--q 0.1,0.2`), naming the flag in errors.
pub fn parse_numbers(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .map(|s| {
            let v: f64 = s.trim().parse().with_context(|| format!("{flag}: '{s}' is not a number"))?;
            anyhow::ensure!(v.is_finite(), "{flag}: '{s}' is not finite");
            Ok(v)
        })
        .collect()
}
