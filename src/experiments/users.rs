//! `users`: 1 to 16 users manipulating the testbed at once, each with a simulated paper device at 1 kHz on
//! a perfect network, joining 10 ms apart, for 3 s. Two layouts:
//!
//! - **same OP**: every user holds the testbed's operational point `link2`;
//! - **spread**: users hold distinct operational points added to the scene at run time along the four links
//!   (the first four at the links' midpoints, then at a quarter, three quarters and nine tenths of each).
//!
//! The users share the paper's wrench: each pushes `F / N` with F = (−0.5 N, 0, −0.0025 N m), so the
//! linkage is driven as hard as by the paper's single user whatever N (with the same OP, the VE's motion
//! should not depend on N at all; its deviation from the one-user run is reported). Each session is
//! labelled by [`super::verdict`] over all users. Cost: the VE's compute per VE tick (its step with every
//! coupling, and every user's snapshot) and the haptic cores' per user and tick, measured single-threaded,
//! best of five.
//!
//! **Sharing over a slow link.** Then 2, 4 and 16 users with hands that behave like hands (relaxed and firm
//! in turn, touring the OP's reach, `sim:paper` devices) share the testbed's `link2`, and 2 and 4 the
//! four-bar's coupler and crank tip, for 10 s at 0-1000 ms one way (both directions), each session twice:
//! with the other users' hands in each b̂ weighted by the measured round trip (the default, see the
//! server's `sharing`) and without that weighting (`VeConfig::exchange_delay_s` infinite: whole, as in the
//! paper's b̂, but for the bound on their inertia's loop, which does not depend on the delay).

use std::time::Duration;

use anyhow::{Context, Result};
use kinloop_client::user::UserSpec;
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_linkage::model::scene::{GeometrySpec, OpSpec};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::common::{
    paper_plan, path_length, rms_error, session, sweep, timed_cost, ve_op_trajectory, Options, Output, Report,
    Trajectory,
};
use super::verdict::{self, Verdict};
use crate::charts::{Chart, Legend, Series, StabilityMap};
use crate::rounding::{round, significant};
use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec};
use kinloop_harness::{ClientPlan, SessionPlan};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_server::core::VeConfig;

/// Simulated seconds per session.
const DURATION_S: f64 = 3.0;
/// Simulated seconds per session of the sharing sweep.
const SHARING_S: f64 = 10.0;
/// The sharing sweep's layouts: scene, its OPs (users take them in turn), the user counts, and a short name.
const SHARING_LAYOUTS: [(&str, &[&str], &[usize], &str); 2] = [
    ("paper-testbed", &["link2"], &[2, 4, 16], "testbed"),
    ("fourbar-crank-rocker", &["coupler", "crank-tip"], &[2, 4], "four-bar, 2 OPs"),
];
/// The sharing sweep's one-way delays (ms).
const SHARING_DELAYS_MS: [u64; 5] = [0, 20, 100, 300, 1000];
/// Time between two users' joins.
const JOIN_SPACING: Duration = Duration::from_millis(10);

#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    SameOp,
    Spread,
}

impl Layout {
    fn name(self) -> &'static str {
        match self {
            Layout::SameOp => "same OP (link2)",
            Layout::Spread => "spread over the links",
        }
    }
    fn key(self) -> &'static str {
        match self {
            Layout::SameOp => "same_op",
            Layout::Spread => "spread",
        }
    }
}

/// Adds operational points along every link (by the length of its capsule, or twice its COM offset) and
/// returns their names in the order users take them.
fn spread_ops(plan: &mut SessionPlan) -> Vec<String> {
    let mut names = Vec::new();
    for fraction in [0.5, 0.25, 0.75, 0.9] {
        for body in &plan.scene.bodies {
            let tip = body
                .geometry
                .iter()
                .find_map(|g| match g {
                    GeometrySpec::Capsule { to, .. } => Some(to.clone()),
                    GeometrySpec::Ball { .. } => None,
                })
                .unwrap_or_else(|| body.com.iter().map(|c| 2.0 * c).collect());
            let name = format!("{}@{}", body.name, fraction);
            names.push(name.clone());
            plan.scene.ops.push(OpSpec {
                name,
                body: body.name.clone(),
                point: tip.iter().map(|x| x * fraction).collect(),
            });
        }
    }
    names
}

fn plan(layout: Layout, users: usize, seconds: f64) -> Result<SessionPlan> {
    let mut plan = paper_plan(seconds)?;
    let ops = match layout {
        Layout::SameOp => vec!["link2".to_string()],
        Layout::Spread => spread_ops(&mut plan),
    };
    let share: Vec<f64> = PAPER_WRENCH.iter().map(|w| w / users as f64).collect();
    plan.clients = (0..users)
        .map(|i| {
            let mut c = ClientPlan::paper(&format!("user{}", i + 1));
            c.op = ops[i % ops.len()].clone();
            c.user = UserSpec::Constant(share.clone());
            c.join_at = JOIN_SPACING * i as u32;
            c
        })
        .collect();
    Ok(plan)
}

#[derive(Clone, Debug)]
struct Measured {
    layout: Layout,
    users: usize,
    verdict: Verdict,
    op_rms_mean_m: f64,
    op_rms_max_m: f64,
    /// RMS distance of the VE's `link2` from the one-user same-OP run's, m.
    deviation_from_one_user_m: Option<f64>,
    /// Path the VE's `link2` travelled, m.
    link2_path_m: f64,
    ve_us_per_tick: f64,
    client_us_per_tick_per_user: f64,
    uplinks_refused: u64,
    link2: Trajectory,
}

fn measure(layout: Layout, users: usize) -> Result<Measured> {
    let plan = plan(layout, users, DURATION_S)?;
    let (summary, rec) = session(&plan).with_context(|| format!("{} users, {}", users, layout.name()))?;
    let rms: Vec<f64> = summary.clients.iter().map(|c| c.device_op_rms_m).collect();
    let link2 = ve_op_trajectory(&plan, &rec, "link2")?;
    Ok(Measured {
        layout,
        users,
        verdict: verdict::judge(&summary, &rec),
        op_rms_mean_m: rms.iter().sum::<f64>() / rms.len().max(1) as f64,
        op_rms_max_m: rms.iter().copied().fold(0.0, f64::max),
        deviation_from_one_user_m: None,
        link2_path_m: path_length(&link2),
        ve_us_per_tick: f64::NAN,
        client_us_per_tick_per_user: f64::NAN,
        uplinks_refused: summary.clients.iter().map(|c| c.uplinks_refused).sum(),
        link2,
    })
}

/// `summary.json`'s `results` of the users experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UsersSummary {
    /// The one-line answer.
    pub answer: String,
    /// Users sharing a linkage under delay.
    pub sharing: SharingSummary,
    /// Whether the largest count of users stayed stable, per layout (none: not run).
    pub stable_with_max_users: StableWithMaxUsers,
    /// The VE's cost per extra user (µs a tick), per layout.
    pub ve_us_per_extra_user: PerLayout,
    /// How far link 2 travels with N users on one OP.
    pub link2_path_mm_same_op: Vec<Link2Path>,
    /// The stability criterion the sessions were judged by.
    pub criterion: Value,
    /// How the sessions ran.
    pub setup: UsersSetup,
    /// Every session of the count sweep.
    pub points: Vec<UsersPoint>,
}

/// Whether the sessions with the most users stayed stable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StableWithMaxUsers {
    /// The most users.
    pub users: usize,
    /// All on one OP.
    pub same_op: Option<bool>,
    /// Spread over the links.
    pub spread: Option<bool>,
}

/// A figure per layout (none where not run).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PerLayout {
    /// All users on one OP.
    pub same_op: Option<f64>,
    /// Users spread over the links.
    pub spread: Option<f64>,
}

/// Link 2's travel with N users on one OP.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Link2Path {
    /// Users.
    pub users: usize,
    /// Path length of link 2's COM (mm).
    pub path_mm: f64,
}

/// How the count sweep's sessions ran.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UsersSetup {
    /// The session.
    pub session: String,
    /// The users' load.
    pub load: String,
    /// The spread layout's OPs.
    pub spread_ops: String,
    /// How the cost was timed.
    pub cost: String,
}

/// One session of the count sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UsersPoint {
    /// `same_op` or `spread`.
    pub layout: String,
    /// Users.
    pub users: usize,
    /// The session's verdict.
    pub stable: bool,
    /// Why not, if not.
    pub reasons: Vec<String>,
    /// Device-OP RMS, mean over users (mm).
    pub device_op_rms_mm_mean_over_users: f64,
    /// Device-OP RMS of the worst user (mm).
    pub device_op_rms_mm_worst_user: f64,
    /// Largest device-OP distance (mm).
    pub device_op_max_mm: f64,
    /// Path length of link 2's COM (mm).
    pub ve_link2_path_mm: f64,
    /// RMS distance of link 2's path from the one-user session's (mm; one OP only).
    pub ve_link2_deviation_from_one_user_mm: Option<f64>,
    /// The VE's compute per tick (µs).
    pub ve_us_per_tick: f64,
    /// One haptic core's compute per tick (µs).
    pub haptic_core_us_per_tick_per_user: f64,
    /// The worst user's saturated fraction of ticks.
    pub worst_saturation: f64,
    /// Energy generated beyond the criterion's allowance (J).
    pub energy_excess_j: f64,
    /// Uplinks the server refused.
    pub uplinks_refused_by_server: u64,
}

/// The sharing sweep's part of the summary.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharingSummary {
    /// The sweep's one-line answer.
    pub answer: String,
    /// Unstable sessions with the others' hands weighted by the round trip.
    pub unstable_weighted: usize,
    /// Unstable sessions with the others' hands whole.
    pub unstable_whole: usize,
    /// Per layout, count and method: the smallest unstable delay (none: all stable).
    pub first_unstable: Vec<FirstUnstable>,
    /// How the sessions ran.
    pub setup: String,
    /// Every session.
    pub points: Vec<SharingPointSummary>,
}

/// The smallest unstable delay of one row of the sharing map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FirstUnstable {
    /// Layout, count and method.
    pub row: String,
    /// One-way delay (ms), none when every delay was stable.
    pub first_unstable_delay_ms: Option<u64>,
}

/// One session of the sharing sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharingPointSummary {
    /// The layout's name.
    pub layout: String,
    /// The OPs the users hold.
    pub ops: Vec<String>,
    /// Users.
    pub users: usize,
    /// One-way delay (ms).
    pub delay_ms: u64,
    /// `weighted` or `whole`.
    pub others_hands: String,
    /// The session's verdict.
    pub stable: bool,
    /// Why not, if not.
    pub reasons: Vec<String>,
    /// Device-OP RMS, mean over users (mm).
    pub device_op_rms_mm_mean_over_users: f64,
    /// Device-OP RMS of the worst user (mm).
    pub device_op_rms_mm_worst_user: f64,
    /// The worst user's saturated fraction of ticks.
    pub worst_saturation: f64,
    /// Energy generated beyond the criterion's allowance (J).
    pub energy_excess_j: f64,
}

fn point_summary(m: &Measured) -> UsersPoint {
    UsersPoint {
        layout: m.layout.key().into(),
        users: m.users,
        stable: m.verdict.stable,
        reasons: m.verdict.reasons.iter().map(|r| r.to_string()).collect(),
        device_op_rms_mm_mean_over_users: round(m.op_rms_mean_m * 1e3, 3),
        device_op_rms_mm_worst_user: round(m.op_rms_max_m * 1e3, 3),
        device_op_max_mm: round(m.verdict.device_op_max_m * 1e3, 3),
        ve_link2_path_mm: round(m.link2_path_m * 1e3, 2),
        ve_link2_deviation_from_one_user_mm: m.deviation_from_one_user_m.map(|d| round(d * 1e3, 3)),
        ve_us_per_tick: round(m.ve_us_per_tick, 2),
        haptic_core_us_per_tick_per_user: round(m.client_us_per_tick_per_user, 3),
        worst_saturation: round(m.verdict.worst_saturation, 3),
        energy_excess_j: significant(m.verdict.energy_excess_j, 3),
        uplinks_refused_by_server: m.uplinks_refused,
    }
}

fn line_per_layout(chart: Chart, measured: &[Measured], label: &str, y: impl Fn(&Measured) -> f64) -> Chart {
    [Layout::SameOp, Layout::Spread].into_iter().fold(chart, |chart, layout| {
        chart.with(Series::line(
            format!("{label}, {}", layout.name()),
            measured.iter().filter(|m| m.layout == layout).map(|m| (m.users as f64, y(m))).collect(),
        ))
    })
}

/// One session of the sharing sweep.
#[derive(Clone, Copy, Debug)]
struct SharingPoint {
    layout: usize,
    users: usize,
    delay_ms: u64,
    /// The other users' hands weighted by the round trip (the default), or whole.
    weighted: bool,
}

impl SharingPoint {
    fn label(&self) -> String {
        format!("{} x{}", SHARING_LAYOUTS[self.layout].3, self.users)
    }
    fn method(&self) -> &'static str {
        if self.weighted {
            "weighted"
        } else {
            "whole"
        }
    }
}

struct SharingMeasured {
    point: SharingPoint,
    verdict: Verdict,
    op_rms_mean_m: f64,
    op_rms_max_m: f64,
}

fn sharing_plan(p: &SharingPoint) -> Result<SessionPlan> {
    let (scene, ops, _, _) = SHARING_LAYOUTS[p.layout];
    let clients = (0..p.users)
        .map(|i| {
            let mut c = ClientPlan::new(&format!("user{}", i + 1), ops[i % ops.len()], DevicePreset::Paper);
            let hand = if i % 2 == 0 { HandKind::Soft } else { HandKind::Firm };
            c.user = UserSpec::Hand(HandSpec::touring(hand));
            let seed = 0x5a4e_0000 + p.layout as u64 * 1_000_000 + p.delay_ms * 1000 + i as u64;
            c.with_link(LinkConfig { delay: Duration::from_millis(p.delay_ms), seed, ..LinkConfig::default() })
        })
        .collect();
    let mut ve = VeConfig::default();
    ve.max_users = ve.max_users.max(p.users);
    if !p.weighted {
        ve.exchange_delay_s = f64::INFINITY;
    }
    Ok(SessionPlan {
        scene: kinloop_linkage::model::builtin::scene(scene).context("built in")??,
        ve,
        clients,
        duration: Duration::from_secs_f64(SHARING_S),
        record_every: 1,
    })
}

fn sharing_measure(p: &SharingPoint) -> Result<SharingMeasured> {
    let plan = sharing_plan(p)?;
    let (summary, rec) = session(&plan).with_context(|| format!("{} at {} ms", p.label(), p.delay_ms))?;
    let rms: Vec<f64> = summary.clients.iter().map(|c| c.device_op_rms_m).collect();
    Ok(SharingMeasured {
        point: *p,
        verdict: verdict::judge(&summary, &rec),
        op_rms_mean_m: rms.iter().sum::<f64>() / rms.len().max(1) as f64,
        op_rms_max_m: rms.iter().copied().fold(0.0, f64::max),
    })
}

/// The sharing sweep: its charts, and its part of the summary.
fn sharing(options: &Options, out: &mut Output) -> Result<SharingSummary> {
    let delays: Vec<u64> = options.pick(SHARING_DELAYS_MS.to_vec(), vec![0, 100]);
    let mut points = Vec::new();
    for (layout, (_, _, counts, _)) in SHARING_LAYOUTS.iter().enumerate() {
        let counts: Vec<usize> = options.pick(counts.to_vec(), counts.iter().copied().filter(|&n| n <= 4).collect());
        for &users in &counts {
            for weighted in [true, false] {
                for &delay_ms in &delays {
                    points.push(SharingPoint { layout, users, delay_ms, weighted });
                }
            }
        }
    }
    let measured = sweep("users sharing under delay", &points, options.threads, options.progress, sharing_measure)?;
    // One row per layout, count and method, in the order swept.
    let mut rows: Vec<(String, usize, usize, bool)> = Vec::new();
    for m in &measured {
        let p = m.point;
        let row = format!("{}, {}", p.label(), p.method());
        if !rows.iter().any(|r| r.0 == row) {
            rows.push((row, p.layout, p.users, p.weighted));
        }
    }
    let row_of = |p: &SharingPoint| rows.iter().position(|r| (r.1, r.2, r.3) == (p.layout, p.users, p.weighted));
    out.map(
        "stability_sharing_vs_delay",
        &StabilityMap {
            title: "Users sharing a linkage under delay".into(),
            x_label: "one-way delay (ms)".into(),
            y_label: "".into(),
            log: false,
            cells: measured
                .iter()
                .filter_map(|m| Some((m.point.delay_ms as f64, row_of(&m.point)? as f64, m.verdict.stable)))
                .collect(),
            overlays: Vec::new(),
            legend: Legend::LowerRight,
            y_categories: rows.iter().map(|r| r.0.clone()).collect(),
        },
    )?;
    let mut tracking = Chart::new(
        "Users sharing a linkage under delay: device-OP distance (RMS, mean over users)",
        "one-way delay (ms)",
        "device-OP distance, RMS (mm)",
    )
    .legend(Legend::UpperLeft);
    for (row, layout, users, weighted) in rows.iter().filter(|r| r.3) {
        let line = measured
            .iter()
            .filter(|m| (m.point.layout, m.point.users, m.point.weighted) == (*layout, *users, *weighted))
            .map(|m| (m.point.delay_ms as f64, m.op_rms_mean_m * 1e3))
            .collect();
        tracking = tracking.with(Series::line(row.clone(), line));
    }
    out.chart("tracking_sharing_vs_delay", &tracking)?;
    let first_unstable = rows
        .iter()
        .map(|(row, layout, users, weighted)| {
            let first = measured
                .iter()
                .filter(|m| (m.point.layout, m.point.users, m.point.weighted) == (*layout, *users, *weighted))
                .filter(|m| !m.verdict.stable)
                .map(|m| m.point.delay_ms)
                .min();
            FirstUnstable { row: row.clone(), first_unstable_delay_ms: first }
        })
        .collect();
    let unstable =
        |weighted: bool| measured.iter().filter(|m| m.point.weighted == weighted && !m.verdict.stable).count();
    let per_method = measured.len() / 2;
    Ok(SharingSummary {
        answer: format!(
            "Users sharing a linkage under delay (0-{} ms one way): {} of {per_method} sessions unstable with the \
             others' hands weighted by the round trip (the default), {} of {per_method} with them whole.",
            delays.iter().max().unwrap_or(&0),
            unstable(true),
            unstable(false),
        ),
        unstable_weighted: unstable(true),
        unstable_whole: unstable(false),
        first_unstable,
        setup: format!(
            "{SHARING_S} s sessions, sim:paper devices, relaxed and firm touring hands in turn, the delay both ways; \
             whole = VeConfig::exchange_delay_s infinite"
        ),
        points: measured
            .iter()
            .map(|m| SharingPointSummary {
                layout: SHARING_LAYOUTS[m.point.layout].0.into(),
                ops: SHARING_LAYOUTS[m.point.layout].1.iter().map(|op| op.to_string()).collect(),
                users: m.point.users,
                delay_ms: m.point.delay_ms,
                others_hands: m.point.method().into(),
                stable: m.verdict.stable,
                reasons: m.verdict.reasons.iter().map(|r| r.to_string()).collect(),
                device_op_rms_mm_mean_over_users: round(m.op_rms_mean_m * 1e3, 3),
                device_op_rms_mm_worst_user: round(m.op_rms_max_m * 1e3, 3),
                worst_saturation: round(m.verdict.worst_saturation, 3),
                energy_excess_j: significant(m.verdict.energy_excess_j, 3),
            })
            .collect(),
    })
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("users", options)?;
    let counts: Vec<usize> = options.pick(vec![1, 2, 4, 8, 12, 16], vec![1, 4, 16]);
    let points: Vec<(Layout, usize)> =
        [Layout::SameOp, Layout::Spread].into_iter().flat_map(|l| counts.iter().map(move |&n| (l, n))).collect();
    let mut measured =
        sweep("users (sessions)", &points, options.threads, options.progress, |&(layout, n)| measure(layout, n))?;
    let reps = 5;
    let costs = sweep("users (cost, 1 thread)", &points, 1, options.progress, |&(layout, n)| {
        let mut p = plan(layout, n, 2.0)?;
        p.record_every = 0;
        let ve_rate = p.ve.ve_rate_hz;
        let client_rate = p.clients[0].rate_hz;
        let (ve, client) = timed_cost(&p, reps)?;
        Ok((ve / ve_rate, client / client_rate / n as f64))
    })?;
    let one_user = measured.iter().find(|m| m.layout == Layout::SameOp && m.users == 1).map(|m| m.link2.clone());
    for (m, (ve, client)) in measured.iter_mut().zip(costs) {
        m.ve_us_per_tick = ve;
        m.client_us_per_tick_per_user = client;
        if m.layout == Layout::SameOp {
            m.deviation_from_one_user_m = one_user.as_ref().map(|base| rms_error(&m.link2, base));
        }
    }

    charts(&mut out, &measured)?;

    let find = |layout: Layout, n: usize| measured.iter().find(|m| m.layout == layout && m.users == n);
    let max_n = counts.iter().copied().max().unwrap_or(1);
    let verdict_of = |layout: Layout| {
        find(layout, max_n).map_or("not run".to_string(), |m| {
            if m.verdict.stable {
                "stable".to_string()
            } else {
                format!("UNSTABLE ({})", m.verdict.reasons.join(", "))
            }
        })
    };
    let per_user_cost = |layout: Layout| {
        let (a, b) = (find(layout, 1)?, find(layout, max_n)?);
        Some(significant((b.ve_us_per_tick - a.ve_us_per_tick) / (max_n - 1).max(1) as f64, 3))
    };
    let mut answer = format!(
        "{max_n} users on one OP: {}; {max_n} users spread over the links: {}. The VE's compute per tick grows from \
         {:.1} us with 1 user to {:.1} us with {max_n} (about {} us per extra user, same OP).",
        verdict_of(Layout::SameOp),
        verdict_of(Layout::Spread),
        find(Layout::SameOp, 1).map_or(f64::NAN, |m| m.ve_us_per_tick),
        find(Layout::SameOp, max_n).map_or(f64::NAN, |m| m.ve_us_per_tick),
        per_user_cost(Layout::SameOp).unwrap_or(f64::NAN),
    );
    if let (Some(one), Some(many)) = (find(Layout::SameOp, 1), find(Layout::SameOp, max_n)) {
        if one.verdict.stable && many.verdict.stable && max_n > 1 {
            answer.push_str(&format!(
                " Sharing the paper's push among N users on one OP should move the linkage as one user does: link 2's \
                 COM travels {:.0} mm with 1 user and {:.0} mm with {max_n}, {:.1} mm RMS from the one-user path (each \
                 device renders the OP's acceleration from every hand, the local model's bias b̂, so the users feel \
                 each other and their devices' masses stay hidden).",
                one.link2_path_m * 1e3,
                many.link2_path_m * 1e3,
                many.deviation_from_one_user_m.unwrap_or(f64::NAN) * 1e3,
            ));
        }
    }
    let sharing = sharing(options, &mut out)?;
    answer.push(' ');
    answer.push_str(&sharing.answer);
    let results = UsersSummary {
        answer,
        sharing,
        stable_with_max_users: StableWithMaxUsers {
            users: max_n,
            same_op: find(Layout::SameOp, max_n).map(|m| m.verdict.stable),
            spread: find(Layout::Spread, max_n).map(|m| m.verdict.stable),
        },
        ve_us_per_extra_user: PerLayout { same_op: per_user_cost(Layout::SameOp), spread: per_user_cost(Layout::Spread) },
        link2_path_mm_same_op: measured
            .iter()
            .filter(|m| m.layout == Layout::SameOp)
            .map(|m| Link2Path { users: m.users, path_mm: round(m.link2_path_m * 1e3, 1) })
            .collect(),
        criterion: verdict::criterion_json(),
        setup: UsersSetup {
            session: "paper testbed, sim:paper devices at 1 kHz, 1 kHz VE and snapshots, perfect network, 3 s, users join 10 ms apart".into(),
            load: "each of N users pushes F/N with F the paper's (-0.5 N, 0, -0.0025 N m): the total is the paper's".into(),
            spread_ops: "added at run time: every link at 0.5, then 0.25, 0.75, 0.9 of its length".into(),
            cost: format!("single thread, best of {reps} runs of 2 s without recording"),
        },
        points: measured.iter().map(point_summary).collect(),
    };
    out.finish(
        "1 to 16 users on one linkage: stability, tracking and VE cost, and sharing it under delay",
        "12 sessions of 3 s and their timing pass, 50 sharing sessions of 10 s; --quick fewer",
        serde_json::to_value(&results)?,
    )
}

/// The run's charts against the number of users: VE and haptic-core cost, tracking, the linkage's motion,
/// stability.
fn charts(out: &mut Output, measured: &[Measured]) -> Result<()> {
    let mut cost = line_per_layout(
        Chart::new(
            "VE compute per tick against the number of users (testbed, 1 kHz)",
            "users",
            "VE compute per tick (us)",
        ),
        measured,
        "VE step + every user's snapshot",
        |m| m.ve_us_per_tick,
    )
    .legend(Legend::UpperLeft);
    cost = line_per_layout(cost, measured, "haptic core per user", |m| m.client_us_per_tick_per_user);
    out.chart("ve_cost_per_tick_vs_users", &cost)?;
    let tracking = line_per_layout(
        Chart::new(
            "Tracking against the number of users: device-OP distance (RMS over each user, then mean)",
            "users",
            "device-OP distance, RMS (mm)",
        ),
        measured,
        "mean over users",
        |m| m.op_rms_mean_m * 1e3,
    );
    let tracking =
        line_per_layout(tracking, measured, "worst user", |m| m.op_rms_max_m * 1e3).legend(Legend::UpperRight);
    out.chart("tracking_vs_users", &tracking)?;
    let motion = line_per_layout(
        Chart::new("Linkage motion when N users share the paper's push (link 2's COM, 3 s)", "users", "length (mm)"),
        measured,
        "path travelled",
        |m| m.link2_path_m * 1e3,
    );
    let motion = motion
        .with(Series::line(
            "RMS deviation from the one-user run, same OP",
            measured.iter().filter_map(|m| m.deviation_from_one_user_m.map(|d| (m.users as f64, d * 1e3))).collect(),
        ))
        .legend(Legend::UpperRight);
    out.chart("linkage_motion_vs_users", &motion)?;
    out.map(
        "stability_users",
        &StabilityMap {
            title: "Stability with 1 to 16 users, on one OP and spread over the links".into(),
            x_label: "users".into(),
            y_label: "layout".into(),
            log: false,
            cells: measured
                .iter()
                .map(|m| (m.users as f64, if m.layout == Layout::SameOp { 0.0 } else { 1.0 }, m.verdict.stable))
                .collect(),
            overlays: Vec::new(),
            legend: Legend::UpperLeft,
            y_categories: vec!["same OP".into(), "spread".into()],
        },
    )
}
