//! `kinloop export SCENE --mjcf`: a scene as an MJCF model MuJoCo loads and simulates (encodings in
//! `docs/mjcf.md`).

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::scene_arg::load_scene;

/// Arguments of `kinloop export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The scene: a file or a built-in name.
    pub scene: String,
    /// Write MJCF (MuJoCo XML), the one format export writes.
    #[arg(long, required = true)]
    pub mjcf: bool,
    /// Where to write the model (default: standard output).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
}

/// Runs `kinloop export`: what the model does not carry is one warning on standard error.
pub fn run(args: &ExportArgs) -> Result<()> {
    let loaded = load_scene(&args.scene)?;
    let export = kinloop_mjcf::export(&loaded.scene, &loaded.label)?;
    if !export.dropped.is_empty() {
        eprintln!("warning: {}: not carried into MJCF: {}", loaded.label, export.dropped.join("; "));
    }
    match &args.out {
        Some(path) => std::fs::write(path, &export.xml).with_context(|| format!("cannot write {}", path.display())),
        None => {
            print!("{}", export.xml);
            Ok(())
        }
    }
}
