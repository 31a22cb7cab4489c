//! `robustness-live`: a sample of the `robustness` matrix in real processes, each session judged beside its
//! virtual-time twin. For every generated linkage of `--seeds` (default the CI sample) × OP × simulated device
//! of its kind × the soft hand × one-way delay {0, 50, 300 ms} ({0, 50} with `--quick`), a
//! `kinloop-server --scene FILE` and a `kinloop-client --op OP --device D --user soft` with default flags,
//! the scene file written as `kinloop generate` writes it and each side's packets delayed as the matrix's link
//! (a tenth of the delay as jitter) — what a user trying a linkage they wrote does — and the same point
//! through [`robustness::evaluate`] in virtual time for as long.
//!
//! A real session fails by the matrix's bounds (`robustness`), read from what the programs left
//! ([`super::programs`]): the client did not get through; unstable (a VE restore, a withheld snapshot, a
//! non-finite value: the energy criterion needs the harness's every-tick recording); closure above 1e-6 of
//! the length scale; more than 5 % of ticks clamped; device-OP RMS above 5 mm at 0 ms, 10 mm at 50 ms, and at
//! 300 ms above 1.2 times the unheard-motion floor of the virtual twin (the same hand on the same tour;
//! the real programs do not record what the VE had heard when).
//!
//! What it answers: whether virtual time predicts what the programs do on linkages never tried — each
//! session's two verdicts side by side, and how often they agree.

use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::json;

use kinloop_client::user::HandKind;

use super::common::{sweep, Options, Output, Report};
use super::programs::{self, Launcher, Measured, Pair};
use super::robustness::{self, Point, DEFAULT_SEEDS};
use crate::charts::HeatMap;
use crate::generate::{generate, Generated};
use crate::rounding::{num, round};

/// A session's length (s); `--quick` halves it.
pub const SECONDS: f64 = 8.0;
/// One-way delays of the sample (ms); `--quick` keeps the first two.
pub const DELAYS_MS: [u64; 3] = [0, 50, 300];

/// One session's two verdicts.
#[derive(Clone, Debug, Serialize)]
pub struct LiveOutcome {
    /// The session.
    pub point: Point,
    /// Why the real session failed (empty: it rendered).
    pub live_failures: Vec<String>,
    /// Why its virtual-time twin failed.
    pub virtual_failures: Vec<String>,
    /// Fraction of the real client's ticks clamped.
    pub clamped_fraction: f64,
    /// The real session's device-OP RMS, device space (m).
    pub device_op_rms_m: f64,
    /// The twin's.
    pub virtual_device_op_rms_m: f64,
    /// The real session's largest closure error over the length scale.
    pub closure_relative: f64,
}

impl LiveOutcome {
    /// Whether the two verdicts agree (both render or both fail).
    pub fn agrees(&self) -> bool {
        self.live_failures.is_empty() == self.virtual_failures.is_empty()
    }
}

/// Runs the sample on `seeds` (the CI sample when `None`), with the programs beside this executable.
pub fn run(options: &Options, seeds: Option<Range<u64>>) -> Result<Report> {
    let out = Output::new("robustness-live", options)?;
    let seeds = seeds.unwrap_or(DEFAULT_SEEDS);
    let launcher = Launcher::beside_this_program()?;
    let linkages: Vec<Generated> = seeds.clone().map(|s| generate(s, None)).collect();
    let delays = if options.quick { &DELAYS_MS[..2] } else { &DELAYS_MS[..] };
    let all = robustness::points(&linkages, &[HandKind::Soft], delays);
    let seconds = options.session_seconds(SECONDS, SECONDS / 2.0);
    let scratch = std::env::temp_dir().join("kinloop-robustness-live");
    // One real session at a time: two real-time loops on two cores is what a user's machine runs.
    let outcomes = sweep("robustness-live", &all, 1, options.progress, |p| {
        let g = linkages.iter().find(|g| g.seed == p.seed).context("the point's linkage")?;
        evaluate(g, p, seconds, &launcher, &scratch)
    })?;
    report(out, &outcomes, seeds, seconds)
}

/// Runs `point` of `g` in real processes for `seconds` (in a folder under `scratch`) and in virtual time, and
/// judges both.
pub fn evaluate(
    g: &Generated,
    point: &Point,
    seconds: f64,
    launcher: &Launcher,
    scratch: &Path,
) -> Result<LiveOutcome> {
    let twin = robustness::evaluate(g, point, seconds);
    let dir = scratch.join(format!("{}_{}_{}_{}ms", point.seed, point.op, point.device.name(), point.delay_ms));
    let dir = dir.to_string_lossy().replace(':', "_");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("scene.toml"), g.scene.to_toml_string())?;
    let link = point.link();
    let pair = Pair {
        scene: "scene.toml".into(),
        op: point.op.clone(),
        device: point.device.name().into(),
        client_flags: vec!["--user".into(), point.hand.name().into()],
        client_env: Vec::new(),
        links: [
            programs::link_flags(link.delay, link.jitter, link.seed),
            programs::link_flags(link.delay, link.jitter, link.seed ^ 1),
        ],
    };
    let ran = programs::run(&pair, seconds, launcher, dir)?;
    let measured = Measured::of(&ran, dir, g.scene.kind)?;
    let scale = robustness::length_scale(g).map_err(anyhow::Error::msg)?;
    let closure_relative = measured.max_closure_error / scale;
    let mut failures = measured.failures.clone();
    failures.extend(robustness::bound_failures(
        point.delay_ms,
        closure_relative,
        measured.clamped_fraction,
        measured.device_op_rms_m,
        twin.device_unheard_rms_m,
    ));
    let outcome = LiveOutcome {
        point: point.clone(),
        live_failures: failures,
        virtual_failures: twin.failures,
        clamped_fraction: measured.clamped_fraction,
        device_op_rms_m: measured.device_op_rms_m,
        virtual_device_op_rms_m: twin.device_op_rms_m,
        closure_relative,
    };
    // Each session's verdicts beside its records, so a long run can be read while it goes.
    std::fs::write(dir.join("result.json"), serde_json::to_string_pretty(&outcome)?)?;
    Ok(outcome)
}

/// The chart and `summary.json`.
fn report(mut out: Output, outcomes: &[LiveOutcome], seeds: Range<u64>, seconds: f64) -> Result<Report> {
    let row = |o: &LiveOutcome| format!("{}:{}", o.point.seed, o.point.op);
    let column = |o: &LiveOutcome| format!("{} {} ms", o.point.device.name(), o.point.delay_ms);
    let mut rows: Vec<String> = Vec::new();
    let mut columns: Vec<String> = Vec::new();
    for o in outcomes {
        for (list, label) in [(&mut rows, row(o)), (&mut columns, column(o))] {
            if !list.contains(&label) {
                list.push(label);
            }
        }
    }
    let mut map = HeatMap::new("Device-OP RMS in real processes (mm, device space)", rows.clone(), columns.clone());
    for o in outcomes {
        let (r, c) = (rows.iter().position(|l| *l == row(o)), columns.iter().position(|l| *l == column(o)));
        if let (Some(r), Some(c)) = (r, c) {
            map.set(r, c, o.device_op_rms_m * 1e3, o.live_failures.is_empty());
        }
    }
    out.heat_map("device_op_rms_live", &map)?;
    let count = |f: &dyn Fn(&LiveOutcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    let live = count(&|o| o.live_failures.is_empty());
    let twin = count(&|o| o.virtual_failures.is_empty());
    let both = count(&|o| o.live_failures.is_empty() && o.virtual_failures.is_empty());
    let neither = count(&|o| !o.live_failures.is_empty() && !o.virtual_failures.is_empty());
    let delays: std::collections::BTreeSet<u64> = outcomes.iter().map(|o| o.point.delay_ms).collect();
    let by_delay: Vec<_> = delays
        .into_iter()
        .map(|d| {
            let of: Vec<&LiveOutcome> = outcomes.iter().filter(|o| o.point.delay_ms == d).collect();
            json!({
                "delay_ms": d,
                "sessions": of.len(),
                "render_live": of.iter().filter(|o| o.live_failures.is_empty()).count(),
                "render_virtual": of.iter().filter(|o| o.virtual_failures.is_empty()).count(),
                "agree": of.iter().filter(|o| o.agrees()).count(),
            })
        })
        .collect();
    let answer = format!(
        "{live} of {} sessions render in real processes on seeds {}..{} ({twin} in virtual time); the verdicts \
         agree on {} ({both} render in both, {neither} fail in both, {} fail only in real processes, {} only in \
         virtual time)",
        outcomes.len(),
        seeds.start,
        seeds.end,
        both + neither,
        twin - both,
        live - both,
    );
    let duration = Duration::from_secs_f64(seconds + 3.0) * outcomes.len() as u32;
    out.finish(
        "Generated linkages in real processes, beside virtual time",
        &format!("one session at a time, about {} s in all", num(duration.as_secs_f64())),
        json!({
            "answer": answer,
            "seeds": [seeds.start, seeds.end],
            "seconds_per_session": seconds,
            "sessions": outcomes.len(),
            "render_live": live,
            "render_virtual": twin,
            "agree": both + neither,
            "by_delay": by_delay,
            "sessions_list": outcomes.iter().map(|o| json!({
                "seed": o.point.seed, "op": o.point.op, "device": o.point.device.name(), "delay_ms": o.point.delay_ms,
                "live_failures": o.live_failures, "virtual_failures": o.virtual_failures,
                "clamped_fraction": round(o.clamped_fraction, 4),
                "device_op_rms_mm": round(o.device_op_rms_m * 1e3, 3),
                "virtual_device_op_rms_mm": round(o.virtual_device_op_rms_m * 1e3, 3),
                "closure_relative": o.closure_relative,
            })).collect::<Vec<_>>(),
        }),
    )
}
