//! The one reader of a command line's scene argument, used by `kinloop` (demo, inspect, simulate, view) and
//! `kinloop-server`: a path ending in `.xml` is an MJCF model, imported (its warning logged once); anything
//! else is a TOML file or a built-in scene name ([`builtin::load`]).

use kinloop_linkage::model::builtin;
use kinloop_linkage::model::scene::Scene;
use thiserror::Error;

use crate::error::MjcfError;
use crate::import::import_file;

/// A scene argument that could not be loaded.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum LoadError {
    /// A TOML scene or a built-in name.
    #[error(transparent)]
    Scene(#[from] kinloop_linkage::error::SceneError),
    /// An MJCF model.
    #[error(transparent)]
    Mjcf(#[from] MjcfError),
}

/// True when `arg` names an MJCF model.
pub fn is_mjcf(arg: &str) -> bool {
    arg.to_ascii_lowercase().ends_with(".xml")
}

/// Loads `arg`: returns the scene and the label its messages carry (the path, or `builtin:NAME`); an MJCF
/// model's warning (what it holds that kinloop cannot use) goes to the log.
pub fn load(arg: &str) -> Result<(Scene, String), LoadError> {
    let loaded = load_with_warning(arg)?;
    if let Some(message) = loaded.warning {
        tracing::warn!("{message}");
    }
    Ok((loaded.scene, loaded.label))
}

/// A scene argument as loaded, with what an MJCF model's import has to say.
#[derive(Clone, Debug, PartialEq)]
pub struct Loaded {
    /// The scene.
    pub scene: Scene,
    /// The label its messages carry (the path, or `builtin:NAME`).
    pub label: String,
    /// An MJCF model's one warning (what it holds that kinloop cannot use).
    pub warning: Option<String>,
    /// An MJCF model's reduction: what was reduced to a planar scene, or why the scene stayed spatial.
    pub reduction: Option<String>,
}

/// As [`load`], handing the MJCF model's warning and reduction to the caller (a command line prints them).
pub fn load_with_warning(arg: &str) -> Result<Loaded, LoadError> {
    if is_mjcf(arg) {
        let import = import_file(std::path::Path::new(arg))?;
        return Ok(Loaded {
            warning: import.warnings.message(arg),
            reduction: Some(import.reduction.describe()),
            scene: import.scene,
            label: arg.to_string(),
        });
    }
    let (scene, label) = builtin::load(arg)?;
    Ok(Loaded { scene, label, warning: None, reduction: None })
}
