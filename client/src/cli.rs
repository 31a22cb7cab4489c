//! The `kinloop-client` program: feel a kinloop server's linkage through a (simulated) haptic device. Its
//! arguments, how they become a [`ClientConfig`], and what it prints; the binary is [`main`] with the
//! process's arguments, and tests run the same function in a child process.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Parser;
use kinloop_protocol::emulator::LinkArgs;
use kinloop_protocol::quic::{ConnectError, Trust};
use kinloop_protocol::{MappingRequest, RefusalReason};

use crate::core::{ConstraintMode, ModelForm};
use crate::device::{DeviceRequest, DhdRequest, HdRequest};
use crate::driver::{Client, ClientConfig, ClientError};
use crate::user::UserSpec;

/// Connects to a kinloop server and renders the linkage at an operational point on a simulated device.
#[derive(Debug, Parser)]
#[command(name = "kinloop-client", version)]
struct Args {
    /// Server address, HOST:PORT. Repeat it to name the other servers of the room, tried in order when
    /// the session is lost (the room resumes where it was on the one reached; trust them with --ca).
    #[arg(long, value_name = "ADDR", required = true)]
    server: Vec<String>,
    /// Access token the server was started with.
    #[arg(long, default_value = "")]
    token: String,
    /// Room to join on a server hosting several (default: the server's default room).
    #[arg(long, value_name = "NAME", default_value = "")]
    room: String,
    /// Trust the server certificates this CA (or self-signed certificate) PEM file vouches for.
    #[arg(long, value_name = "FILE", conflicts_with = "fingerprint")]
    ca: Option<PathBuf>,
    /// Trust exactly the server certificate with this SHA-256 fingerprint (hex).
    #[arg(long, value_name = "HEX")]
    fingerprint: Option<String>,
    /// Name the server's certificate must carry (with --ca).
    #[arg(long, default_value = "localhost")]
    server_name: String,
    /// Operational point to hold (default: the scene's first).
    #[arg(long)]
    op: Option<String>,
    /// Device: simulated sim:paper (planar), sim:falcon or sim:touch (default: sim:paper for planar scenes,
    /// sim:touch for spatial ones); dhd[:INDEX] a Force Dimension device through the DHD SDK (found through
    /// KINLOOP_DHD_LIB, FORCEDIM_SDK or the usual install places); hd[:NAME] a 3D Systems device through
    /// OpenHaptics (libHD, found through KINLOOP_HD_LIB, OH_SDK_BASE or the usual install places; NAME as
    /// Touch Setup lists it); dhd,sim:NAME or hd,sim:NAME falls back to a simulated device when the vendor's
    /// cannot be used.
    #[arg(long)]
    device: Option<DeviceRequest>,
    /// With --device dhd: when the device is not calibrated (drdIsInitialized false), run drdAutoInit, which
    /// moves the device on its own (let go of the handle first). Without it an uncalibrated device is refused.
    #[arg(long)]
    dhd_auto_init: bool,
    /// With --device hd: when the device needs calibrating (hdCheckCalibration), run hdUpdateCalibration.
    /// Without it such a device is refused with what to do.
    #[arg(long)]
    hd_calibrate: bool,
    /// Simulated user: a hand soft|firm|release|poke (touring the OP's reach; KIND:PATH or KIND:hold for a
    /// scripted one), path:line:X0,Y0,X1,Y1,T | path:circle:R,T | path:waypoints:T:X,Y;... (a soft hand),
    /// constant:FX,FY,TZ (planar: forces x, y then torque z) or constant:FX,FY,FZ,TX,TY,TZ (spatial: forces
    /// then torques, world axes), paper (the paper's constant wrench), replay:FILE.
    #[arg(long, default_value = "soft")]
    user: UserSpec,
    /// Device metres per VE metre (default: the server fits the OP's reach into the device's workspace).
    #[arg(long, value_name = "SCALE")]
    position_scale: Option<f64>,
    /// Device newtons per VE newton (default: the server maps the OP's static load to about a third of the
    /// device's continuous force).
    #[arg(long, value_name = "SCALE")]
    force_scale: Option<f64>,
    /// The VE holds the linkage's weight at this user's OP: feel its inertia and its loops, not its weight.
    #[arg(long)]
    gravity_compensation: bool,
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

/// Fraction of ticks at the force limit above which the client warns.
const CLAMPED_WARNING: f64 = 0.03;

fn rounded(values: &[f64]) -> Vec<f64> {
    values.iter().map(|v| (v * 1e4).round() / 1e4).collect()
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
    let mut servers = args.server.into_iter();
    let mut config = ClientConfig::new(servers.next().unwrap_or_default(), trust);
    config.fallback_servers = servers.collect();
    config.server_name = args.server_name;
    config.token = args.token;
    config.room = args.room;
    config.op = args.op;
    match args.device {
        Some(DeviceRequest::Simulated(preset)) => config.device = Some(preset),
        Some(DeviceRequest::Dhd(request)) => {
            config.dhd = Some(DhdRequest { auto_init: args.dhd_auto_init, ..request });
        }
        Some(DeviceRequest::Hd(request)) => config.hd = Some(HdRequest { calibrate: args.hd_calibrate, ..request }),
        None => {}
    }
    config.user = args.user;
    config.rate_hz = args.rate;
    config.duration = duration;
    config.constraint_mode = args.constraint_mode;
    config.form = args.form;
    config.record = args.record;
    for (flag, scale) in [("--position-scale", args.position_scale), ("--force-scale", args.force_scale)] {
        if let Some(value) = scale {
            if !(value.is_finite() && value > 0.0) {
                bail!("{flag} {value}: must be a positive number (device units per VE unit)");
            }
        }
    }
    config.mapping = MappingRequest {
        position_scale: args.position_scale,
        force_scale: args.force_scale,
        gravity_compensation: args.gravity_compensation,
    };
    config.realtime_priority = !args.no_realtime;
    config.deadband = args.deadband.then(Default::default);
    config.link = args.link.emulated_link().context("link emulation")?;
    Ok((config, args.json))
}

/// What the person at the client can do about a refusal, in this program's flags.
fn remedy(reason: &RefusalReason) -> Option<String> {
    Some(match reason {
        RefusalReason::UnsupportedVersion { server, .. } => {
            format!("use a kinloop-client that speaks protocol version {server}")
        }
        RefusalReason::BadToken => "pass the token the server's operator gave you with --token".into(),
        RefusalReason::ServerFull { .. } => "try again when a user has left".into(),
        RefusalReason::UnknownOp { available, .. } if available.is_empty() => {
            "every operational point is held; try again when one is free".into()
        }
        RefusalReason::UnknownOp { .. } => "choose a free one with --op NAME, or leave --op out for the first".into(),
        RefusalReason::RoleNotAllowed => "ask the server's operator for a manipulator token".into(),
        RefusalReason::Device { .. } => {
            "try another --device, or leave --position-scale and --force-scale to the server".into()
        }
        RefusalReason::Unservable { .. } => {
            "ask the server's operator: the scene as written cannot be served (values outside the protocol's \
             SI bounds often mean a scene in millimetres or grams)"
                .into()
        }
        RefusalReason::UnknownRoom { available, .. } if available.is_empty() => {
            "no room on this server opens to your token; ask the server's operator".into()
        }
        RefusalReason::UnknownRoom { .. } => "choose one of the rooms listed with --room NAME".into(),
        RefusalReason::OverBudget { .. } => "try again later or another room: the server is at capacity".into(),
        RefusalReason::Malformed { .. } => return None,
    })
}

/// A client that could not start, said once, with what to do when the server refused.
fn not_started(error: ClientError) -> anyhow::Error {
    let advice = match &error {
        ClientError::Connect { source: ConnectError::Refused(refused), .. } => remedy(&refused.reason),
        _ => None,
    };
    match advice {
        Some(advice) => {
            let said = kinloop_process::report::one_line(&error);
            anyhow::Error::new(error).context(format!("{said}; {advice}"))
        }
        None => error.into(),
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let (config, json) = config(args)?;
    let user = config.user.label();
    let client = Client::start(config).map_err(not_started)?;
    let (w, g) = (client.welcome(), client.gains());
    eprintln!(
        "kinloop-client: holding {} of {} with {}, user {user}; mapping: position ×{:.4}, force ×{:.4}{}",
        w.scene.op_name,
        w.scene.name,
        client.device(),
        w.mapping.position_scale,
        w.mapping.force_scale,
        if w.mapping.gravity_compensation { ", gravity compensated" } else { "" },
    );
    eprintln!(
        "kinloop-client: gains (device units) k_j {:.1} N/m, b_j {:.2} N s/m, K_pc {:?}, B_pc {:?}; server coupling K_g {:?}, B_g {:?}",
        g.joint_stiffness,
        g.joint_damping,
        rounded(&g.position_stiffness),
        rounded(&g.position_damping),
        rounded(&w.coupling.stiffness),
        rounded(&w.coupling.damping),
    );
    let session = client.session_json();
    let stats = client.run_until_stopped();
    let core = stats.core.unwrap_or_default();
    let clamped = if core.active_ticks > 0 { core.clamped_ticks as f64 / core.active_ticks as f64 } else { 0.0 };
    let warning = (clamped > CLAMPED_WARNING).then(|| {
        format!(
            "the device sat at its force limit on {:.1} % of its ticks: the linkage's loads exceed what it renders at \
             this mapping; try a smaller --force-scale, --gravity-compensation, a stronger --device, or a firmer \
             --user that moves less abruptly",
            clamped * 100.0
        )
    });
    if let Some(w) = &warning {
        tracing::warn!("{w}");
    }
    if json {
        let mut out = stats.to_json();
        if let Some(map) = out.as_object_mut() {
            map.insert("session".into(), session);
            map.insert("clamped_fraction".into(), clamped.into());
            map.insert("warning".into(), warning.into());
        }
        println!("{}", serde_json::to_string_pretty(&out)?);
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
    if stats.device_lost {
        bail!("the device failed (said above): its force was zeroed and the session ended");
    }
    Ok(())
}

/// `kinloop-client ARGS...`: `args` as the process gets them (program name first). Bad arguments print
/// clap's message and exit at once (code 2; `--help` and `--version` code 0); a failure prints one line,
/// `error: ...`, and returns failure.
pub fn main<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args = Args::try_parse_from(args).unwrap_or_else(|e| e.exit());
    kinloop_process::report::run_program("kinloop_client=info", || run(args))
}
