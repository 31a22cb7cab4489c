//! The `latency` experiment's lead rows (the tracking goals): what a VE that runs ahead of the hand
//! buys, and what it costs.
//!
//! A VE that follows what it hears trails the device by the uplink's delay: on the testbed's soft tour the
//! device has moved further since the pose the VE heard of (`device_unheard_rms_mm`) than the tracking goals
//! ([`GOAL_RMS_100MS_M`], [`GOAL_RMS_1S_M`]) allow. Only a VE that runs ahead of the hand
//! can be nearer. `VeConfig::coupling_lead_max_s` (`kinloop-server --lead-max-ms`, 100 ms by default, over the
//! one-way delays of `VeConfig::coupling_lead_delays_s`, from 75 ms on by default) aims each
//! graphics controller at the heard model pose moved along its twist by the one-way delay, up to the cap
//! and no longer than the heard motion supports (`Coupling::trusted_lead_s`: the twist's recent rates of
//! change, held over the lead, may put no more into the PD's spring than it holds stretched
//! `VeConfig::coupling_lead_guess_miss_m` at the device); what it guesses wrong is energy the hand never put in. Each row runs the grid's sessions
//! (every scene and hand, [`DELAYS_MS`]) on a clean network and on the grid's worst (30 ms of jitter, 20 %
//! bursty loss) with one lead ([`leads`]: none, at most 100 ms or the whole delay at every delay, and the
//! default), the rest as `kinloop-server` and
//! `kinloop-client` run by default (passivity controller on), and is judged by the sweep's criterion; the
//! energy comparison is made at the client time the VE aimed at (`Snapshot::uplink_time_s`), so a lead is
//! charged only for what the hand had not done by then. A last row ([`everywhere`]) runs every session the
//! grid ran with the default method again with the lead set the other way: what turning the default over
//! would do to tracking, stability and feel.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use kinloop_client::user::HandKind;
use kinloop_server::core::VeConfig;

use super::common::{sweep, Options, Output};
use super::delay_point::{
    fill_felt_changes, measure_leading, seconds_per_point, AtGoalDelays, Lead, Loss, Measured, Network, Point,
    PointSummary, GOAL_RMS_100MS_M, GOAL_RMS_1S_M, TARGETS,
};
use crate::charts::{Chart, HeatMap, Legend, Series};
use crate::rounding::round;

/// One-way delays of the rows (ms).
pub const DELAYS_MS: [f64; 7] = [50.0, 100.0, 200.0, 300.0, 500.0, 750.0, 1000.0];
/// The leads of the rows: none (a VE that follows what it hears, the paper's), at most 100 ms and at most
/// the whole delay of the grid at every delay, and the default (at most 100 ms over the one-way delays of
/// `DEFAULT_COUPLING_LEAD_DELAYS_S`).
pub fn leads() -> [Lead; 4] {
    [Lead::NONE, Lead::everywhere(0.1), Lead::everywhere(1.0), Lead::default()]
}

/// A row's lead as its name.
fn lead_name(lead: Lead) -> String {
    if lead == Lead::default() {
        format!("{} (default)", lead.name())
    } else {
        lead.name()
    }
}

/// What one lead's sessions came to.
struct LeadTally {
    lead: Lead,
    unstable: usize,
    sessions: usize,
    first_unstable_ms: Option<f64>,
    first_unstable_clean_ms: Option<f64>,
    soft_rms_100_mm: Option<f64>,
    soft_rms_1000_mm: Option<f64>,
}

/// The lead rows' part of the latency summary (its `lead`), typed so that tests read its fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeadSummary {
    /// The rows' answer: one sentence per lead, then the [`everywhere`] row's.
    pub answer: String,
    /// Per lead: its sessions and how they came out.
    pub rows: Vec<LeadRow>,
    /// Every session of the rows.
    pub points: Vec<LeadPoint>,
    /// The grid's default sessions run again with the lead set the other way.
    pub everywhere: EverywhereSummary,
    /// How the sessions ran.
    pub setup: String,
}

/// One lead over its sessions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeadRow {
    /// The lead's name ("(default)" appended for the default).
    pub lead: String,
    /// The longest lead (s; 0: none).
    pub cap_s: f64,
    /// The one-way delays it acts over (ms, from and until; `None`, written null, for no bound).
    pub delays_ms: [Option<f64>; 2],
    /// Its unstable sessions.
    pub unstable: usize,
    /// Its sessions.
    pub sessions: usize,
    /// The smallest one-way delay with an unstable session (ms), none if all were stable.
    pub first_unstable_delay_ms: Option<f64>,
    /// The same on the clean network only.
    pub first_unstable_delay_clean_network_ms: Option<f64>,
    /// The testbed's soft tour on a clean network: device-OP RMS (mm) at the goals' delays.
    pub testbed_soft_clean_device_op_rms_mm: AtGoalDelays,
}

/// One session of the rows: the delay experiments' point and the lead it ran with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeadPoint {
    /// The point.
    #[serde(flatten)]
    pub point: PointSummary,
    /// The lead's name, as its row's.
    pub lead: String,
    /// The longest lead (s).
    pub cap_s: f64,
}

/// The [`everywhere`] row: the grid's default sessions with the lead set the other way.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EverywhereSummary {
    /// The led sessions' lead.
    pub led: String,
    /// Its cap (s).
    pub cap_s: f64,
    /// Whether the default leads (then the grid's sessions are the led side, else the unled).
    pub default_leads: bool,
    /// Sessions on each side.
    pub sessions: usize,
    /// Unstable sessions led.
    pub unstable_led: usize,
    /// Unstable sessions unled.
    pub unstable_unled: usize,
    /// The unstable sessions of each side.
    pub unstable_points: LedAndUnled<Vec<PointSummary>>,
    /// Mean device-OP RMS (mm) over the sessions at each delay.
    pub device_op_rms_mm_mean_by_delay: Vec<ByDelay<f64>>,
    /// Median over the touring hands of the felt-vs-rendered impedance error at each delay.
    pub felt_vs_rendered_impedance_error_median_by_delay: Vec<ByDelay<Option<f64>>>,
    /// Median over the touring hands of the felt impedance's change from the same hand without delay.
    pub felt_change_from_undelayed_median_by_delay: Vec<ByDelay<Option<f64>>>,
}

/// Something of the led sessions and the same of the unled.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LedAndUnled<T> {
    /// Of the led sessions.
    pub led: T,
    /// Of the unled sessions.
    pub unled: T,
}

/// A figure of the led and the unled sessions at one one-way delay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ByDelay<T> {
    /// The one-way delay (ms).
    pub delay_ms: f64,
    /// The led sessions' figure.
    pub led: T,
    /// The unled sessions' figure.
    pub unled: T,
}

/// Runs the rows, draws their stability map and the testbed's soft tour at each cap, and returns their
/// summary.
///
/// `defaults` are the grid's sessions with the default method: each is run again with the lead set the other
/// way (see [`everywhere`]); `undelayed` holds the grid's sessions without delay on a clean network.
pub fn run(out: &mut Output, options: &Options, defaults: &[&Measured], undelayed: &[Measured]) -> Result<LeadSummary> {
    let chosen: Vec<Lead> = options.pick(leads().to_vec(), vec![Lead::everywhere(1.0)]);
    let targets: Vec<usize> = options.pick((0..TARGETS.len()).collect(), vec![0]);
    let hands = options.pick(HandKind::ALL.to_vec(), vec![HandKind::Soft, HandKind::Poke]);
    let delays: Vec<f64> = options.pick(DELAYS_MS.to_vec(), vec![100.0, 1000.0]);
    let clean = Network::CLEAN;
    let worst = Network { jitter_ms: 30.0, loss: Loss::Bursty20 };
    let networks = options.pick(vec![clean, worst], vec![clean]);
    let passivity = VeConfig::default().passivity;
    let mut rows: Vec<(Lead, usize, HandKind, Network)> = Vec::new();
    for &lead in &chosen {
        for &target in &targets {
            for &hand in &hands {
                for &network in &networks {
                    rows.push((lead, target, hand, network));
                }
            }
        }
    }
    // Row-major: a row's delays one after the other.
    let points: Vec<(Lead, Point)> = rows
        .iter()
        .flat_map(|&(lead, target, hand, network)| {
            delays.iter().map(move |&delay_ms| (lead, Point { target, hand, delay_ms, network, passivity }))
        })
        .collect();
    let all: Vec<(Lead, Measured)> =
        sweep("latency: lead", &points, options.threads, options.progress, |(lead, p)| {
            Ok((*lead, measure_leading(p, seconds_per_point(options), None, *lead)?))
        })?;

    stability_map(out, &rows, &delays, &all)?;

    let soft_clean = |lead: Lead| soft_clean_tour(&all, lead);
    tracking_chart(out, &chosen, &all)?;

    let of = |lead: Lead| all.iter().filter(move |(c, _)| *c == lead).map(|(_, m)| m);
    let first_unstable = |lead: Lead, clean_only: bool| {
        of(lead)
            .filter(|m| !m.verdict.stable && (!clean_only || m.point.network.is_clean()))
            .map(|m| m.point.delay_ms)
            .reduce(f64::min)
    };
    let soft_rms_at = |lead: Lead, delay_ms: f64| {
        soft_clean(lead).find(|(_, m)| m.point.delay_ms == delay_ms).map(|(_, m)| round(m.device_op_rms_m * 1e3, 2))
    };
    // One tally per lead, which both the JSON rows and the answer read.
    let tallies: Vec<LeadTally> = chosen
        .iter()
        .map(|&lead| LeadTally {
            lead,
            unstable: of(lead).filter(|m| !m.verdict.stable).count(),
            sessions: of(lead).count(),
            first_unstable_ms: first_unstable(lead, false),
            first_unstable_clean_ms: first_unstable(lead, true),
            soft_rms_100_mm: soft_rms_at(lead, 100.0),
            soft_rms_1000_mm: soft_rms_at(lead, 1000.0),
        })
        .collect();
    let rows: Vec<LeadRow> = tallies
        .iter()
        .map(|t| LeadRow {
            lead: lead_name(t.lead),
            cap_s: t.lead.max_s,
            // An unbounded end is written null, as JSON has no infinity.
            delays_ms: t.lead.delays_s.map(|s| Some(s * 1e3).filter(|ms| ms.is_finite())),
            unstable: t.unstable,
            sessions: t.sessions,
            first_unstable_delay_ms: t.first_unstable_ms,
            first_unstable_delay_clean_network_ms: t.first_unstable_clean_ms,
            testbed_soft_clean_device_op_rms_mm: AtGoalDelays {
                at_100ms: t.soft_rms_100_mm,
                at_1000ms: t.soft_rms_1000_mm,
            },
        })
        .collect();
    let mm = |r: Option<f64>| r.map_or("n/a".into(), |r| r.to_string());
    let answer = tallies
        .iter()
        .map(|t| {
            format!(
                "Leading the VE by the one-way delay, {}: testbed soft clean {} mm at 100 ms and {} mm at 1 s; {} \
                 of {} sessions unstable{}.",
                lead_name(t.lead),
                mm(t.soft_rms_100_mm),
                mm(t.soft_rms_1000_mm),
                t.unstable,
                t.sessions,
                t.first_unstable_ms.map_or(String::new(), |d| format!(" (from {d} ms)")),
            )
        })
        .collect::<Vec<_>>()
        .join(" ");
    let (everywhere, everywhere_answer) = everywhere(out, options, defaults, undelayed)?;
    let answer = format!("{answer} {everywhere_answer}");
    let points: Vec<LeadPoint> = all
        .iter()
        .map(|(lead, m)| LeadPoint { point: PointSummary::of(m), lead: lead_name(*lead), cap_s: lead.max_s })
        .collect();
    Ok(LeadSummary {
        answer,
        rows,
        points,
        everywhere,
        setup: "VeConfig::coupling_lead_max_s (kinloop-server --lead-max-ms) at each lead, at every one-way delay or (the default) over VeConfig::coupling_lead_delays_s (--lead-delays-ms), bounded by VeConfig::coupling_lead_guess_miss_m (the PD spring's energy at a 1 mm miss at the device), the passivity controller on as by default; the grid's sessions on a clean network and on 30 ms of jitter with 20 % bursty loss".into(),
    })
}

/// The testbed's soft tour on a clean network, where the goals are set, with the lead `lead`.
fn soft_clean_tour(all: &[(Lead, Measured)], lead: Lead) -> impl Iterator<Item = &(Lead, Measured)> {
    all.iter().filter(move |(c, m)| {
        *c == lead && m.point.target == 0 && m.point.hand == HandKind::Soft && m.point.network.is_clean()
    })
}

/// Which sessions of each row (lead, scene, hand, network) are unstable, against the delay.
fn stability_map(
    out: &mut Output,
    rows: &[(Lead, usize, HandKind, Network)],
    delays: &[f64],
    all: &[(Lead, Measured)],
) -> Result<()> {
    let mut map = HeatMap::new(
        "Leading the VE's target by the one-way delay: 1 = unstable",
        rows.iter()
            .map(|&(lead, t, h, n)| format!("{} {} {} {}", TARGETS[t].2, h.name(), n.name(), lead_name(lead)))
            .collect(),
        delays.iter().map(|d| format!("{d} ms")).collect(),
    );
    for (i, row) in all.chunks(delays.len()).enumerate() {
        for (j, (_, m)) in row.iter().enumerate() {
            map.set(i, j, if m.verdict.stable { 0.0 } else { 1.0 }, m.verdict.stable);
        }
    }
    out.heat_map("stability_lead", &map)
}

/// The testbed's soft tour on a clean network against the delay, for each lead, with the goals.
fn tracking_chart(out: &mut Output, chosen: &[Lead], all: &[(Lead, Measured)]) -> Result<()> {
    let soft_clean = |lead: Lead| soft_clean_tour(all, lead);
    let rms = |m: &Measured| (m.point.delay_ms, m.device_op_rms_m * 1e3);
    let mut chart = Chart::new(
        "Testbed, soft hand, clean network: following what is heard vs leading it (circles: unstable)",
        "one-way delay (ms)",
        "device-OP distance, RMS, device space (mm)",
    )
    .legend(Legend::LowerRight);
    chart.log_y = true;
    for &lead in chosen {
        chart = chart.with(Series::line(lead_name(lead), soft_clean(lead).map(|(_, m)| rms(m)).collect()));
    }
    if let Some(&lead) = chosen.first() {
        let floor = soft_clean(lead).map(|(_, m)| (m.point.delay_ms, m.device_unheard_rms_m * 1e3)).collect();
        chart = chart.with(Series::reference("a VE exactly on the device as heard", floor));
    }
    let unstable_soft = chosen.iter().flat_map(|&c| soft_clean(c)).filter(|(_, m)| !m.verdict.stable);
    chart = chart.with(Series::markers("unstable", unstable_soft.map(|(_, m)| rms(m)).collect()));
    chart = chart.with(Series::markers(
        "goals: 3 mm at 100 ms, 25 mm at 1 s",
        vec![(100.0, GOAL_RMS_100MS_M * 1e3), (1000.0, GOAL_RMS_1S_M * 1e3)],
    ));
    out.chart("tracking_lead", &chart)
}

/// A median over a set of sessions at one delay (ms).
type MedianByDelay<'a> = dyn Fn(&[&Measured], f64) -> Option<f64> + 'a;

/// The sessions of `set` the criterion judged unstable.
fn unstable<'m>(set: &[&'m Measured]) -> Vec<&'m Measured> {
    set.iter().copied().filter(|m| !m.verdict.stable).collect()
}

/// The cap of the [`everywhere`] row's led sessions when the default does not lead (s).
pub const EVERYWHERE_CAP_S: f64 = 0.1;

/// Every session of the grid that the default method ran (`defaults`), run again with the lead set the other
/// way (no lead when the default leads, else led by at most [`EVERYWHERE_CAP_S`] at every delay), judged by the same
/// criterion, with the device-OP distance and what the hand feels beside the default sessions' (chart
/// `impedance_lead`): the felt-vs-rendered impedance error, and the felt impedance's change from the same hand
/// without delay (its sessions in `undelayed`; at 0 ms a lead of at most the delay is none). Returns its
/// summary and one sentence.
fn everywhere(
    out: &mut Output,
    options: &Options,
    defaults: &[&Measured],
    undelayed: &[Measured],
) -> Result<(EverywhereSummary, String)> {
    let points: Vec<Point> = defaults.iter().map(|m| m.point).collect();
    let default_leads = Lead::default().max_s > 0.0;
    let led_lead = if default_leads { Lead::default() } else { Lead::everywhere(EVERYWHERE_CAP_S) };
    let other_lead = if default_leads { Lead::NONE } else { led_lead };
    let mut others: Vec<Measured> =
        sweep("latency: lead set the other way", &points, options.threads, options.progress, |p| {
            measure_leading(p, seconds_per_point(options), None, other_lead)
        })?;
    fill_felt_changes(&mut others, undelayed);
    let others: Vec<&Measured> = others.iter().collect();
    let (led, unled) = if default_leads { (defaults, &others[..]) } else { (&others[..], defaults) };
    // Tracking, led and not, over the same sessions: the mean device-OP RMS at each delay.
    let delays: Vec<f64> = {
        let mut d: Vec<f64> = points.iter().map(|p| p.delay_ms).collect();
        d.sort_by(f64::total_cmp);
        d.dedup();
        d
    };
    let mean_rms_mm = |set: &[&Measured], delay_ms: f64| {
        let at: Vec<f64> =
            set.iter().filter(|m| m.point.delay_ms == delay_ms).map(|m| m.device_op_rms_m * 1e3).collect();
        round(at.iter().sum::<f64>() / at.len().max(1) as f64, 3)
    };
    // What the hand feels, led and not: the median over the touring hands (soft, firm) at each delay; a lead
    // that brings the OP to the device can take the feel away from the linkage.
    let median_of = |metric: fn(&Measured) -> Option<f64>| {
        move |set: &[&Measured], delay_ms: f64| {
            let mut at: Vec<f64> = set
                .iter()
                .filter(|m| m.point.delay_ms == delay_ms && matches!(m.point.hand, HandKind::Soft | HandKind::Firm))
                .filter_map(|m| metric(m))
                .collect();
            at.sort_by(f64::total_cmp);
            at.get(at.len() / 2).map(|&e| round(e, 3))
        }
    };
    let median_impedance_error = median_of(|m| m.impedance_error);
    let median_felt_change = median_of(|m| m.felt_change);
    let by_delay: Vec<ByDelay<f64>> = delays
        .iter()
        .map(|&d| ByDelay { delay_ms: d, led: mean_rms_mm(led, d), unled: mean_rms_mm(unled, d) })
        .collect();
    let led_and_unled = |median: &MedianByDelay| -> Vec<ByDelay<Option<f64>>> {
        delays.iter().map(|&d| ByDelay { delay_ms: d, led: median(led, d), unled: median(unled, d) }).collect()
    };
    let impedance_by_delay = led_and_unled(&median_impedance_error);
    let felt_change_by_delay = led_and_unled(&median_felt_change);
    let mut chart = Chart::new(
        format!("Every session led ({}) or not: what the hand feels, median over touring hands", led_lead.name()),
        "one-way delay (ms)",
        "relative impedance error",
    )
    .legend(Legend::UpperLeft);
    for (name, set) in [("led", led), ("following what is heard", unled)] {
        let lines: [(&str, &MedianByDelay); 2] = [
            ("|Z_handle - Z_OP| / |Z_OP|", &median_impedance_error),
            ("|Z_handle - Z_handle(0 ms)| / |Z_handle(0 ms)|", &median_felt_change),
        ];
        for (metric, median) in lines {
            let line = delays.iter().filter_map(|&d| median(set, d).map(|e| (d, e))).collect();
            chart = chart.with(Series::line(format!("{name}: {metric}"), line));
        }
    }
    out.chart("impedance_lead", &chart)?;
    let (unstable_led, unstable_unled) = (unstable(led), unstable(unled));
    let summary = EverywhereSummary {
        led: lead_name(led_lead),
        cap_s: led_lead.max_s,
        default_leads,
        sessions: led.len(),
        unstable_led: unstable_led.len(),
        unstable_unled: unstable_unled.len(),
        unstable_points: LedAndUnled {
            led: unstable_led.iter().map(|m| PointSummary::of(m)).collect(),
            unled: unstable_unled.iter().map(|m| PointSummary::of(m)).collect(),
        },
        device_op_rms_mm_mean_by_delay: by_delay,
        felt_vs_rendered_impedance_error_median_by_delay: impedance_by_delay,
        felt_change_from_undelayed_median_by_delay: felt_change_by_delay,
    };
    let at_100 = |f: &MedianByDelay, set: &[&Measured]| f(set, 100.0).map_or("n/a".to_string(), |v| v.to_string());
    let rms_at = |set: &[&Measured], d: f64| Some(mean_rms_mm(set, d));
    let listed = |set: &[&Measured]| {
        if set.is_empty() {
            return String::new();
        }
        let names: Vec<String> = set
            .iter()
            .map(|m| {
                let p = &m.point;
                format!("{} {} {} ms {}", TARGETS[p.target].2, p.hand.name(), p.delay_ms, p.network.name())
            })
            .collect();
        format!(" ({})", names.join("; "))
    };
    let answer = format!(
        "Every session of the grid led ({}) and not: mean device-OP RMS at 100 ms {} mm led against {} unled; median \
         over touring hands at 100 ms of the felt-vs-rendered impedance error {} against {}, and of the felt \
         impedance's change from the same hand without delay {} against {}; unstable: {} of {} led{}, {} unled{}.",
        lead_name(led_lead),
        at_100(&rms_at, led),
        at_100(&rms_at, unled),
        at_100(&median_impedance_error, led),
        at_100(&median_impedance_error, unled),
        at_100(&median_felt_change, led),
        at_100(&median_felt_change, unled),
        unstable_led.len(),
        led.len(),
        listed(&unstable_led),
        unstable_unled.len(),
        listed(&unstable_unled),
    );
    Ok((summary, answer))
}
