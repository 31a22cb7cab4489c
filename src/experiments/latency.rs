//! `latency`: how far does network delay go before rendering a linkage with default settings goes unstable,
//! with and without the VE's passivity controller (time-domain passivity observer and PD scale on each
//! coupling, `VeConfig::passivity`, on by default; `kinloop-server --passivity off` without)?
//!
//! The grid (issue 22, item 4): one-way delay {0, 50, 100, 200, 300, 500, 750, 1000 ms} × jitter (standard
//! deviation of the one-way delay) {0, 10, 30 ms} × loss {none, 5 % independent, 20 % in bursts
//! (Gilbert-Elliott, mean burst [`BURST_LENGTH`] packets)} × hand {soft, firm, release, poke} × scene
//! {paper-testbed:link2, fourbar-crank-rocker:coupler, watt-six-bar:link5} × passivity {off, on}; the same
//! conditions both ways. Everything else is what `kinloop-server` and `kinloop-client` do by default: the
//! server's designed coupling and mapping, the client's designed gains, the `sim:paper` device (the planar
//! scenes' default), stiffness mode, 1 kHz. Each point is a [`SECONDS`] s session of a simulated hand
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
//! hand on the issue's own 5 mm circle ([`goal_circle`]) at each delay, the motion its goals were set with.
//! A (scene, hand, method) **first fails** at the smallest delay where some network condition of the grid is
//! unstable.

use std::time::Duration;

use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::{json, Value};

use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec, Intent, PathSpec, UserSpec};
use kinloop_protocol::emulator::{GilbertElliott, LinkConfig};
use kinloop_server::core::VeConfig;

use super::common::{round, session, significant, sweep, Options, Output, Report};
use super::impedance;
use super::lead;
use super::model_update;
use super::verdict::{self, Verdict};
use crate::charts::{Chart, HeatMap, Legend, Series};
use crate::harness::{ClientPlan, CoreEdit, SessionPlan};

/// Simulated seconds per point: as long as the real-process test's sessions. (At 8 s the sweep missed the
/// testbed tour's segment near 9 s where a firm wrist out-twists the `sim:paper` device's 0.2 N m, which
/// the real processes met at every delay.)
pub const SECONDS: f64 = 10.0;

/// Seconds per point of this run: [`SECONDS`], or `--seconds` (at 40 s a hand tours its whole reach, there
/// and back; the grid's lead and model-update rows run as long, so their comparisons stay like for like).
pub fn seconds_per_point(options: &Options) -> f64 {
    options.session_seconds(SECONDS, SECONDS)
}
/// One-way delays of the full grid (ms).
pub const DELAYS_MS: [f64; 8] = [0.0, 50.0, 100.0, 200.0, 300.0, 500.0, 750.0, 1000.0];
/// Jitters of the full grid (ms).
pub const JITTERS_MS: [f64; 3] = [0.0, 10.0, 30.0];
/// Mean length of a loss burst (packets; snapshots and uplinks go at 1 kHz, so about milliseconds).
pub const BURST_LENGTH: f64 = 10.0;
/// The goals of issue 22 for the soft hand on the testbed, default settings, clean network: device-OP RMS at
/// most this at 100 ms one-way (m).
pub const GOAL_RMS_100MS_M: f64 = 0.003;
/// ... and at most this at 1 s one-way (m).
pub const GOAL_RMS_1S_M: f64 = 0.025;
/// The motion issue 22 measured the baseline of those goals with (`--user path:circle:0.005,2`: the soft hand
/// on a 5 mm circle through its grasp, a turn every 2 s; device-OP RMS 1.4 mm at 100 ms then). The sweep's
/// touring hand moves up to [`kinloop_client::user::hand::TOUR_SPEED_M_S`] between waypoints, about 4 cm in
/// the second a VE 1 s away has not heard of, more than the 1 s goal: the goals are judged on both motions.
pub fn goal_circle() -> PathSpec {
    PathSpec::Circle { radius: 0.005, period_s: 2.0 }
}
/// Issue 22, item 3: the passivity layer is on by default when, without delay, the device-OP distance with it
/// is within this factor of the distance without it (mean over the 0 ms points of the grid).
pub const GOAL_PASSIVITY_COST_AT_0MS: f64 = 1.10;

/// The scenes and operational points of the grid: (built-in scene, OP, short name).
pub const TARGETS: [(&str, &str, &str); 3] = [
    ("paper-testbed", "link2", "testbed"),
    ("fourbar-crank-rocker", "coupler", "fourbar"),
    ("watt-six-bar", "link5", "sixbar"),
];

/// Packet loss of a point, each direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Loss {
    /// No loss.
    None,
    /// 5 % of packets, independently.
    Random5,
    /// 20 % of packets in bursts (Gilbert: lost only in the bad state, mean burst [`BURST_LENGTH`]).
    Bursty20,
}

impl Loss {
    /// Every level, in order.
    pub const ALL: [Loss; 3] = [Loss::None, Loss::Random5, Loss::Bursty20];

    /// Name in summaries and charts.
    pub fn name(self) -> &'static str {
        match self {
            Loss::None => "no loss",
            Loss::Random5 => "5 % loss",
            Loss::Bursty20 => "20 % bursty loss",
        }
    }

    fn apply(self, link: &mut LinkConfig) {
        match self {
            Loss::None => {}
            Loss::Random5 => link.loss = 0.05,
            Loss::Bursty20 => {
                // Stationary loss p_gb / (p_gb + p_bg) = 0.2 with bursts of mean length 1 / p_bg.
                let p_bg = 1.0 / BURST_LENGTH;
                link.burst = Some(GilbertElliott {
                    p_good_to_bad: p_bg / 4.0,
                    p_bad_to_good: p_bg,
                    loss_good: 0.0,
                    loss_bad: 1.0,
                });
            }
        }
    }
}

/// The network of a point (besides its delay).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Network {
    /// Standard deviation of the one-way delay (ms).
    pub jitter_ms: f64,
    /// Loss.
    pub loss: Loss,
}

impl Network {
    /// No jitter and no loss.
    pub const CLEAN: Network = Network { jitter_ms: 0.0, loss: Loss::None };

    /// Name in summaries.
    pub fn name(self) -> String {
        format!("jitter {} ms, {}", self.jitter_ms, self.loss.name())
    }

    /// No jitter and no loss.
    pub fn is_clean(self) -> bool {
        self == Network::CLEAN
    }
}

/// One point of the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Index into [`TARGETS`].
    pub target: usize,
    /// The hand.
    pub hand: HandKind,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// Jitter and loss.
    pub network: Network,
    /// The VE's passivity controller on.
    pub passivity: bool,
}

impl Point {
    /// The emulated link (each direction; the harness gives the downlink its own seed).
    fn link(&self) -> LinkConfig {
        let ms = |v: f64| Duration::from_secs_f64(v / 1000.0);
        let loss = Loss::ALL.iter().position(|l| *l == self.network.loss).unwrap_or(0) as u64;
        let hand = HandKind::ALL.iter().position(|h| *h == self.hand).unwrap_or(0) as u64;
        let seed = 0x1a7e_0000
            + self.delay_ms as u64 * 1_000_000
            + self.network.jitter_ms as u64 * 1000
            + loss * 100
            + self.target as u64 * 10
            + hand;
        let mut link =
            LinkConfig { delay: ms(self.delay_ms), jitter: ms(self.network.jitter_ms), seed, ..LinkConfig::default() };
        self.network.loss.apply(&mut link);
        link
    }
}

/// What one point measured.
#[derive(Clone, Debug)]
pub struct Measured {
    /// The point.
    pub point: Point,
    /// The criterion's label.
    pub verdict: Verdict,
    /// Device-OP distance, RMS, device space (m).
    pub device_op_rms_m: f64,
    /// Device-local-model distance, RMS, device space (m).
    pub device_model_rms_m: f64,
    /// How far the device has moved since the pose the VE has heard of, RMS, device space (m): the floor of
    /// `device_op_rms_m` for a VE that does not run ahead of the hand (`ClientSummary::device_unheard_rms_m`).
    pub device_unheard_rms_m: f64,
    /// VE state restores.
    pub ve_restores: u64,
    /// Fraction of active ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Non-finite values the client's safety layer refused.
    pub non_finite: u64,
    /// Energy the coupling absorbed, as the passivity observer booked it (J; negative: generated; 0 when off).
    pub passivity_absorbed_j: f64,
    /// VE ticks in which the controller scaled the PD down.
    pub passivity_activations: u64,
    /// Median relative error of the impedance felt at the handle against the one the VE's linkage presents
    /// at the OP ([`impedance::felt_vs_rendered_error`]); `None` where the hand moved too little to tell.
    pub impedance_error: Option<f64>,
    /// The impedances behind it, per linear axis and frequency (`None` without samples enough).
    pub impedances: Option<impedance::Impedances>,
    /// Median relative change of the impedance felt at the handle from the same scene, hand and method
    /// without delay on a clean network (filled by [`fill_felt_changes`]; `None` until then, or where
    /// either session's hand moved too little to tell).
    pub felt_change: Option<f64>,
}

/// The undelayed session a point's feel is compared with: same scene, hand and method, 0 ms, clean network.
fn is_undelayed_reference(m: &Measured, of: &Point) -> bool {
    m.point.target == of.target
        && m.point.hand == of.hand
        && m.point.passivity == of.passivity
        && m.point.delay_ms == 0.0
        && m.point.network.is_clean()
}

/// Fills each point's [`Measured::felt_change`] against its undelayed session among `references`: how far
/// the delay, and whatever the VE and the client do about it, moved what the hand feels from what the same
/// hand feels without a network. The felt-vs-rendered error compares the handle with the VE's OP, whose
/// wrench-over-velocity depends on how the coupling drives it (on the testbed's soft tour, unled, its relative
/// change from the undelayed session's is 1.2 at 50 ms and 6.8 at 1 s), so it cannot tell a change of feel
/// from a change in how the VE is driven; this can.
pub fn fill_felt_changes(points: &mut [Measured], references: &[Measured]) {
    for m in points.iter_mut() {
        let reference = references.iter().find(|r| is_undelayed_reference(r, &m.point));
        m.felt_change = match (m.impedances.as_ref(), reference.and_then(|r| r.impedances.as_ref())) {
            (Some(z), Some(reference)) => impedance::relative_error(&z.felt, &reference.felt),
            _ => None,
        };
    }
}

/// Runs one point.
pub fn measure(p: &Point, seconds: f64) -> Result<Measured> {
    measure_with(p, seconds, None)
}

/// Runs one point with a change to the client's settings.
pub fn measure_with(p: &Point, seconds: f64, edit: Option<CoreEdit>) -> Result<Measured> {
    measure_leading(p, seconds, edit, Lead::default())
}

/// How a session's VE leads its couplings' targets ([`VeConfig::coupling_lead_max_s`] over the one-way delays
/// of [`VeConfig::coupling_lead_delays_s`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lead {
    /// The longest lead (s; 0: none).
    pub max_s: f64,
    /// The one-way delays it acts over (s, from and until).
    pub delays_s: [f64; 2],
}

impl Default for Lead {
    /// As `kinloop-server` leads by default.
    fn default() -> Self {
        let ve = VeConfig::default();
        Lead { max_s: ve.coupling_lead_max_s, delays_s: ve.coupling_lead_delays_s }
    }
}

impl Lead {
    /// A VE that follows what it hears.
    pub const NONE: Lead = Lead { max_s: 0.0, delays_s: [0.0, f64::INFINITY] };

    /// Leading by up to `max_s` at every delay.
    pub fn everywhere(max_s: f64) -> Self {
        Lead { max_s, delays_s: [0.0, f64::INFINITY] }
    }

    /// Its name in charts and summaries: "no lead", "lead <= 100 ms", "lead <= 100 ms from 75 ms".
    pub fn name(&self) -> String {
        if self.max_s <= 0.0 {
            return "no lead".into();
        }
        let [from, until] = self.delays_s;
        let within = match (from > 0.0, until.is_finite()) {
            (false, false) => String::new(),
            (_, true) => format!(" at {}-{} ms", from * 1e3, until * 1e3),
            (true, false) => format!(" from {} ms", from * 1e3),
        };
        format!("lead <= {} ms{within}", self.max_s * 1e3)
    }
}

/// As [`measure_with`] with the VE leading each coupling's target as `lead` says (the [`lead`] rows).
pub fn measure_leading(p: &Point, seconds: f64, edit: Option<CoreEdit>, lead: Lead) -> Result<Measured> {
    measure_intending(p, Intent::Tour, seconds, edit, lead)
}

/// As [`measure_leading`] with the point's hand intending `intent` instead of touring the OP's reach.
pub fn measure_intending(
    p: &Point,
    intent: Intent,
    seconds: f64,
    edit: Option<CoreEdit>,
    lead: Lead,
) -> Result<Measured> {
    let (scene_name, op, _) = TARGETS[p.target];
    let scene = kinloop_linkage::model::builtin::scene(scene_name).context("built in")??;
    let mut client = ClientPlan::new("user", op, DevicePreset::Paper);
    client.user = UserSpec::Hand(HandSpec { kind: p.hand, intent });
    client.configure = edit;
    let client = client.with_link(p.link());
    let ve = VeConfig {
        passivity: p.passivity,
        coupling_lead_max_s: lead.max_s,
        coupling_lead_delays_s: lead.delays_s,
        ..VeConfig::default()
    };
    let plan =
        SessionPlan { scene, ve, clients: vec![client], duration: Duration::from_secs_f64(seconds), record_every: 1 };
    let (summary, rec) = session(&plan).with_context(|| format!("{p:?}"))?;
    let c = &summary.clients[0];
    let user_id = rec.ve.iter().find_map(|v| v.users.first().map(|u| u.0));
    let impedances = user_id.and_then(|id| impedance::estimate(&rec, 0, id));
    let impedance_error = impedances.as_ref().and_then(|z| impedance::relative_error(&z.felt, &z.rendered));
    Ok(Measured {
        point: *p,
        verdict: verdict::judge(&summary, &rec),
        device_op_rms_m: c.device_op_rms_m,
        device_model_rms_m: c.device_model_rms_m,
        device_unheard_rms_m: c.device_unheard_rms_m,
        ve_restores: summary.ve_restores,
        clamped_fraction: c.saturated_fraction,
        non_finite: c.non_finite,
        passivity_absorbed_j: c.passivity_absorbed_j,
        passivity_activations: c.passivity_activations,
        impedance_error,
        impedances,
        felt_change: None,
    })
}

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

/// Whether the default VE runs the passivity controller (the method the goals are judged on).
fn default_passivity() -> bool {
    VeConfig::default().passivity
}

fn method(passivity: bool) -> &'static str {
    if passivity {
        "passivity"
    } else {
        "plain"
    }
}

/// One measured point as the summaries list it.
pub fn point_json(m: &Measured) -> Value {
    let p = &m.point;
    json!({
        "scene": TARGETS[p.target].0,
        "op": TARGETS[p.target].1,
        "hand": p.hand.name(),
        "delay_ms": p.delay_ms,
        "jitter_ms": p.network.jitter_ms,
        "loss": p.network.loss,
        "method": method(p.passivity),
        "stable": m.verdict.stable,
        "reasons": m.verdict.reasons,
        "device_op_rms_mm": round(m.device_op_rms_m * 1e3, 3),
        "device_op_max_mm": round(m.verdict.device_op_max_m * 1e3, 3),
        "device_op_heard_max_mm": round(m.verdict.device_op_heard_max_m * 1e3, 3),
        "device_local_model_rms_mm": round(m.device_model_rms_m * 1e3, 3),
        "device_unheard_rms_mm": round(m.device_unheard_rms_m * 1e3, 3),
        "ve_restores": m.ve_restores,
        "max_closure_error_m": significant(m.verdict.max_closure_error_m, 3),
        "clamped_fraction": round(m.clamped_fraction, 4),
        "worst_saturation": round(m.verdict.worst_saturation, 3),
        "non_finite": m.non_finite,
        "energy_excess_j": significant(m.verdict.energy_excess_j, 3),
        "energy_flow_max_j": significant(m.verdict.energy_flow_max_j, 3),
        "passivity_absorbed_j": significant(m.passivity_absorbed_j, 3),
        "passivity_activations": m.passivity_activations,
        "felt_vs_rendered_impedance_error": m.impedance_error.map(|e| round(e, 3)),
        "felt_change_from_undelayed": m.felt_change.map(|e| round(e, 3)),
    })
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
            format!("{} soft on the issue's 5 mm circle, {}", TARGETS[0].2, method(default_passivity())),
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
    // The goals' other motion: the testbed's soft hand on the circle, defaults, clean network.
    let circle_points: Vec<Point> = if grid.targets.contains(&0) {
        let network = Network::CLEAN;
        let at =
            |delay_ms| Point { target: 0, hand: HandKind::Soft, delay_ms, network, passivity: default_passivity() };
        grid.delays_ms.iter().map(|&d| at(d)).collect()
    } else {
        Vec::new()
    };
    let circle = sweep("latency: the issue's circle", &circle_points, options.threads, options.progress, |p| {
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

    let mut first_failures = Vec::new();
    let mut table = Vec::new();
    for &target in &grid.targets {
        for &hand in &grid.hands {
            for passivity in [false, true] {
                let first = first_failure(pair(&all, target, hand, passivity));
                let first_clean =
                    first_failure(pair(&all, target, hand, passivity).filter(|m| m.point.network.is_clean()));
                let unstable: Vec<&Measured> =
                    pair(&all, target, hand, passivity).filter(|m| !m.verdict.stable).collect();
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
                first_failures.push(json!({
                    "scene": TARGETS[target].0,
                    "op": TARGETS[target].1,
                    "hand": hand.name(),
                    "method": method(passivity),
                    "first_failure_ms": first,
                    "first_failure_clean_network_ms": first_clean,
                    "unstable_points": unstable.len(),
                    "points": pair(&all, target, hand, passivity).count(),
                    "unstable_at_first_failure": at_first,
                }));
            }
        }
    }
    let unstable = |passivity: bool| all.iter().filter(|m| m.point.passivity == passivity && !m.verdict.stable).count();
    let per_method = |passivity: bool| all.iter().filter(|m| m.point.passivity == passivity).count();
    let max_delay = grid.delays_ms.iter().copied().fold(0.0, f64::max);
    // A distance (mm) of the testbed's soft hand on a clean network, when the grid has that point.
    let testbed_soft_mm = |delay_ms: f64, passivity: bool, metres: fn(&Measured) -> f64| {
        grid.hands
            .contains(&HandKind::Soft)
            .then(|| clean(&all, 0, HandKind::Soft, passivity, delay_ms))
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
    // Item 3: what the passivity layer costs without delay, over every 0 ms point of the grid.
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
    let goals = json!({
        "default_method": method(default),
        "no_unstable_point_with_defaults": unstable(default) == 0,
        "unstable_points_with_defaults": unstable(default),
        "passivity_cost_at_0ms": {
            "device_op_rms_mm_mean_on": cost_on.map(|r| round(r, 3)),
            "device_op_rms_mm_mean_off": cost_off.map(|r| round(r, 3)),
            "ratio": cost_ratio,
            "goal": GOAL_PASSIVITY_COST_AT_0MS,
            "goal_met": cost_ratio.map(|r| r <= GOAL_PASSIVITY_COST_AT_0MS),
        },
        "testbed_soft_device_op_rms_mm_at_100ms": rms_100,
        "testbed_soft_device_op_rms_mm_at_100ms_goal_met": rms_100.map(|r| r <= GOAL_RMS_100MS_M * 1e3),
        "testbed_soft_device_op_rms_mm_at_1000ms": rms_1000,
        "testbed_soft_device_op_rms_mm_at_1000ms_goal_met": rms_1000.map(|r| r <= GOAL_RMS_1S_M * 1e3),
        "testbed_soft_device_op_rms_mm_with_passivity_off": {"100ms": goal_rms(100.0, false), "1000ms": goal_rms(1000.0, false)},
        "testbed_soft_device_unheard_rms_mm": {"100ms": floor_100, "1000ms": floor_1000},
        "testbed_soft_issue_circle": {
            "motion": "the soft hand on issue 22's own measured motion, --user path:circle:0.005,2 (a 5 mm circle, a turn every 2 s)",
            "device_op_rms_mm": {"100ms": circle_100, "1000ms": circle_1000},
            "device_unheard_rms_mm": {"100ms": circle_mm(100.0, |m| m.device_unheard_rms_m), "1000ms": circle_mm(1000.0, |m| m.device_unheard_rms_m)},
            "goal_met_at_100ms": circle_goal_met(circle_100, GOAL_RMS_100MS_M, 100.0),
            "goal_met_at_1000ms": circle_goal_met(circle_1000, GOAL_RMS_1S_M, 1000.0),
            "unstable_points": circle.iter().filter(|m| !m.verdict.stable).count(),
            "points": circle.iter().map(point_json).collect::<Vec<_>>(),
        },
        "device_unheard_rms_means": "how far the device had moved since the pose the VE had heard of: the device-OP distance of a VE sitting exactly on the device as heard, which a VE that does not run ahead of the hand cannot beat on average",
    });
    let answer = format!(
        "Up to {max_delay} ms one-way, {} of {} points are unstable with the defaults (passivity controller on), {} of {} \
         with it off (plain coupling). Without delay the controller costs {} (device-OP RMS, mean over the 0 ms points, \
         on / off; goal at most {GOAL_PASSIVITY_COST_AT_0MS}). First failing delay per scene, hand and method (any \
         jitter and loss of the grid): {}. Testbed, soft hand, clean network, defaults: device-OP RMS {} mm at 100 ms \
         (goal 3), {} mm at 1 s (goal 25); the device had moved {} mm and {} mm (RMS) from the pose the VE had heard \
         of. The same hand on the issue's 5 mm circle: {} mm at 100 ms, {} mm at 1 s ({} of {} delays unstable).",
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
    let results = json!({
        "answer": format!("{answer} {} {}", model_update["answer"].as_str().unwrap_or_default(), lead.answer),
        "goals": goals,
        "model_update": model_update,
        "lead": lead.summary,
        "first_failures": first_failures,
        "criterion": verdict::criterion_json(),
        "grid": {
            "scenes": grid.targets.iter().map(|&t| format!("{}:{}", TARGETS[t].0, TARGETS[t].1)).collect::<Vec<_>>(),
            "hands": grid.hands.iter().map(|h| h.name()).collect::<Vec<_>>(),
            "delays_ms": grid.delays_ms,
            "networks": grid.networks.iter().map(|n| n.name()).collect::<Vec<_>>(),
            "methods": ["plain (VeConfig::passivity off, --passivity off)", "passivity (VeConfig::passivity, the default)"],
            "points": all.len(),
            "seconds_per_point": seconds,
            "reduced": options.quick.then_some("--quick: the four-bar coupler, hands soft and poke, delays 0/100/500/1000 ms, a clean network and 30 ms jitter with 20 % bursty loss"),
        },
        "setup": {
            "session": "one client with default settings (server-designed coupling and mapping, designed client gains, sim:paper, stiffness mode, 1 kHz VE and haptic loop), a simulated hand touring the OP's reach; the client knows the nominal one-way delay",
            "network": format!("the same conditions both ways; jitter is the standard deviation of the one-way delay; 5 % loss is independent; 20 % bursty loss is Gilbert (lost in the bad state only) with mean burst {BURST_LENGTH} packets"),
            "first_failure": "the smallest delay at which some jitter and loss of the grid is unstable; null: none up to the largest delay",
            "passivity": "VeConfig::passivity: time-domain passivity observer on each coupling port (graphics-controller PD and force channel, per axis and in total) and controller: when the VE has received through the coupling more than the hand put in at the client (its books trusted as far as the uplinks show), the PD is scaled down, to zero once the excess reaches passivity_allowance_j, and what is taken off it brakes the OP",
        },
        "points": all.iter().map(point_json).collect::<Vec<_>>(),
    });
    out.finish(
        "Network delay, jitter and loss with default settings, with and without the passivity controller",
        "about 1 to 2 minutes on this 2-core machine shared with other work (1728 sessions of 10 s, 144 model-update sessions and 8 on the issue's circle, --threads 2); --quick (40 sessions) 2 to 3 s",
        results,
    )
}

/// One-way delays of the real-time run (ms), each with [`LIVE_JITTER_MS`] of jitter each way.
pub const LIVE_DELAYS_MS: [f64; 4] = [100.0, 300.0, 500.0, 1000.0];
/// Jitter of the real-time run (ms).
pub const LIVE_JITTER_MS: f64 = 10.0;
/// Devices of the real-time run.
pub const LIVE_DEVICES: [DevicePreset; 2] = [DevicePreset::Paper, DevicePreset::Falcon];
/// The hand of the real-time run's circle rows.
const LIVE_CIRCLE_HAND: &str = "soft on path:circle:0.005,2";
/// The real-time run's bound on ticks clamped at the device's limit (issue 22's goal).
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
    /// The soft hand on the circle ([`goal_circle`]) instead of the demo's default hand and tour.
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
    /// The hand: the demo's default, or the soft hand on the circle.
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
    })
}

/// `latency-live`: issue 22's real-process goal, three scenes × two devices × one-way delay {100, 300, 500,
/// 1000 ms} with 10 ms jitter each way, each a 10 s real-time session with default flags (3 s, testbed only,
/// with `--quick`), one at a time, and the testbed on `sim:paper` with the soft hand on the circle
/// ([`goal_circle`]) at each delay, where its tracking goals are read. A point meets the goal with no VE
/// restore, no withheld snapshot, nothing non-finite, closure within 1e-6 m and at most 5 % of the client's
/// ticks clamped at the device's limit.
pub fn run_live(options: &Options) -> Result<Report> {
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
    // Issue 22's tracking goals on the motion it measured them with, in real processes.
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
        "testbed_issue_circle_device_op_rms_mm": {"100ms": circle_100, "1000ms": circle_1000},
        "testbed_issue_circle_tracking_goal_met": circle_100.zip(circle_1000)
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
        "Issue 22's real-process goal: three scenes x two devices x delay, real time",
        "about 6 minutes (28 sessions of 10 s, one at a time); --quick about 30 s",
        results,
    )
}
