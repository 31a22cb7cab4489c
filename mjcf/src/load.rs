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
    let (scene, label, warning) = load_with_warning(arg)?;
    if let Some(message) = warning {
        tracing::warn!("{message}");
    }
    Ok((scene, label))
}

/// As [`load`], handing the MJCF model's one warning to the caller (a command line prints it).
pub fn load_with_warning(arg: &str) -> Result<(Scene, String, Option<String>), LoadError> {
    if is_mjcf(arg) {
        let import = import_file(std::path::Path::new(arg))?;
        return Ok((import.scene, arg.to_string(), import.warnings.message(arg)));
    }
    let (scene, label) = builtin::load(arg)?;
    Ok((scene, label, None))
}
