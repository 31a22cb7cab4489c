//! `kinloop-client`: feel a kinloop server's linkage through a (simulated) haptic device.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Parser;
use kinloop_client::core::{ConstraintMode, ModelForm};
use kinloop_client::device::DevicePreset;
use kinloop_client::driver::{Client, ClientConfig};
use kinloop_client::user::UserSpec;
use kinloop_protocol::emulator::LinkArgs;
use kinloop_protocol::quic::Trust;

/// Connects to a kinloop server and renders the linkage at an operational point on a simulated device.
#[derive(Debug, Parser)]
#[command(name = "kinloop-client", version)]
struct Args {
    /// Server address, HOST:PORT.
    #[arg(long, value_name = "ADDR")]
    server: String,
    /// Access token the server was started with.
    #[arg(long, default_value = "")]
    token: String,
    /// Trust the server certificates this CA (or self-signed certificate) PEM file vouches for.
    #[arg(long, value_name = "FILE", conflicts_with = "fingerprint")]
    ca: Option<PathBuf>,
    /// Trust exactly the server certificate with this SHA-256 fingerprint (hex).
    #[arg(long, value_name = "HEX")]
    fingerprint: Option<String>,
    /// Name the server's certificate must carry (with --ca).
    #[arg(long, default_value = "localhost")]
    server_name: String,
    /// Operational point to hold.
    #[arg(long, default_value = "link2")]
    op: String,
    /// Simulated device: sim:paper, sim:falcon or sim:touch.
    #[arg(long, default_value = "sim:paper")]
    device: DevicePreset,
    /// Simulated user: constant:FX,FY,TZ | path:line:X0,Y0,X1,Y1,T | path:circle:R,T | path:waypoints:T:X,Y;... | replay:FILE.
    #[arg(long, default_value = "constant:-0.5,0,-0.0025")]
    user: UserSpec,
    /// Haptic loop rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Run this many seconds, then exit (default: until Ctrl-C).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Joint-constraint rendering: stiffness or impedance.
    #[arg(long, default_value = "stiffness", value_parser = parse_mode)]
    constraint_mode: ConstraintMode,
    /// Local model: op (reduced operational-space form) or config (the paper's eq 11).
    #[arg(long, default_value = "op", value_parser = parse_form)]
    form: ModelForm,
    /// Write one CSV row per tick to FILE.
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
    /// Print the exit statistics as JSON.
    #[arg(long)]
    json: bool,
    /// Perceptual deadband on the uplink (IEEE 1918.1.1 style).
    #[arg(long)]
    deadband: bool,
    /// Do not ask for SCHED_FIFO.
    #[arg(long)]
    no_realtime: bool,
    #[command(flatten)]
    link: LinkArgs,
}

fn parse_mode(s: &str) -> Result<ConstraintMode, String> {
    ConstraintMode::parse(s).ok_or_else(|| format!("{s:?}: expected stiffness or impedance"))
}

fn parse_form(s: &str) -> Result<ModelForm, String> {
    ModelForm::parse(s).ok_or_else(|| format!("{s:?}: expected op or config"))
}

fn config(args: Args) -> anyhow::Result<(ClientConfig, bool)> {
    let trust = match (args.ca, args.fingerprint) {
        (Some(file), None) => Trust::CaFile(file),
        (None, Some(hex)) => Trust::Fingerprint(hex),
        _ => bail!("say how to trust the server: --ca FILE or --fingerprint HEX"),
    };
    let duration = match args.duration {
        // try_from: a finite but huge value (1e300 s) does not fit a Duration, which would panic.
        Some(s) if s > 0.0 => match Duration::try_from_secs_f64(s) {
            Ok(d) => Some(d),
            Err(_) => bail!("--duration {s}: must be a positive number of seconds that fits a clock"),
        },
        Some(s) => bail!("--duration {s}: must be a positive number of seconds"),
        None => None,
    };
    let mut config = ClientConfig::new(args.server, trust);
    config.server_name = args.server_name;
    config.token = args.token;
    config.op = args.op;
    config.device = args.device;
    config.user = args.user;
    config.rate_hz = args.rate;
    config.duration = duration;
    config.constraint_mode = args.constraint_mode;
    config.form = args.form;
    config.record = args.record;
    config.realtime_priority = !args.no_realtime;
    config.deadband = args.deadband.then(Default::default);
    config.link = args.link.emulated_link().context("link emulation")?;
    Ok((config, args.json))
}

fn run() -> anyhow::Result<()> {
    let (config, json) = config(Args::parse())?;
    let server = config.server.clone();
    let bounded = config.duration.is_some();
    let client = Client::start(config).with_context(|| format!("kinloop-client could not start against {server}"))?;
    let stats = if bounded {
        client.wait()
    } else {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
        runtime.block_on(async {
            loop {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => break,
                    _ = tokio::time::sleep(Duration::from_millis(200)) => if client.is_finished() { break },
                }
            }
        });
        client.shutdown()
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&stats.to_json())?);
    } else {
        let s = &stats;
        println!(
            "ticks {} at {:.1} Hz; lateness p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs; misses {}",
            s.lateness.ticks, s.rate_hz, s.lateness.p50_us, s.lateness.p99_us, s.lateness.max_us, s.lateness.misses
        );
        let core = s.core.unwrap_or_default();
        println!(
            "rtt p50 {}; max force ratio {:.3}; tracking rms {:.2} mm (max {:.2} mm); snapshots {}; uplinks {} (saved {:.0}%); reconnects {}",
            s.rtt_ms_p50.map_or("n/a".into(), |r| format!("{r:.2} ms")),
            s.max_force_ratio,
            core.tracking_error_rms() * 1e3,
            core.tracking_error_max * 1e3,
            s.snapshots_received,
            s.uplinks_sent,
            core.uplink_saving() * 100.0,
            s.reconnects
        );
    }
    Ok(())
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "kinloop_client=info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
