//! The one stability criterion every experiment labels its points with.
//!
//! A session is **unstable** when any of these holds, and **stable** otherwise:
//! 1. **divergence** — a client commanded or computed a non-finite value, the VE restored a non-finite
//!    state, the VE's operational point ended up more than [`DIVERGENCE_DISTANCE_M`] (5 cm) from its device
//!    as the VE has heard of it (the device's position at the client time of the newest uplink it used), or the
//!    loop-closure error, seen on the device (times the mapping's position scale), exceeded
//!    [`CLOSURE_LIMIT_M`] (1 mm: the loop visibly opens);
//! 2. **sustained saturation** — in some [`SATURATION_WINDOW_S`] (1 s) window after the output ramp-in
//!    (from [`RAMP_IN_S`] = 0.25 s on), more than [`SATURATION_FRACTION`] (10 %) of a client's haptic ticks
//!    had their command clamped at the device's force or torque limit, and the clamped command turned round
//!    (reversed its direction between clamped ticks) at least [`LIMIT_CYCLE_TURNS`] times in that window: a
//!    limit cycle against the motors. A window as saturated whose clamped command turns less is a hand
//!    pushing harder than the device renders, held at its limit ([`Verdict::held_at_limit`]): the device
//!    resists the whole time and nothing swings, so it is not instability; its clamped ticks count against
//!    rendering (the experiments' clamped-tick bound) instead. A device driven away on its own is caught by
//!    the divergence and energy tests, whatever its command does;
//! 3. **energy growth** — at some instant the linkage has gained more mechanical energy (kinetic, plus
//!    the change of its potential energy since the start) than all hands together had done work on their
//!    devices by the times the VE has heard of (each hand's work up to the client time of the newest uplink
//!    the VE used from it), by more than [`ENERGY_FRACTION`] (half) of the largest energy that has flowed so far (the
//!    hands' work or the potential energy's change, in absolute value) plus [`ENERGY_FLOOR_J`] (5 mJ at the device): the
//!    system made energy nobody put in. (A passive chain from hand to
//!    linkage keeps `E_kin(t) + ΔE_pot(t) ≤ W_hand(t)`; the margin absorbs the device's own kinetic energy
//!    and the springs of the couplings.)
//!
//! The hand's work is `W(t) = Σ_k F_h(k) · ẋ_d(k) Δt` over haptic ticks (force and torque, the device's
//! measured twist, both in VE units: a device mapped with scales does `c_f c_p` times this work itself),
//! the linkage's kinetic energy `½ q̇ᵀ D q̇` and potential energy after every VE tick. Device-OP distances
//! are in the device's space. The verdict needs a recording of every tick (`record_every = 1`).
//!
//! **In any units.** Every threshold is a figure at the device (metres and joules a hand at the handle would
//! notice), and the VE's figures are brought there through the mapping (`c_p`, and `c_f c_p` for energy; the
//! largest over the clients, the strictest), so a linkage written in millimetres and grams is judged exactly
//! as its SI twin. Every figure the verdict reports is at the device too.
//!
//! **Like with like under delay.** The VE at time t has heard of each device, and of the work its hand did,
//! only up to the client time its newest uplink carried (`Snapshot::uplink_time_s`), so both comparisons are made there: about t minus the
//! uplink's delay, later by jitter and loss, and at zero delay the plain comparisons. A VE that leads its target
//! (`VeConfig::coupling_lead_max_s`) names the later client time it aims at, and is compared there: it is
//! charged for what it guessed and the hand had not done by then. Compared with the device *now*, a VE that
//! follows faithfully 1 s behind a touring hand is centimetres away, and would be judged diverged, though the
//! gap never grows; and a jab that the hand took back before
//! its delayed copy reached the VE made the VE's energy look unpaid for. The device's distance to the VE's OP
//! now is still measured and reported (`device_op_max_m`, the RMS figures): it is the transparency, not the
//! stability.

use serde::Serialize;
use serde_json::{json, Value};

use kinloop_harness::{Recording, SessionSummary};
use kinloop_protocol::Mapping;

/// Device–OP distance beyond which a session has diverged (device m).
pub const DIVERGENCE_DISTANCE_M: f64 = 0.05;
/// Closure error beyond which the loop has opened (device m: the VE's closure error times the position scale).
pub const CLOSURE_LIMIT_M: f64 = 1e-3;
/// Length of the saturation window (s).
pub const SATURATION_WINDOW_S: f64 = 1.0;
/// Largest fraction of clamped ticks in any window.
pub const SATURATION_FRACTION: f64 = 0.10;
/// The reason the saturation test gives (experiments that count it apart match it by this name).
pub const SUSTAINED_SATURATION: &str = "sustained saturation";
/// Fewest turns of the clamped command in a saturated window that make it a limit cycle (one period: out and
/// back). Saturation with fewer is a steady push held at the device's limit, not instability.
pub const LIMIT_CYCLE_TURNS: usize = 2;
/// Ticks before this time (the client's output ramp-in) are not judged for saturation (s).
pub const RAMP_IN_S: f64 = 0.25;
/// Energy made beyond the hands' work, as a fraction of the largest work done so far.
pub const ENERGY_FRACTION: f64 = 0.5;
/// Energy made beyond the hands' work that is never held against a session (J at the device).
pub const ENERGY_FLOOR_J: f64 = 0.005;

/// The criterion in one sentence, for summaries.
pub const CRITERION: &str = "unstable <=> divergence (a non-finite value, a VE state restore, the VE's OP more than 5 \
cm from its device as the VE has heard of it (at the client time of its newest uplink used), or a closure error \
above 1 mm as seen on the device) OR sustained saturation (more than 10 % of a client's haptic \
ticks clamped at the device limit in some 1 s window after the 0.25 s ramp-in, the clamped command turning round \
at least twice in it: a limit cycle; a window as clamped whose command never turns is a push held at the limit, \
reported, not unstable) OR energy growth (at some instant the \
linkage's kinetic energy plus the change of its potential energy exceeds the work all hands had done on their \
devices up to the client times of the newest uplinks the VE used by more than half the largest energy that has flowed so far (hands' work or potential energy change, in \
absolute value) plus 5 mJ, energies taken at the device through the mapping's scales); stable otherwise";

/// The criterion as a JSON object (the sentence and its thresholds).
pub fn criterion_json() -> Value {
    json!({
        "rule": CRITERION,
        "divergence_distance_m": DIVERGENCE_DISTANCE_M,
        "closure_limit_m": CLOSURE_LIMIT_M,
        "saturation_window_s": SATURATION_WINDOW_S,
        "saturation_fraction": SATURATION_FRACTION,
        "limit_cycle_turns": LIMIT_CYCLE_TURNS,
        "ramp_in_s": RAMP_IN_S,
        "energy_fraction_of_work": ENERGY_FRACTION,
        "energy_floor_j": ENERGY_FLOOR_J,
    })
}

/// The label of one session and the numbers behind it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Verdict {
    /// Stable by the criterion.
    pub stable: bool,
    /// Which parts of the criterion failed (empty when stable).
    pub reasons: Vec<&'static str>,
    /// Largest device–OP distance over all clients (m).
    pub device_op_max_m: f64,
    /// Largest distance between the VE's OP and its device as the VE has heard of it, over all clients
    /// (m): what the divergence test judges.
    pub device_op_heard_max_m: f64,
    /// Largest closure error as seen on the device (device m).
    pub max_closure_error_m: f64,
    /// Largest fraction of clamped ticks in any window, over all clients.
    pub worst_saturation: f64,
    /// The most the clamped command turned round (its direction reversed between consecutive clamped ticks) in
    /// any window more than [`SATURATION_FRACTION`] clamped, over all clients: a limit cycle against the
    /// motors turns it every period, a hand pushing into a wall harder than the device renders never does.
    pub saturation_turns: usize,
    /// Some window was more than [`SATURATION_FRACTION`] clamped, but no such window turned the command
    /// [`LIMIT_CYCLE_TURNS`] times: a push held at the device's limit. Not a reason to be unstable.
    pub held_at_limit: bool,
    /// Largest `E_kin(t) − W(t)` (J at the device).
    pub energy_excess_j: f64,
    /// Largest energy that had flowed at any instant: the hands' total work or the potential energy's change,
    /// in absolute value (J at the device).
    pub energy_flow_max_j: f64,
    /// Largest kinetic energy of the linkage (J at the device).
    pub kinetic_energy_max_j: f64,
}

/// Judges a session from its summary and its every-tick recording.
pub fn judge(summary: &SessionSummary, rec: &Recording) -> Verdict {
    let mut reasons = Vec::new();
    let device_op_max_m = summary.clients.iter().map(|c| c.device_op_max_m).fold(0.0, f64::max);
    let device_op_heard_max_m = summary.clients.iter().map(|c| c.device_op_heard_max_m).fold(0.0, f64::max);
    let non_finite = summary.clients.iter().any(|c| c.non_finite > 0);
    if non_finite {
        reasons.push("divergence: non-finite value");
    }
    if summary.ve_restores > 0 {
        reasons.push("divergence: VE state restored");
    }
    if exceeds(device_op_heard_max_m, DIVERGENCE_DISTANCE_M) {
        reasons.push("divergence: OP more than 5 cm from its device as heard");
    }
    let to_device = DeviceFigures::of(summary);
    let max_closure_error_m = summary.max_closure_error * to_device.length;
    if exceeds(max_closure_error_m, CLOSURE_LIMIT_M) {
        reasons.push("divergence: closure error above 1 mm");
    }
    let saturation =
        rec.clients.iter().map(|samples| saturation_of(samples)).fold(Saturation::default(), |all, client| {
            Saturation {
                worst: all.worst.max(client.worst),
                turns_when_saturated: all.turns_when_saturated.max(client.turns_when_saturated),
            }
        });
    let (worst_saturation, saturation_turns) = (saturation.worst, saturation.turns_when_saturated);
    let saturated = worst_saturation > SATURATION_FRACTION;
    if saturated && saturation_turns >= LIMIT_CYCLE_TURNS {
        reasons.push(SUSTAINED_SATURATION);
    }
    let held_at_limit = saturated && saturation_turns < LIMIT_CYCLE_TURNS;
    let (excess, flow, kinetic) = energy_balance(rec);
    let (energy_excess_j, energy_flow_max_j, kinetic_energy_max_j) =
        (excess * to_device.energy, flow * to_device.energy, kinetic * to_device.energy);
    if exceeds(energy_excess_j, ENERGY_FRACTION * energy_flow_max_j + ENERGY_FLOOR_J) {
        reasons.push("energy growth");
    }
    Verdict {
        stable: reasons.is_empty(),
        reasons,
        device_op_max_m,
        device_op_heard_max_m,
        max_closure_error_m,
        worst_saturation,
        saturation_turns,
        held_at_limit,
        energy_excess_j,
        energy_flow_max_j,
        kinetic_energy_max_j,
    }
}

/// How the VE's figures are seen at the devices: device metres per VE length unit (`c_p`) and device joules
/// per VE energy unit (`c_f c_p`), the largest over the clients (the strictest reading); one to one for a
/// client whose mapping the summary does not give.
struct DeviceFigures {
    length: f64,
    energy: f64,
}

impl DeviceFigures {
    fn of(summary: &SessionSummary) -> Self {
        let usable = Mapping::usable_scale;
        let mapped = summary.clients.iter().filter(|c| usable(c.position_scale) && usable(c.force_scale));
        let (mut length, mut energy) = (0.0f64, 0.0f64);
        for c in mapped {
            length = length.max(c.position_scale);
            energy = energy.max(c.position_scale * c.force_scale);
        }
        DeviceFigures { length: Mapping::scale_or_one(length), energy: Mapping::scale_or_one(energy) }
    }
}

/// `x > limit`, counting NaN as beyond any limit.
fn exceeds(x: f64, limit: f64) -> bool {
    x.is_nan() || x > limit
}

/// How a client's clamped ticks fell in the windows of [`SATURATION_WINDOW_S`] after [`RAMP_IN_S`].
#[derive(Debug, Default, PartialEq)]
struct Saturation {
    /// The largest fraction of clamped ticks in any window (one window over what remains when the run is
    /// shorter).
    worst: f64,
    /// The most turns of the clamped command in any window more than [`SATURATION_FRACTION`] clamped.
    turns_when_saturated: usize,
}

/// Slides the window over `samples` once, with running counts of clamped ticks and of turns, so a session of
/// any length is judged in time linear in its ticks.
fn saturation_of(samples: &[kinloop_harness::ClientSample]) -> Saturation {
    let judged: Vec<&kinloop_harness::ClientSample> =
        samples.iter().filter(|s| s.t >= RAMP_IN_S && s.gain > 0.0).collect();
    if judged.is_empty() {
        return Saturation::default();
    }
    let clamped = |s: &kinloop_harness::ClientSample| s.clamp_scale < 1.0;
    // Counts before each judged tick: clamped ticks, and turns (a clamped tick whose command points against
    // the previous clamped tick's).
    let (mut clamped_before, mut turns_before) = (vec![0usize; judged.len() + 1], vec![0usize; judged.len() + 1]);
    // The first clamped tick at or after each judged tick (`judged.len()` when none).
    let mut next_clamped = vec![judged.len(); judged.len() + 1];
    let mut previous: Option<&[f64]> = None;
    for (k, s) in judged.iter().enumerate() {
        let turned =
            clamped(s) && previous.is_some_and(|p| p.iter().zip(&s.command).map(|(a, b)| a * b).sum::<f64>() < 0.0);
        if clamped(s) {
            previous = Some(&s.command);
        }
        clamped_before[k + 1] = clamped_before[k] + usize::from(clamped(s));
        turns_before[k + 1] = turns_before[k] + usize::from(turned);
    }
    for k in (0..judged.len()).rev() {
        next_clamped[k] = if clamped(judged[k]) { k } else { next_clamped[k + 1] };
    }
    let t_last = judged[judged.len() - 1].t;
    let mut out = Saturation::default();
    let mut end = 0;
    for start in 0..judged.len() {
        let t0 = judged[start].t;
        if t0 + SATURATION_WINDOW_S > t_last && start > 0 {
            break;
        }
        while end < judged.len() && judged[end].t < t0 + SATURATION_WINDOW_S {
            end += 1;
        }
        let n = end - start;
        let fraction = if n > 0 { (clamped_before[end] - clamped_before[start]) as f64 / n as f64 } else { 0.0 };
        out.worst = out.worst.max(fraction);
        if fraction > SATURATION_FRACTION {
            // Turns between clamped ticks both inside the window: those after its first clamped tick.
            let first = next_clamped[start];
            let turns = if first < end { turns_before[end] - turns_before[first + 1] } else { 0 };
            out.turns_when_saturated = out.turns_when_saturated.max(turns);
        }
    }
    out
}

/// `(max_t E_kin(t) − W(t), max_t W(t), max_t E_kin(t))` with W summed over clients at each VE sample, each
/// client's work taken up to the client time the VE had heard of it by then (its sample's `ve_heard_s`; the
/// sample's own time when the recording does not say).
fn energy_balance(rec: &Recording) -> (f64, f64, f64) {
    // Cumulative work per client at each of its samples.
    let work: Vec<Vec<(f64, f64)>> = rec
        .clients
        .iter()
        .map(|samples| {
            let mut w = 0.0;
            let mut last_t: Option<f64> = None;
            samples
                .iter()
                .map(|s| {
                    let dt = last_t.map_or(0.0, |t| s.t - t);
                    last_t = Some(s.t);
                    let power: f64 = s.hand.iter().zip(&s.device_twist).map(|(f, v)| f * v).sum();
                    if power.is_finite() {
                        w += power * dt;
                    }
                    (s.t, w)
                })
                .collect()
        })
        .collect();
    let mut cursors = vec![0usize; work.len()];
    let mut sample_cursors = vec![0usize; work.len()];
    // Recordings that say what the VE had heard (the harness's) are judged by it; others by the sample time.
    let says_heard: Vec<bool> = rec.clients.iter().map(|c| c.iter().any(|s| s.ve_heard_s.is_some())).collect();
    let (mut excess, mut work_max, mut ke_max) = (f64::NEG_INFINITY, 0.0f64, 0.0f64);
    let potential_start = rec.ve.first().map_or(0.0, |v| v.potential_energy);
    for v in &rec.ve {
        let mut w_total = 0.0;
        for (client, (series, cursor)) in work.iter().zip(cursors.iter_mut()).enumerate() {
            let samples = &rec.clients[client];
            let at = &mut sample_cursors[client];
            while *at + 1 < samples.len() && samples[*at + 1].t <= v.t {
                *at += 1;
            }
            let Some(sample) = samples.get(*at).filter(|s| s.t <= v.t) else { continue };
            // Before the VE has heard of a client, none of its work has reached the linkage.
            let heard_by = match sample.ve_heard_s {
                Some(heard) => heard.min(v.t),
                None if says_heard[client] => continue,
                None => v.t,
            };
            // Heard times only grow, but a cursor that overshot one would skip work: search when it goes back.
            if series.get(*cursor).is_some_and(|&(t, _)| t > heard_by) {
                *cursor = series.partition_point(|&(t, _)| t <= heard_by).saturating_sub(1);
            }
            while *cursor + 1 < series.len() && series[*cursor + 1].0 <= heard_by {
                *cursor += 1;
            }
            if let Some(&(t, w)) = series.get(*cursor) {
                if t <= heard_by {
                    w_total += w;
                }
            }
        }
        // The energy that has flowed: the hands' work or what gravity gave or took, whichever is larger (a hand
        // lowering a heavy linkage does negative work; the tolerance scales with the flow, not the balance).
        work_max = work_max.max(w_total.abs()).max((v.potential_energy - potential_start).abs());
        let ke = if v.kinetic_energy.is_finite() { v.kinetic_energy } else { f64::INFINITY };
        ke_max = ke_max.max(ke);
        // What the linkage gained beyond what gravity and its springs gave back: kinetic plus the change of
        // potential energy.
        let gained = ke + (v.potential_energy - potential_start);
        excess = excess.max(gained - w_total);
    }
    (if excess == f64::NEG_INFINITY { 0.0 } else { excess }, work_max, ke_max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_harness::{ClientSample, VeSample};

    fn sample(t: f64, clamped: bool, hand: f64, v: f64) -> ClientSample {
        ClientSample {
            t,
            hand: vec![hand, 0.0, 0.0],
            device_twist: vec![v, 0.0, 0.0],
            gain: 1.0,
            clamp_scale: if clamped { 0.5 } else { 1.0 },
            ..ClientSample::default()
        }
    }

    fn recording(clamp_from: f64, ke: f64) -> (SessionSummary, Recording) {
        let mut rec = Recording::new(vec!["a".into()]);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            rec.push_client(0, sample(t, t >= clamp_from, 1.0, 0.01));
            rec.push_ve(VeSample { t, kinetic_energy: ke * t / 3.0, ..VeSample::default() });
        }
        let summary = SessionSummary { clients: vec![Default::default()], ..Default::default() };
        (summary, rec)
    }

    #[test]
    fn a_quiet_session_is_stable() {
        // 1 N at 1 cm/s for 3 s: 30 mJ of work; the linkage ends with 20 mJ.
        let (s, r) = recording(10.0, 0.02);
        let v = judge(&s, &r);
        assert!(v.stable, "{v:?}");
        assert!((v.energy_flow_max_j - 0.03).abs() < 1e-3);
    }

    #[test]
    fn energy_growth_and_divergence_are_caught() {
        let (s, r) = recording(10.0, 0.2);
        assert_eq!(judge(&s, &r).reasons, vec!["energy growth"]);
        let (mut s, r) = recording(10.0, 0.0);
        s.clients[0].device_op_heard_max_m = 0.06;
        assert!(!judge(&s, &r).stable);
        // Trailing the device by a delay's worth of motion is not divergence.
        let (mut s, r) = recording(10.0, 0.0);
        s.clients[0].device_op_max_m = 0.06;
        s.clients[0].device_op_heard_max_m = 0.01;
        assert!(judge(&s, &r).stable);
    }

    /// Samples of 3 s whose command is `command(t)`, clamped where `clamped(t)`.
    fn commanded(command: &dyn Fn(f64) -> f64, clamped: &dyn Fn(f64) -> bool) -> Recording {
        let mut rec = Recording::new(vec!["a".into()]);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            rec.push_client(0, ClientSample { command: vec![command(t), 0.0, 0.0], ..sample(t, clamped(t), 1.0, 0.0) });
            rec.push_ve(VeSample { t, ..VeSample::default() });
        }
        rec
    }

    /// A command held at the limit against a hand never turns: it is a push held at the limit, reported and
    /// stable. One that swings between the limits at 10 Hz turns twice a period: a limit cycle, unstable. Turns
    /// in windows clamped no more than a tenth of their ticks are not a limit cycle against the motors.
    #[test]
    fn a_saturated_window_is_a_limit_cycle_only_when_its_clamped_command_turns() {
        let summary = SessionSummary { clients: vec![Default::default()], ..Default::default() };
        let held = |t: f64| if t >= 1.0 { -3.0 } else { 0.0 };
        let swinging = |t: f64| if (t * 20.0).floor() as i64 % 2 == 0 { 3.0 } else { -3.0 };
        let after_one_second = |t: f64| t >= 1.0;

        let rec = commanded(&held, &after_one_second);
        assert_eq!(saturation_of(&rec.clients[0]), Saturation { worst: 1.0, turns_when_saturated: 0 });
        let v = judge(&summary, &rec);
        assert!(v.stable && v.held_at_limit, "{v:?}");

        let rec = commanded(&swinging, &after_one_second);
        let swung = saturation_of(&rec.clients[0]);
        assert_eq!(swung.worst, 1.0);
        assert!((19..=21).contains(&swung.turns_when_saturated), "{swung:?}: a second at 10 Hz");
        let v = judge(&summary, &rec);
        assert_eq!(v.reasons, vec![SUSTAINED_SATURATION], "{v:?}");
        assert!(!v.held_at_limit);

        // Swinging, but clamped on one tick in twenty (5 %): saturated nowhere, so its turns are not counted.
        let rec = commanded(&swinging, &|t| (t * 1e3).round() as i64 % 20 == 0);
        let sparse = saturation_of(&rec.clients[0]);
        assert!((sparse.worst - 0.05).abs() < 0.002, "{sparse:?}");
        assert_eq!(sparse.turns_when_saturated, 0);
        assert!(judge(&summary, &rec).stable);

        let rec = commanded(&swinging, &|_| false);
        assert_eq!(saturation_of(&rec.clients[0]), Saturation::default(), "never clamped");
    }

    #[test]
    fn the_energy_balance_compares_the_ve_with_the_work_it_has_heard_of() {
        // A jab: the hand puts 40 mJ in over [1.0, 1.1) s, holds, and takes 38 mJ back over [1.3, 1.4) s. The
        // VE hears of it 0.5 s later and holds 90 % of the work it has heard of as kinetic energy.
        let work = |t: f64| match t {
            t if t < 1.0 => 0.0,
            t if t < 1.1 => 0.4 * (t - 1.0),
            t if t < 1.3 => 0.04,
            t if t < 1.4 => 0.04 - 0.38 * (t - 1.3),
            _ => 0.002,
        };
        let mut rec = Recording::new(vec!["a".into()]);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let (hand, v) = match t {
                t if (1.0..1.1).contains(&t) => (4.0, 0.1),
                t if (1.3..1.4).contains(&t) => (-3.8, 0.1),
                _ => (0.0, 0.0),
            };
            let mut s = sample(t, false, hand, v);
            s.ve_heard_s = Some(t - 0.5).filter(|&h| h > 0.0);
            rec.push_client(0, s);
            rec.push_ve(VeSample { t, kinetic_energy: 0.9 * work(t - 0.5), ..VeSample::default() });
        }
        let summary = SessionSummary { clients: vec![Default::default()], ..Default::default() };
        // Against the work the VE had heard of, it is paid for ...
        let heard = judge(&summary, &rec);
        assert!(heard.stable, "{heard:?}");
        assert!(heard.energy_excess_j < 1e-3, "{heard:?}");
        // ... against the work done by the same instant, 36 mJ held against 2 mJ of work is growth.
        let mut plain = rec.clone();
        plain.clients[0].iter_mut().for_each(|s| s.ve_heard_s = None);
        let now = judge(&summary, &plain);
        assert!((now.energy_excess_j - 0.034).abs() < 1e-3, "{now:?}");
        assert_eq!(now.reasons, vec!["energy growth"]);
        // Energy made from nothing is still caught, delay or not.
        for v in rec.ve.iter_mut().filter(|v| v.t >= 2.5) {
            v.kinetic_energy = 0.1;
        }
        assert_eq!(judge(&summary, &rec).reasons, vec!["energy growth"]);
    }
}
