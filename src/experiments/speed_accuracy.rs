//! `speed-accuracy`: what accuracy each VE integrator, VE rate, snapshot rate and local-model form buys,
//! and at what cost.
//!
//! **Reference.** The testbed alone (no device, no network) under the paper's wrench at the OP, integrated by
//! RK4 at 10 kHz with projection; the wrench fades in with the same raised cosine over the same 0.2 s as the
//! VE's coupling of a new user does, so the reference starts as the sessions do.
//!
//! **Sessions.** The paper's manipulation through the whole system (3 s; quick: 2 s) for every integrator ×
//! VE rate × snapshot rate (no faster than the VE) × local-model form. All sessions use the paper's linear
//! graphics-controller gains K_g = 1000 N/m, B_g = 100 N s/m with unit-consistent angular gains K_g L²,
//! B_g L² (L the scene's length scale): with the paper's own angular gains (10⁴) only semi-implicit Euler
//! with implicit coupling runs at all (see `stability` (d)), and the comparison would have one contestant.
//! Semi-implicit Euler treats the coupling implicitly; explicit Euler and RK4 cannot.
//!
//! **Accuracy** is the RMS distance between the VE's OP and the reference OP over the run (at every VE
//! tick), with the largest closure error beside it; **cost** is the wall-clock compute of the VE plus the
//! haptic core per simulated second (µs/s), measured in a separate single-threaded pass, best of a few
//! repetitions. Points judged unstable by [`super::verdict`] are reported but never on the Pareto front.
//!
//! A second view takes the network and the device out: the linkage alone under the faded wrench for each
//! integrator × rate (250 Hz to 10 kHz), OP error against the same reference, cost per simulated second.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use kinloop_client::core::ModelForm;
use kinloop_linkage::{
    algorithms::dynamics::OpWrench, algorithms::integrator::step, algorithms::integrator::Integrator,
    algorithms::integrator::StepConfig, math::space::Planar, model::data::Data, model::Model,
};
use kinloop_server::core::AxisGains;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::common::{
    op_position, paper_plan, pareto_front, rms_error, session, sweep, timed_cost, ve_op_trajectory, Options, Output,
    Report, Trajectory,
};
use super::verdict;
use crate::charts::{Chart, Legend, Series};
use crate::rounding::{round, significant};
use kinloop_harness::SessionPlan;

const PAPER_KG: f64 = 1000.0;
const PAPER_BG: f64 = 100.0;

/// One configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Config {
    integrator: Integrator,
    ve_rate_hz: f64,
    snapshot_rate_hz: f64,
    form: ModelForm,
}

impl Config {
    fn label(&self) -> String {
        format!(
            "{} {} Hz, snapshots {} Hz, {} form",
            self.integrator.name(),
            self.ve_rate_hz,
            self.snapshot_rate_hz,
            form_name(self.form)
        )
    }
}

fn form_name(form: ModelForm) -> &'static str {
    match form {
        ModelForm::Op => "op",
        ModelForm::Config => "config",
    }
}

fn plan(c: &Config, seconds: f64, length_scale: f64) -> Result<SessionPlan> {
    let mut plan = paper_plan(seconds)?;
    plan.ve.integrator = c.integrator;
    plan.ve.ve_rate_hz = c.ve_rate_hz;
    plan.ve.snapshot_rate_hz = c.snapshot_rate_hz;
    let l2 = length_scale * length_scale;
    plan.ve.coupling_stiffness = Some(AxisGains::Uniform { linear: PAPER_KG, angular: PAPER_KG * l2 });
    plan.ve.coupling_damping = Some(AxisGains::Uniform { linear: PAPER_BG, angular: PAPER_BG * l2 });
    plan.clients[0].form = c.form;
    Ok(plan)
}

/// Raised-cosine weight of a coupling fading in over `fade_s` (the VE's fade).
fn fade(t: f64, fade_s: f64) -> f64 {
    if t <= 0.0 {
        0.0
    } else if t >= fade_s {
        1.0
    } else {
        0.5 - 0.5 * (std::f64::consts::PI * t / fade_s).cos()
    }
}

/// The linkage alone under the paper's wrench, faded in from `start` over `fade` seconds when `fade_in` is
/// `Some((start, fade))`, sampled after every step; also returns the wall-clock seconds spent in `step`.
fn linkage_alone(
    plan: &SessionPlan,
    integrator: Integrator,
    rate_hz: f64,
    fade_in: Option<(f64, f64)>,
) -> Result<(Trajectory, f64)> {
    let model: Model<Planar> = Model::compile(&plan.scene, &plan.scene.name)?;
    let mut data = Data::new(&model);
    let (mut q, mut qd) = (model.q0.clone(), model.qd0.clone());
    let wrench = Vector3::from(kinloop_linkage::model::builtin::PAPER_WRENCH);
    let mut force = OpWrench::<Planar> { op: model.op_index("link2").context("OP link2")?, wrench };
    let dt = 1.0 / rate_hz;
    let cfg = StepConfig { integrator, dt, project: true, implicit_forces: false };
    let steps = (plan.duration.as_secs_f64() * rate_hz).round() as usize;
    let op = force.op;
    let mut out = Vec::with_capacity(steps + 1);
    out.push((0.0, op_position(&model, &mut data, &q, op)));
    let mut spent = Duration::ZERO;
    for k in 0..steps {
        let t = k as f64 * dt;
        if let Some((start, fade_s)) = fade_in {
            force.wrench = wrench * fade(t - start, fade_s);
        }
        let started = Instant::now();
        step(&model, &mut data, &mut q, &mut qd, &mut force, &cfg).with_context(|| format!("step {k}"))?;
        spent += started.elapsed();
        out.push(((k + 1) as f64 * dt, op_position(&model, &mut data, &q, op)));
    }
    Ok((out, spent.as_secs_f64()))
}

/// What one configuration measured.
#[derive(Clone, Debug)]
struct Measured {
    config: Config,
    op_error_rms_m: f64,
    numerical_error_rms_m: f64,
    device_error_rms_m: f64,
    max_closure_error_m: f64,
    stable: bool,
    reasons: Vec<&'static str>,
    cost_us_per_s: f64,
    ve_cost_us_per_s: f64,
    client_cost_us_per_s: f64,
}

fn ve_trajectory(c: &Config, seconds: f64, length: f64) -> Result<Trajectory> {
    let plan = plan(c, seconds, length)?;
    let (_, rec) = session(&plan).with_context(|| c.label())?;
    ve_op_trajectory(&plan, &rec, "link2")
}

fn accuracy(c: &Config, seconds: f64, length: f64, reference: &Trajectory, fine: &Trajectory) -> Result<Measured> {
    let plan = plan(c, seconds, length)?;
    let (summary, rec) = session(&plan).with_context(|| c.label())?;
    let verdict = verdict::judge(&summary, &rec);
    let ve = ve_op_trajectory(&plan, &rec, "link2")?;
    let device: Trajectory =
        rec.clients[0].iter().filter(|s| s.gain > 0.0).map(|s| (s.t, [s.device[0], s.device[1]])).collect();
    Ok(Measured {
        config: *c,
        op_error_rms_m: rms_error(&ve, reference),
        numerical_error_rms_m: rms_error(&ve, fine),
        device_error_rms_m: rms_error(&device, reference),
        max_closure_error_m: summary.max_closure_error,
        stable: verdict.stable,
        reasons: verdict.reasons,
        cost_us_per_s: f64::NAN,
        ve_cost_us_per_s: f64::NAN,
        client_cost_us_per_s: f64::NAN,
    })
}

fn configs(options: &Options) -> Vec<Config> {
    let ve_rates: Vec<f64> = options.pick(vec![250.0, 500.0, 1000.0, 2000.0], vec![250.0, 1000.0]);
    let snapshot_rates: Vec<f64> = options.pick(vec![100.0, 250.0, 500.0, 1000.0, 2000.0], vec![100.0, 1000.0]);
    let mut out = Vec::new();
    for integrator in Integrator::ALL {
        for &ve_rate_hz in &ve_rates {
            let mut snaps: Vec<f64> = snapshot_rates.iter().copied().filter(|&s| s <= ve_rate_hz).collect();
            if options.quick && !snaps.contains(&ve_rate_hz) {
                snaps.push(ve_rate_hz);
            }
            for snapshot_rate_hz in snaps {
                for form in [ModelForm::Op, ModelForm::Config] {
                    out.push(Config { integrator, ve_rate_hz, snapshot_rate_hz, form });
                }
            }
        }
    }
    out
}

/// `summary.json`'s `results` of the speed-accuracy experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpeedAccuracySummary {
    /// The one-line answer.
    pub answer: String,
    /// The configurations on the Pareto front of OP error against cost.
    pub pareto_front: Vec<String>,
    /// Their figures.
    pub pareto_front_points: Vec<SpeedAccuracyPoint>,
    /// The configurations on the Pareto front of numerical error against cost.
    pub numerical_pareto_front: Vec<String>,
    /// How the sessions ran and were measured.
    pub setup: SpeedAccuracySetup,
    /// Every configuration.
    pub points: Vec<SpeedAccuracyPoint>,
    /// The integrators on the linkage alone.
    pub linkage_alone: LinkageAlone,
}

/// How the sessions ran and were measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpeedAccuracySetup {
    /// The session.
    pub session: String,
    /// The graphics controller's coupling.
    pub coupling: String,
    /// The reference trajectory.
    pub reference: String,
    /// The accuracy figures.
    pub accuracy: String,
    /// The cost figure.
    pub cost: String,
    /// The stability criterion.
    pub criterion: String,
}

/// One configuration's figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpeedAccuracyPoint {
    /// Integrator's name.
    pub integrator: String,
    /// VE rate (Hz).
    pub ve_rate_hz: f64,
    /// Snapshot rate (Hz).
    pub snapshot_rate_hz: f64,
    /// Local-model form.
    pub form: String,
    /// RMS distance of the VE's OP from the linkage alone (m).
    pub op_error_rms_m: f64,
    /// RMS distance of the VE's OP from the numerical reference (m).
    pub numerical_error_rms_m: f64,
    /// RMS distance of the device from the linkage alone (m).
    pub device_error_rms_m: f64,
    /// Largest closure error (m).
    pub max_closure_error_m: f64,
    /// VE + haptic-core compute per simulated second (µs/s).
    pub cost_us_per_simulated_s: f64,
    /// The VE's part of it.
    pub ve_cost_us_per_simulated_s: f64,
    /// The haptic cores' part of it.
    pub client_cost_us_per_simulated_s: f64,
    /// Stable by the criterion.
    pub stable: bool,
    /// Why not, if not.
    pub reasons: Vec<String>,
}

/// The integrators on the linkage alone.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkageAlone {
    /// `integrator rate Hz` on the Pareto front of error against cost.
    pub pareto_front: Vec<String>,
    /// Every integrator and rate.
    pub points: Vec<LinkageAlonePoint>,
}

/// One integrator at one rate on the linkage alone.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkageAlonePoint {
    /// Integrator's name.
    pub integrator: String,
    /// Step rate (Hz).
    pub rate_hz: f64,
    /// RMS OP distance from the RK4 10 kHz reference (m).
    pub op_error_rms_m: f64,
    /// Step compute per simulated second (µs/s).
    pub cost_us_per_simulated_s: f64,
}

fn point_summary(m: &Measured) -> SpeedAccuracyPoint {
    SpeedAccuracyPoint {
        integrator: m.config.integrator.name().into(),
        ve_rate_hz: m.config.ve_rate_hz,
        snapshot_rate_hz: m.config.snapshot_rate_hz,
        form: form_name(m.config.form).into(),
        op_error_rms_m: significant(m.op_error_rms_m, 4),
        numerical_error_rms_m: significant(m.numerical_error_rms_m, 4),
        device_error_rms_m: significant(m.device_error_rms_m, 4),
        max_closure_error_m: significant(m.max_closure_error_m, 3),
        cost_us_per_simulated_s: round(m.cost_us_per_s, 1),
        ve_cost_us_per_simulated_s: round(m.ve_cost_us_per_s, 1),
        client_cost_us_per_simulated_s: round(m.client_cost_us_per_s, 1),
        stable: m.stable,
        reasons: m.reasons.iter().map(|r| r.to_string()).collect(),
    }
}

fn scatter(title: &str, y_label: &str, points: &[Measured], y: impl Fn(&Measured) -> f64, front: &[usize]) -> Chart {
    let mut chart = Chart::new(title, "cost: VE + haptic-core compute per simulated second (us/s)", y_label);
    chart.log_x = true;
    chart.log_y = true;
    for integrator in Integrator::ALL {
        for form in [ModelForm::Op, ModelForm::Config] {
            let pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|m| m.stable && m.config.integrator == integrator && m.config.form == form)
                .map(|m| (m.cost_us_per_s, y(m).max(1e-16)))
                .collect();
            if !pts.is_empty() {
                chart = chart.with(Series::markers(format!("{}, {} form", integrator.name(), form_name(form)), pts));
            }
        }
    }
    if !front.is_empty() {
        chart = chart.with(Series::line(
            "Pareto front",
            front.iter().map(|&i| (points[i].cost_us_per_s, y(&points[i]).max(1e-16))).collect(),
        ));
    }
    chart.legend(Legend::LowerLeft)
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("speed-accuracy", options)?;
    let seconds = options.pick(3.0, 2.0);
    let base = paper_plan(seconds)?;
    let length = Model::<Planar>::compile(&base.scene, &base.scene.name)?.length_scale;
    let fade_s = base.ve.fade_time.as_secs_f64();
    // The first uplink reaches the VE during its first period; its coupling fades in from the next tick.
    let reference_start = 1e-3;
    let (reference, _) = linkage_alone(&base, Integrator::Rk4, 10_000.0, Some((reference_start, fade_s)))?;
    // The numerical reference inside the system: the same session with RK4 at 10 kHz.
    let fine =
        Config { integrator: Integrator::Rk4, ve_rate_hz: 10_000.0, snapshot_rate_hz: 1000.0, form: ModelForm::Op };
    let fine_ve = ve_trajectory(&fine, seconds, length)?;

    let configs = configs(options);
    let mut measured = sweep("sessions (accuracy)", &configs, options.threads, options.progress, |c| {
        accuracy(c, seconds, length, &reference, &fine_ve)
    })?;
    // Cost: one thread, best of a few repetitions, no recording.
    let reps = options.pick(5, 3);
    let timing_s = 1.0;
    let costs = sweep("sessions (cost, 1 thread)", &configs, 1, options.progress, |c| {
        let mut p = plan(c, timing_s, length)?;
        p.record_every = 0;
        timed_cost(&p, reps)
    })?;
    for (m, (ve, client)) in measured.iter_mut().zip(costs) {
        m.ve_cost_us_per_s = ve;
        m.client_cost_us_per_s = client;
        m.cost_us_per_s = ve + client;
    }
    // The front of the figures as the summary reports them (`point_summary`'s rounding): two configurations
    // whose errors agree to the reported digits are told apart by their cost alone, as a reader of the summary
    // would, not by a difference below the digits shown.
    let front_of = |error: &dyn Fn(&Measured) -> f64| {
        let reported = |m: &Measured| (round(m.cost_us_per_s, 1), significant(error(m), 4));
        let pairs: Vec<(f64, f64)> =
            measured.iter().map(|m| if m.stable { reported(m) } else { (f64::INFINITY, f64::INFINITY) }).collect();
        pareto_front(&pairs)
    };
    let front = front_of(&|m| m.op_error_rms_m);
    let numerical_front = front_of(&|m| m.numerical_error_rms_m);
    scatter_charts(&mut out, &measured, &front, &numerical_front)?;

    // The linkage alone: integrators × rates.
    let alone_rates: Vec<f64> =
        options.pick(vec![250.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0], vec![250.0, 1000.0, 5000.0]);
    let alone_points: Vec<(Integrator, f64)> =
        Integrator::ALL.iter().flat_map(|&i| alone_rates.iter().map(move |&r| (i, r))).collect();
    let (smooth_reference, _) = linkage_alone(&base, Integrator::Rk4, 10_000.0, None)?;
    let alone = sweep("linkage alone (1 thread)", &alone_points, 1, options.progress, |&(integrator, rate)| {
        let (trajectory, spent) = linkage_alone(&base, integrator, rate, None)?;
        Ok((rms_error(&trajectory, &smooth_reference), spent * 1e6 / seconds))
    })?;
    let mut alone_chart = Chart::new(
        "The linkage alone: integrator accuracy vs cost (250 Hz to 10 kHz, projection on)",
        "cost: VE step compute per simulated second (us/s)",
        "RMS OP trajectory error (m)",
    )
    .legend(Legend::UpperRight);
    alone_chart.log_x = true;
    alone_chart.log_y = true;
    for integrator in Integrator::ALL {
        let pts: Vec<(f64, f64)> = alone_points
            .iter()
            .zip(&alone)
            .filter(|(p, _)| p.0 == integrator)
            .map(|(_, &(err, cost))| (cost, err.max(1e-16)))
            .collect();
        alone_chart = alone_chart.with(Series::line(integrator.name(), pts));
    }
    out.chart("linkage_alone_integrators", &alone_chart)?;
    let alone_pairs: Vec<(f64, f64)> = alone.iter().map(|&(e, c)| (c, e)).collect();
    let alone_front = pareto_front(&alone_pairs);

    let answer = answer(&measured, &front, &numerical_front);
    let results = SpeedAccuracySummary {
        answer,
        pareto_front: front.iter().map(|&i| measured[i].config.label()).collect(),
        pareto_front_points: front.iter().map(|&i| point_summary(&measured[i])).collect(),
        numerical_pareto_front: numerical_front.iter().map(|&i| measured[i].config.label()).collect(),
        setup: SpeedAccuracySetup {
            session: format!("paper testbed and user, sim:paper device, 1 kHz haptic loop, perfect network, {seconds} s"),
            coupling: format!("K_g = 1000 N/m, B_g = 100 N s/m linear; angular K_g L^2, B_g L^2 with L = {:.4} m; implicit for semi-implicit Euler, explicit otherwise", length),
            reference: "the linkage alone under the paper's wrench (faded in over 0.2 s like the VE's coupling), RK4 at 10 kHz with projection".into(),
            accuracy: "RMS distance between the VE's OP and the reference OP at every VE tick (op_error_rms_m); the same against the numerical reference, the whole session with RK4 at 10 kHz, op form, 1 kHz snapshots (numerical_error_rms_m); device error against the linkage reference at every haptic tick".into(),
            cost: format!("VE + haptic-core wall-clock compute per simulated second, one thread, best of {reps} runs of {timing_s} s"),
            criterion: verdict::CRITERION.into(),
        },
        points: measured.iter().map(point_summary).collect(),
        linkage_alone: LinkageAlone {
            pareto_front: alone_front.iter().map(|&i| format!("{} {} Hz", alone_points[i].0.name(), alone_points[i].1)).collect(),
            points: alone_points
                .iter()
                .zip(&alone)
                .map(|(p, &(err, cost))| LinkageAlonePoint {
                    integrator: p.0.name().into(),
                    rate_hz: p.1,
                    op_error_rms_m: significant(err, 4),
                    cost_us_per_simulated_s: round(cost, 1),
                })
                .collect(),
        },
    };
    out.finish(
        "Speed against accuracy: integrators x VE rates x snapshot rates x local-model forms, with the Pareto front",
        "84 sessions of 3 s, their timing pass, 18 linkage-alone runs; --quick fewer",
        serde_json::to_value(&results)?,
    )
}

/// The accuracy-vs-cost scatter charts of the sessions, the Pareto fronts marked.
fn scatter_charts(out: &mut Output, measured: &[Measured], front: &[usize], numerical_front: &[usize]) -> Result<()> {
    out.chart(
        "pareto_op_error_vs_cost",
        &scatter(
            "Accuracy vs cost: VE OP error against the ideal linkage (alone, RK4 at 10 kHz)",
            "RMS OP trajectory error (m)",
            measured,
            |m| m.op_error_rms_m,
            front,
        ),
    )?;
    out.chart(
        "pareto_numerical_error_vs_cost",
        &scatter(
            "Numerical accuracy vs cost: VE OP error against the same session with RK4 at 10 kHz",
            "RMS OP trajectory error (m)",
            measured,
            |m| m.numerical_error_rms_m,
            numerical_front,
        ),
    )?;
    out.chart(
        "closure_error_vs_cost",
        &scatter(
            "Loop-closure error vs cost (paper manipulation)",
            "largest closure error (m)",
            measured,
            |m| m.max_closure_error_m,
            &[],
        ),
    )?;
    out.chart(
        "device_error_vs_cost",
        &scatter(
            "What the hand feels: device trajectory error against the reference vs cost",
            "RMS device trajectory error (m)",
            measured,
            |m| m.device_error_rms_m,
            &[],
        ),
    )?;
    Ok(())
}

/// The run's answer: the error range of the stable sessions and what the two Pareto fronts hold.
fn answer(measured: &[Measured], front: &[usize], numerical_front: &[usize]) -> String {
    let describe = |front: &[usize]| {
        let distinct = |f: &dyn Fn(&Config) -> String| {
            let mut v: Vec<String> = front.iter().map(|&i| f(&measured[i].config)).collect();
            // Numbers in numeric order, names in alphabetical order.
            v.sort_by(|a, b| match (a.parse::<f64>(), b.parse::<f64>()) {
                (Ok(x), Ok(y)) => x.total_cmp(&y),
                _ => a.cmp(b),
            });
            v.dedup();
            v.join(", ")
        };
        format!(
            "{} of {} configurations (integrators: {}; VE rates: {} Hz; snapshot rates: {} Hz; forms: {})",
            front.len(),
            measured.len(),
            distinct(&|c| c.integrator.name().to_string()),
            distinct(&|c| c.ve_rate_hz.to_string()),
            distinct(&|c| c.snapshot_rate_hz.to_string()),
            distinct(&|c| form_name(c.form).to_string()),
        )
    };
    let error_range = |f: &dyn Fn(&Measured) -> f64| {
        let v: Vec<f64> = measured.iter().filter(|m| m.stable).map(f).collect();
        (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(0.0, f64::max))
    };
    let (lo, hi) = error_range(&|m| m.op_error_rms_m);
    format!(
        "Against the ideal linkage every stable configuration is {:.2}-{:.2} mm RMS off (the haptic coupling, not the \
         integrator, sets the error); the Pareto front of that error vs cost is {}. Against the numerical reference \
         (same session, RK4 at 10 kHz) the front is {}. Unstable configurations: {}.",
        lo * 1e3,
        hi * 1e3,
        describe(front),
        describe(numerical_front),
        measured.iter().filter(|m| !m.stable).count()
    )
}
