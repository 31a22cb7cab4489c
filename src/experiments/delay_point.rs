//! A point of the delay experiments (`latency`, its `lead` and `model_update` rows, `latency-live`): the
//! scenes, hands and network conditions, the goals, and measuring one point in virtual time. It sits below
//! the experiments that use it.

use std::time::Duration;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec, Intent, PathSpec, UserSpec};
use kinloop_harness::{ClientPlan, CoreEdit, SessionPlan};
use kinloop_protocol::emulator::{GilbertElliott, LinkConfig};
use kinloop_server::core::VeConfig;

use super::common::{session, Options};
use super::impedance;
use super::verdict::{self, Verdict};
use crate::rounding::{round, significant};

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
/// The tracking goals for the soft hand on the testbed, default settings, clean network: device-OP RMS at
/// most this at 100 ms one-way (m).
pub const GOAL_RMS_100MS_M: f64 = 0.003;
/// ... and at most this at 1 s one-way (m).
pub const GOAL_RMS_1S_M: f64 = 0.025;
/// The motion those goals were set on (`--user path:circle:0.005,2`: the soft hand on a 5 mm circle through
/// its grasp, a turn every 2 s), the 5 mm goal circle. The sweep's
/// touring hand moves up to [`kinloop_client::user::hand::TOUR_SPEED_M_S`] between waypoints, about 4 cm in
/// the second a VE 1 s away has not heard of, more than the 1 s goal: the goals are judged on both motions.
pub fn goal_circle() -> PathSpec {
    PathSpec::Circle { radius: 0.005, period_s: 2.0 }
}
/// The passivity layer is on by default when, without delay, the device-OP distance with it
/// is within this factor of the distance without it (mean over the 0 ms points of the grid).
pub const GOAL_PASSIVITY_COST_AT_0MS: f64 = 1.10;

/// The scenes and operational points of the grid: (built-in scene, OP, short name).
pub const TARGETS: [(&str, &str, &str); 3] = [
    ("paper-testbed", "link2", "testbed"),
    ("fourbar-crank-rocker", "coupler", "fourbar"),
    ("watt-six-bar", "link5", "sixbar"),
];

/// Packet loss of a point, each direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
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
pub fn is_undelayed_reference(m: &Measured, of: &Point) -> bool {
    m.point.target == of.target
        && m.point.hand == of.hand
        && m.point.passivity == of.passivity
        && m.point.delay_ms == 0.0
        && m.point.network.is_clean()
}

/// Fills each point's [`Measured::felt_change`] against its undelayed session among `references`: how far
/// the delay, and whatever the VE and the client do about it, moved what the hand feels from what the same
/// hand feels without a network. The felt-vs-rendered error compares the handle with the VE's OP, whose
/// wrench-over-velocity depends on how the coupling drives it (and changes with the delay even when the hand's
/// feel does not), so it cannot tell a change of feel
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

/// Whether the default VE runs the passivity controller (the method the goals are judged on).
pub fn default_passivity() -> bool {
    VeConfig::default().passivity
}

/// The name of a coupling method in the summaries.
pub fn method(passivity: bool) -> &'static str {
    if passivity {
        "passivity"
    } else {
        "plain"
    }
}

/// One measured point as the summaries list it; tests read it back.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointSummary {
    /// Scene name.
    pub scene: String,
    /// Operational point.
    pub op: String,
    /// Hand name.
    pub hand: String,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// Jitter: standard deviation of the one-way delay (ms).
    pub jitter_ms: f64,
    /// Packet loss.
    pub loss: Loss,
    /// `plain` or `passivity` ([`method`]).
    pub method: String,
    /// The criterion's label.
    pub stable: bool,
    /// The parts of the criterion that failed.
    pub reasons: Vec<String>,
    /// Device-OP distance, RMS, device space (mm).
    pub device_op_rms_mm: f64,
    /// Largest device-OP distance (mm).
    pub device_op_max_mm: f64,
    /// Largest distance between the device as the VE heard it and the OP (mm).
    pub device_op_heard_max_mm: f64,
    /// Device-local-model distance, RMS (mm).
    pub device_local_model_rms_mm: f64,
    /// How far the device had moved since the pose the VE had heard of, RMS (mm).
    pub device_unheard_rms_mm: f64,
    /// VE state restores.
    pub ve_restores: u64,
    /// Largest loop-closure residual (m).
    pub max_closure_error_m: f64,
    /// Fraction of active ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Worst saturation of the criterion.
    pub worst_saturation: f64,
    /// Non-finite values the client's safety layer refused.
    pub non_finite: u64,
    /// Energy the linkage gained beyond the hand's work (J).
    pub energy_excess_j: f64,
    /// Largest energy flow of the criterion (J).
    pub energy_flow_max_j: f64,
    /// Energy the passivity observer booked as absorbed by the coupling (J).
    pub passivity_absorbed_j: f64,
    /// VE ticks in which the passivity controller scaled the PD down.
    pub passivity_activations: u64,
    /// Felt against rendered impedance at 0.5-4 Hz, median relative error.
    pub felt_vs_rendered_impedance_error: Option<f64>,
    /// Felt impedance against the same hand without delay, median relative change.
    pub felt_change_from_undelayed: Option<f64>,
}

impl PointSummary {
    /// The summary of one measured point, rounded for reading.
    pub fn of(m: &Measured) -> Self {
        let p = &m.point;
        PointSummary {
            scene: TARGETS[p.target].0.to_owned(),
            op: TARGETS[p.target].1.to_owned(),
            hand: p.hand.name().to_owned(),
            delay_ms: p.delay_ms,
            jitter_ms: p.network.jitter_ms,
            loss: p.network.loss,
            method: method(p.passivity).to_owned(),
            stable: m.verdict.stable,
            reasons: m.verdict.reasons.iter().map(|r| (*r).to_owned()).collect(),
            device_op_rms_mm: round(m.device_op_rms_m * 1e3, 3),
            device_op_max_mm: round(m.verdict.device_op_max_m * 1e3, 3),
            device_op_heard_max_mm: round(m.verdict.device_op_heard_max_m * 1e3, 3),
            device_local_model_rms_mm: round(m.device_model_rms_m * 1e3, 3),
            device_unheard_rms_mm: round(m.device_unheard_rms_m * 1e3, 3),
            ve_restores: m.ve_restores,
            max_closure_error_m: significant(m.verdict.max_closure_error_m, 3),
            clamped_fraction: round(m.clamped_fraction, 4),
            worst_saturation: round(m.verdict.worst_saturation, 3),
            non_finite: m.non_finite,
            energy_excess_j: significant(m.verdict.energy_excess_j, 3),
            energy_flow_max_j: significant(m.verdict.energy_flow_max_j, 3),
            passivity_absorbed_j: significant(m.passivity_absorbed_j, 3),
            passivity_activations: m.passivity_activations,
            felt_vs_rendered_impedance_error: m.impedance_error.map(|e| round(e, 3)),
            felt_change_from_undelayed: m.felt_change.map(|e| round(e, 3)),
        }
    }
}

/// A figure at the tracking goals' one-way delays, 100 ms and 1 s (written `100ms` and `1000ms`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AtGoalDelays {
    /// At 100 ms.
    #[serde(rename = "100ms")]
    pub at_100ms: Option<f64>,
    /// At 1 s.
    #[serde(rename = "1000ms")]
    pub at_1000ms: Option<f64>,
}

/// One measured point as the summaries list it ([`PointSummary`]).
pub fn point_json(m: &Measured) -> Value {
    json!(PointSummary::of(m))
}
