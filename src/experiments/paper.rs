//! `paper`: the paper's two manipulations of its planar testbed (section VI) through the whole system —
//! the loop closure rendered by stiffness control (Fig 6), then by acceleration-zeroing impedance control
//! (Fig 7) — with the paper's user (a constant wrench (−0.5 N, 0, −0.0025 N m) at the COM of link 2),
//! its gains (k_j = 200 N/m/kg, b_j = 50 N s/m/kg on the 1 kg simulated device, K_pc = (100, 100, 0.5),
//! B_pc = (70, 70, 0.375)), a 1 kHz VE and haptic loop, a perfect network, 3 s.
//!
//! Charts: the constraint count on the OP over time (Figs 6a, 7a), device against OP trajectories (6b, 7b),
//! the joint-constraint wrench on the device (6c), and the device–OP distance of both manipulations.
//! The same two manipulations also run with kinloop's default gains (the server's recommendation) for the
//! summary.

use anyhow::Result;
use kinloop_client::core::{ConstraintMode, GainChoice};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::common::{paper_plan, session, sweep, Options, Output, Report};
use crate::charts::{Chart, Legend, Series};
use crate::rounding::{round, significant};
use kinloop_harness::{ClientSample, CoreEdit, Recording, SessionSummary};

/// Simulated seconds of each manipulation (the paper's experiment lasts about 3 s).
const DURATION_S: f64 = 3.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Gains {
    Paper,
    Default,
}

impl Gains {
    fn name(self) -> &'static str {
        match self {
            Gains::Paper => "paper",
            Gains::Default => "default",
        }
    }
}

fn mode_name(mode: ConstraintMode) -> &'static str {
    match mode {
        ConstraintMode::Stiffness => "stiffness",
        ConstraintMode::Impedance => "impedance",
    }
}

fn manipulation(mode: ConstraintMode, gains: Gains) -> Result<(SessionSummary, Recording)> {
    let mut plan = paper_plan(DURATION_S)?;
    plan.clients[0].constraint_mode = mode;
    if gains == Gains::Paper {
        plan.clients[0].configure = Some(CoreEdit::new(|c| c.gains = GainChoice::Paper));
    }
    session(&plan)
}

/// `[start, end]` intervals (s) during which the VE's constraint count on the OP was 2.
fn two_constraint_intervals(samples: &[ClientSample]) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    for s in samples {
        match (s.snapshot_count >= 2, start) {
            (true, None) => start = Some(s.t),
            (false, Some(t0)) => {
                out.push([round(t0, 3), round(s.t, 3)]);
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(t0), Some(last)) = (start, samples.last()) {
        out.push([round(t0, 3), round(last.t, 3)]);
    }
    out
}

fn force_norm(s: &ClientSample) -> f64 {
    s.joint_constraint[0].hypot(s.joint_constraint[1])
}

/// Mean joint-constraint force (N) over full-output ticks with `count` constraints in the VE.
fn mean_force_with(samples: &[ClientSample], count: u8) -> Option<f64> {
    let v: Vec<f64> = samples.iter().filter(|s| s.gain > 0.999 && s.snapshot_count == count).map(force_norm).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Distance (m) between the device and the VE's OP in the plane, when the VE's OP is known.
pub(crate) fn device_op_distance(s: &ClientSample) -> Option<f64> {
    s.ve_op.as_ref().map(|op| (s.device[0] - op[0]).hypot(s.device[1] - op[1]))
}

/// What one session (a gain choice and a constraint mode) of the paper's manipulation measured, as the
/// summary lists it; tests read it back.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeSummary {
    /// Device-OP distance, RMS (mm).
    pub device_op_rms_mm: f64,
    /// Largest device-OP distance (mm).
    pub device_op_max_mm: f64,
    /// Device-local-model distance, RMS (mm).
    pub device_local_model_rms_mm: f64,
    /// When the OP first had two joint constraints (s; the loop closure binding, Fig 6a).
    pub first_time_two_constraints_s: Option<f64>,
    /// Every `[start, end]` interval with two joint constraints (s).
    pub two_constraint_intervals_s: Vec<[f64; 2]>,
    /// Mean joint-constraint force while one constraint binds (N).
    pub mean_joint_constraint_force_n_with_1_constraint: Option<f64>,
    /// ... and while two bind (N, Fig 6c).
    pub mean_joint_constraint_force_n_with_2_constraints: Option<f64>,
    /// Largest loop-closure residual (m).
    pub max_closure_error_m: f64,
    /// Largest commanded force over the device's limit.
    pub max_force_ratio: f64,
    /// Fraction of ticks saturated at the device's limit.
    pub saturated_fraction: f64,
    /// Uplinks the server refused.
    pub uplinks_refused_by_server: u64,
}

impl ModeSummary {
    /// The summary of one session.
    pub fn of(summary: &SessionSummary, rec: &Recording) -> Self {
        let c = &summary.clients[0];
        let samples = &rec.clients[0];
        let intervals = two_constraint_intervals(samples);
        ModeSummary {
            device_op_rms_mm: round(c.device_op_rms_m * 1e3, 3),
            device_op_max_mm: round(c.device_op_max_m * 1e3, 3),
            device_local_model_rms_mm: round(c.device_model_rms_m * 1e3, 3),
            first_time_two_constraints_s: intervals.first().map(|i| i[0]),
            two_constraint_intervals_s: intervals,
            mean_joint_constraint_force_n_with_1_constraint: mean_force_with(samples, 1).map(|f| round(f, 4)),
            mean_joint_constraint_force_n_with_2_constraints: mean_force_with(samples, 2).map(|f| round(f, 4)),
            max_closure_error_m: significant(summary.max_closure_error, 3),
            max_force_ratio: round(c.max_force_ratio, 4),
            saturated_fraction: round(c.saturated_fraction, 4),
            uplinks_refused_by_server: c.uplinks_refused,
        }
    }
}

/// The device-OP distance (mm) over time, from the first tick with output (the device is mapped onto the OP
/// at the first snapshot, before which the distance means nothing).
pub(crate) fn distance_series(label: &str, samples: &[ClientSample]) -> Series {
    let points = samples.iter().filter(|s| s.gain > 0.0);
    Series::line(label, points.filter_map(|s| device_op_distance(s).map(|d| (s.t, d * 1e3))).collect())
}

/// Figs 6a, 7a: the constraint count on the OP over time (`heading` names the figure, `scene` the linkage).
pub(crate) fn count_chart(heading: &str, scene: &str, samples: &[ClientSample]) -> Chart {
    Chart::new(format!("{heading}: joint constraints on the OP, {scene}"), "time (s)", "number of joint constraints")
        .with(Series::line(
            "in the VE (snapshot)",
            samples.iter().map(|s| (s.t, f64::from(s.snapshot_count))).collect(),
        ))
        .with(Series::reference(
            "used by the controllers (hysteresis)",
            samples.iter().map(|s| (s.t, s.constraint_count as f64)).collect(),
        ))
}

/// Figs 6b, 7b: the device against the VE's OP in the plane, over the samples' time span.
pub(crate) fn trajectory_chart(heading: &str, samples: &[ClientSample]) -> Chart {
    let span = samples.last().map_or(0.0, |s| s.t) - samples.first().map_or(0.0, |s| s.t);
    let mut chart =
        Chart::new(format!("{heading}: device (HD) and OP trajectories, {} s", round(span, 1)), "x (mm)", "y (mm)")
            .with(Series::line(
                "OP on the linkage (VE)",
                samples.iter().filter_map(|s| s.ve_op.as_ref().map(|p| (p[0] * 1e3, p[1] * 1e3))).collect(),
            ))
            .with(Series::line(
                "haptic device end-effector (HD)",
                samples.iter().filter(|s| s.gain > 0.0).map(|s| (s.device[0] * 1e3, s.device[1] * 1e3)).collect(),
            ));
    chart.equal_axes = true;
    chart.legend(Legend::UpperLeft)
}

/// Fig 6c: the joint-constraint wrench on the device, with the VE's constraint count for reference.
pub(crate) fn wrench_chart(heading: &str, samples: &[ClientSample]) -> Chart {
    Chart::new(
        format!("{heading}: joint-constraint wrench on the device"),
        "time (s)",
        "force (N), torque (N cm), count",
    )
    .with(Series::line("|f| joint-constraint force (N)", samples.iter().map(|s| (s.t, force_norm(s))).collect()))
    .with(Series::line(
        "tau_z joint-constraint torque (N cm)",
        samples.iter().map(|s| (s.t, s.joint_constraint[2] * 100.0)).collect(),
    ))
    .with(Series::reference(
        "joint constraints in the VE (2: loop closure active)",
        samples.iter().map(|s| (s.t, f64::from(s.snapshot_count))).collect(),
    ))
    .legend(Legend::LowerRight)
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("paper", options)?;
    let cases = [
        (ConstraintMode::Stiffness, Gains::Paper),
        (ConstraintMode::Impedance, Gains::Paper),
        (ConstraintMode::Stiffness, Gains::Default),
        (ConstraintMode::Impedance, Gains::Default),
    ];
    let runs = sweep("paper manipulations", &cases, options.threads, options.progress, |&(mode, gains)| {
        manipulation(mode, gains)
    })?;
    let (stiff, imp) = (&runs[0], &runs[1]);
    let (s, i) = (&stiff.1.clients[0], &imp.1.clients[0]);
    let testbed = "paper testbed";
    out.chart("fig6a_stiffness_constraint_count", &count_chart("Fig 6a (stiffness control)", testbed, s))?;
    out.chart("fig6b_stiffness_trajectories", &trajectory_chart("Fig 6b (stiffness control)", s))?;
    out.chart("fig6c_stiffness_joint_constraint_wrench", &wrench_chart("Fig 6c (stiffness control)", s))?;
    out.chart("fig7a_impedance_constraint_count", &count_chart("Fig 7a (impedance control)", testbed, i))?;
    out.chart("fig7b_impedance_trajectories", &trajectory_chart("Fig 7b (impedance control)", i))?;
    let mut distance = Chart::new(
        "Device-OP distance: stiffness vs impedance rendering of the loop closure (paper gains)",
        "time (s)",
        "device-OP distance (mm)",
    );
    for (label, run) in [("stiffness control (Fig 6)", stiff), ("impedance control (Fig 7)", imp)] {
        distance = distance.with(distance_series(label, &run.1.clients[0]));
    }
    distance.log_y = true;
    out.chart("device_op_distance", &distance.legend(Legend::LowerRight))?;

    let mut by_gains = serde_json::Map::new();
    for ((mode, gains), (summary, rec)) in cases.iter().zip(&runs) {
        let entry = by_gains.entry(gains.name()).or_insert_with(|| json!({}));
        entry[mode_name(*mode)] = json!(ModeSummary::of(summary, rec));
    }
    let rms = |r: &(SessionSummary, Recording)| r.0.clients[0].device_op_rms_m;
    let results = json!({
        "setup": {
            "scene": "paper-testbed (Fig 5, Table I)",
            "user": "constant wrench (-0.5 N, 0 N, -0.0025 N m) at the COM of link 2",
            "device": "sim:paper, 1 kg per linear axis (so the paper's per-kg gains read as N/m and N s/m)",
            "paper_gains": "k_j = 200 N/m, b_j = 50 N s/m, K_pc = (100 N/m, 100 N/m, 0.5 N m/rad), B_pc = (70, 70, 0.375)",
            "default_gains": "the server's recommendation, scaled by the client into the device's stable stiffness",
            "ve": "1 kHz semi-implicit Euler with projection and implicit coupling, K_g = (1000, 1000, 10000), B_g = (100, 100, 10000)",
            "duration_s": DURATION_S,
        },
        "answer": format!(
            "With the paper's gains the device follows the OP within {:.2} mm RMS under stiffness control and drifts \
             {:.1} mm RMS under impedance control ({:.0}x), as in Figs 6b and 7b.",
            rms(stiff) * 1e3,
            rms(imp) * 1e3,
            rms(imp) / rms(stiff).max(1e-12)
        ),
        "impedance_over_stiffness_rms": round(rms(imp) / rms(stiff).max(1e-12), 2),
        "gains": Value::Object(by_gains),
    });
    out.finish(
        "The paper's two manipulations: loop closure by stiffness control (Fig 6) and by impedance control (Fig 7)",
        "the full and quick runs are the same two sessions",
        results,
    )
}
