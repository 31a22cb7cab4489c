//! `kinloop load --server ADDR (--ca FILE | --fingerprint HEX) --users N [--room NAME | --rooms A,B,..]
//! [--hand SPEC] [--duration S] [--json]`: N real client sessions from this process, their haptic loops on
//! one shared clock (see [`crate::load`]); prints each user's outcome (one JSON object with `--json`).

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Result;
use clap::Parser;
use kinloop_client::user::UserSpec;
use kinloop_protocol::quic::Trust;

use crate::load::{self, LoadOptions, LoadSummary, MAX_USERS};

/// Arguments of `kinloop load`.
#[derive(clap::Args, Debug)]
#[command(group = clap::ArgGroup::new("trust").required(true).args(["ca", "fingerprint"]))]
pub struct LoadArgs {
    /// Server address, HOST:PORT.
    #[arg(long, value_name = "ADDR")]
    pub server: String,
    /// Trust the server certificates this CA (or self-signed certificate) PEM file vouches for.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
    /// Trust exactly the server certificate with this SHA-256 fingerprint (hex).
    #[arg(long, value_name = "HEX")]
    pub fingerprint: Option<String>,
    /// Name the server's certificate must carry (with --ca).
    #[arg(long, default_value = "localhost")]
    pub server_name: String,
    /// Access token, the same for every user.
    #[arg(long, default_value = "")]
    pub token: String,
    /// Users (client sessions) to open.
    #[arg(long, value_name = "N", value_parser = parse_users)]
    pub users: usize,
    /// The room every user joins (default: the server's default room).
    #[arg(long, value_name = "NAME", conflicts_with = "rooms")]
    pub room: Option<String>,
    /// Rooms the users join in turn (user i joins the (i mod count)-th).
    #[arg(long, value_name = "A,B,..", value_delimiter = ',')]
    pub rooms: Vec<String>,
    /// Every user's simulated user, as kinloop-client's --user: a hand soft|firm|release|poke touring its
    /// OP's reach, a path, a constant wrench, paper (default: soft and firm hands in turn).
    #[arg(long, value_name = "SPEC")]
    pub hand: Option<UserSpec>,
    /// Seconds each user's loop runs.
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = parse_seconds)]
    pub duration: f64,
    /// Haptic loop rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// Ask SCHED_FIFO for the one clock thread that steps every user's loop.
    #[arg(long)]
    pub realtime: bool,
    /// Worker threads of the one runtime every user's network side shares.
    #[arg(long, value_name = "N", default_value_t = load::NETWORK_THREADS, value_parser = parse_net_threads)]
    pub net_threads: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Longest load `--duration` accepts: a day.
const MAX_DURATION_S: f64 = 86_400.0;

fn parse_users(s: &str) -> Result<usize, String> {
    super::parse_user_count(s, MAX_USERS)
}

fn parse_net_threads(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=16).contains(&n) => Ok(n),
        _ => Err(format!("{s:?}: worker threads, 1 to 16")),
    }
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v <= MAX_DURATION_S => Ok(v),
        _ => Err(format!("{s:?}: seconds, more than 0 and at most {MAX_DURATION_S}")),
    }
}

/// The options `args` ask for.
pub fn options(args: &LoadArgs) -> Result<LoadOptions> {
    let trust = match (&args.ca, &args.fingerprint) {
        (Some(file), None) => Trust::CaFile(file.clone()),
        (None, Some(hex)) => Trust::Fingerprint(hex.clone()),
        _ => anyhow::bail!("say how to trust the server: --ca FILE or --fingerprint HEX"),
    };
    anyhow::ensure!(
        args.rate.is_finite() && (10.0..=20_000.0).contains(&args.rate),
        "--rate {}: between 10 and 20000 Hz",
        args.rate
    );
    let mut options = LoadOptions::new(args.server.clone(), trust, args.users);
    options.server_name = args.server_name.clone();
    options.token = args.token.clone();
    options.rooms = match &args.room {
        Some(room) => vec![room.clone()],
        None => args.rooms.clone(),
    };
    options.user = args.hand.clone();
    options.duration = Duration::from_secs_f64(args.duration);
    options.rate_hz = args.rate;
    options.realtime = args.realtime;
    options.network_threads = args.net_threads;
    Ok(options)
}

/// Runs the load and reports; an error only when nothing could start (each user's own refusal is part of
/// the report).
pub fn run(args: &LoadArgs) -> Result<()> {
    let summary = load::run(&options(args)?)?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print!("{}", human(&summary));
    }
    anyhow::ensure!(summary.rendered > 0, "no user rendered");
    Ok(())
}

/// The outcome for people.
pub fn human(s: &LoadSummary) -> String {
    let cpu = s.cpu_cores.map_or_else(|| "n/a".into(), |c| format!("{:.2} cores", c));
    let mut out = format!(
        "kinloop load: {} of {} users rendered for {:.1} s at {:.0} Hz on one clock ({} refused); the load process used {cpu}\n",
        s.rendered, s.users, s.duration_s, s.rate_hz, s.refused
    );
    for u in &s.per_user {
        match &u.error {
            Some(why) => out += &format!("  {} (room {:?}): {why}\n", u.name, u.room),
            None => {
                out += &format!(
                    "  {} (room {:?}, user {}, {}): lateness p99 {:.0} µs, device-LM rms {:.2} mm, clamped {:.1} %, uplinks lost {:.2} %, {} snapshots\n",
                    u.name,
                    u.room,
                    u.user_id.unwrap_or_default(),
                    u.op.as_deref().unwrap_or("?"),
                    u.lateness_us_p99,
                    u.device_lm_rms_mm,
                    u.clamped_fraction * 100.0,
                    u.uplink_loss * 100.0,
                    u.snapshots_received
                )
            }
        }
    }
    out
}

/// `kinloop load` as a program of its own (the arguments without `kinloop load`): tests run it in a child
/// process, as they run kinloop-server's and kinloop-client's `main`.
pub fn main<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    #[derive(Parser, Debug)]
    #[command(name = "kinloop load")]
    struct Program {
        #[command(flatten)]
        load: LoadArgs,
    }
    match Program::try_parse_from(args) {
        Ok(program) => kinloop_process::report::run_program("error", || run(&program.load)),
        Err(e) => {
            let _ = e.print();
            ExitCode::from(2)
        }
    }
}
