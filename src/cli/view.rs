//! `kinloop view FILE.csv [--scene S] [--listen ADDR] [--token-file F] [--duration S]`: replays a recording
//! (a server's or a client's `--record` CSV) in the web page the live view serves, with a timeline slider
//! (play, pause, scrub). See `kinloop_server::view::replay`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use kinloop_server::view::replay::Replay;
use kinloop_server::view::{self, ViewConfig};
use kinloop_server::Access;

use crate::scene_arg::load_scene;

/// Arguments of `kinloop view`.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {
    /// A recording: `kinloop-server --record` (one row per VE step) or `kinloop-client --record` (one row
    /// per haptic tick; the linkage is posed to put the scene's first OP on the recorded local model).
    #[arg(value_name = "FILE.csv")]
    pub file: PathBuf,
    /// The scene the recording was made on (file or built-in name).
    #[arg(long, value_name = "FILE_OR_NAME", default_value = "paper-testbed")]
    pub scene: String,
    /// TCP address to serve the page on.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Ask pages for a token from this file (the server's format; any role may watch a replay).
    #[arg(long, value_name = "F")]
    pub token_file: Option<PathBuf>,
    /// Stop after S seconds (default: run until Ctrl-C).
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
}

/// Serves the replay until Ctrl-C (or `--duration`).
pub fn run(args: &ViewArgs) -> Result<()> {
    let scene = load_scene(&args.scene)?;
    let replay = Replay::load(&args.file, &scene.scene, &scene.label)?;
    let info = replay.info().clone();
    let access = match &args.token_file {
        Some(path) => Access::from_file(path)?,
        None => Access::open(),
    };
    let stop = args
        .duration
        .map(|s| Duration::try_from_secs_f64(s).context("--duration must be a non-negative number of seconds"))
        .transpose()?;
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    runtime.block_on(async {
        let handle = view::start_replay(&ViewConfig::new(args.listen), access, replay)?;
        println!(
            "kinloop view: {} ({} recording, {} rows, {:.3} to {:.3} s) at http://{}/",
            info.file,
            info.source,
            info.rows,
            info.t0,
            info.t1,
            handle.local_addr()
        );
        let until = async {
            match stop {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = until => {}
        }
        handle.shutdown().await;
        anyhow::Ok(())
    })
}
