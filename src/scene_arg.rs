//! Reading the SCENE argument of the CLI: an MJCF model (`.xml`), a scene file, or the name of a built-in
//! scene (`paper-testbed`, `chain50_loops5`, ...), through [`kinloop_mjcf::load::load`], the reader the
//! server uses too.

use anyhow::{Context, Result};
use kinloop_linkage::model::scene::Scene;

/// A scene and the label its errors should carry.
pub struct LoadedScene {
    /// The parsed scene.
    pub scene: Scene,
    /// The file it came from, or `builtin:NAME`.
    pub label: String,
    /// An MJCF model's reduction (planar, or why it stayed spatial), for `inspect` to say.
    pub reduction: Option<String>,
}

/// Loads `arg` as an MJCF model, a scene file or a built-in scene name (see [`kinloop_mjcf::load::load`]).
pub fn load_scene(arg: &str) -> Result<LoadedScene> {
    let loaded = kinloop_mjcf::load::load_with_warning(arg)?;
    if let Some(message) = loaded.warning {
        eprintln!("warning: {message}");
    }
    Ok(LoadedScene { scene: loaded.scene, label: loaded.label, reduction: loaded.reduction })
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
