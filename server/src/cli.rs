//! The `kinloop-server` program: host one linkage for many haptic users over QUIC. Its arguments, how they
//! become a [`ServerConfig`], and what it prints; the binary is [`main`] with the process's arguments, and
//! tests run the same function in a child process.

use std::ffi::OsString;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, ValueEnum};
use kinloop_linkage::algorithms::integrator::Integrator;
use kinloop_protocol::emulator::LinkArgs;
use kinloop_protocol::room_key::RoomKey;

use crate::bench::RealtimeRun;
use crate::core::{AxisGains, DEFAULT_COUPLING_LEAD_DELAYS_S, DEFAULT_COUPLING_LEAD_MAX_S};
use crate::driver::load_scene;
#[cfg(feature = "agones")]
use crate::fleet::agones::{AgonesAdapter, AgonesConfig};
use crate::view::{LiveSource, ViewConfig};
use crate::{Access, Identity, Server, ServerConfig, VeConfig};

/// After the drain, how long the Agones adapter may take to report the last counts and call Shutdown.
#[cfg(feature = "agones")]
const AGONES_FINISH: Duration = Duration::from_secs(15);

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Switch {
    On,
    Off,
}

/// `--passivity`: the port controller (on), none (off), or the per-axis controller for stiff gains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum PassivityMode {
    On,
    Off,
    PerAxis,
}

/// Host a virtual linkage with kinematic loops that several people feel at once through haptic devices.
#[derive(Debug, Parser)]
#[command(name = "kinloop-server", version)]
struct Cli {
    /// Scene file (TOML) or built-in name (paper-testbed, fourbar-crank-rocker, chain50_loops5, ...).
    #[arg(long, value_name = "FILE_OR_BUILTIN_NAME", required_unless_present = "rooms", conflicts_with = "rooms")]
    scene: Option<String>,
    /// Host several linkages: a rooms file (TOML, one `[[room]]` per room: name, scene, token_file,
    /// max_users, record; docs/rooms.md). Clients pick a room with `--room NAME`.
    #[arg(long, value_name = "FILE")]
    rooms: Option<PathBuf>,
    /// Real-time threads stepping the rooms (default: one fewer than the cores, at least one).
    #[arg(long, value_name = "N", default_value_t = crate::driver::rooms::default_rt_threads())]
    rt_threads: usize,
    /// Pin the first real-time thread and the network workers to the last CPU: the VE's wake-up of the
    /// network side each round stays on one CPU (a few µs, where waking another CPU costs 15-20 µs on a VM).
    #[arg(long)]
    pin_network: bool,
    /// Accept admin commands (create, remove, list rooms) carrying a token from this file.
    #[arg(long, value_name = "FILE")]
    admin_token: Option<PathBuf>,
    /// UDP address to listen on, e.g. 0.0.0.0:4433 or 127.0.0.1:0.
    #[arg(long, value_name = "ADDR")]
    listen: SocketAddr,
    /// VE loop rate (Hz).
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    ve_rate: f64,
    /// Snapshot rate (Hz); defaults to the VE rate.
    #[arg(long, value_name = "HZ")]
    snapshot_rate: Option<f64>,
    /// Integrator: euler (semi-implicit, implicit coupling), rk4 or explicit-euler.
    #[arg(long, value_name = "NAME", default_value = "euler", value_parser = parse_integrator)]
    integrator: Integrator,
    /// Token file: one token per line, optionally `TOKEN manipulator|observer`; `#` comments.
    #[arg(long, value_name = "F")]
    token_file: Option<PathBuf>,
    /// Most users at once.
    #[arg(long, value_name = "N", default_value_t = 16)]
    max_users: usize,
    /// Directory of the server certificate (created on first start; the fingerprint stays the same).
    #[arg(long, value_name = "D", default_value = ".kinloop-server")]
    cert_dir: PathBuf,
    /// Certificate chain (PEM) instead of --cert-dir's, e.g. one issued by the room's CA (with --key).
    #[arg(long, value_name = "FILE", requires = "key")]
    cert: Option<PathBuf>,
    /// Private key (PEM) of --cert.
    #[arg(long, value_name = "FILE", requires = "cert")]
    key: Option<PathBuf>,
    /// The room's key, shared by the servers of a room: the server signs its state for its clients and
    /// resumes from a state a client brings back from a server that died (docs/resume.md).
    #[arg(long, value_name = "FILE")]
    room_key: Option<PathBuf>,
    #[command(flatten)]
    link: LinkArgs,
    /// Write one CSV row per VE step to this file.
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
    /// Graphics-controller stiffness K_g as `LINEAR,ANGULAR` (N/m, N·m/rad) for every user; default: each
    /// user's designed from its OP's lightest effective mass (8 Hz, critically damped; printed at join). The
    /// paper's testbed values are 1000,10000 (with --coupling-damping 100,10000).
    #[arg(long, value_name = "LIN,ANG", value_parser = parse_gains)]
    coupling_stiffness: Option<AxisGains>,
    /// Graphics-controller damping B_g as `LINEAR,ANGULAR` (N·s/m, N·m·s/rad) for every user; default designed
    /// (given alone, the stiffness is the paper's).
    #[arg(long, value_name = "LIN,ANG", value_parser = parse_gains)]
    coupling_damping: Option<AxisGains>,
    /// Time-domain passivity on each coupling: its port's energy books (sent in the snapshots) and a PD scale
    /// when the VE has received through the coupling more than the hand put in at the client (the client's
    /// books trusted only as far as its uplinks show). `per-axis`: each axis on its own account, for stiff
    /// coupling gains on a turning OP (see `VeConfig::passivity_per_axis`).
    #[arg(long, value_name = "on|off|per-axis", default_value = "on")]
    passivity: PassivityMode,
    /// Play each user's uplinks out at the stream's steady delay once their lateness reaches 25 ms (a jitter
    /// buffer): steadies a linkage pushed over a jittery link (off: each uplink is used on arrival).
    #[arg(long, value_name = "on|off", default_value = "on")]
    jitter_buffer: Switch,
    /// Aim each graphics controller at where its client's local model is predicted to be after the network's
    /// one-way delay (half the shortest round trip), up to MS milliseconds ahead of the uplink heard and no
    /// further than the hand's recent accelerations make a safe guess, for users whose one-way delay is within
    /// --lead-delays-ms (0: follow what is heard, as the paper's VE does). Brings the VE's OP nearer the device
    /// under delay (docs/benchmarks.md has the figures).
    #[arg(long, value_name = "MS", default_value_t = DEFAULT_COUPLING_LEAD_MAX_S * 1e3, value_parser = parse_lead_ms)]
    lead_max_ms: f64,
    /// The one-way delays over which the VE leads, FROM..UNTIL in milliseconds (UNTIL may be left out: no
    /// upper bound). Outside them the guesses cost more than they buy (see `kinloop experiment latency`).
    #[arg(long, value_name = "FROM..UNTIL", default_value_t = LeadDelays(DEFAULT_COUPLING_LEAD_DELAYS_S.map(|s| s * 1e3)), value_parser = parse_lead_delays)]
    lead_delays_ms: LeadDelays,
    /// Let the linkage move on its own while no manipulator holds it (by default it waits at rest, so the
    /// first user grasps a still linkage rather than one that gravity has been swinging).
    #[arg(long)]
    free_run: bool,
    /// Log statistics every S seconds (0: never).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    stats_every: f64,
    /// Stop after S seconds (default: run until Ctrl-C or SIGTERM).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// On Ctrl-C, SIGTERM or the end of --duration, drain: refuse new clients, hand each client the room's
    /// newest signed state and tell it to move, wait up to S seconds for them to go, then exit (code 0).
    #[arg(long, value_name = "S", default_value_t = crate::driver::DEFAULT_DRAIN.as_secs_f64())]
    drain_s: f64,
    /// Run as an Agones GameServer: talk to the SDK sidecar in the pod (port from AGONES_SDK_GRPC_PORT, else
    /// 9357): Ready once listening, health pings while the VE ticks, the `rooms` Counter and `users` List,
    /// Shutdown after the drain (docs/fleet.md). Without a sidecar the server stops within a few seconds.
    #[arg(long)]
    agones: bool,
    /// With --agones, the period of the health pings (ms); the Fleet's health check must allow for it.
    #[arg(long, value_name = "MS", default_value_t = crate::fleet::DEFAULT_HEALTH_PERIOD.as_millis() as u64, requires = "agones", value_parser = clap::value_parser!(u64).range(10..=60_000))]
    agones_health_ms: u64,
    /// Print the final statistics as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Instead of listening, run the VE thread for --duration with N synthetic in-process users and report
    /// tick times and deadline misses (the real-time check).
    #[arg(long, value_name = "N")]
    synthetic_users: Option<usize>,
    /// Serve a web page on this TCP address (e.g. 127.0.0.1:8080) that draws the linkage live: bodies,
    /// obstacles, each user's OP, device and coupling force, the constraint directions, the closure error
    /// and a panel of users, RTT and VE timing. With --token-file the page asks for a token (observer tokens
    /// watch, manipulator tokens may also drag an OP with the mouse). No TLS: serve on loopback or a trusted
    /// network.
    #[arg(long, value_name = "ADDR")]
    view: Option<SocketAddr>,
    /// Without --token-file, let any page grab an OP with the mouse (default: pages only watch).
    #[arg(long, requires = "view")]
    view_grab: bool,
    /// Frames per second the view sends (1-240).
    #[arg(long, value_name = "HZ", default_value_t = crate::view::DEFAULT_FRAME_RATE_HZ, requires = "view")]
    view_rate: f64,
}

/// `--synthetic-users`, with a watch-only view of the VE when `view` is given: the VE thread feeds the
/// view's tap as the server's does, so the run measures what pages cost the VE.
fn synthetic_run(
    run: RealtimeRun,
    view: Option<ViewConfig>,
    access: Access,
) -> anyhow::Result<(crate::bench::RealtimeReport, Option<crate::view::ViewStats>)> {
    let Some(view) = view else { return Ok((crate::bench::realtime_run(run)?, None)) };
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let users = run.ve.max_users.max(run.users);
    let (tap, reader) = crate::view::tap_for_scene(&run.scene, &run.scene_label, users, run.ve.ve_rate_hz, &view)?;
    let source = LiveSource { scene: run.scene.clone(), scene_label: run.scene_label.clone(), reader, access };
    let handle = runtime.block_on(async { crate::view::start_live(&view, source) })?;
    println!("view: http://{}/", handle.local_addr());
    let report = crate::bench::realtime_run_with_view(run, Some(tap));
    let stats = runtime.block_on(handle.shutdown());
    Ok((report?, Some(stats)))
}

/// `LINEAR,ANGULAR`: two finite, non-negative gains.
fn parse_gains(s: &str) -> Result<AxisGains, String> {
    let values: Vec<f64> = s
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{s:?} is not two comma-separated numbers LINEAR,ANGULAR"))?;
    match values[..] {
        [linear, angular] if [linear, angular].iter().all(|g| g.is_finite() && *g >= 0.0) => {
            Ok(AxisGains::Uniform { linear, angular })
        }
        [_, _] => Err(format!("{s:?}: gains must be finite and non-negative")),
        _ => Err(format!("{s:?} is not two comma-separated numbers LINEAR,ANGULAR")),
    }
}

/// The one-way delays a lead acts over (ms), as `--lead-delays-ms` reads them.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LeadDelays([f64; 2]);

impl std::fmt::Display for LeadDelays {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [from, until] = self.0;
        if until.is_finite() {
            write!(f, "{from}..{until}")
        } else {
            write!(f, "{from}..")
        }
    }
}

/// `FROM..UNTIL` or `FROM..` in milliseconds: numbers, 0 <= FROM <= UNTIL.
fn parse_lead_delays(s: &str) -> Result<LeadDelays, String> {
    let (from, until) = s.split_once("..").ok_or_else(|| format!("{s:?} is not FROM..UNTIL (milliseconds)"))?;
    let number = |t: &str| -> Result<f64, String> {
        let ms: f64 = t.trim().parse().map_err(|_| format!("{t:?} is not a number of milliseconds"))?;
        if ms.is_finite() && ms >= 0.0 {
            Ok(ms)
        } else {
            Err(format!("{ms} ms is not a delay"))
        }
    };
    let from = number(from)?;
    let until = if until.trim().is_empty() { f64::INFINITY } else { number(until)? };
    if until < from {
        return Err(format!("{until} ms ends before {from} ms"));
    }
    Ok(LeadDelays([from, until]))
}

/// The longest lead in milliseconds: finite, 0 to 4000 (the VE keeps 4 s of snapshot times to measure round
/// trips with, `round_trip::BUILT_KEPT`; a longer lead would guess past any round trip it shares).
fn parse_lead_ms(s: &str) -> Result<f64, String> {
    let ms: f64 = s.trim().parse().map_err(|_| format!("{s:?} is not a number of milliseconds"))?;
    if !(0.0..=4000.0).contains(&ms) {
        return Err(format!("{ms} ms is outside 0..4000 ms"));
    }
    Ok(ms)
}

fn parse_integrator(s: &str) -> Result<Integrator, String> {
    Integrator::parse(s).ok_or_else(|| format!("unknown integrator {s:?}; use euler, rk4 or explicit-euler"))
}

fn seconds(what: &str, s: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(s).with_context(|| format!("{what} must be a non-negative number of seconds"))
}

/// `kinloop-server ARGS...`: `args` as the process gets them (program name first). Bad arguments print
/// clap's message and exit at once (code 2; `--help` and `--version` code 0); a failure prints one line,
/// `error: ...`, and returns failure.
pub fn main<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = Cli::try_parse_from(args).unwrap_or_else(|e| e.exit());
    kinloop_process::report::run_program("info", || run(cli))
}

/// The VE's settings from the flags (the rest are `VeConfig::default`).
fn ve_config(cli: &Cli) -> VeConfig {
    VeConfig {
        ve_rate_hz: cli.ve_rate,
        snapshot_rate_hz: cli.snapshot_rate.unwrap_or(cli.ve_rate),
        integrator: cli.integrator,
        max_users: cli.max_users,
        passivity: cli.passivity != PassivityMode::Off,
        passivity_per_axis: cli.passivity == PassivityMode::PerAxis,
        jitter_buffer: cli.jitter_buffer == Switch::On,
        coupling_stiffness: cli.coupling_stiffness.clone(),
        coupling_damping: cli.coupling_damping.clone(),
        rest_unheld: !cli.free_run,
        coupling_lead_max_s: cli.lead_max_ms * 1e-3,
        coupling_lead_delays_s: cli.lead_delays_ms.0.map(|ms| ms * 1e-3),
        ..VeConfig::default()
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let rooms = cli.rooms.as_deref().map(crate::driver::rooms::load_rooms_file).transpose()?.unwrap_or_default();
    let (scene, label) = match (&cli.scene, rooms.first()) {
        (Some(scene), _) => load_scene(scene).with_context(|| format!("cannot load scene {scene}"))?,
        (None, Some(first)) => (first.scene.clone(), first.scene_label.clone()),
        (None, None) => anyhow::bail!("give --scene or --rooms"),
    };
    let ve = ve_config(&cli);
    let duration = cli.duration.map(|s| seconds("--duration", s)).transpose()?;

    let access = match &cli.token_file {
        Some(path) => Access::from_file(path)?,
        None => Access::open(),
    };
    let view = cli.view.map(|listen| ViewConfig {
        grab_without_token: cli.view_grab,
        frame_rate_hz: cli.view_rate,
        ..ViewConfig::new(listen)
    });
    if let Some(users) = cli.synthetic_users {
        let duration = duration.unwrap_or(Duration::from_secs(10));
        let run = RealtimeRun { scene, scene_label: label, users, duration, ve, warm_up: Duration::ZERO };
        let (report, view_stats) = synthetic_run(run, view, access)?;
        if cli.json {
            let mut json = serde_json::to_value(&report)?;
            if let (Some(stats), Some(object)) = (view_stats, json.as_object_mut()) {
                object.insert("view".into(), serde_json::to_value(stats)?);
            }
            println!("{}", serde_json::to_string_pretty(&json)?);
        } else {
            println!(
                "{} users, {} ticks: step p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs; {} deadline misses; SCHED_FIFO {}",
                report.users,
                report.ve.step_time.samples,
                report.ve.step_time.p50_ns as f64 / 1e3,
                report.ve.step_time.p99_ns as f64 / 1e3,
                report.ve.step_time.max_ns as f64 / 1e3,
                report.ve.deadline_misses,
                if report.ve.realtime_priority { "on" } else { "off" },
            );
        }
        return Ok(());
    }

    let mut config = ServerConfig {
        scene,
        scene_label: label,
        listen: cli.listen,
        ve,
        access,
        identity: match (&cli.cert, &cli.key) {
            (Some(cert), Some(key)) => Identity::Files { cert: cert.clone(), key: key.clone() },
            _ => Identity::CertDir(cli.cert_dir.clone()),
        },
        room_key: cli.room_key.as_deref().map(RoomKey::load).transpose()?,
        link: cli.link.emulated_link()?,
        record: cli.record.clone(),
        stats_every: Some(seconds("--stats-every", cli.stats_every)?),
        realtime: true,
        view,
        drain: seconds("--drain-s", cli.drain_s)?,
        fleet: None,
        rt_threads: cli.rt_threads.max(1),
        network_cpu: cli.pin_network.then(kinloop_process::affinity::last_cpu),
        admin: cli.admin_token.as_deref().map(Access::from_file).transpose().context("--admin-token")?,
        rooms,
    };
    let many = !config.rooms.is_empty();
    let network_cpu = config.network_cpu;
    let runtime = crate::driver::network_runtime::network_runtime("kinloop-server-net", network_cpu, true)?;
    runtime.block_on(async move {
        let agones = if cli.agones { Some(start_agones(cli.agones_health_ms, &mut config).await?) } else { None };
        let server = Server::start(config)?;
        println!("kinloop-server listening on {}", server.local_addr());
        println!("certificate fingerprint (sha-256): {}", server.fingerprint());
        if let Some(addr) = server.view_addr() {
            println!("view: http://{addr}/");
        }
        let stop = async {
            match duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => tracing::info!("Ctrl-C: draining"),
            _ = terminated() => tracing::info!("SIGTERM: draining"),
            _ = stop => tracing::info!("--duration elapsed: draining"),
        }
        if many {
            let reports = server.shutdown_rooms().await?;
            finish_agones(agones).await;
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "rooms": reports }))?);
            }
        } else {
            let stats = server.shutdown().await?;
            finish_agones(agones).await;
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&stats)?);
            }
        }
        anyhow::Ok(())
    })
}

/// Connects to the Agones SDK sidecar and starts the adapter the server's fleet feed drives.
#[cfg(feature = "agones")]
async fn start_agones(health_ms: u64, config: &mut ServerConfig) -> anyhow::Result<AgonesAdapter> {
    let settings = AgonesConfig { health_period: Duration::from_millis(health_ms), ..AgonesConfig::default() };
    let sdk = crate::fleet::agones::connect(&settings).await?;
    let (feed, events) = crate::fleet::channel();
    config.fleet = Some(feed);
    Ok(AgonesAdapter::spawn(sdk, &settings, events))
}

/// Without the `agones` feature the SDK (and the protoc its build needs) is not compiled in: say so.
#[cfg(not(feature = "agones"))]
async fn start_agones(_health_ms: u64, _config: &mut ServerConfig) -> anyhow::Result<std::convert::Infallible> {
    anyhow::bail!("--agones: this kinloop-server was built without Agones support; build it with `--features agones`")
}

/// After the drain, lets the Agones adapter (if any) report the last counts and call Shutdown.
#[cfg(feature = "agones")]
async fn finish_agones(agones: Option<AgonesAdapter>) {
    if let Some(agones) = agones {
        agones.finished(AGONES_FINISH).await;
    }
}

#[cfg(not(feature = "agones"))]
async fn finish_agones(_agones: Option<std::convert::Infallible>) {}

/// Resolves when the process is asked to terminate (SIGTERM: Kubernetes, Agones, systemd, `kill`); never
/// where there is no such signal or it cannot be watched (then Ctrl-C and --duration still stop the server).
async fn terminated() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                term.recv().await;
                return;
            }
            Err(error) => tracing::warn!(%error, "SIGTERM is not watched: stop with Ctrl-C"),
        }
    }
    std::future::pending::<()>().await
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gains parse as `LINEAR,ANGULAR`; anything else, or a negative or non-finite gain, is refused with a
    /// message saying what was expected.
    #[test]
    fn coupling_gains_parse_or_say_why_not() {
        assert_eq!(parse_gains("1000, 100"), Ok(AxisGains::Uniform { linear: 1000.0, angular: 100.0 }));
        for bad in ["1000", "1,2,3", "a,b", "", "1,nan", "-1,5", "1,inf"] {
            let why = parse_gains(bad).unwrap_err();
            assert!(why.contains("LINEAR,ANGULAR") || why.contains("finite and non-negative"), "{bad:?}: {why}");
        }
    }

    /// The passivity controller is on by default (the port's); `off` removes it, `per-axis` picks the per-axis
    /// one, and any other value is refused naming the flag.
    #[test]
    fn passivity_flag_picks_the_controller() {
        let config = |extra: &[&str]| {
            let args = ["kinloop-server", "--scene", "paper-testbed", "--listen", "127.0.0.1:0"].iter().chain(extra);
            Cli::try_parse_from(args).map(|cli| {
                let ve = ve_config(&cli);
                (ve.passivity, ve.passivity_per_axis)
            })
        };
        assert_eq!(config(&[]).unwrap(), (true, false));
        assert_eq!(config(&["--passivity", "on"]).unwrap(), (true, false));
        assert_eq!(config(&["--passivity", "off"]).unwrap(), (false, false));
        assert_eq!(config(&["--passivity", "per-axis"]).unwrap(), (true, true));
        let refused = config(&["--passivity", "sometimes"]).unwrap_err().to_string();
        assert!(refused.contains("--passivity") && refused.contains("per-axis"), "{refused}");
    }

    /// The VE follows what it hears unless told to lead; a lead is given in milliseconds, and one that is not a
    /// number, negative or beyond 4 s is refused naming the flag.
    #[test]
    fn lead_flag_sets_the_longest_lead() {
        let lead = |extra: &[&str]| {
            let args = ["kinloop-server", "--scene", "paper-testbed", "--listen", "127.0.0.1:0"].iter().chain(extra);
            Cli::try_parse_from(args).map(|cli| ve_config(&cli).coupling_lead_max_s)
        };
        assert_eq!(lead(&[]).unwrap(), 0.1);
        assert_eq!(lead(&["--lead-max-ms", "0"]).unwrap(), 0.0);
        assert!((lead(&["--lead-max-ms", "150"]).unwrap() - 0.15).abs() < 1e-12);
        for bad in ["-5", "NaN", "inf", "4001", "soon"] {
            let refused = lead(&[&format!("--lead-max-ms={bad}")]).unwrap_err().to_string();
            assert!(refused.contains("--lead-max-ms"), "{bad}: {refused}");
        }
    }

    /// The delays a lead acts over: from 75 ms on by default (the default's `75..` reads back as itself),
    /// FROM..UNTIL in milliseconds, UNTIL optional; anything else is refused naming the flag.
    #[test]
    fn lead_delays_flag_sets_where_the_ve_leads() {
        let delays = |extra: &[&str]| {
            let args = ["kinloop-server", "--scene", "paper-testbed", "--listen", "127.0.0.1:0"].iter().chain(extra);
            Cli::try_parse_from(args).map(|cli| ve_config(&cli).coupling_lead_delays_s)
        };
        let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12;
        let default = delays(&[]).unwrap();
        assert!((default[0] - DEFAULT_COUPLING_LEAD_DELAYS_S[0]).abs() < 1e-12, "{default:?}");
        assert_eq!(default[1], DEFAULT_COUPLING_LEAD_DELAYS_S[1]);
        assert!(close(delays(&["--lead-delays-ms", "0..1000"]).unwrap(), [0.0, 1.0]));
        assert_eq!(delays(&["--lead-delays-ms", "50.."]).unwrap(), [0.05, f64::INFINITY]);
        for bad in ["100", "300..100", "-5..10", "a..b", "NaN..1", "..", "5..inf"] {
            let refused = delays(&[&format!("--lead-delays-ms={bad}")]).unwrap_err().to_string();
            assert!(refused.contains("--lead-delays-ms"), "{bad}: {refused}");
        }
    }
}
