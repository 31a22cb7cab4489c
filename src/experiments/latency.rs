//! `latency`: the paper's manipulation over a bad network, with and without the VE's passivity
//! controller (time-domain passivity observer and damper on each coupling, `VeConfig::passivity`).
//!
//! Three sweeps, each with passivity off ("plain coupling") and on: one-way delay 0 to 500 ms (both
//! directions, no jitter, no loss); jitter (standard deviation of the per-packet delay) at 50 ms delay;
//! independent packet loss at 50 ms delay. Each point is an 8 s session of the paper's user and
//! device; the client knows the nominal one-way delay (its driver would measure it as half the RTT) and
//! predicts snapshots forward by it. Measured: the device–OP distance (tracking), the energy balance of the
//! criterion (linkage kinetic energy against the hand's work) and the couplings' energy account,
//! and the stability label of [`super::verdict`]. A delay "fails" when its point is unstable.

use std::time::Duration;

use anyhow::{Context, Result};
use kinloop_protocol::emulator::LinkConfig;
use serde::Serialize;
use serde_json::{json, Value};

use super::common::{paper_plan, round, session, significant, sweep, Options, Output, Report};
use super::verdict::{self, Verdict};
use crate::charts::{Chart, Legend, Series, StabilityMap};
use crate::harness::ClientPlan;

/// Delay of the jitter and loss sweeps (ms).
const BASE_DELAY_MS: f64 = 50.0;

/// What a sweep varies.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
enum Variable {
    /// One-way delay (ms).
    Delay,
    /// Jitter (ms) at [`BASE_DELAY_MS`].
    Jitter,
    /// Loss probability at [`BASE_DELAY_MS`].
    Loss,
}

impl Variable {
    fn axis(self) -> &'static str {
        match self {
            Variable::Delay => "one-way delay (ms)",
            Variable::Jitter => "jitter, std dev of the one-way delay (ms), at 50 ms delay",
            Variable::Loss => "packet loss (%), each direction, at 50 ms delay",
        }
    }

    fn link(self, value: f64, seed: u64) -> LinkConfig {
        let ms = |v: f64| Duration::from_secs_f64(v / 1000.0);
        match self {
            Variable::Delay => LinkConfig { delay: ms(value), seed, ..LinkConfig::default() },
            Variable::Jitter => {
                LinkConfig { delay: ms(BASE_DELAY_MS), jitter: ms(value), seed, ..LinkConfig::default() }
            }
            Variable::Loss => {
                LinkConfig { delay: ms(BASE_DELAY_MS), loss: value / 100.0, seed, ..LinkConfig::default() }
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Point {
    variable: Variable,
    value: f64,
    passivity: bool,
}

#[derive(Clone, Debug)]
struct Measured {
    point: Point,
    verdict: Verdict,
    device_op_rms_m: f64,
    device_model_rms_m: f64,
    passivity_absorbed_j: f64,
    passivity_activations: u64,
    uplinks_refused: u64,
}

fn measure(p: &Point, seconds: f64) -> Result<Measured> {
    let mut plan = paper_plan(seconds)?;
    plan.ve.passivity = p.passivity;
    let seed = 1000 + (p.value * 10.0).round() as u64;
    plan.clients[0] = ClientPlan::paper("user").with_link(p.variable.link(p.value, seed));
    let (summary, rec) = session(&plan).with_context(|| format!("{p:?}"))?;
    let c = &summary.clients[0];
    Ok(Measured {
        point: *p,
        verdict: verdict::judge(&summary, &rec),
        device_op_rms_m: c.device_op_rms_m,
        device_model_rms_m: c.device_model_rms_m,
        passivity_absorbed_j: c.passivity_absorbed_j,
        passivity_activations: c.passivity_activations,
        uplinks_refused: c.uplinks_refused,
    })
}

fn mode(passivity: bool) -> &'static str {
    if passivity {
        "with passivity controller"
    } else {
        "plain coupling"
    }
}

fn point_json(m: &Measured) -> Value {
    json!({
        "value": m.point.value,
        "passivity": m.point.passivity,
        "stable": m.verdict.stable,
        "reasons": m.verdict.reasons,
        "device_op_rms_mm": round(m.device_op_rms_m * 1e3, 3),
        "device_op_max_mm": round(m.verdict.device_op_max_m * 1e3, 3),
        "device_local_model_rms_mm": round(m.device_model_rms_m * 1e3, 3),
        "energy_excess_j": significant(m.verdict.energy_excess_j, 3),
        "energy_flow_max_j": significant(m.verdict.energy_flow_max_j, 3),
        "linkage_kinetic_energy_max_j": significant(m.verdict.kinetic_energy_max_j, 3),
        "worst_saturation": round(m.verdict.worst_saturation, 3),
        "passivity_absorbed_j": significant(m.passivity_absorbed_j, 3),
        "passivity_activations": m.passivity_activations,
        "uplinks_refused_by_server": m.uplinks_refused,
    })
}

/// The values whose points are unstable, per passivity setting, in sweep order.
fn failures(points: &[Measured], passivity: bool) -> Vec<f64> {
    points.iter().filter(|m| m.point.passivity == passivity && !m.verdict.stable).map(|m| m.point.value).collect()
}

/// The smallest value whose point is unstable, per passivity setting.
fn first_failure(points: &[Measured], passivity: bool) -> Option<f64> {
    failures(points, passivity).into_iter().reduce(f64::min)
}

fn charts(out: &mut Output, variable: Variable, points: &[Measured]) -> Result<()> {
    let name = match variable {
        Variable::Delay => "delay",
        Variable::Jitter => "jitter",
        Variable::Loss => "loss",
    };
    let mut tracking = Chart::new(
        format!("Tracking vs {name}: device-OP distance, paper manipulation (dots: unstable)"),
        variable.axis(),
        "device-OP distance, RMS (mm)",
    )
    .legend(Legend::UpperRight);
    tracking.log_y = true;
    for passivity in [false, true] {
        let of = |stable: Option<bool>| -> Vec<(f64, f64)> {
            points
                .iter()
                .filter(|m| m.point.passivity == passivity && stable.is_none_or(|s| m.verdict.stable == s))
                .map(|m| (m.point.value, m.device_op_rms_m * 1e3))
                .collect()
        };
        tracking = tracking.with(Series::line(mode(passivity), of(None)));
        tracking = tracking.with(Series::markers(format!("unstable, {}", mode(passivity)), of(Some(false))));
    }
    out.chart(&format!("tracking_vs_{name}"), &tracking)?;
    if variable == Variable::Delay {
        let mut zoom = tracking.clone();
        zoom.title = "Tracking vs delay, the first 50 ms (dots: unstable)".into();
        for s in &mut zoom.series {
            s.points.retain(|p| p.0 <= 50.0);
        }
        out.chart("tracking_vs_delay_first_50ms", &zoom)?;
    }
    let mut energy = Chart::new(
        format!("Energy vs {name}: linkage energy beyond the hand's work (floored at 0.1 mJ)"),
        variable.axis(),
        "energy (J)",
    )
    .legend(Legend::UpperRight);
    energy.log_y = true;
    let floor = 1e-4;
    for passivity in [false, true] {
        energy = energy.with(Series::line(
            format!("max(E_kin - W_hand), {}", mode(passivity)),
            points
                .iter()
                .filter(|m| m.point.passivity == passivity)
                .map(|m| (m.point.value, m.verdict.energy_excess_j.max(floor)))
                .collect(),
        ));
    }
    energy = energy.with(Series::reference(
        "energy-growth threshold, plain (half the hand's work + 5 mJ)",
        points
            .iter()
            .filter(|m| !m.point.passivity)
            .map(|m| (m.point.value, verdict::ENERGY_FRACTION * m.verdict.energy_flow_max_j + verdict::ENERGY_FLOOR_J))
            .collect(),
    ));
    energy = energy.with(Series::reference(
        "energy the couplings generated, passivity on (booked by its observer)",
        points
            .iter()
            .filter(|m| m.point.passivity)
            .map(|m| (m.point.value, (-m.passivity_absorbed_j).max(floor)))
            .collect(),
    ));
    out.chart(&format!("energy_vs_{name}"), &energy)?;
    out.map(
        &format!("stability_{name}"),
        &StabilityMap {
            title: format!("Stability vs {name}: plain coupling and passivity controller"),
            x_label: variable.axis().into(),
            y_label: "coupling".into(),
            log: false,
            cells: points
                .iter()
                .map(|m| (m.point.value, f64::from(u8::from(m.point.passivity)), m.verdict.stable))
                .collect(),
            overlays: Vec::new(),
            legend: Legend::UpperLeft,
            y_categories: vec!["plain".into(), "passivity".into()],
        },
    )
}

fn sweep_json(variable: Variable, points: &[Measured]) -> Value {
    let by =
        |passivity: bool| points.iter().filter(|m| m.point.passivity == passivity).map(point_json).collect::<Vec<_>>();
    json!({
        "variable": variable,
        "axis": variable.axis(),
        "first_unstable_value_plain": first_failure(points, false),
        "first_unstable_value_passivity": first_failure(points, true),
        "unstable_values_plain": failures(points, false),
        "unstable_values_passivity": failures(points, true),
        "plain": by(false),
        "passivity": by(true),
    })
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("latency", options)?;
    let seconds = 8.0;
    let values: [(Variable, Vec<f64>); 3] = [
        (
            Variable::Delay,
            options.pick(
                (0..=15)
                    .map(|i| 2.0 * i as f64)
                    .chain([40.0, 50.0, 60.0, 75.0, 100.0, 125.0, 150.0, 175.0, 200.0, 225.0, 250.0, 300.0, 350.0])
                    .chain([400.0, 450.0, 500.0])
                    .collect(),
                vec![0.0, 10.0, 50.0, 200.0, 500.0],
            ),
        ),
        (Variable::Jitter, options.pick(vec![0.0, 2.0, 5.0, 10.0, 20.0, 40.0], vec![0.0, 10.0, 40.0])),
        (Variable::Loss, options.pick(vec![0.0, 1.0, 5.0, 10.0, 20.0, 30.0, 50.0], vec![0.0, 10.0, 50.0])),
    ];
    let mut sweeps = serde_json::Map::new();
    let mut delay_points = Vec::new();
    for (variable, vs) in values {
        let points: Vec<Point> = [false, true]
            .into_iter()
            .flat_map(|passivity| vs.iter().map(move |&value| Point { variable, value, passivity }))
            .collect();
        let measured =
            sweep(&format!("{variable:?}").to_lowercase(), &points, options.threads, options.progress, |p| {
                measure(p, seconds)
            })?;
        charts(&mut out, variable, &measured)?;
        sweeps.insert(format!("{variable:?}").to_lowercase(), sweep_json(variable, &measured));
        if variable == Variable::Delay {
            delay_points = measured;
        }
    }
    let describe = |passivity: bool| match first_failure(&delay_points, passivity) {
        None => "at no delay up to 500 ms".to_string(),
        Some(d) => format!("{d} ms (unstable at {:?} ms)", failures(&delay_points, passivity)),
    };
    let plain = first_failure(&delay_points, false);
    let passive = first_failure(&delay_points, true);
    let rms_at = |delay: f64, passivity: bool| {
        delay_points
            .iter()
            .find(|m| m.point.value == delay && m.point.passivity == passivity)
            .map_or(f64::NAN, |m| round(m.device_op_rms_m * 1e3, 2))
    };
    let answer = format!(
        "Plain coupling first fails at {}; with the passivity controller at {}. Device-OP RMS at 0 / 100 / 500 ms: \
         {} / {} / {} mm plain, {} / {} / {} mm with passivity. At 50 ms delay, plain coupling fails first at a jitter \
         of {} and at a loss of {}.",
        describe(false),
        describe(true),
        rms_at(0.0, false),
        rms_at(100.0, false),
        rms_at(500.0, false),
        rms_at(0.0, true),
        rms_at(100.0, true),
        rms_at(500.0, true),
        sweeps["jitter"]["first_unstable_value_plain"]
            .as_f64()
            .map_or("(none up to 40 ms)".into(), |v| format!("{v} ms")),
        sweeps["loss"]["first_unstable_value_plain"].as_f64().map_or("(none up to 50 %)".into(), |v| format!("{v} %")),
    );
    let results = json!({
        "answer": answer,
        "failing_delay_ms": { "plain_coupling": plain, "with_passivity": passive },
        "passivity_extends_failing_delay_by_ms": match (plain, passive) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        },
        "criterion": verdict::criterion_json(),
        "setup": {
            "session": format!("paper testbed, user and device, 1 kHz VE and haptic loop, {seconds} s per point"),
            "network": "the same conditions in both directions; each point its own emulator seeds",
            "passivity": "VeConfig::passivity: time-domain passivity observer on each axis of each coupling port (the graphics-controller PD, the hand's force channel excluded); an axis whose PD generated more energy than the port as a whole absorbed has its PD scaled down, to zero once the excess reaches passivity_allowance_j",
            "null": "a null failing value means no point of the sweep was unstable",
        },
        "sweeps": Value::Object(sweeps),
    });
    out.finish(
        "Network delay, jitter and loss with and without the passivity controller",
        "about 5 s on this 2-core machine (82 sessions of 8 s); --quick about 1 s",
        results,
    )
}
