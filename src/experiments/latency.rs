//! `latency`: how far does network delay go before rendering a linkage with default settings goes unstable,
//! with and without the VE's passivity controller (time-domain passivity observer and PD scale on each
//! coupling, `VeConfig::passivity`, on by default; `kinloop-server --passivity off` without)?
//!
//! The grid: one-way delay {0, 50, 100, 200, 300, 500, 750, 1000 ms} × jitter (standard
//! deviation of the one-way delay) {0, 10, 30 ms} × loss {none, 5 % independent, 20 % in bursts
//! (Gilbert-Elliott, mean burst [`BURST_LENGTH`] packets)} × hand {soft, firm, release, poke} × scene
//! {paper-testbed:link2, fourbar-crank-rocker:coupler, watt-six-bar:link5} × passivity {off, on}; the same
//! conditions both ways. Everything else is what `kinloop-server` and `kinloop-client` do by default: the
//! server's designed coupling and mapping, the client's designed gains, the `sim:paper` device (the planar
//! scenes' default), stiffness mode, 1 kHz. Each point is a [`SECONDS`](super::delay_point::SECONDS) s session of a simulated hand
//! touring the OP's reach (`release` lets go at 2 s, `poke` jabs 1 cm at 1.5 s); the client knows the
//! nominal one-way delay, as its driver measures it (half the round trip), and predicts snapshots by it.
//! Both settings of the passivity controller see the same network draws (the seed depends on the point's
//! network, scene, hand and delay, not on the controller).
//!
//! Each point is labelled by the one criterion of [`verdict`] (divergence including VE restores, sustained
//! saturation, energy growth). Measured beside it: the device-OP distance in the device's space (what the hand
//! feels) and its floor, how far the device had moved since the pose the VE had heard of (a VE that follows
//! what it hears cannot be nearer on average), loop closure, clamped ticks, the coupling's energy account
//! when the passivity controller books it, and two impedance figures at 0.5-4 Hz: the handle's against the
//! VE's OP (felt vs rendered) and the handle's against the same hand's without delay (how far the network
//! moved the feel, [`fill_felt_changes`]). The [`model_update`] rows add the local model's update: the
//! free pull at a fixed 200 ms against the default, with and without its energy tank; the [`lead`] rows a VE
//! that runs ahead of the hand (not default), the only way below the device-OP floor; and the testbed's soft
//! hand on the 5 mm goal circle ([`goal_circle`]) at each delay, the motion its goals were set on.
//! A (scene, hand, method) **first fails** at the smallest delay where some network condition of the grid is
//! unstable.

use anyhow::Result;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use kinloop_client::user::{HandKind, Intent};

use super::common::{sweep, Options, Output, Report};
use super::delay_point::{
    default_passivity, fill_felt_changes, goal_circle, is_undelayed_reference, measure, measure_intending, method,
    seconds_per_point, AtGoalDelays, Lead, Loss, Measured, Network, Point, PointSummary, BURST_LENGTH, DELAYS_MS,
    GOAL_PASSIVITY_COST_AT_0MS, GOAL_RMS_100MS_M, GOAL_RMS_1S_M, JITTERS_MS, TARGETS,
};
use super::lead::{self, LeadSummary};
use super::model_update::{self, ModelUpdateSummary};
use super::verdict;
use crate::charts::{Chart, HeatMap, Legend, Series};
use crate::rounding::round;

/// The axes of a run's grid.
#[derive(Clone, Debug)]
pub struct Grid {
    /// Indices into [`TARGETS`].
    pub targets: Vec<usize>,
    /// Hands.
    pub hands: Vec<HandKind>,
    /// One-way delays (ms).
    pub delays_ms: Vec<f64>,
    /// Jitter × loss.
    pub networks: Vec<Network>,
}

impl Grid {
    /// The full grid of the module documentation.
    pub fn full() -> Self {
        Grid {
            targets: (0..TARGETS.len()).collect(),
            hands: HandKind::ALL.to_vec(),
            delays_ms: DELAYS_MS.to_vec(),
            networks: JITTERS_MS
                .iter()
                .flat_map(|&jitter_ms| Loss::ALL.iter().map(move |&loss| Network { jitter_ms, loss }))
                .collect(),
        }
    }

    /// The quick grid: the four-bar's coupler, the soft hand and the poke, four delays, a clean network and
    /// the worst one (30 ms of jitter with 20 % bursty loss).
    pub fn quick() -> Self {
        Grid {
            targets: vec![1],
            hands: vec![HandKind::Soft, HandKind::Poke],
            delays_ms: vec![0.0, 100.0, 500.0, 1000.0],
            networks: vec![Network::CLEAN, Network { jitter_ms: 30.0, loss: Loss::Bursty20 }],
        }
    }

    /// Every point, methods innermost so that both see the same network one after the other.
    pub fn points(&self) -> Vec<Point> {
        let mut out = Vec::new();
        for &target in &self.targets {
            for &hand in &self.hands {
                for &network in &self.networks {
                    for &delay_ms in &self.delays_ms {
                        for passivity in [false, true] {
                            out.push(Point { target, hand, delay_ms, network, passivity });
                        }
                    }
                }
            }
        }
        out
    }
}

/// The `latency` experiment's results (the summary's `results`), typed so that tests read its fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    /// The run's answer, then the model-update rows' and the lead rows'.
    pub answer: String,
    /// The goals' figures.
    pub goals: Goals,
    /// The model-update rows.
    pub model_update: ModelUpdateSummary,
    /// The lead rows.
    pub lead: LeadSummary,
    /// The first failing delay of each (scene, hand, method).
    pub first_failures: Vec<FirstFailure>,
    /// The stability criterion's rules and thresholds.
    pub criterion: Value,
    /// The grid the run swept.
    pub grid: GridSummary,
    /// How the sessions ran.
    pub setup: Setup,
    /// Every point of the grid.
    pub points: Vec<PointSummary>,
}

/// The axes of the run's grid, as names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridSummary {
    /// The scenes, as `scene:op`.
    pub scenes: Vec<String>,
    /// The hands.
    pub hands: Vec<String>,
    /// The one-way delays (ms).
    pub delays_ms: Vec<f64>,
    /// The network conditions.
    pub networks: Vec<String>,
    /// The two methods, plain and passivity.
    pub methods: Vec<String>,
    /// The grid's points.
    pub points: usize,
    /// Each session's length (s).
    pub seconds_per_point: f64,
    /// What `--quick` reduced the grid to; `None` for the full grid.
    pub reduced: Option<String>,
}

/// The summary's notes on how the sessions ran.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// One session.
    pub session: String,
    /// The network conditions.
    pub network: String,
    /// What a first failure is.
    pub first_failure: String,
    /// The passivity controller.
    pub passivity: String,
}

/// The first failing delay of one (scene, hand, method).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FirstFailure {
    /// Scene name.
    pub scene: String,
    /// Operational point.
    pub op: String,
    /// Hand name.
    pub hand: String,
    /// `plain` or `passivity`.
    pub method: String,
    /// The smallest delay where some network condition is unstable (ms); `None` up to the largest delay.
    pub first_failure_ms: Option<f64>,
    /// The same on the clean network only.
    pub first_failure_clean_network_ms: Option<f64>,
    /// Its unstable points.
    pub unstable_points: usize,
    /// Its points.
    pub points: usize,
    /// The unstable points at the first failing delay: `network: reasons`.
    pub unstable_at_first_failure: Vec<String>,
}

/// The goals' figures: the defaults' stability, what the passivity controller costs without delay, and the
/// testbed's soft hand at 100 ms and 1 s on its tour and on the 5 mm goal circle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Goals {
    /// The default method (`passivity` or `plain`).
    pub default_method: String,
    /// No point of the default method is unstable.
    pub no_unstable_point_with_defaults: bool,
    /// The default method's unstable points.
    pub unstable_points_with_defaults: usize,
    /// The passivity controller's cost without delay.
    pub passivity_cost_at_0ms: PassivityCost,
    /// Testbed, soft hand, clean network, defaults: device-OP RMS at 100 ms (mm).
    pub testbed_soft_device_op_rms_mm_at_100ms: Option<f64>,
    /// Whether it meets the 100 ms goal.
    pub testbed_soft_device_op_rms_mm_at_100ms_goal_met: Option<bool>,
    /// The same at 1 s (mm).
    pub testbed_soft_device_op_rms_mm_at_1000ms: Option<f64>,
    /// Whether it meets the 1 s goal.
    pub testbed_soft_device_op_rms_mm_at_1000ms_goal_met: Option<bool>,
    /// The same with the passivity controller off (mm).
    pub testbed_soft_device_op_rms_mm_with_passivity_off: AtGoalDelays,
    /// How far the device had moved from the pose the VE had heard of, RMS (mm).
    pub testbed_soft_device_unheard_rms_mm: AtGoalDelays,
    /// The soft hand on the 5 mm goal circle.
    pub testbed_soft_goal_circle: GoalCircle,
    /// What `device_unheard_rms` means.
    pub device_unheard_rms_means: String,
}

/// What the passivity controller costs without delay: the mean device-OP RMS over the 0 ms points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PassivityCost {
    /// With it on (mm).
    pub device_op_rms_mm_mean_on: Option<f64>,
    /// With it off (mm).
    pub device_op_rms_mm_mean_off: Option<f64>,
    /// On over off.
    pub ratio: Option<f64>,
    /// The largest ratio the goal allows ([`GOAL_PASSIVITY_COST_AT_0MS`]).
    pub goal: f64,
    /// Whether the ratio meets it.
    pub goal_met: Option<bool>,
}

/// The testbed's soft hand on the 5 mm goal circle, the motion the tracking goals were set on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalCircle {
    /// The motion.
    pub motion: String,
    /// Device-OP RMS (mm).
    pub device_op_rms_mm: AtGoalDelays,
    /// How far the device had moved from the pose the VE had heard of, RMS (mm).
    pub device_unheard_rms_mm: AtGoalDelays,
    /// Stable and within the 100 ms goal.
    pub goal_met_at_100ms: Option<bool>,
    /// Stable and within the 1 s goal.
    pub goal_met_at_1000ms: Option<bool>,
    /// Its unstable sessions.
    pub unstable_points: usize,
    /// Its sessions.
    pub points: Vec<PointSummary>,
}

/// The points of one (scene, hand, method), in grid order.
fn pair(all: &[Measured], target: usize, hand: HandKind, passivity: bool) -> impl Iterator<Item = &Measured> {
    all.iter().filter(move |m| m.point.target == target && m.point.hand == hand && m.point.passivity == passivity)
}

/// The smallest delay at which some point of `points` is unstable.
fn first_failure<'a>(points: impl Iterator<Item = &'a Measured>) -> Option<f64> {
    points.filter(|m| !m.verdict.stable).map(|m| m.point.delay_ms).reduce(f64::min)
}

/// The clean-network point of (scene, hand, method) at `delay_ms`.
fn clean(all: &[Measured], target: usize, hand: HandKind, passivity: bool, delay_ms: f64) -> Option<&Measured> {
    pair(all, target, hand, passivity).find(|m| m.point.network.is_clean() && m.point.delay_ms == delay_ms)
}

fn tracking_charts(out: &mut Output, grid: &Grid, all: &[Measured], circle: &[Measured]) -> Result<()> {
    let axis = "one-way delay (ms)";
    let rms = |m: &Measured| (m.point.delay_ms, m.device_op_rms_m * 1e3);
    // The overview: the soft hand on every scene, clean network.
    let mut overview = Chart::new(
        "Tracking vs delay: soft hand, no jitter or loss, default settings (circles: unstable)",
        axis,
        "device-OP distance, RMS, device space (mm)",
    )
    .legend(Legend::LowerRight);
    overview.log_y = true;
    let soft = if grid.hands.contains(&HandKind::Soft) { HandKind::Soft } else { grid.hands[0] };
    for passivity in [false, true] {
        for &target in &grid.targets {
            let line = grid.delays_ms.iter().filter_map(|&d| clean(all, target, soft, passivity, d)).map(rms).collect();
            overview = overview.with(Series::line(format!("{} {}", TARGETS[target].2, method(passivity)), line));
        }
    }
    // A colour of its own: before the markers, which reuse the palette's first colours.
    if let Some(&target) = grid.targets.first() {
        let floor = grid
            .delays_ms
            .iter()
            .filter_map(|&d| clean(all, target, soft, false, d))
            .filter(|m| m.point.delay_ms > 0.0)
            .map(|m| (m.point.delay_ms, m.device_unheard_rms_m * 1e3))
            .collect();
        overview = overview.with(Series::reference(
            format!("{}: a VE exactly on the device as heard (no prediction)", TARGETS[target].2),
            floor,
        ));
    }
    if !circle.is_empty() {
        overview = overview.with(Series::line(
            format!("{} soft on the 5 mm goal circle, {}", TARGETS[0].2, method(default_passivity())),
            circle.iter().map(rms).collect(),
        ));
    }
    for passivity in [false, true] {
        let unstable = grid
            .targets
            .iter()
            .flat_map(|&t| grid.delays_ms.iter().filter_map(move |&d| clean(all, t, soft, passivity, d)))
            .chain(circle.iter().filter(|m| m.point.passivity == passivity))
            .filter(|m| !m.verdict.stable)
            .map(rms)
            .collect();
        overview = overview.with(Series::markers(format!("unstable, {}", method(passivity)), unstable));
    }
    overview = overview.with(Series::markers(
        "goals: testbed soft, 3 mm at 100 ms, 25 mm at 1 s",
        vec![(100.0, GOAL_RMS_100MS_M * 1e3), (1000.0, GOAL_RMS_1S_M * 1e3)],
    ));
    out.chart("tracking_vs_delay", &overview)?;
    // Per scene: every hand, both methods, clean network.
    for &target in &grid.targets {
        let mut chart = Chart::new(
            format!(
                "Tracking vs delay, {}:{}, no jitter or loss (circles: unstable)",
                TARGETS[target].0, TARGETS[target].1
            ),
            axis,
            "device-OP distance, RMS, device space (mm)",
        )
        .legend(Legend::LowerRight);
        chart.log_y = true;
        for passivity in [false, true] {
            for &hand in &grid.hands {
                let line =
                    grid.delays_ms.iter().filter_map(|&d| clean(all, target, hand, passivity, d)).map(rms).collect();
                chart = chart.with(Series::line(format!("{} {}", hand.name(), method(passivity)), line));
            }
        }
        for passivity in [false, true] {
            let unstable = grid
                .hands
                .iter()
                .flat_map(|&h| grid.delays_ms.iter().filter_map(move |&d| clean(all, target, h, passivity, d)))
                .filter(|m| !m.verdict.stable)
                .map(rms)
                .collect();
            chart = chart.with(Series::markers(format!("unstable, {}", method(passivity)), unstable));
        }
        out.chart(&format!("tracking_vs_delay_{}", TARGETS[target].2), &chart)?;
    }
    Ok(())
}

fn stability_chart(out: &mut Output, grid: &Grid, all: &[Measured]) -> Result<()> {
    let rows: Vec<(usize, HandKind, bool)> = [false, true]
        .iter()
        .flat_map(|&p| grid.targets.iter().flat_map(move |&t| grid.hands.iter().map(move |&h| (t, h, p))))
        .collect();
    let mut map = HeatMap::new(
        format!(
            "Unstable network conditions (of {}: jitter x loss) at each one-way delay; green: none",
            grid.networks.len()
        ),
        rows.iter().map(|&(t, h, p)| format!("{} {} {}", TARGETS[t].2, h.name(), method(p))).collect(),
        grid.delays_ms.iter().map(|d| format!("{d} ms")).collect(),
    );
    for (i, &(target, hand, passivity)) in rows.iter().enumerate() {
        for (j, &d) in grid.delays_ms.iter().enumerate() {
            let unstable =
                pair(all, target, hand, passivity).filter(|m| m.point.delay_ms == d && !m.verdict.stable).count();
            map.set(i, j, unstable as f64, unstable == 0);
        }
    }
    out.heat_map("stability_delay", &map)
}

fn energy_chart(out: &mut Output, grid: &Grid, all: &[Measured]) -> Result<()> {
    let floor = 1e-4;
    let mut chart = Chart::new(
        "Energy vs delay, worst over hands, jitter and loss (floored at 0.1 mJ)",
        "one-way delay (ms)",
        "energy (J)",
    )
    .legend(Legend::UpperLeft);
    chart.log_y = true;
    let worst = |target: usize, passivity: bool, value: &dyn Fn(&Measured) -> f64| -> Vec<(f64, f64)> {
        grid.delays_ms
            .iter()
            .map(|&d| {
                let v = all
                    .iter()
                    .filter(|m| m.point.target == target && m.point.passivity == passivity && m.point.delay_ms == d)
                    .map(value)
                    .fold(floor, f64::max);
                (d, v)
            })
            .collect()
    };
    for passivity in [false, true] {
        for &target in &grid.targets {
            chart = chart.with(Series::line(
                format!("{}: max(E_linkage - W_hand), {}", TARGETS[target].2, method(passivity)),
                worst(target, passivity, &|m| m.verdict.energy_excess_j),
            ));
        }
    }
    for &target in &grid.targets {
        chart = chart.with(Series::reference(
            format!("{}: energy the coupling generated, booked by the passivity observer", TARGETS[target].2),
            worst(target, true, &|m| -m.passivity_absorbed_j),
        ));
    }
    out.chart("energy_vs_delay", &chart)
}

/// An impedance figure against delay: per scene and touring hand (soft, firm), the median over the networks
/// of the grid of `metric` (points where it could not be told are left out).
fn impedance_chart(
    out: &mut Output,
    grid: &Grid,
    all: &[Measured],
    (name, title, y): (&str, &str, &str),
    metric: fn(&Measured) -> Option<f64>,
) -> Result<()> {
    let mut chart = Chart::new(title, "one-way delay (ms)", y).legend(Legend::UpperLeft);
    chart.log_y = true;
    // The touring hands (a released handle has no hand on it to feel anything; the poke is the firm hand's
    // tour with a jab, in summary.json).
    let hands = grid.hands.iter().filter(|&&h| matches!(h, HandKind::Soft | HandKind::Firm));
    for &target in &grid.targets {
        for &hand in hands.clone() {
            let line: Vec<(f64, f64)> = grid
                .delays_ms
                .iter()
                .filter_map(|&d| {
                    let mut values: Vec<f64> = pair(all, target, hand, default_passivity())
                        .filter(|m| m.point.delay_ms == d)
                        .filter_map(metric)
                        // A log axis has no place for an undelayed session's zero change.
                        .filter(|&v| v > 0.0)
                        .collect();
                    values.sort_by(f64::total_cmp);
                    values.get(values.len() / 2).map(|&v| (d, v))
                })
                .collect();
            chart = chart.with(Series::line(format!("{} {}", TARGETS[target].2, hand.name()), line));
        }
    }
    out.chart(name, &chart)
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("latency", options)?;
    let grid = options.pick(Grid::full(), Grid::quick());
    let points = grid.points();
    let seconds = seconds_per_point(options);
    let mut all = sweep("latency", &points, options.threads, options.progress, |p| measure(p, seconds))?;
    let references: Vec<Measured> = all.iter().filter(|m| is_undelayed_reference(m, &m.point)).cloned().collect();
    fill_felt_changes(&mut all, &references);
    // The goals' other motion: the testbed's soft hand on the 5 mm goal circle, defaults, clean network.
    let circle_points: Vec<Point> = if grid.targets.contains(&0) {
        let network = Network::CLEAN;
        let at =
            |delay_ms| Point { target: 0, hand: HandKind::Soft, delay_ms, network, passivity: default_passivity() };
        grid.delays_ms.iter().map(|&d| at(d)).collect()
    } else {
        Vec::new()
    };
    let circle = sweep("latency: the 5 mm goal circle", &circle_points, options.threads, options.progress, |p| {
        measure_intending(p, Intent::Path(goal_circle()), seconds, None, Lead::default())
    })?;
    tracking_charts(&mut out, &grid, &all, &circle)?;
    stability_chart(&mut out, &grid, &all)?;
    energy_chart(&mut out, &grid, &all)?;
    impedance_chart(
        &mut out,
        &grid,
        &all,
        (
            "impedance_vs_delay",
            "Felt vs rendered impedance at 0.5-4 Hz, median over networks",
            "|Z_handle - Z_OP| / |Z_OP|",
        ),
        |m| m.impedance_error,
    )?;
    impedance_chart(
        &mut out,
        &grid,
        &all,
        (
            "felt_change_vs_delay",
            "Felt impedance at 0.5-4 Hz against the same hand without delay, median over networks",
            "|Z_handle - Z_handle(0 ms)| / |Z_handle(0 ms)|",
        ),
        |m| m.felt_change,
    )?;
    let model_update = model_update::run(&mut out, options)?;
    let defaults: Vec<&Measured> = all.iter().filter(|m| m.point.passivity == default_passivity()).collect();
    let lead = lead::run(&mut out, options, &defaults, &references)?;

    let (table, first_failures) = first_failures(&grid, &all);
    let (goals, answer) = goals_and_answer(&grid, &all, &circle, &table);
    let results = LatencySummary {
        answer: format!("{answer} {} {}", model_update.answer, lead.answer),
        goals,
        model_update,
        lead,
        first_failures,
        criterion: verdict::criterion_json(),
        grid: GridSummary {
            scenes: grid.targets.iter().map(|&t| format!("{}:{}", TARGETS[t].0, TARGETS[t].1)).collect(),
            hands: grid.hands.iter().map(|h| h.name().to_owned()).collect(),
            delays_ms: grid.delays_ms.clone(),
            networks: grid.networks.iter().map(|n| n.name()).collect(),
            methods: vec![
                "plain (VeConfig::passivity off, --passivity off)".into(),
                "passivity (VeConfig::passivity, the default)".into(),
            ],
            points: all.len(),
            seconds_per_point: seconds,
            reduced: options.quick.then(|| "--quick: the four-bar coupler, hands soft and poke, delays 0/100/500/1000 ms, a clean network and 30 ms jitter with 20 % bursty loss".into()),
        },
        setup: Setup {
            session: "one client with default settings (server-designed coupling and mapping, designed client gains, sim:paper, stiffness mode, 1 kHz VE and haptic loop), a simulated hand touring the OP's reach; the client knows the nominal one-way delay".into(),
            network: format!("the same conditions both ways; jitter is the standard deviation of the one-way delay; 5 % loss is independent; 20 % bursty loss is Gilbert (lost in the bad state only) with mean burst {BURST_LENGTH} packets"),
            first_failure: "the smallest delay at which some jitter and loss of the grid is unstable; null: none up to the largest delay".into(),
            passivity: "VeConfig::passivity: time-domain passivity observer on each coupling port (graphics-controller PD and force channel, per axis and in total) and controller: when the VE has received through the coupling more than the hand put in at the client (its books trusted as far as the uplinks show), the PD is scaled down, to zero once the excess reaches passivity_allowance_j, and what is taken off it brakes the OP".into(),
        },
        points: all.iter().map(PointSummary::of).collect(),
    };
    out.finish(
        "Network delay, jitter and loss with default settings, with and without the passivity controller",
        "1728 sessions of 10 s, 144 model-update sessions and 8 on the 5 mm goal circle; --quick 40 sessions",
        serde_json::to_value(&results)?,
    )
}

/// The first failing delay of each (scene, hand, method) of the grid: a phrase for the answer and a row for
/// the summary.
fn first_failures(grid: &Grid, all: &[Measured]) -> (Vec<String>, Vec<FirstFailure>) {
    let mut first_failures = Vec::new();
    let mut table = Vec::new();
    for &target in &grid.targets {
        for &hand in &grid.hands {
            for passivity in [false, true] {
                let first = first_failure(pair(all, target, hand, passivity));
                let first_clean =
                    first_failure(pair(all, target, hand, passivity).filter(|m| m.point.network.is_clean()));
                let unstable: Vec<&Measured> =
                    pair(all, target, hand, passivity).filter(|m| !m.verdict.stable).collect();
                let at_first: Vec<String> = unstable
                    .iter()
                    .filter(|m| Some(m.point.delay_ms) == first)
                    .map(|m| format!("{}: {}", m.point.network.name(), m.verdict.reasons.join(", ")))
                    .collect();
                table.push(format!(
                    "{}:{} {} {}: {}",
                    TARGETS[target].0,
                    TARGETS[target].1,
                    hand.name(),
                    method(passivity),
                    first.map_or("none".into(), |d| format!("{d} ms"))
                ));
                first_failures.push(FirstFailure {
                    scene: TARGETS[target].0.to_owned(),
                    op: TARGETS[target].1.to_owned(),
                    hand: hand.name().to_owned(),
                    method: method(passivity).to_owned(),
                    first_failure_ms: first,
                    first_failure_clean_network_ms: first_clean,
                    unstable_points: unstable.len(),
                    points: pair(all, target, hand, passivity).count(),
                    unstable_at_first_failure: at_first,
                });
            }
        }
    }
    (table, first_failures)
}

/// The goals' figures (the testbed's soft hand at 100 ms and 1 s, on its tour and on the 5 mm goal circle;
/// what the passivity controller costs without delay) and the run's answer, given the first failures'
/// phrases.
fn goals_and_answer(grid: &Grid, all: &[Measured], circle: &[Measured], table: &[String]) -> (Goals, String) {
    let unstable = |passivity: bool| all.iter().filter(|m| m.point.passivity == passivity && !m.verdict.stable).count();
    let per_method = |passivity: bool| all.iter().filter(|m| m.point.passivity == passivity).count();
    let max_delay = grid.delays_ms.iter().copied().fold(0.0, f64::max);
    // A distance (mm) of the testbed's soft hand on a clean network, when the grid has that point.
    let testbed_soft_mm = |delay_ms: f64, passivity: bool, metres: fn(&Measured) -> f64| {
        grid.hands
            .contains(&HandKind::Soft)
            .then(|| clean(all, 0, HandKind::Soft, passivity, delay_ms))
            .flatten()
            .map(|m| round(metres(m) * 1e3, 2))
    };
    let default = default_passivity();
    let goal_rms = |delay_ms: f64, passivity: bool| testbed_soft_mm(delay_ms, passivity, |m| m.device_op_rms_m);
    let (rms_100, rms_1000) = (goal_rms(100.0, default), goal_rms(1000.0, default));
    let floor = |delay_ms: f64| testbed_soft_mm(delay_ms, default, |m| m.device_unheard_rms_m);
    let (floor_100, floor_1000) = (floor(100.0), floor(1000.0));
    let on_circle = |delay_ms: f64| circle.iter().find(|m| m.point.delay_ms == delay_ms);
    let circle_mm =
        |delay_ms: f64, metres: fn(&Measured) -> f64| on_circle(delay_ms).map(|m| round(metres(m) * 1e3, 2));
    let (circle_100, circle_1000) = (circle_mm(100.0, |m| m.device_op_rms_m), circle_mm(1000.0, |m| m.device_op_rms_m));
    let circle_goal_met = |rms: Option<f64>, goal_m: f64, delay_ms: f64| {
        rms.zip(on_circle(delay_ms)).map(|(r, m)| m.verdict.stable && r <= goal_m * 1e3)
    };
    // What the passivity layer costs without delay, over every 0 ms point of the grid.
    let mean_rms_at_0ms = |passivity: bool| {
        let at_0: Vec<f64> = all
            .iter()
            .filter(|m| m.point.passivity == passivity && m.point.delay_ms == 0.0)
            .map(|m| m.device_op_rms_m * 1e3)
            .collect();
        (!at_0.is_empty()).then(|| at_0.iter().sum::<f64>() / at_0.len() as f64)
    };
    let (cost_on, cost_off) = (mean_rms_at_0ms(true), mean_rms_at_0ms(false));
    let cost_ratio = cost_on.zip(cost_off).map(|(on, off)| round(on / off, 3));
    let goals = Goals {
        default_method: method(default).to_owned(),
        no_unstable_point_with_defaults: unstable(default) == 0,
        unstable_points_with_defaults: unstable(default),
        passivity_cost_at_0ms: PassivityCost {
            device_op_rms_mm_mean_on: cost_on.map(|r| round(r, 3)),
            device_op_rms_mm_mean_off: cost_off.map(|r| round(r, 3)),
            ratio: cost_ratio,
            goal: GOAL_PASSIVITY_COST_AT_0MS,
            goal_met: cost_ratio.map(|r| r <= GOAL_PASSIVITY_COST_AT_0MS),
        },
        testbed_soft_device_op_rms_mm_at_100ms: rms_100,
        testbed_soft_device_op_rms_mm_at_100ms_goal_met: rms_100.map(|r| r <= GOAL_RMS_100MS_M * 1e3),
        testbed_soft_device_op_rms_mm_at_1000ms: rms_1000,
        testbed_soft_device_op_rms_mm_at_1000ms_goal_met: rms_1000.map(|r| r <= GOAL_RMS_1S_M * 1e3),
        testbed_soft_device_op_rms_mm_with_passivity_off: AtGoalDelays {
            at_100ms: goal_rms(100.0, false),
            at_1000ms: goal_rms(1000.0, false),
        },
        testbed_soft_device_unheard_rms_mm: AtGoalDelays { at_100ms: floor_100, at_1000ms: floor_1000 },
        testbed_soft_goal_circle: GoalCircle {
            motion: "the soft hand on the motion the tracking goals were set on, --user path:circle:0.005,2 (a 5 mm circle, a turn every 2 s)".into(),
            device_op_rms_mm: AtGoalDelays { at_100ms: circle_100, at_1000ms: circle_1000 },
            device_unheard_rms_mm: AtGoalDelays {
                at_100ms: circle_mm(100.0, |m| m.device_unheard_rms_m),
                at_1000ms: circle_mm(1000.0, |m| m.device_unheard_rms_m),
            },
            goal_met_at_100ms: circle_goal_met(circle_100, GOAL_RMS_100MS_M, 100.0),
            goal_met_at_1000ms: circle_goal_met(circle_1000, GOAL_RMS_1S_M, 1000.0),
            unstable_points: circle.iter().filter(|m| !m.verdict.stable).count(),
            points: circle.iter().map(PointSummary::of).collect(),
        },
        device_unheard_rms_means: "how far the device had moved since the pose the VE had heard of: the device-OP distance of a VE sitting exactly on the device as heard, which a VE that does not run ahead of the hand cannot beat on average".into(),
    };
    let answer = format!(
        "Up to {max_delay} ms one-way, {} of {} points are unstable with the defaults (passivity controller on), {} of {} \
         with it off (plain coupling). Without delay the controller costs {} (device-OP RMS, mean over the 0 ms points, \
         on / off; goal at most {GOAL_PASSIVITY_COST_AT_0MS}). First failing delay per scene, hand and method (any \
         jitter and loss of the grid): {}. Testbed, soft hand, clean network, defaults: device-OP RMS {} mm at 100 ms \
         (goal 3), {} mm at 1 s (goal 25); the device had moved {} mm and {} mm (RMS) from the pose the VE had heard \
         of. The same hand on the 5 mm goal circle: {} mm at 100 ms, {} mm at 1 s ({} of {} delays unstable).",
        unstable(default),
        per_method(default),
        unstable(!default),
        per_method(!default),
        cost_ratio.map_or("n/a".into(), |r| format!("{r:.3}")),
        table.join("; "),
        rms_100.map_or("n/a".into(), |r| r.to_string()),
        rms_1000.map_or("n/a".into(), |r| r.to_string()),
        floor_100.map_or("n/a".into(), |r| r.to_string()),
        floor_1000.map_or("n/a".into(), |r| r.to_string()),
        circle_100.map_or("n/a".into(), |r| r.to_string()),
        circle_1000.map_or("n/a".into(), |r| r.to_string()),
        circle.iter().filter(|m| !m.verdict.stable).count(),
        circle.len(),
    );
    (goals, answer)
}
