//! `kinloop import MODEL.xml`: an MJCF model as a kinloop scene file (see `docs/mjcf.md`).

use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `kinloop import`.
#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The MuJoCo model (MJCF XML).
    pub model: PathBuf,
    /// Where to write the scene (default: standard output).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
}

/// Runs `kinloop import`: what the model holds that kinloop cannot use is one warning on standard error.
pub fn run(args: &ImportArgs) -> Result<()> {
    let import = kinloop_mjcf::import_file(&args.model)?;
    let label = args.model.display().to_string();
    if let Some(message) = import.warnings.message(&label) {
        eprintln!("warning: {message}");
    }
    let reduction = import.reduction.describe();
    eprintln!("{label}: {reduction}");
    let text = format!("# Imported by `kinloop import` from {label}: {reduction}.\n{}", import.scene.to_toml_string());
    match &args.out {
        Some(path) => std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display())),
        None => {
            print!("{text}");
            Ok(())
        }
    }
}
