//! `kinloop demo [--users N] [--duration S] [--delay D] [--jitter J] [--loss L] [--seed N] [--scene FILE]
//! [--device NAME] [--op NAME] [--hand KIND] [--json] [--out DIR] [--view ADDR [--view-grab]]`: a server and N simulated-device clients over loopback QUIC in this process, in
//! real time (see [`crate::demo`]); prints a summary (one JSON object on stdout with `--json`) and writes
//! the charts, the records and `summary.json` into `DIR/demo/`.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use kinloop_client::device::{DeviceRequest, DhdRequest, HdRequest};
use kinloop_client::user::{HandKind, HandSpec};
use kinloop_protocol::emulator::{parse_duration, LinkArgs};

use kinloop_server::view::ViewConfig;

use crate::demo::{self, DemoOptions, DemoSummary, MAX_DURATION, MAX_USERS};
use crate::scene_arg::load_scene;

/// Arguments of `kinloop demo`. The link options are `kinloop-server`'s and `kinloop-client`'s; in the
/// demo both sides apply them to what they send, so `--delay 20ms` makes a 40 ms round trip.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Simulated users: each a client with `kinloop-client`'s defaults and a simulated hand (relaxed and firm
    /// in turn) touring its OP's reach, spread over the scene's operational points in turn.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = parse_users)]
    pub users: usize,
    /// How long the clients run: seconds (1.5) or with a unit (1500ms).
    #[arg(long, value_name = "S", default_value = "3", value_parser = parse_seconds)]
    pub duration: Duration,
    #[command(flatten)]
    pub link: LinkArgs,
    /// Scene file (TOML) or built-in name.
    #[arg(long, value_name = "FILE", default_value = "paper-testbed")]
    pub scene: String,
    /// Print the summary as one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Charts, records and summary.json go to DIR/demo/.
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub out: PathBuf,
    /// Do not ask for SCHED_FIFO for the VE and haptic threads.
    #[arg(long)]
    pub no_realtime: bool,
    /// Serve a web page on this TCP address that draws the session live (see `kinloop-server --view`);
    /// pass a longer --duration to watch it.
    #[arg(long, value_name = "ADDR")]
    pub view: Option<std::net::SocketAddr>,
    /// With --view, let the page grab an OP with the mouse.
    #[arg(long, requires = "view")]
    pub view_grab: bool,
    /// The users all hold the first operational point and share the paper's constant push (section VI)
    /// instead of touring with hands.
    #[arg(long)]
    pub paper_push: bool,
    /// The device every user holds: sim:paper, sim:falcon or sim:touch (default: the scene's, as
    /// `kinloop-client` picks it); or dhd[:INDEX] or hd[:NAME] (dhd,sim:NAME to fall back): the first user
    /// holds that Force Dimension or 3D Systems device, as `kinloop-client --device dhd|hd` does, the others
    /// the scene's simulated one.
    #[arg(long, value_name = "NAME")]
    pub device: Option<DeviceRequest>,
    /// With --device dhd: run drdAutoInit on an uncalibrated device (it moves on its own).
    #[arg(long)]
    pub dhd_auto_init: bool,
    /// With --device hd: run hdUpdateCalibration on a device that needs it.
    #[arg(long)]
    pub hd_calibrate: bool,
    /// The first user's operational point (default: the scene's first); further users take the next ones.
    #[arg(long, value_name = "NAME")]
    pub op: Option<String>,
    /// Every user's hand: soft, firm, release or poke (default: soft and firm in turn).
    #[arg(long, value_name = "KIND", value_parser = parse_hand)]
    pub hand: Option<HandKind>,
    /// Afterwards, run the same session in virtual time (same users, hands and join times, a link of the
    /// measured loopback round trip) and report each user's tracking there beside the real one's.
    #[arg(long)]
    pub twin: bool,
    /// Pin the server's real-time thread and network workers to the last CPU (as `kinloop-server
    /// --pin-network`): the VE's wake-up of the network side each round stays on one CPU.
    #[arg(long)]
    pub pin_network: bool,
}

fn parse_hand(s: &str) -> Result<HandKind, String> {
    HandKind::parse(s).ok_or_else(|| {
        let names: Vec<&str> = HandKind::ALL.iter().map(|k| k.name()).collect();
        format!("{s:?} is not a hand: one of {}", names.join(", "))
    })
}

fn parse_users(s: &str) -> Result<usize, String> {
    super::parse_user_count(s, MAX_USERS)
}

fn parse_seconds(s: &str) -> Result<Duration, String> {
    let parsed = match s.trim().parse::<f64>() {
        Ok(seconds) => Duration::try_from_secs_f64(seconds).map_err(|_| format!("{s:?} is not a number of seconds")),
        Err(_) => parse_duration(s).map_err(|e| e.to_string()),
    }?;
    if parsed.is_zero() || parsed > MAX_DURATION {
        return Err(format!("{s}: more than 0 s and at most {} s", MAX_DURATION.as_secs()));
    }
    Ok(parsed)
}

/// Runs the demo and reports.
pub fn run(args: &DemoArgs) -> Result<()> {
    let scene = load_scene(&args.scene)?;
    let options = DemoOptions {
        scene: scene.scene,
        scene_label: scene.label,
        users: args.users,
        duration: args.duration,
        link: args.link.config(),
        out: args.out.clone(),
        progress: true,
        ctrl_c: true,
        realtime: !args.no_realtime,
        view: args.view.map(|listen| ViewConfig { grab_without_token: args.view_grab, ..ViewConfig::new(listen) }),
        paper_push: args.paper_push,
        device: match &args.device {
            Some(DeviceRequest::Simulated(preset)) => Some(*preset),
            _ => None,
        },
        dhd: match &args.device {
            Some(DeviceRequest::Dhd(request)) => Some(DhdRequest { auto_init: args.dhd_auto_init, ..*request }),
            _ => None,
        },
        hd: match &args.device {
            Some(DeviceRequest::Hd(request)) => Some(HdRequest { calibrate: args.hd_calibrate, ..request.clone() }),
            _ => None,
        },
        first_op: args.op.clone(),
        hand: args.hand.map(HandSpec::touring),
        twin: args.twin,
        pin_network: args.pin_network,
    };
    let report = demo::run(&options).context("kinloop demo")?;
    if args.json {
        println!("{}", serde_json::to_string(&report.summary)?);
    } else {
        print!("{}", human(&report.summary));
        println!("charts, records and summary.json: {}", report.dir.display());
    }
    Ok(())
}

fn fmt_opt(v: Option<f64>, unit: &str, decimals: usize) -> String {
    v.map_or_else(|| "n/a".into(), |v| format!("{v:.decimals$} {unit}"))
}

/// The summary for people.
pub fn human(s: &DemoSummary) -> String {
    let link = if s.delay_ms == 0.0 && s.jitter_ms == 0.0 && s.loss == 0.0 {
        "no emulated impairment".to_string()
    } else {
        format!("each side adds {} ms ± {} ms, loses {:.1} %", s.delay_ms, s.jitter_ms, s.loss * 100.0)
    };
    let mut out = format!(
        "kinloop demo: {} user{} on {} over loopback QUIC ({link}), {:.1} s{}\n",
        s.users,
        if s.users == 1 { "" } else { "s" },
        s.scene,
        s.wall_s,
        if s.cancelled { ", stopped by Ctrl-C" } else { "" }
    );
    out += &format!(
        "  VE      {:.0} Hz, {} ticks: tick p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs; {} deadline misses; SCHED_FIFO {}\n",
        s.ve_rate_hz,
        s.ve_ticks,
        s.ve_tick_us_p50,
        s.ve_tick_us_p99,
        s.ve_tick_us_max,
        s.ve_deadline_misses,
        if s.ve_realtime_priority { "on" } else { "off" }
    );
    let st = &s.ve_stages;
    let us = |p: &kinloop_server::gateway::Percentiles| p.p50_ns as f64 / 1e3;
    out += &format!(
        "  VE tick stages (p50 µs): intake {:.2}, step {:.2}, snapshot terms {:.2}, encode {:.2}, ring push {:.2}, \
         wake {:.2}, events+record {:.2}, view {:.2}, stats {:.2}; VE thread CPU {}\n",
        us(&st.intake),
        us(&st.step),
        us(&st.snapshot_terms),
        us(&st.encode),
        us(&st.ring_push),
        us(&st.wake),
        us(&st.events_record),
        us(&st.view),
        us(&st.stats),
        s.ve_cpu_fraction.map_or("unknown".to_string(), |f| format!("{:.1} %", 100.0 * f)),
    );
    out += &format!(
        "  haptic  {} ticks: lateness p50 {:.1} µs, p99 {:.1} µs (worst user), max {:.1} µs; {} misses (> 500 µs late)\n",
        s.loop_ticks, s.loop_lateness_us_p50, s.loop_lateness_us_p99, s.loop_lateness_us_max, s.loop_misses
    );
    out += &format!(
        "  physics closure error ≤ {:.2e} m; largest force {:.1} % of the device limit; {} uplinks refused\n",
        s.max_closure_error,
        s.max_force_ratio * 100.0,
        s.uplinks_rejected
    );
    out += &format!("  network round trip p50 {}\n", fmt_opt(s.rtt_ms_p50, "ms", 2));
    for u in &s.per_user {
        let c = &u.client;
        out += &format!(
            "  {} (user {}, {}): rtt p50 {}, device-OP rms {} (max {}), force ratio {:.3}, snapshots {}\n",
            u.name,
            u.user_id,
            u.op,
            fmt_opt(c["rtt_ms_p50"].as_f64(), "ms", 2),
            fmt_opt(u.device_op_rms_mm, "mm", 2),
            fmt_opt(u.device_op_max_mm, "mm", 2),
            c["max_force_ratio"].as_f64().unwrap_or(f64::NAN),
            c["snapshots_received"]
        );
    }
    if let Some(t) = &s.twin {
        let rms: Vec<String> = t.device_op_rms_mm.iter().map(|r| format!("{r:.2}")).collect();
        out += &format!(
            "  twin    the same session in virtual time ({:.3} ± {:.3} ms one way): device-OP rms per user {} mm; {} restores\n",
            t.one_way_ms,
            t.jitter_ms,
            rms.join(", "),
            t.ve_restores
        );
    }
    out
}
