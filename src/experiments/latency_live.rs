//! `latency-live`: the delay experiment's scenes and devices in real time over loopback QUIC, each point a
//! whole demo (VE server and one simulated-device client as real processes' threads) judged by the same
//! criterion as the virtual-time points.

use std::time::Duration;

use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::json;

use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec, Intent};
use kinloop_protocol::emulator::LinkConfig;

use super::common::{sweep, Options, Output, Report};
use super::delay_point::{goal_circle, GOAL_RMS_100MS_M, GOAL_RMS_1S_M, SECONDS, TARGETS};
use crate::charts::HeatMap;

/// One-way delays of the real-time run (ms), each with [`LIVE_JITTER_MS`] of jitter each way.
pub const LIVE_DELAYS_MS: [f64; 4] = [100.0, 300.0, 500.0, 1000.0];
/// Jitter of the real-time run (ms).
pub const LIVE_JITTER_MS: f64 = 10.0;
/// Devices of the real-time run.
pub const LIVE_DEVICES: [DevicePreset; 2] = [DevicePreset::Paper, DevicePreset::Falcon];
/// The hand of the real-time run's circle rows.
const LIVE_CIRCLE_HAND: &str = "soft on path:circle:0.005,2";
/// The real-time run's bound on the fraction of ticks clamped at the device's limit.
pub const LIVE_CLAMPED_BOUND: f64 = 0.05;
/// ... and on the loops' closure (m).
pub const LIVE_CLOSURE_BOUND_M: f64 = 1e-6;

/// A point of the real-time run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LivePoint {
    /// Index into [`TARGETS`].
    pub target: usize,
    /// The device.
    pub device: DevicePreset,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// The soft hand on the 5 mm goal circle ([`goal_circle`]) instead of the demo's default hand and tour.
    pub on_circle: bool,
}

/// What a real-time session measured.
#[derive(Clone, Debug, Serialize)]
pub struct LiveMeasured {
    /// `scene:op`.
    pub target: String,
    /// Device preset name.
    pub device: &'static str,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// The hand: the demo's default, or the soft hand on the 5 mm goal circle.
    pub hand: &'static str,
    /// VE state restores.
    pub ve_restores: u64,
    /// Snapshots the VE withheld as out of the wire's range.
    pub snapshots_withheld: u64,
    /// Largest closure error (m).
    pub max_closure_error_m: f64,
    /// Fraction of the client's ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Non-finite values the client's safety layer refused.
    pub non_finite: f64,
    /// Device-OP RMS, device space (mm).
    pub device_op_rms_mm: Option<f64>,
    /// Meets the goal: no restore, nothing withheld or non-finite, closure and clamped ticks within bounds.
    pub meets: bool,
    /// Why the server says the session ended: the client's close should reach it before the server shuts
    /// down, over any delay ("room closed" means it never did and the server's drain waited for it).
    pub server_session_end: Option<&'static str>,
}

/// Runs one point of the real-time run: a `kinloop demo` session (server and client on real threads over
/// loopback QUIC through the emulated link, default flags) of `seconds`.
pub fn measure_live(p: &LivePoint, seconds: f64, scratch: &std::path::Path) -> Result<LiveMeasured> {
    let (scene, op, _) = TARGETS[p.target];
    let ms = |v: f64| Duration::from_secs_f64(v / 1000.0);
    let link = LinkConfig {
        delay: ms(p.delay_ms),
        jitter: ms(LIVE_JITTER_MS),
        seed: 0x11fe + p.delay_ms as u64,
        ..LinkConfig::default()
    };
    let hand = p.on_circle.then(|| HandSpec { kind: HandKind::Soft, intent: Intent::Path(goal_circle()) });
    let o = super::renderability::demo_options(scene, op, p.device, hand, link, seconds, scratch)?;
    let report = crate::demo::run(&o).with_context(|| format!("{scene}:{op} {} {} ms", p.device.name(), p.delay_ms))?;
    let s = &report.summary;
    let counts = super::renderability::LiveCounts::of(&report)?;
    let (clamped_fraction, non_finite) = (counts.clamped_fraction, counts.non_finite);
    let meets = counts.stable && s.max_closure_error <= LIVE_CLOSURE_BOUND_M && clamped_fraction <= LIVE_CLAMPED_BOUND;
    Ok(LiveMeasured {
        target: format!("{scene}:{op}"),
        device: p.device.name(),
        delay_ms: p.delay_ms,
        hand: if p.on_circle { LIVE_CIRCLE_HAND } else { "default (soft, touring)" },
        ve_restores: s.ve_restores,
        snapshots_withheld: s.snapshots_withheld,
        max_closure_error_m: s.max_closure_error,
        clamped_fraction,
        non_finite,
        device_op_rms_mm: counts.user.device_op_rms_mm,
        meets,
        server_session_end: report.summary.per_user.first().and_then(|u| u.server.as_ref()).and_then(|s| s.ended),
    })
}

/// `latency-live`: the real-process goal, three scenes × two devices × one-way delay {100, 300, 500,
/// 1000 ms} with 10 ms jitter each way, each a 10 s real-time session with default flags (3 s, testbed only,
/// with `--quick`), one at a time, and the testbed on `sim:paper` with the soft hand on the 5 mm goal
/// circle ([`goal_circle`]) at each delay, where its tracking goals are read. A point meets the goal with no
/// VE restore, no withheld snapshot, nothing non-finite, closure within 1e-6 m and at most 5 % of the client's
/// ticks clamped at the device's limit.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("latency-live", options)?;
    let targets: &[usize] = if options.quick { &[0] } else { &[0, 1, 2] };
    let mut points = Vec::new();
    for &target in targets {
        for device in LIVE_DEVICES {
            for delay_ms in LIVE_DELAYS_MS {
                points.push(LivePoint { target, device, delay_ms, on_circle: false });
            }
        }
    }
    // The tracking goals on the motion they were set on, in real processes.
    for delay_ms in LIVE_DELAYS_MS {
        points.push(LivePoint { target: 0, device: DevicePreset::Paper, delay_ms, on_circle: true });
    }
    let seconds = options.session_seconds(SECONDS, 3.0);
    let scratch = std::env::temp_dir().join("kinloop-latency-live");
    let all = sweep("latency-live", &points, 1, options.progress, |p| measure_live(p, seconds, &scratch))?;
    let rows: Vec<String> = targets
        .iter()
        .flat_map(|&t| LIVE_DEVICES.iter().map(move |d| format!("{} {}", TARGETS[t].2, d.name())))
        .chain(std::iter::once(format!("{} {} circle", TARGETS[0].2, DevicePreset::Paper.name())))
        .collect();
    let columns: Vec<String> = LIVE_DELAYS_MS.iter().map(|d| format!("{d} ms")).collect();
    let mut clamped =
        HeatMap::new("Ticks clamped at the device limit (%), real time, 10 ms jitter", rows.clone(), columns.clone());
    let mut tracking = HeatMap::new("Device-OP RMS (mm, device space), real time, 10 ms jitter", rows, columns);
    for (i, m) in all.iter().enumerate() {
        let (row, column) = (i / LIVE_DELAYS_MS.len(), i % LIVE_DELAYS_MS.len());
        clamped.set(row, column, m.clamped_fraction * 100.0, m.meets);
        tracking.set(row, column, m.device_op_rms_mm.unwrap_or(f64::NAN), m.meets);
    }
    out.heat_map("clamped_fraction", &clamped)?;
    out.heat_map("tracking_rms", &tracking)?;
    let meeting = all.iter().filter(|m| m.meets).count();
    let failing: Vec<String> = all
        .iter()
        .filter(|m| !m.meets)
        .map(|m| {
            format!(
                "{} {} {} {} ms: {} restores, {:.1} % clamped, closure {:.1e} m",
                m.target,
                m.device,
                m.hand,
                m.delay_ms,
                m.ve_restores,
                m.clamped_fraction * 100.0,
                m.max_closure_error_m
            )
        })
        .collect();
    let circle_mm = |delay_ms: f64| {
        all.iter().find(|m| m.hand == LIVE_CIRCLE_HAND && m.delay_ms == delay_ms).and_then(|m| m.device_op_rms_mm)
    };
    let (circle_100, circle_1000) = (circle_mm(100.0), circle_mm(1000.0));
    let answer = format!(
        "{meeting} of {} real-time sessions meet the goal (no VE restore, closure <= 1e-6 m, <= 5 % of ticks clamped){}. \
         Testbed, sim:paper, {LIVE_CIRCLE_HAND}: device-OP RMS {} mm at 100 ms (goal 3), {} mm at 1 s (goal 25).",
        all.len(),
        if failing.is_empty() { String::new() } else { format!("; not: {}", failing.join("; ")) },
        circle_100.map_or("n/a".into(), |r| format!("{r:.2}")),
        circle_1000.map_or("n/a".into(), |r| format!("{r:.2}")),
    );
    let results = json!({
        "answer": answer,
        "goal_met": meeting == all.len(),
        "testbed_goal_circle_device_op_rms_mm": {"100ms": circle_100, "1000ms": circle_1000},
        "testbed_goal_circle_tracking_goal_met": circle_100.zip(circle_1000)
            .map(|(a, b)| a <= GOAL_RMS_100MS_M * 1e3 && b <= GOAL_RMS_1S_M * 1e3),
        "setup": {
            "session": "kinloop demo: a server and one client on real threads over loopback QUIC through the emulated link, default flags (the scene's OP, the device preset, the client's default hand)",
            "seconds": seconds,
            "jitter_ms": LIVE_JITTER_MS,
            "bounds": {"clamped_fraction": LIVE_CLAMPED_BOUND, "closure_m": LIVE_CLOSURE_BOUND_M},
        },
        "points": all,
    });
    out.finish(
        "The real-process goal: three scenes x two devices x delay, real time",
        "28 sessions of 10 s, one at a time; --quick fewer sessions of 3 s",
        results,
    )
}
