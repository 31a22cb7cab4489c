//! `robustness`: does kinloop hold on linkages it was never tuned on? Generated linkages ([`generate`],
//! seeds `--seeds A..B`) × every operational point × the simulated devices matching the scene's kind
//! (`sim:paper`, `sim:falcon`, `sim:touch` planar; the last two spatial) × hands {soft, firm, release, poke}
//! touring the OP's reach × one-way delay {0, 50, 300, 1000 ms} with a tenth of it as jitter, each a
//! virtual-time session of [`SECONDS`] (the whole tour), with what `kinloop-client` does by default.
//!
//! A session **fails** for each of these that holds (the robustness goals):
//! - **refused**: the harness could not start it (its join was refused, or the scene did not compile); a
//!   join refused by the load rule stated in advance (`design::check_holdable`, docs/robustness.md) is
//!   counted apart, as **refused (predicted)**;
//! - **unstable**: the one criterion of [`verdict`] (energy growth, a saturation limit cycle, divergence,
//!   which includes VE restores and non-finite values). Sessions with a window as saturated whose clamped
//!   command turned round fewer than twice (a hand pushing harder than the device renders, held at its limit:
//!   [`Outcome::held_at_limit`]) are not unstable; they are counted in the answer and `summary.json`
//!   (`held_at_limit`), and their clamped ticks count against the saturation bound below;
//! - **closure**: the loops opened by more than [`CLOSURE_RELATIVE`] of the scene's length scale;
//! - **saturation**: more than [`CLAMPED_BOUND`] of the device's ticks clamped at its limit;
//! - **tracking**: device-OP RMS (device space) above [`RMS_PERFECT_M`] at 0 ms, [`RMS_DELAYED_M`] at
//!   50 ms, and above [`UNHEARD_FACTOR`] times the unheard-motion floor (how far the device moved since
//!   the pose the VE had heard of, as `latency` reports it) at 300 ms and 1 s.
//!
//! `summary.json` lists every failure with its seed and reasons, and what the sample covered (classes, unit
//! systems, OP counts, near-singular linkages, extras), so that a narrow sample cannot pass unnoticed.
//!
//! [`generate`]: crate::generate
//! [`verdict`]: super::verdict

use std::collections::BTreeMap;
use std::ops::Range;
use std::time::Duration;

use anyhow::Result;
use serde::Serialize;
use serde_json::json;

use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::HandKind;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind, math::space::Spatial, model::Model};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_server::core::design::PREDICTED_REFUSAL;

use super::common::{session, sweep, touring_plan, Options, Output, Report};
use super::renderability::{CLAMPED_BOUND, DEVICES, RMS_DELAYED_M, RMS_PERFECT_M};
use super::verdict::judge;
use crate::charts::HeatMap;
use crate::generate::{generate, Class, Generated};
use crate::rounding::{num, round};
use kinloop_harness::SessionPlan;

/// Largest closure error of a session, as a fraction of the scene's length scale.
pub const CLOSURE_RELATIVE: f64 = 1e-6;
/// At 300 ms and 1 s, the device-OP RMS may be this many times the unheard-motion floor.
pub const UNHEARD_FACTOR: f64 = 1.2;
/// One-way delays of the matrix (ms).
pub const DELAYS_MS: [u64; 4] = [0, 50, 300, 1000];
/// Length of a session (s): the touring hand's whole tour there and back (see `renderability::SECONDS`).
pub const SECONDS: f64 = 40.0;
/// The failure class of a join refused by the load rule stated in advance (`design::check_holdable`).
pub const PREDICTED_CLASS: &str = "refused (predicted)";
/// The seeds `experiment robustness` runs without `--seeds`: the fixed sample CI runs with `--quick`.
pub const DEFAULT_SEEDS: Range<u64> = 1..4;

/// One session of the matrix.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Point {
    /// Generator seed.
    pub seed: u64,
    /// Operational point.
    pub op: String,
    /// Device.
    pub device: DevicePreset,
    /// Hand.
    pub hand: HandKind,
    /// One-way delay (ms); the jitter is a tenth of it.
    pub delay_ms: u64,
}

impl Point {
    /// The emulated link of this point (each direction).
    pub fn link(&self) -> LinkConfig {
        LinkConfig {
            delay: Duration::from_millis(self.delay_ms),
            jitter: Duration::from_millis(self.delay_ms / 10),
            seed: 0x5eed ^ self.seed,
            ..LinkConfig::default()
        }
    }
}

/// What one session measured and why it failed, if it did.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    /// The session.
    pub point: Point,
    /// Why it failed (empty: it rendered).
    pub failures: Vec<String>,
    /// Stable by the criterion (false when refused).
    pub stable: bool,
    /// VE state restores.
    pub ve_restores: u64,
    /// Fraction of active ticks clamped.
    pub clamped_fraction: f64,
    /// Device-OP RMS, device space (m).
    pub device_op_rms_m: f64,
    /// The unheard-motion floor, device space (m).
    pub device_unheard_rms_m: f64,
    /// Largest closure error over the scene's length scale.
    pub closure_relative: f64,
    /// The energy criterion's largest excess (scene units).
    pub energy_excess: f64,
    /// The most turns of the clamped command in a saturated second (`Verdict::saturation_turns`).
    pub saturation_turns: usize,
    /// A second was saturated but its clamped command turned round fewer than twice: a push held at the limit
    /// (`Verdict::held_at_limit`), not a limit cycle.
    pub held_at_limit: bool,
}

/// Every session for the linkages of `seeds` (each generated once, in `linkages`).
pub fn points(linkages: &[Generated], hands: &[HandKind], delays: &[u64]) -> Vec<Point> {
    let mut out = Vec::new();
    for g in linkages {
        for op in &g.scene.ops {
            for device in DEVICES {
                if g.scene.kind == SceneKind::Spatial && device == DevicePreset::Paper {
                    continue;
                }
                for &hand in hands {
                    for &delay_ms in delays {
                        out.push(Point { seed: g.seed, op: op.name.clone(), device, hand, delay_ms });
                    }
                }
            }
        }
    }
    out
}

/// The scene's length scale (what closure is judged against), or why it does not compile.
pub(crate) fn length_scale(g: &Generated) -> Result<f64, String> {
    let compiled = match g.scene.kind {
        SceneKind::Planar => Model::<Planar>::compile(&g.scene, &g.scene.name).map(|m| m.length_scale),
        SceneKind::Spatial => Model::<Spatial>::compile(&g.scene, &g.scene.name).map(|m| m.length_scale),
    };
    compiled.map_err(|e| e.to_string())
}

/// The session `point` runs on `g`'s linkage for `seconds`, every tick recorded, with the default VE.
pub fn session_plan(g: &Generated, point: &Point, seconds: f64) -> SessionPlan {
    touring_plan(g.scene.clone(), &point.op, point.device, point.hand, point.link(), seconds)
}

/// Runs one session for `seconds` on the linkage `g` and judges it.
pub fn evaluate(g: &Generated, point: &Point, seconds: f64) -> Outcome {
    let refused = |why: String| Outcome {
        point: point.clone(),
        // A refusal by the rule stated in advance (`design::check_holdable`) is counted apart from the others.
        failures: vec![if why.contains(PREDICTED_REFUSAL) {
            format!("{PREDICTED_CLASS}: {why}")
        } else {
            format!("refused: {why}")
        }],
        stable: false,
        ve_restores: 0,
        clamped_fraction: f64::NAN,
        device_op_rms_m: f64::NAN,
        device_unheard_rms_m: f64::NAN,
        closure_relative: f64::NAN,
        energy_excess: f64::NAN,
        saturation_turns: 0,
        held_at_limit: false,
    };
    let scale = match length_scale(g) {
        Ok(scale) => scale,
        Err(why) => return refused(why),
    };
    let plan = session_plan(g, point, seconds);
    let (summary, rec) = match session(&plan) {
        Ok(ran) => ran,
        Err(e) => return refused(format!("{e:#}")),
    };
    let verdict = judge(&summary, &rec);
    let Some(c) = summary.clients.first() else { return refused("the session had no client".into()) };
    let closure_relative = summary.max_closure_error / scale;
    let mut failures: Vec<String> = verdict.reasons.iter().map(|r| format!("unstable: {r}")).collect();
    failures.extend(bound_failures(
        point.delay_ms,
        closure_relative,
        c.saturated_fraction,
        c.device_op_rms_m,
        c.device_unheard_rms_m,
    ));
    Outcome {
        point: point.clone(),
        failures,
        stable: verdict.stable,
        ve_restores: summary.ve_restores,
        clamped_fraction: c.saturated_fraction,
        device_op_rms_m: c.device_op_rms_m,
        device_unheard_rms_m: c.device_unheard_rms_m,
        closure_relative,
        energy_excess: verdict.energy_excess_j,
        saturation_turns: verdict.saturation_turns,
        held_at_limit: verdict.held_at_limit,
    }
}

/// The bounds beyond stability a session at one-way `delay_ms` is held to: closure (its largest error over
/// the length scale), clamped ticks, and device-OP RMS (device space, m) against the delay's bound, at 300 ms
/// and beyond [`UNHEARD_FACTOR`] times the unheard-motion floor `unheard_rms_m`. NaN fails.
pub fn bound_failures(
    delay_ms: u64,
    closure_relative: f64,
    clamped_fraction: f64,
    rms_m: f64,
    unheard_rms_m: f64,
) -> Vec<String> {
    let mut failures = Vec::new();
    if closure_relative.is_nan() || closure_relative > CLOSURE_RELATIVE {
        failures.push(format!("closure: {closure_relative:.1e} of the length scale"));
    }
    if clamped_fraction.is_nan() || clamped_fraction > CLAMPED_BOUND {
        failures.push(format!("saturation: {:.1} % clamped", clamped_fraction * 100.0));
    }
    let rms_bound = match delay_ms {
        0 => RMS_PERFECT_M,
        d if d <= 50 => RMS_DELAYED_M,
        _ => UNHEARD_FACTOR * unheard_rms_m,
    };
    if rms_m.is_nan() || rms_m > rms_bound {
        failures.push(format!("tracking: RMS {:.1} mm > {:.1} mm", rms_m * 1e3, rms_bound * 1e3));
    }
    failures
}

/// The class of a failure reason (its words before the colon).
fn failure_class(reason: &str) -> &str {
    reason.split(':').next().unwrap_or(reason)
}

/// Runs the experiment on the default seeds (see [`run_seeds`]).
pub fn run(options: &Options) -> Result<Report> {
    run_seeds(options, DEFAULT_SEEDS)
}

/// Runs the experiment on the linkages of `seeds`. `--quick` keeps the soft hand and delays 0 and 300 ms,
/// with 10 s sessions.
pub fn run_seeds(options: &Options, seeds: Range<u64>) -> Result<Report> {
    let out = Output::new("robustness", options)?;
    let linkages: Vec<Generated> = seeds.clone().map(|s| generate(s, None)).collect();
    let hands: &[HandKind] = if options.quick { &[HandKind::Soft] } else { &HandKind::ALL };
    let delays: &[u64] = if options.quick { &[0, 300] } else { &DELAYS_MS };
    let seconds = options.session_seconds(SECONDS, 10.0);
    let all = points(&linkages, hands, delays);
    let by_seed: BTreeMap<u64, &Generated> = linkages.iter().map(|g| (g.seed, g)).collect();
    let outcomes =
        sweep("robustness", &all, options.threads, options.progress, |p| Ok(evaluate(by_seed[&p.seed], p, seconds)))?;
    report(out, &linkages, &outcomes, seeds, seconds)
}

/// What the sample covered: counts per class, unit system, extra, and of near-singular linkages and OPs.
fn coverage(linkages: &[Generated]) -> serde_json::Value {
    let mut classes: BTreeMap<String, usize> = Class::ALL.iter().map(|c| (c.name().to_string(), 0)).collect();
    let mut units: BTreeMap<String, usize> = BTreeMap::new();
    let mut extras: BTreeMap<&str, usize> = BTreeMap::new();
    for g in linkages {
        *classes.entry(g.class.name().to_string()).or_default() += 1;
        *units.entry(g.units.to_string()).or_default() += 1;
        for e in &g.extras {
            *extras.entry(e).or_default() += 1;
        }
    }
    let near: Vec<&Generated> = linkages.iter().filter(|g| g.near_singular).collect();
    json!({
        "linkages": linkages.len(),
        "classes": classes,
        "min_per_class": classes.values().min().copied().unwrap_or(0),
        "unit_systems": units,
        "extras": extras,
        "ops": linkages.iter().map(|g| g.scene.ops.len()).sum::<usize>(),
        "near_singular_linkages": near.len(),
        "near_singular_ops": near.iter().map(|g| g.scene.ops.len()).sum::<usize>(),
    })
}

/// Charts and `summary.json`.
fn report(
    mut out: Output,
    linkages: &[Generated],
    outcomes: &[Outcome],
    seeds: Range<u64>,
    seconds: f64,
) -> Result<Report> {
    let class_of: BTreeMap<u64, &Generated> = linkages.iter().map(|g| (g.seed, g)).collect();
    let rows: Vec<String> = Class::ALL.iter().map(|c| c.name().to_string()).collect();
    let columns: Vec<String> = DELAYS_MS.iter().map(|d| format!("{d} ms")).collect();
    let mut rendered =
        HeatMap::new("Sessions that render (%), by class and one-way delay", rows.clone(), columns.clone());
    let mut tallies: BTreeMap<(usize, usize), (usize, usize)> = BTreeMap::new();
    for o in outcomes {
        let row = Class::ALL.iter().position(|c| *c == class_of[&o.point.seed].class).unwrap_or(0);
        let column = DELAYS_MS.iter().position(|d| *d == o.point.delay_ms).unwrap_or(0);
        let t = tallies.entry((row, column)).or_default();
        t.0 += usize::from(o.failures.is_empty());
        t.1 += 1;
    }
    for ((row, column), (good, total)) in &tallies {
        rendered.set(*row, *column, 100.0 * *good as f64 / *total as f64, good == total);
    }
    out.heat_map("render_by_class_and_delay", &rendered)?;
    let mut classes_failed: BTreeMap<&str, usize> = BTreeMap::new();
    for o in outcomes {
        let mut seen: Vec<&str> = o.failures.iter().map(|f| failure_class(f)).collect();
        seen.dedup();
        for c in seen {
            *classes_failed.entry(c).or_default() += 1;
        }
    }
    let rendering = outcomes.iter().filter(|o| o.failures.is_empty()).count();
    let refused_by =
        |class: &str| outcomes.iter().filter(|o| o.failures.iter().any(|f| failure_class(f) == class)).count();
    let (refused, predicted) = (refused_by("refused"), refused_by(PREDICTED_CLASS));
    let unstable = outcomes.iter().filter(|o| !o.stable).count() - refused - predicted;
    let held = outcomes.iter().filter(|o| o.held_at_limit).count();
    let failing: Vec<_> = outcomes
        .iter()
        .filter(|o| !o.failures.is_empty())
        .map(|o| {
            let g = class_of[&o.point.seed];
            json!({
                "seed": o.point.seed, "class": g.class.name(), "units": g.units.to_string(),
                "near_singular": g.near_singular, "op": o.point.op, "device": o.point.device.name(),
                "hand": o.point.hand.name(), "delay_ms": o.point.delay_ms, "failures": o.failures,
                "clamped_fraction": round(o.clamped_fraction, 4), "device_op_rms_mm": round(o.device_op_rms_m * 1e3, 3),
                "device_unheard_rms_mm": round(o.device_unheard_rms_m * 1e3, 3),
                "saturation_turns": o.saturation_turns, "held_at_limit": o.held_at_limit,
            })
        })
        .collect();
    let answer = format!(
        "{rendering} of {} sessions render on seeds {}..{} ({} unstable; {held} held a push at the device's limit \
         for a second, by itself not unstable; {refused} refused, {predicted} refused by the stated load rule); failures by \
         kind: {}",
        outcomes.len(),
        seeds.start,
        seeds.end,
        unstable,
        if classes_failed.is_empty() {
            "none".to_string()
        } else {
            classes_failed.iter().map(|(k, n)| format!("{k} {n}")).collect::<Vec<_>>().join(", ")
        }
    );
    let worst_rms = outcomes.iter().map(|o| o.device_op_rms_m).filter(|x| x.is_finite()).fold(0.0, f64::max);
    out.finish(
        "Generated linkages with default settings",
        "about a minute per linkage on 2 cores",
        json!({
            "answer": answer,
            "seeds": [seeds.start, seeds.end],
            "seconds_per_session": seconds,
            "sessions": outcomes.len(),
            "rendering": rendering,
            "unstable": unstable,
            "held_at_limit": held,
            "refused": refused,
            "refused_predicted": predicted,
            "failures_by_kind": classes_failed,
            "worst_rms_mm": num(worst_rms * 1e3),
            "coverage": coverage(linkages),
            "bounds": {"closure_of_length_scale": CLOSURE_RELATIVE, "clamped_fraction": CLAMPED_BOUND,
                "rms_0ms_m": RMS_PERFECT_M, "rms_50ms_m": RMS_DELAYED_M, "unheard_factor_300ms_1s": UNHEARD_FACTOR},
            "failing": failing,
        }),
    )
}
