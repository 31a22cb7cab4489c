//! `renderability`: does every shipped linkage feel right with default settings? Every scene × every
//! operational point × device {sim:paper, sim:falcon, sim:touch} × network {perfect, 50 ms one-way with
//! 5 ms jitter} × hand {soft, firm}, each a session of a simulated hand touring the OP's reach there and back
//! ([`SECONDS`]), with what `kinloop-client` does by default (the server's mapping and coupling gains, the
//! client's designed gains).
//!
//! A pair **renders** when it is stable by the one criterion ([`verdict`], which includes VE restores), its
//! loops stay closed (≤ [`CLOSURE_BOUND_M`]), no value goes non-finite, the device is clamped on at most
//! [`CLAMPED_BOUND`] of its ticks, and the device follows the VE's OP within [`RMS_PERFECT_M`] RMS on a
//! perfect network and [`RMS_DELAYED_M`] at 50 ms (device space: what the hand feels). Spatial scenes skip
//! `sim:paper`, which is planar.
//!
//! [`verdict`]: super::verdict

use std::time::Duration;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec};
use kinloop_linkage::{math::space::SceneKind, model::builtin};
use kinloop_protocol::emulator::LinkConfig;

use super::common::{session, sweep, touring_plan, Options, Output, Report};
use super::verdict::judge;
use crate::charts::HeatMap;
use crate::rounding::{num, round};
use kinloop_harness::{Recording, SessionPlan, SessionSummary};

/// Largest closure error of a rendering pair (m).
pub const CLOSURE_BOUND_M: f64 = 1e-6;
/// Largest fraction of ticks at the device's force limit.
pub const CLAMPED_BOUND: f64 = 0.05;
/// Largest device-OP RMS on a perfect network (m, device space).
pub const RMS_PERFECT_M: f64 = 0.005;
/// Largest device-OP RMS at 50 ms one-way (m, device space).
pub const RMS_DELAYED_M: f64 = 0.010;
/// The devices of the matrix.
pub const DEVICES: [DevicePreset; 3] = [DevicePreset::Paper, DevicePreset::Falcon, DevicePreset::Touch];

/// The network of a point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Network {
    /// No delay, no loss.
    Perfect,
    /// 50 ms one-way delay with 5 ms of jitter, each way.
    Delayed50,
}

impl Network {
    /// Both, in order.
    pub const ALL: [Network; 2] = [Network::Perfect, Network::Delayed50];

    /// Name in summaries and charts.
    pub fn name(self) -> &'static str {
        match self {
            Network::Perfect => "perfect",
            Network::Delayed50 => "50ms+5ms",
        }
    }

    /// The emulated link (each direction).
    pub fn link(self, seed: u64) -> LinkConfig {
        match self {
            Network::Perfect => LinkConfig::default(),
            Network::Delayed50 => LinkConfig {
                delay: Duration::from_millis(50),
                jitter: Duration::from_millis(5),
                seed,
                ..LinkConfig::default()
            },
        }
    }

    /// The RMS bound of this network.
    pub fn rms_bound(self) -> f64 {
        match self {
            Network::Perfect => RMS_PERFECT_M,
            Network::Delayed50 => RMS_DELAYED_M,
        }
    }
}

/// One pair of the matrix.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Point {
    /// The scene argument: a built-in scene's name, a scene file or an MJCF model.
    pub scene: String,
    /// Operational point.
    pub op: String,
    /// Device.
    pub device: DevicePreset,
    /// Network.
    pub network: Network,
    /// Hand.
    pub hand: HandKind,
}

/// What one pair measured.
#[derive(Clone, Debug, Serialize)]
pub struct PointResult {
    /// The pair.
    pub point: Point,
    /// Renders by every bound.
    pub renders: bool,
    /// Which bounds failed.
    pub failures: Vec<String>,
    /// Stable by the criterion.
    pub stable: bool,
    /// VE state restores.
    pub ve_restores: u64,
    /// Fraction of active ticks clamped at the device limit.
    pub clamped_fraction: f64,
    /// Device-OP RMS, device space (m).
    pub device_op_rms_m: f64,
    /// Largest closure error (m).
    pub max_closure_error_m: f64,
    /// The energy criterion's numbers (virtual time only): the largest excess of the linkage's energy over
    /// the hands' work, and the largest energy that had flowed (J).
    pub energy_excess_j: Option<f64>,
    /// See `energy_excess_j`.
    pub energy_flow_max_j: Option<f64>,
    /// Position scale chosen.
    pub position_scale: f64,
    /// Force scale chosen.
    pub force_scale: f64,
    /// K_g then B_g per axis.
    pub coupling: Vec<f64>,
    /// k_j, b_j, K_pc per axis, B_pc per axis (device units).
    pub gains: Vec<f64>,
}

/// Every (scene, operational point, the scene's kind) of `scenes` (all built-in scenes when empty; each a
/// scene argument: a built-in name, a scene file or an MJCF model, whose import decides its kind): the rows
/// of the matrices.
pub fn scene_ops(scenes: &[&str]) -> Result<Vec<(String, String, SceneKind)>> {
    let names: Vec<&str> =
        if scenes.is_empty() { builtin::SCENE_FILES.iter().map(|(n, _)| *n).collect() } else { scenes.to_vec() };
    let mut out = Vec::new();
    for name in names {
        let (scene, _) = kinloop_mjcf::load::load(name)?;
        out.extend(scene.ops.iter().map(|op| (name.to_owned(), op.name.clone(), scene.kind)));
    }
    Ok(out)
}

/// Every pair of the matrix for `scenes` (all built-in scenes with an operational point when empty).
pub fn points(scenes: &[&str], hands: &[HandKind]) -> Result<Vec<Point>> {
    let mut out = Vec::new();
    for (scene, op, kind) in scene_ops(scenes)? {
        for device in DEVICES {
            if kind == SceneKind::Spatial && device == DevicePreset::Paper {
                continue;
            }
            for network in Network::ALL {
                for &hand in hands {
                    out.push(Point { scene: scene.clone(), op: op.clone(), device, network, hand });
                }
            }
        }
    }
    Ok(out)
}

/// Runs one pair for `seconds` and judges it.
pub fn evaluate(point: &Point, seconds: f64) -> Result<PointResult> {
    let (summary, rec) = session(&plan(point, seconds)?)?;
    Ok(judged(point, &summary, &rec))
}

/// The session of one pair, `seconds` long: its one client a touring hand with default flags.
pub fn plan(point: &Point, seconds: f64) -> Result<SessionPlan> {
    let (scene, _) = kinloop_mjcf::load::load(&point.scene)?;
    Ok(touring_plan(scene, &point.op, point.device, point.hand, point.network.link(0x5eed), seconds))
}

/// A pair's session judged by every bound (see the module documentation).
pub fn judged(point: &Point, summary: &SessionSummary, rec: &Recording) -> PointResult {
    let verdict = judge(summary, rec);
    let c = &summary.clients[0];
    let mut failures = Vec::new();
    if !verdict.stable {
        failures.extend(verdict.reasons.iter().map(|r| r.to_string()));
    }
    if c.non_finite > 0 {
        failures.push("non-finite value".into());
    }
    failures.extend(bound_failures(summary.max_closure_error, c.saturated_fraction, c.device_op_rms_m, point.network));
    PointResult {
        point: point.clone(),
        renders: failures.is_empty(),
        failures,
        stable: verdict.stable,
        ve_restores: summary.ve_restores,
        clamped_fraction: c.saturated_fraction,
        device_op_rms_m: c.device_op_rms_m,
        max_closure_error_m: summary.max_closure_error,
        energy_excess_j: Some(verdict.energy_excess_j),
        energy_flow_max_j: Some(verdict.energy_flow_max_j),
        position_scale: c.position_scale,
        force_scale: c.force_scale,
        coupling: c.coupling.clone(),
        gains: c.gains.clone(),
    }
}

/// Length of a pair's session (s): long enough for the touring hand's whole tour, there and back, on every
/// shipped pair. A pair judged over less of its tour is judged on less of its reach, and misses the failures
/// that only the far end of a tour meets.
pub const SECONDS: f64 = 40.0;

/// Runs the experiment (see the module documentation).
pub fn run(options: &Options) -> Result<Report> {
    let out = Output::new("renderability", options)?;
    let all = points(&[], &HANDS)?;
    let seconds = options.session_seconds(SECONDS, 3.0);
    let results = sweep("renderability", &all, options.threads, options.progress, |p| evaluate(p, seconds))?;
    report(
        out,
        &results,
        seconds,
        "Every shipped linkage with default settings",
        "a 40 s session per point of the matrix; --quick fewer, shorter",
    )
}

/// `renderability-live`: the same matrix in real time, each pair a `kinloop demo` session (a server and one
/// client over loopback QUIC on real threads, the programs' own drivers, default flags) of 4 s (2 s with
/// `--quick`, which also keeps only the soft hand), one at a time. What the programs do, not what the
/// harness predicts: it catches what virtual time leaves out (a VE that ran before the join, the real
/// network stack, the loops' timing). The energy criterion needs the every-tick recording the harness
/// keeps, so here "stable" is no VE restore, no withheld snapshot and no non-finite value.
pub fn run_live(options: &Options) -> Result<Report> {
    let out = Output::new("renderability-live", options)?;
    let hands: &[HandKind] = if options.quick { &HANDS[..1] } else { &HANDS };
    let all = points(&[], hands)?;
    let seconds = options.session_seconds(4.0, 2.0);
    // Each session's records land in the system's temporary directory in turn (the last one stays there).
    let scratch = std::env::temp_dir().join("kinloop-renderability-live");
    let results = sweep("renderability-live", &all, 1, options.progress, |p| evaluate_live(p, seconds, &scratch))?;
    report(out, &results, seconds, "Every shipped linkage with default settings, in real time", "about 20 minutes")
}

/// The hands of the matrix.
const HANDS: [HandKind; 2] = [HandKind::Soft, HandKind::Firm];

/// Runs one pair in real time for `seconds` (records under `scratch`) and judges it by the same bounds.
pub fn evaluate_live(point: &Point, seconds: f64, scratch: &std::path::Path) -> Result<PointResult> {
    let options = live_options(point, seconds, scratch)?;
    let report = crate::demo::run(&options).with_context(|| format!("{} in real time", row_label(point)))?;
    judge_live(point, &report)
}

/// The demo session that runs `point` for `seconds` with default flags, records under `scratch`.
pub fn live_options(point: &Point, seconds: f64, scratch: &std::path::Path) -> Result<crate::demo::DemoOptions> {
    let link = point.network.link(0x5eed);
    demo_options(&point.scene, &point.op, point.device, Some(HandSpec::touring(point.hand)), link, seconds, scratch)
}

/// A `kinloop demo` session of one user holding built-in `scene`'s `op` on `device` with `hand` (`None`: the
/// demo's default) through `link`, for `seconds`, with its records under `scratch`: what the real-time runs
/// (`renderability-live`, `latency-live`) are made of.
pub fn demo_options(
    scene: &str,
    op: &str,
    device: DevicePreset,
    hand: Option<HandSpec>,
    link: LinkConfig,
    seconds: f64,
    scratch: &std::path::Path,
) -> Result<crate::demo::DemoOptions> {
    let mut o = crate::demo::DemoOptions::new(scratch)?;
    o.scene = builtin::scene(scene).context("built in")??;
    o.scene_label = scene.into();
    o.duration = Duration::from_secs_f64(seconds);
    o.progress = false;
    o.device = Some(device);
    o.first_op = Some(op.into());
    o.hand = hand;
    o.link = link;
    Ok(o)
}

/// What a real-time session's user measured that the live runs judge: stable (no VE restore, no withheld
/// snapshot, no non-finite value), the fraction of ticks clamped, and the non-finite events.
pub struct LiveCounts<'a> {
    /// The session's one user.
    pub user: &'a crate::demo::UserSummary,
    /// Stable as far as a session without an every-tick recording can tell.
    pub stable: bool,
    /// Fraction of the client's ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Non-finite values the client's safety layer refused.
    pub non_finite: f64,
}

impl<'a> LiveCounts<'a> {
    /// Reads them from a demo's report.
    pub fn of(report: &'a crate::demo::DemoReport) -> Result<Self> {
        let s = &report.summary;
        let user = s.per_user.first().context("the demo's user")?;
        let count = |key: &str| user.client[key].as_f64().unwrap_or(f64::NAN);
        let non_finite = count("non_finite_events");
        Ok(LiveCounts {
            user,
            stable: s.ve_restores == 0 && s.snapshots_withheld == 0 && non_finite == 0.0,
            clamped_fraction: count("clamped_ticks") / count("ticks").max(1.0),
            non_finite,
        })
    }
}

/// Judges a real-time session of `point` by the matrix's bounds. "Stable" here is no VE restore, no withheld
/// snapshot and no non-finite value (the energy criterion needs the harness's every-tick recording).
pub fn judge_live(point: &Point, report: &crate::demo::DemoReport) -> Result<PointResult> {
    let s = &report.summary;
    let LiveCounts { user: u, stable, clamped_fraction, non_finite } = LiveCounts::of(report)?;
    let device_op_rms_m = u.device_op_rms_mm.map_or(f64::NAN, |mm| mm * 1e-3);
    let mut failures = Vec::new();
    if !stable {
        failures.push(format!(
            "unstable: {} VE restores, {} snapshots withheld, {non_finite} non-finite events",
            s.ve_restores, s.snapshots_withheld
        ));
    }
    failures.extend(bound_failures(s.max_closure_error, clamped_fraction, device_op_rms_m, point.network));
    Ok(PointResult {
        point: point.clone(),
        renders: failures.is_empty(),
        failures,
        stable,
        ve_restores: s.ve_restores,
        clamped_fraction,
        device_op_rms_m,
        max_closure_error_m: s.max_closure_error,
        energy_excess_j: None,
        energy_flow_max_j: None,
        position_scale: u.position_scale,
        force_scale: u.force_scale,
        coupling: Vec::new(),
        gains: Vec::new(),
    })
}

/// The bounds every pair is held to beyond stability: closure, clamped ticks, tracking.
pub fn bound_failures(closure_m: f64, clamped: f64, rms_m: f64, network: Network) -> Vec<String> {
    let mut failures = Vec::new();
    if !within(closure_m, CLOSURE_BOUND_M) {
        failures.push(format!("closure {closure_m:.1e} m"));
    }
    if !within(clamped, CLAMPED_BOUND) {
        failures.push(format!("clamped {:.1} %", clamped * 100.0));
    }
    if !within(rms_m, network.rms_bound()) {
        failures.push(format!("RMS {:.1} mm", rms_m * 1e3));
    }
    failures
}

/// Charts and `summary.json` of a run of the matrix.
fn report(mut out: Output, results: &[PointResult], seconds: f64, title: &str, runtime_note: &str) -> Result<Report> {
    let hands = HANDS;
    let rows: Vec<String> = {
        let mut rows: Vec<String> = Vec::new();
        for r in results {
            let label = row_label(&r.point);
            if !rows.contains(&label) {
                rows.push(label);
            }
        }
        rows
    };
    let columns: Vec<String> =
        Network::ALL.iter().flat_map(|n| hands.iter().map(move |h| format!("{} {}", n.name(), h.name()))).collect();
    let cell = |r: &PointResult| {
        let row = rows.iter().position(|l| *l == row_label(&r.point)).unwrap_or(0);
        let column = columns.iter().position(|c| *c == format!("{} {}", r.point.network.name(), r.point.hand.name()));
        (row, column.unwrap_or(0))
    };
    let mut clamped =
        HeatMap::new("Ticks clamped at the device limit (%), default settings", rows.clone(), columns.clone());
    let mut tracking =
        HeatMap::new("Device-OP RMS (mm, device space), default settings", rows.clone(), columns.clone());
    for r in results {
        let (row, column) = cell(r);
        clamped.set(row, column, r.clamped_fraction * 100.0, r.clamped_fraction <= CLAMPED_BOUND);
        tracking.set(
            row,
            column,
            r.device_op_rms_m * 1e3,
            r.device_op_rms_m <= r.point.network.rms_bound() && r.stable,
        );
    }
    out.heat_map("clamped_fraction", &clamped)?;
    out.heat_map("tracking_rms", &tracking)?;
    let rendering = results.iter().filter(|r| r.renders).count();
    let failing: Vec<_> = results
        .iter()
        .filter(|r| !r.renders)
        .map(|r| FailingPair {
            pair: row_label(&r.point),
            network: r.point.network.name().into(),
            hand: r.point.hand.name().into(),
            failures: r.failures.clone(),
        })
        .collect();
    let worst_rms = results.iter().map(|r| r.device_op_rms_m).fold(0.0, f64::max);
    let worst_clamped = results.iter().map(|r| r.clamped_fraction).fold(0.0, f64::max);
    let answer = format!(
        "{rendering} of {} pairs render with default settings (stable, closure <= 1e-6 m, clamped <= 5 %, RMS <= 5 mm \
         perfect / 10 mm at 50 ms); worst clamped {} %, worst RMS {} mm",
        results.len(),
        num(worst_clamped * 100.0),
        num(worst_rms * 1e3)
    );
    out.finish(
        title,
        runtime_note,
        serde_json::to_value(RenderabilitySummary {
            answer,
            seconds_per_pair: seconds,
            pairs: results.len(),
            rendering,
            failing,
            bounds: RenderBounds {
                closure_m: CLOSURE_BOUND_M,
                clamped_fraction: CLAMPED_BOUND,
                rms_perfect_m: RMS_PERFECT_M,
                rms_50ms_m: RMS_DELAYED_M,
            },
            points: results.iter().map(point_summary).collect(),
        })?,
    )
}

/// `summary.json`'s `results` of the renderability matrix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderabilitySummary {
    /// The one-line answer.
    pub answer: String,
    /// Simulated seconds of each pair's session.
    pub seconds_per_pair: f64,
    /// Pairs run.
    pub pairs: usize,
    /// Pairs that render by every bound.
    pub rendering: usize,
    /// The pairs that do not, and why.
    pub failing: Vec<FailingPair>,
    /// The bounds a pair is judged by.
    pub bounds: RenderBounds,
    /// Every pair.
    pub points: Vec<RenderPoint>,
}

/// A pair that does not render.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FailingPair {
    /// `scene:op device`.
    pub pair: String,
    /// The network's name.
    pub network: String,
    /// The hand's name.
    pub hand: String,
    /// Which bounds failed.
    pub failures: Vec<String>,
}

/// The bounds of the matrix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderBounds {
    /// Largest closure error (m).
    pub closure_m: f64,
    /// Largest fraction of ticks clamped at the device limit.
    pub clamped_fraction: f64,
    /// Largest device-OP RMS on a perfect network (device m).
    pub rms_perfect_m: f64,
    /// Largest device-OP RMS at 50 ms one way (device m).
    pub rms_50ms_m: f64,
}

/// One pair's figures, as [`PointResult`] with names for the JSON.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderPoint {
    /// Scene.
    pub scene: String,
    /// Operational point.
    pub op: String,
    /// Device preset's name.
    pub device: String,
    /// Network's name.
    pub network: String,
    /// Hand's name.
    pub hand: String,
    /// See [`PointResult::renders`].
    pub renders: bool,
    /// See [`PointResult::failures`].
    pub failures: Vec<String>,
    /// See [`PointResult::stable`].
    pub stable: bool,
    /// See [`PointResult::ve_restores`].
    pub ve_restores: u64,
    /// See [`PointResult::clamped_fraction`] (4 decimals).
    pub clamped_fraction: f64,
    /// Device-OP RMS, device space (mm, 3 decimals).
    pub device_op_rms_mm: f64,
    /// See [`PointResult::max_closure_error_m`].
    pub max_closure_error_m: f64,
    /// See [`PointResult::energy_excess_j`].
    pub energy_excess_j: Option<f64>,
    /// See [`PointResult::energy_flow_max_j`].
    pub energy_flow_max_j: Option<f64>,
    /// See [`PointResult::position_scale`].
    pub position_scale: f64,
    /// See [`PointResult::force_scale`].
    pub force_scale: f64,
    /// K_g then B_g per axis.
    pub coupling_kg_bg: Vec<f64>,
    /// k_j, b_j, K_pc per axis, B_pc per axis (device units).
    pub gains_kj_bj_kpc_bpc: Vec<f64>,
}

fn point_summary(r: &PointResult) -> RenderPoint {
    RenderPoint {
        scene: r.point.scene.clone(),
        op: r.point.op.clone(),
        device: r.point.device.name().into(),
        network: r.point.network.name().into(),
        hand: r.point.hand.name().into(),
        renders: r.renders,
        failures: r.failures.clone(),
        stable: r.stable,
        ve_restores: r.ve_restores,
        clamped_fraction: round(r.clamped_fraction, 4),
        device_op_rms_mm: round(r.device_op_rms_m * 1e3, 3),
        max_closure_error_m: r.max_closure_error_m,
        energy_excess_j: r.energy_excess_j,
        energy_flow_max_j: r.energy_flow_max_j,
        position_scale: r.position_scale,
        force_scale: r.force_scale,
        coupling_kg_bg: r.coupling.clone(),
        gains_kj_bj_kpc_bpc: r.gains.clone(),
    }
}

fn row_label(p: &Point) -> String {
    format!("{}:{} {}", p.scene, p.op, p.device.name())
}

/// `value <= bound`, false for NaN: a figure that is not a number fails its bound.
fn within(value: f64, bound: f64) -> bool {
    value <= bound
}
