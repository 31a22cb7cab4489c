//! The `latency` experiment's model-update rows: does the local model's pull toward the
//! delayed VE make energy?
//!
//! The pull compares the VE's state, predicted to now, with the model's (step 2 of the client core's tick)
//! and corrects what differs over a time constant τ; what it corrects comes back a round trip `T` later, and
//! such a loop is stable only for `T < π τ / 2`: a fixed τ of 200 ms leaves no margin from a few hundred
//! milliseconds one way when the free directions are compared with the model's own state that the VE answered
//! (a Smith predictor); compared with the VE's state predicted to now, as the core does, the rows show whether
//! any session is unstable (docs/benchmarks.md), and the default keeps its margin. Each row here runs the grid's clean-network
//! sessions (soft and firm hands, every scene, [`DELAYS_MS`]) with one way of pulling:
//! - `fixed pull, no tank`: τ = 200 ms at every delay, the update unbounded;
//! - `fixed pull, tank`: the same with the energy tank that pays for each correction
//!   (`CoreConfig::passive_update`), which bounds what the update puts into the device-model coupling;
//! - `default, no tank`: τ of at least two round trips (`CoreConfig::free_blend_round_trips`);
//! - `default`: both, as `kinloop-client` runs.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use kinloop_client::user::HandKind;
use kinloop_server::core::VeConfig;

use super::common::{sweep, Options, Output};
use super::delay_point::{measure_with, seconds_per_point, Measured, Network, Point, PointSummary, TARGETS};
use crate::charts::HeatMap;
use kinloop_harness::CoreEdit;

/// One-way delays of the rows (ms).
pub const DELAYS_MS: [f64; 6] = [100.0, 200.0, 300.0, 500.0, 750.0, 1000.0];

/// A way of pulling the local model toward the VE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    /// τ = 200 ms at every delay, no tank.
    FixedBare,
    /// τ = 200 ms at every delay, with the tank.
    FixedTank,
    /// τ ≥ two round trips, no tank.
    ScaledBare,
    /// τ ≥ two round trips with the tank: the default.
    Default,
}

impl Update {
    /// Every way, the default last.
    pub const ALL: [Update; 4] = [Update::FixedBare, Update::FixedTank, Update::ScaledBare, Update::Default];

    /// Name in summaries and charts.
    pub fn name(self) -> &'static str {
        match self {
            Update::FixedBare => "fixed pull, no tank",
            Update::FixedTank => "fixed pull, tank",
            Update::ScaledBare => "default, no tank",
            Update::Default => "default",
        }
    }

    fn edit(self) -> Option<CoreEdit> {
        let (fixed, tank) = match self {
            Update::FixedBare => (true, false),
            Update::FixedTank => (true, true),
            Update::ScaledBare => (false, false),
            Update::Default => return None,
        };
        Some(CoreEdit::new(move |c| {
            if fixed {
                c.free_blend_round_trips = 0.0;
            }
            c.passive_update = tank;
        }))
    }
}

/// The model-update rows' part of the latency summary.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelUpdateSummary {
    /// The rows' one-line answer.
    pub answer: String,
    /// Per way of updating: its sessions and how many were unstable.
    pub rows: Vec<UpdateRow>,
    /// Every session.
    pub points: Vec<UpdatePoint>,
    /// How the sessions ran.
    pub setup: String,
}

/// One way of updating the local model over its sessions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UpdateRow {
    /// The way's name.
    pub update: String,
    /// Its unstable sessions.
    pub unstable: usize,
    /// Its sessions.
    pub sessions: usize,
    /// The smallest one-way delay with an unstable session (ms), none if all were stable.
    pub first_unstable_delay_ms: Option<f64>,
}

/// One session: the delay experiments' point and the way of updating it ran with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UpdatePoint {
    /// The point.
    #[serde(flatten)]
    pub point: PointSummary,
    /// The way of updating.
    pub update: String,
}

/// Runs the rows, draws their stability map, and returns their summary.
pub fn run(out: &mut Output, options: &Options) -> Result<ModelUpdateSummary> {
    let targets: Vec<usize> = options.pick((0..TARGETS.len()).collect(), vec![0]);
    let hands = options.pick(vec![HandKind::Soft, HandKind::Firm], vec![HandKind::Soft]);
    let delays: Vec<f64> = options.pick(DELAYS_MS.to_vec(), vec![300.0, 1000.0]);
    let clean = Network::CLEAN;
    let mut rows: Vec<(Update, usize, HandKind)> = Vec::new();
    for &update in &Update::ALL {
        for &target in &targets {
            for &hand in &hands {
                rows.push((update, target, hand));
            }
        }
    }
    // Row-major: a row's delays one after the other.
    let points: Vec<(Update, Point)> = rows
        .iter()
        .flat_map(|&(update, target, hand)| {
            delays.iter().map(move |&delay_ms| {
                (update, Point { target, hand, delay_ms, network: clean, passivity: VeConfig::default().passivity })
            })
        })
        .collect();
    let all: Vec<(Update, Measured)> =
        sweep("latency: model update", &points, options.threads, options.progress, |(update, p)| {
            Ok((*update, measure_with(p, seconds_per_point(options), update.edit())?))
        })?;

    let mut map = HeatMap::new(
        "Model update: 1 = unstable, clean network (fixed: the free pull at 200 ms whatever the delay)",
        rows.iter().map(|&(u, t, h)| format!("{} {} {}", TARGETS[t].2, h.name(), u.name())).collect(),
        delays.iter().map(|d| format!("{d} ms")).collect(),
    );
    for (i, row) in all.chunks(delays.len()).enumerate() {
        for (j, (_, m)) in row.iter().enumerate() {
            map.set(i, j, if m.verdict.stable { 0.0 } else { 1.0 }, m.verdict.stable);
        }
    }
    out.heat_map("stability_model_update", &map)?;

    let unstable = |u: Update| all.iter().filter(|(w, m)| *w == u && !m.verdict.stable).count();
    let per = |u: Update| all.iter().filter(|(w, _)| *w == u).count();
    let first_unstable = |u: Update| {
        all.iter().filter(|(w, m)| *w == u && !m.verdict.stable).map(|(_, m)| m.point.delay_ms).reduce(f64::min)
    };
    let rows = Update::ALL
        .iter()
        .map(|&u| UpdateRow {
            update: u.name().into(),
            unstable: unstable(u),
            sessions: per(u),
            first_unstable_delay_ms: first_unstable(u),
        })
        .collect();
    let answer = format!(
        "The local model's update (clean network, hands {}, {} ms one way): {}.",
        hands.iter().map(|h| h.name()).collect::<Vec<_>>().join("/"),
        delays.iter().map(|d| d.to_string()).collect::<Vec<_>>().join("/"),
        Update::ALL
            .iter()
            .map(|&u| format!(
                "{} {} of {} unstable{}",
                u.name(),
                unstable(u),
                per(u),
                first_unstable(u).map_or(String::new(), |d| format!(" (from {d} ms)"))
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let points = all.iter().map(|(u, m)| UpdatePoint { point: PointSummary::of(m), update: u.name().into() }).collect();
    Ok(ModelUpdateSummary {
        answer,
        rows,
        points,
        setup: "clean network (no jitter or loss), the grid's sessions otherwise; fixed: CoreConfig::free_blend_round_trips = 0 (the free pull at its configured 200 ms at every delay); tank: CoreConfig::passive_update".into(),
    })
}
