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

/// Loads `arg`: returns the scene and the label its messages carry (the path, or `builtin:NAME`).
pub fn load(arg: &str) -> Result<(Scene, String), LoadError> {
    if is_mjcf(arg) {
        let import = import_file(std::path::Path::new(arg))?;
        if let Some(message) = import.warnings.message(arg) {
            tracing::warn!("{message}");
        }
        return Ok((import.scene, arg.to_string()));
    }
    Ok(builtin::load(arg)?)
}
