//! `scale`: how the VE's step, the local model's step (both forms) and the snapshot grow with the linkage,
//! on the benchmark chains `chainN_loopsL` (`builtin::chain`: N links of 5 cm, L tips pinned to ground),
//! N from 4 to 100 and L from 0 to 10 (L ≤ N; chains whose closures leave no freedom are still measured, as
//! redundant closures must work).
//!
//! Each number is the median over batches of `kinloop_linkage::bench::measure`, single-threaded, state
//! 0.5 s into the paper's manipulation (the linkage moving):
//! - **VE step**: one semi-implicit Euler step with projection at 1 kHz (`bench::Case::ve_step`);
//! - **VE tick with a snapshot**: a whole `VeCore` tick with one user joined (the step plus that user's
//!   snapshot: Λ̂⁻¹, its SVD and, in the configuration form, the eq-11 terms), per form;
//! - **local-model step**: one haptic-rate step of the reduced operational-space model and of the
//!   configuration-space model (eq 11), and the latter's update (its factorization, once per snapshot);
//! - **snapshot bytes**: one encoded snapshot datagram, per form.
//!
//! Growth is summarized by the exponent p of a power-law fit `cost ∝ N^p` over N ≥ 8 for each L.

use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::bench::{measure, paper_wrench, Case};
use kinloop_linkage::{algorithms::integrator::Integrator, math::space::Planar, model::Model};
use kinloop_linkage::{
    algorithms::local_model::{ConfigSpaceLocalModel, ConfigSpaceTerms, LocalModelTerms},
    math::space::OpPose,
};
use kinloop_protocol::codec::encode_datagram;
use kinloop_protocol::{LocalModelForm, Role};
use kinloop_server::core::{JoinRequest, VeConfig, VeCore};
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::json;

use super::common::{log_log_slope, sweep, Options, Output, Report};
use crate::charts::{Chart, Legend, Series};
use crate::rounding::round;

/// Datagram payload quinn reported right after the handshake (see dependencies.md): a snapshot larger than
/// this needs the stream path.
const DATAGRAM_BUDGET_BYTES: f64 = 1162.0;

/// One chain's measurements (ns per call, bytes).
#[derive(Clone, Debug)]
struct Measured {
    links: usize,
    loops: usize,
    ve_step_ns: f64,
    tick_op_ns: f64,
    tick_config_ns: f64,
    op_step_ns: f64,
    config_step_ns: f64,
    config_update_ns: f64,
    snapshot_op_bytes: usize,
    snapshot_config_bytes: usize,
}

/// A VE with one user of `form` joined at `link2`; returns it after one tick with its snapshot's size.
fn ve_with_user(scene: &str, form: LocalModelForm) -> Result<(VeCore<Planar>, usize)> {
    let scene = kinloop_linkage::model::builtin::scene(scene).ok_or_else(|| anyhow!("no scene {scene}"))??;
    let model: Model<Planar> = Model::compile(&scene, &scene.name)?;
    let mut ve = VeCore::new(model, VeConfig::paper()).map_err(|e| anyhow!("{e}"))?;
    let request = JoinRequest {
        name: "probe".into(),
        role: Role::Manipulator,
        op: "link2".into(),
        form,
        device: None,
        mapping: Default::default(),
    };
    ve.join(Duration::ZERO, request).map_err(|e| anyhow!("join: {e:?}"))?;
    let period = ve.config().ve_period();
    ve.handle_timeout(period);
    let bytes = {
        let pending = ve.poll_snapshot().context("a snapshot after the first tick")?;
        encode_datagram(pending.datagram())?.len()
    };
    while ve.poll_snapshot().is_some() {}
    Ok((ve, bytes))
}

/// Median ns per VE tick (step + snapshot), ticking on from `ve`'s state.
fn time_ticks(mut ve: VeCore<Planar>, budget: Duration) -> f64 {
    let period = ve.config().ve_period();
    let mut now = ve.poll_timeout();
    measure(budget, || {
        ve.handle_timeout(now);
        while ve.poll_snapshot().is_some() {}
        now += period;
    })
    .median_ns
}

fn measure_chain(links: usize, loops: usize, budget: Duration) -> Result<Option<Measured>> {
    let name = format!("chain{links}_loops{loops}");
    let Some(mut case) = Case::new(&name) else { return Ok(None) };
    let ve_step_ns = measure(budget, || case.ve_step(Integrator::SemiImplicitEuler)).median_ns;

    let mut lm = case.local_model();
    let f = paper_wrench();
    let op_step_ns = measure(budget, || {
        std::hint::black_box(lm.step(1e-3, &f));
    })
    .median_ns;

    case.prepare_op_space();
    op_space_inertia(&case.model, &mut case.data, 0).with_context(|| format!("{name}: op-space inertia"))?;
    let (n, m) = (case.model.nv(), case.model.nc());
    let mut terms = ConfigSpaceTerms::zeros(n, m, 3);
    terms.fill_from(&case.model, &mut case.data, &case.q, &case.qd, &f, LocalModelTerms::full());
    let pose = OpPose::<Planar>::of_op(&case.model, &case.data, 0);
    let mut config = ConfigSpaceLocalModel::<Planar>::new(n, m);
    let config_update_ns = measure(budget, || {
        std::hint::black_box(config.update(&terms, pose));
    })
    .median_ns;
    anyhow::ensure!(config.update(&terms, pose), "{name}: the configuration-space model refused its terms");
    let config_step_ns = measure(budget, || {
        std::hint::black_box(config.step(1e-3, &f));
    })
    .median_ns;

    let (ve_op, snapshot_op_bytes) = ve_with_user(&name, LocalModelForm::OpSpace)?;
    let tick_op_ns = time_ticks(ve_op, budget);
    let (ve_config, snapshot_config_bytes) = ve_with_user(&name, LocalModelForm::ConfigSpace)?;
    let tick_config_ns = time_ticks(ve_config, budget);
    Ok(Some(Measured {
        links,
        loops,
        ve_step_ns,
        tick_op_ns,
        tick_config_ns,
        op_step_ns,
        config_step_ns,
        config_update_ns,
        snapshot_op_bytes,
        snapshot_config_bytes,
    }))
}

/// `summary.json`'s `results` of the scale experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleSummary {
    /// The one-line answer.
    pub answer: String,
    /// How each cost grows with the links.
    pub growth_exponents_over_links: Growth,
    /// Which snapshots outgrow one datagram.
    pub snapshot_over_datagram_budget: DatagramBudget,
    /// The chains and how they were timed.
    pub setup: ScaleSetup,
    /// Chains of the grid that could not be measured (`chainN_loopsL`).
    pub skipped: Vec<String>,
    /// Every chain measured.
    pub points: Vec<ScalePoint>,
    /// The grid's largest chain with the most loops, if it was measured.
    pub largest_chain: Option<ScalePoint>,
}

/// Power-law exponents of a cost against the links, by loop count (`loops_L`; none where no fit).
pub type Exponents = BTreeMap<String, Option<f64>>;

/// Each cost's power-law exponents over the links.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Growth {
    /// How the exponents were fitted.
    pub fit: String,
    /// The VE's step.
    pub ve_step: Exponents,
    /// The VE's tick with an op-form user's snapshot.
    pub ve_tick_with_op_snapshot: Exponents,
    /// The VE's tick with a config-form user's snapshot.
    pub ve_tick_with_config_snapshot: Exponents,
    /// The op-form local model's step.
    pub op_local_model_step: Exponents,
    /// The config-form local model's step.
    pub config_local_model_step: Exponents,
    /// The config-form local model's update from a snapshot.
    pub config_local_model_update: Exponents,
    /// The config-form snapshot's size.
    pub snapshot_bytes_config: Exponents,
}

/// Snapshot sizes against what one datagram carries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatagramBudget {
    /// Bytes one datagram carries.
    pub budget_bytes: f64,
    /// The first chain whose config-form snapshot is over the budget.
    pub config_form_first_over: Option<String>,
    /// The largest op-form snapshot (bytes).
    pub op_form_largest_bytes: Option<usize>,
}

/// The chains and how they were timed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleSetup {
    /// The scenes.
    pub scenes: String,
    /// How each number was timed.
    pub timing: String,
    /// The state timed.
    pub state: String,
}

/// One chain's costs and snapshot sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalePoint {
    /// Links N.
    pub links: usize,
    /// Loops L.
    pub loops: usize,
    /// The VE's step (µs).
    pub ve_step_us: f64,
    /// The VE's tick with an op-form user's snapshot (µs).
    pub ve_tick_with_op_snapshot_us: f64,
    /// The VE's tick with a config-form user's snapshot (µs).
    pub ve_tick_with_config_snapshot_us: f64,
    /// The op-form local model's step (ns).
    pub op_local_model_step_ns: f64,
    /// The config-form local model's step (ns).
    pub config_local_model_step_ns: f64,
    /// The config-form local model's update (µs).
    pub config_local_model_update_us: f64,
    /// An op-form snapshot (bytes).
    pub snapshot_bytes_op: usize,
    /// A config-form snapshot (bytes).
    pub snapshot_bytes_config: usize,
}

fn point_summary(m: &Measured) -> ScalePoint {
    ScalePoint {
        links: m.links,
        loops: m.loops,
        ve_step_us: round(m.ve_step_ns / 1e3, 3),
        ve_tick_with_op_snapshot_us: round(m.tick_op_ns / 1e3, 3),
        ve_tick_with_config_snapshot_us: round(m.tick_config_ns / 1e3, 3),
        op_local_model_step_ns: round(m.op_step_ns, 1),
        config_local_model_step_ns: round(m.config_step_ns, 1),
        config_local_model_update_us: round(m.config_update_ns / 1e3, 3),
        snapshot_bytes_op: m.snapshot_op_bytes,
        snapshot_bytes_config: m.snapshot_config_bytes,
    }
}

/// Power-law exponents over N ≥ 8 for each loop count.
fn exponents(points: &[Measured], loops: &[usize], cost: impl Fn(&Measured) -> f64) -> Exponents {
    let mut out = Exponents::new();
    for &l in loops {
        let sel: Vec<&Measured> = points.iter().filter(|m| m.loops == l && m.links >= 8).collect();
        let xs: Vec<f64> = sel.iter().map(|m| m.links as f64).collect();
        let ys: Vec<f64> = sel.iter().map(|m| cost(m)).collect();
        out.insert(format!("loops_{l}"), log_log_slope(&xs, &ys).map(|p| round(p, 2)));
    }
    out
}

/// An exponent as the answer prints it (as the JSON does; `null` where there is no fit).
fn exponent(exponents: &Exponents, loops: usize) -> serde_json::Value {
    json!(exponents.get(&format!("loops_{loops}")).copied().flatten())
}

/// A line of a chart against links: label, loop count, the plotted value.
type Line<'a> = (String, usize, &'a dyn Fn(&Measured) -> f64);

fn by_links(title: &str, y_label: &str, points: &[Measured], lines: &[Line<'_>]) -> Chart {
    let mut chart = Chart::new(title, "links N (chainN_loopsL)", y_label).legend(Legend::UpperLeft);
    chart.log_x = true;
    chart.log_y = true;
    for (label, loops, y) in lines {
        chart = chart.with(Series::line(
            label.clone(),
            points.iter().filter(|m| m.loops == *loops).map(|m| (m.links as f64, y(m))).collect(),
        ));
    }
    chart
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("scale", options)?;
    let links: Vec<usize> = options.pick(vec![4, 6, 8, 12, 16, 25, 35, 50, 70, 100], vec![4, 8, 16, 35, 70, 100]);
    let loops: Vec<usize> = options.pick(vec![0, 1, 2, 5, 10], vec![0, 1, 5, 10]);
    let budget = Duration::from_millis(options.pick(100, 10));
    let grid: Vec<(usize, usize)> =
        links.iter().flat_map(|&n| loops.iter().filter(move |&&l| l <= n).map(move |&l| (n, l))).collect();
    // Timings: one thread, so that points do not slow each other.
    let results = sweep("chains (1 thread)", &grid, 1, options.progress, |&(n, l)| measure_chain(n, l, budget))?;
    let skipped: Vec<String> = grid
        .iter()
        .zip(&results)
        .filter(|(_, r)| r.is_none())
        .map(|((n, l), _)| format!("chain{n}_loops{l}"))
        .collect();
    let points: Vec<Measured> = results.into_iter().flatten().collect();

    charts(&mut out, &points, &links, &loops)?;

    let us = |ns: f64| ns / 1e3;
    let (l_lo, l_hi) = (loops[0], loops[loops.len() - 1]);
    let largest = links[links.len() - 1];

    let find = |n: usize, l: usize| points.iter().find(|m| m.links == n && m.loops == l);
    let ve_exp = exponents(&points, &loops, |m| m.ve_step_ns);
    let config_exp = exponents(&points, &loops, |m| m.config_step_ns);
    let op_exp = exponents(&points, &loops, |m| m.op_step_ns);
    let answer = format!(
        "VE step grows as about N^{} (no loops) to N^{} ({l_hi} loops); at {largest} links it costs {:.1} us with {l_lo} loops \
         and {:.1} us with {l_hi}. The op-form local-model step stays near {:.0} ns whatever the linkage (exponent {}), the \
         config-form step grows as N^{} ({:.0} ns at {largest} links). Snapshots: {} B (op form) vs {} B (config form) at \
         {largest} links and {l_hi} loops.",
        exponent(&ve_exp, l_lo),
        exponent(&ve_exp, l_hi),
        find(largest, l_lo).map_or(f64::NAN, |m| us(m.ve_step_ns)),
        find(largest, l_hi).map_or(f64::NAN, |m| us(m.ve_step_ns)),
        find(largest, l_hi).map_or(f64::NAN, |m| m.op_step_ns),
        exponent(&op_exp, l_hi),
        exponent(&config_exp, l_hi),
        find(largest, l_hi).map_or(f64::NAN, |m| m.config_step_ns),
        find(largest, l_hi).map_or(0, |m| m.snapshot_op_bytes),
        find(largest, l_hi).map_or(0, |m| m.snapshot_config_bytes),
    );
    let results = ScaleSummary {
        answer,
        growth_exponents_over_links: Growth {
            fit: "least squares of log cost against log N over N >= 8, per loop count".into(),
            ve_step: ve_exp,
            ve_tick_with_op_snapshot: exponents(&points, &loops, |m| m.tick_op_ns),
            ve_tick_with_config_snapshot: exponents(&points, &loops, |m| m.tick_config_ns),
            op_local_model_step: op_exp,
            config_local_model_step: config_exp,
            config_local_model_update: exponents(&points, &loops, |m| m.config_update_ns),
            snapshot_bytes_config: exponents(&points, &loops, |m| m.snapshot_config_bytes as f64),
        },
        snapshot_over_datagram_budget: DatagramBudget {
            budget_bytes: DATAGRAM_BUDGET_BYTES,
            config_form_first_over: points
                .iter()
                .filter(|m| m.snapshot_config_bytes as f64 > DATAGRAM_BUDGET_BYTES)
                .map(|m| format!("chain{}_loops{}", m.links, m.loops))
                .next(),
            op_form_largest_bytes: points.iter().map(|m| m.snapshot_op_bytes).max(),
        },
        setup: ScaleSetup {
            scenes: "builtin::chain(N, L): N links of 5 cm and 1 kg, L tips pinned to ground, OP at link 2's COM"
                .into(),
            timing: format!(
                "kinloop_linkage::bench::measure, median over batches, {} ms per number, one thread",
                budget.as_millis()
            ),
            state: "0.5 s into the paper's wrench at the OP, rewound every 3 s".into(),
        },
        skipped,
        points: points.iter().map(point_summary).collect(),
        largest_chain: find(largest, l_hi).map(point_summary),
    };
    out.finish(
        "Scaling: VE step, local-model step and snapshot size against links and loops",
        "45 chains, 7 timings of 0.1 s each; --quick fewer",
        serde_json::to_value(&results)?,
    )
}

/// The run's charts: VE step and tick, local-model step and update, and snapshot size against links; cost
/// against loops at the largest chain.
fn charts(out: &mut Output, points: &[Measured], links: &[usize], loops: &[usize]) -> Result<()> {
    let us = |ns: f64| ns / 1e3;
    let step_plain = |m: &Measured| us(m.ve_step_ns);
    let ve_lines: Vec<Line<'_>> =
        loops.iter().map(|&l| (format!("{l} loops"), l, &step_plain as &dyn Fn(&Measured) -> f64)).collect();
    out.chart(
        "ve_step_vs_links",
        &by_links("VE step cost against links (semi-implicit Euler + projection)", "VE step (us)", points, &ve_lines),
    )?;
    let (l_lo, l_hi) = (loops[0], loops[loops.len() - 1]);
    let tick_op = |m: &Measured| us(m.tick_op_ns);
    let tick_config = |m: &Measured| us(m.tick_config_ns);
    out.chart(
        "ve_tick_with_snapshot_vs_links",
        &by_links(
            "VE tick with one user's snapshot against links",
            "VE tick (us)",
            points,
            &[
                (format!("step only, {l_hi} loops"), l_hi, &step_plain),
                (format!("step + op-form snapshot, {l_lo} loops"), l_lo, &tick_op),
                (format!("step + op-form snapshot, {l_hi} loops"), l_hi, &tick_op),
                (format!("step + config-form snapshot, {l_lo} loops"), l_lo, &tick_config),
                (format!("step + config-form snapshot, {l_hi} loops"), l_hi, &tick_config),
            ],
        ),
    )?;
    let op_step = |m: &Measured| m.op_step_ns;
    let config_step = |m: &Measured| m.config_step_ns;
    let config_update = |m: &Measured| m.config_update_ns;
    out.chart(
        "local_model_vs_links",
        &by_links(
            "Local-model cost against links: op form vs configuration form (eq 11)",
            "ns per call",
            points,
            &[
                (format!("op-form step, {l_hi} loops"), l_hi, &op_step),
                (format!("config-form step, {l_lo} loops"), l_lo, &config_step),
                (format!("config-form step, {l_hi} loops"), l_hi, &config_step),
                (format!("config-form update (per snapshot), {l_lo} loops"), l_lo, &config_update),
                (format!("config-form update (per snapshot), {l_hi} loops"), l_hi, &config_update),
            ],
        ),
    )?;
    let bytes_op = |m: &Measured| m.snapshot_op_bytes as f64;
    let bytes_config = |m: &Measured| m.snapshot_config_bytes as f64;
    let mut bytes = by_links(
        "Snapshot datagram size against links",
        "bytes per snapshot",
        points,
        &[
            (format!("op form, {l_hi} loops"), l_hi, &bytes_op),
            (format!("config form, {l_lo} loops"), l_lo, &bytes_config),
            (format!("config form, {l_hi} loops"), l_hi, &bytes_config),
        ],
    );
    bytes = bytes.with(Series::reference(
        "datagram budget after the QUIC handshake (1162 B)",
        vec![(links[0] as f64, DATAGRAM_BUDGET_BYTES), (links[links.len() - 1] as f64, DATAGRAM_BUDGET_BYTES)],
    ));
    out.chart("snapshot_bytes_vs_links", &bytes)?;
    let largest = links[links.len() - 1];
    let mut vs_loops = Chart::new(format!("Cost against loops at {largest} links"), "closed loops L", "us per call")
        .legend(Legend::UpperLeft);
    vs_loops.log_y = true;
    let at_largest: Vec<&Measured> = points.iter().filter(|m| m.links == largest).collect();
    for (label, f) in [
        ("VE step", &step_plain as &dyn Fn(&Measured) -> f64),
        ("VE tick + op-form snapshot", &tick_op),
        ("VE tick + config-form snapshot", &tick_config),
        ("config-form update", &|m: &Measured| us(m.config_update_ns)),
    ] {
        vs_loops = vs_loops.with(Series::line(label, at_largest.iter().map(|m| (m.loops as f64, f(m))).collect()));
    }
    out.chart("cost_vs_loops", &vs_loops)
}
