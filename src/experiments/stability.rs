//! `stability`: where methods fail. Every point is one session of the paper's manipulation (testbed,
//! constant wrench (−0.5 N, 0, −0.0025 N m), 3 s, the paper's controller gains unless swept) labelled stable
//! or unstable by the criterion of [`super::verdict`]. Four maps:
//!
//! - **(a) k_j × b_j at 1 kHz**, the joint-constraint controller's stiffness and damping (the position
//!   channels keep the paper's K_pc = 100 N/m, B_pc = 70 N s/m; the device's stable-stiffness cap is lifted
//!   so the client renders exactly the swept gains). The paper quotes k_j, b_j per kg of device mass; the
//!   simulated paper device has 1 kg per linear axis, so N/m/kg and N/m coincide. Drawn over the map:
//!   Colgate's passivity bound `b > K T / 2 + |B|` with b the device's own viscous damping (0.02 N s/m, the
//!   physical b), K = k_j and B = b_j, i.e. the curve `b_j = b − k_j T / 2`; the same balance with the
//!   controller's damping standing in for b (`b_j + B_pc = (k_j + K_pc) T / 2`); and the sampled-damper
//!   limit `b_j + B_pc = 2 m / T`.
//! - **(b) haptic rate × k_j**, 250 Hz to 10 kHz at the paper's b_j = 50 N s/m.
//! - **(c) Baumgarte α × VE time step**, projection off (so Baumgarte alone holds the loop), semi-implicit
//!   Euler, β = 1.
//! - **(d) K_g × B_g**, the graphics controller's gains (angular gains scaled with the paper's ratios,
//!   ×10 for K_g and ×100 for B_g), with implicit and with explicit coupling.

use anyhow::{Context, Result};
use kinloop_client::core::{ControllerGains, GainChoice};
use kinloop_client::device::presets::DevicePreset;
use kinloop_linkage::{math::space::Planar, math::space::SceneKind, model::Model};
use kinloop_server::core::AxisGains;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::common::{log_grid, paper_plan, session, sweep, Options, Output, Report};
use super::verdict::{self, Verdict};
use crate::charts::{Chart, Legend, Series, StabilityMap};
use crate::rounding::{num, round, significant};
use kinloop_harness::{CoreEdit, SessionPlan};

/// Simulated seconds per point.
const DURATION_S: f64 = 3.0;
/// The paper's joint-constraint gains on the 1 kg device (N/m, N s/m).
const PAPER_KJ: f64 = 200.0;
const PAPER_BJ: f64 = 50.0;
/// The paper's position-channel gains on the linear axes (N/m, N s/m).
const PAPER_KPC: f64 = 100.0;
const PAPER_BPC: f64 = 70.0;
/// The paper's graphics-controller gains: linear (N/m, N s/m) and angular (N m/rad, N m s/rad).
const PAPER_KG: f64 = 1000.0;
const PAPER_BG: f64 = 100.0;
const PAPER_KG_ANGULAR: f64 = 10_000.0;
const PAPER_BG_ANGULAR: f64 = 10_000.0;

/// Which map a point belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Part {
    /// x = k_j (N/m), y = b_j (N s/m), 1 kHz.
    Gains,
    /// x = haptic rate (Hz), y = k_j (N/m), b_j = 50.
    Rate,
    /// x = VE time step (ms), y = Baumgarte α (1/s).
    Baumgarte,
    /// x = K_g (N/m), y = B_g (N s/m) on the linear axes and `x L²`, `y L²` on the angular one (the
    /// unit-consistent scaling with the scene's length scale L), or the paper's angular gains when
    /// `paper_angular`; implicit coupling or not.
    Coupling { implicit: bool, paper_angular: bool },
}

/// Joint-constraint and position-channel gains exactly as given: the device's stable-stiffness cap is
/// lifted so the client does not scale them down.
fn custom_gains(k_j: f64, b_j: f64) -> CoreEdit {
    CoreEdit::new(move |c| {
        c.gains = GainChoice::Custom(ControllerGains {
            joint_stiffness: k_j,
            joint_damping: b_j,
            position_stiffness: vec![PAPER_KPC, PAPER_KPC, 0.5],
            position_damping: vec![PAPER_BPC, PAPER_BPC, 0.375],
        });
        c.device.max_stiffness = f64::INFINITY;
        c.device.max_damping = f64::INFINITY;
    })
}

fn plan(part: Part, x: f64, y: f64) -> Result<SessionPlan> {
    let mut plan = paper_plan(DURATION_S)?;
    let client = &mut plan.clients[0];
    match part {
        Part::Gains => client.configure = Some(custom_gains(x, y)),
        Part::Rate => {
            client.rate_hz = x;
            client.configure = Some(custom_gains(y, PAPER_BJ));
        }
        Part::Baumgarte => {
            client.configure = Some(CoreEdit::new(|c| c.gains = GainChoice::Paper));
            plan.ve.projection = false;
            plan.ve.ve_rate_hz = 1000.0 / x;
            plan.ve.snapshot_rate_hz = plan.ve.ve_rate_hz.min(1000.0);
            plan.scene.baumgarte.alpha = y;
            plan.scene.baumgarte.beta = 1.0;
        }
        Part::Coupling { implicit, paper_angular } => {
            client.configure = Some(CoreEdit::new(|c| c.gains = GainChoice::Paper));
            let l2 = length_scale(&plan)?.powi(2);
            let (k_ang, b_ang) = if paper_angular { (PAPER_KG_ANGULAR, PAPER_BG_ANGULAR) } else { (x * l2, y * l2) };
            plan.ve.implicit_coupling = implicit;
            plan.ve.coupling_stiffness = Some(AxisGains::Uniform { linear: x, angular: k_ang });
            plan.ve.coupling_damping = Some(AxisGains::Uniform { linear: y, angular: b_ang });
        }
    }
    Ok(plan)
}

/// The scene's length scale L (m), which makes angular and linear quantities commensurate.
fn length_scale(plan: &SessionPlan) -> Result<f64> {
    Ok(Model::<Planar>::compile(&plan.scene, &plan.scene.name)?.length_scale)
}

/// One judged point of a map.
#[derive(Clone, Debug)]
struct Cell {
    x: f64,
    y: f64,
    verdict: Verdict,
}

fn judge_point(part: Part, x: f64, y: f64) -> Result<Cell> {
    let plan = plan(part, x, y)?;
    let (summary, rec) = session(&plan).with_context(|| format!("{part:?} at ({x}, {y})"))?;
    Ok(Cell { x, y, verdict: verdict::judge(&summary, &rec) })
}

fn run_map(label: &str, part: Part, xs: &[f64], ys: &[f64], options: &Options) -> Result<Vec<Cell>> {
    let points: Vec<(f64, f64)> = xs.iter().flat_map(|&x| ys.iter().map(move |&y| (x, y))).collect();
    sweep(label, &points, options.threads, options.progress, |&(x, y)| judge_point(part, x, y))
}

/// A map's cell under the JSON names of its axes.
macro_rules! map_cell {
    ($(#[$doc:meta])* $name:ident, $x:ident, $y:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        pub struct $name {
            /// The x axis's value.
            pub $x: f64,
            /// The y axis's value.
            pub $y: f64,
            /// Stable by the criterion.
            pub stable: bool,
            /// Why not, if not.
            pub reasons: Vec<String>,
        }

        impl From<&Cell> for $name {
            fn from(c: &Cell) -> Self {
                $name {
                    $x: c.x,
                    $y: c.y,
                    stable: c.verdict.stable,
                    reasons: c.verdict.reasons.iter().map(|r| r.to_string()).collect(),
                }
            }
        }
    };
}

map_cell!(
    /// A cell of map (a).
    GainsCell, k_j, b_j
);
map_cell!(
    /// A cell of map (b).
    RateCell, rate_hz, k_j
);
map_cell!(
    /// A cell of map (c).
    BaumgarteCell, step_ms, alpha
);
map_cell!(
    /// A cell of map (d).
    CouplingCell, k_g, b_g
);

fn typed_cells<T: for<'a> From<&'a Cell>>(cells: &[Cell]) -> Vec<T> {
    cells.iter().map(T::from).collect()
}

fn map(title: &str, x_label: &str, y_label: &str, cells: &[Cell], overlays: Vec<Series>) -> StabilityMap {
    map_with_legend(Legend::UpperLeft, title, x_label, y_label, cells, overlays)
}

fn map_with_legend(
    legend: Legend,
    title: &str,
    x_label: &str,
    y_label: &str,
    cells: &[Cell],
    overlays: Vec<Series>,
) -> StabilityMap {
    StabilityMap {
        title: title.into(),
        x_label: x_label.into(),
        y_label: y_label.into(),
        log: true,
        cells: cells.iter().map(|c| (c.x, c.y, c.verdict.stable)).collect(),
        overlays,
        legend,
        y_categories: Vec::new(),
    }
}

/// Largest x (or y, with `by_y`) among stable cells, and the cell.
fn largest_stable(cells: &[Cell], key: impl Fn(&Cell) -> f64) -> Option<&Cell> {
    cells.iter().filter(|c| c.verdict.stable).max_by(|a, b| key(a).total_cmp(&key(b)))
}

fn nearest(cells: &[Cell], x: f64, y: f64) -> Option<&Cell> {
    let d = |c: &Cell| (c.x.ln() - x.ln()).powi(2) + (c.y.ln() - y.ln()).powi(2);
    cells.iter().min_by(|a, b| d(a).total_cmp(&d(b)))
}

fn curve(label: &str, xs: impl Iterator<Item = f64>, f: impl Fn(f64) -> f64) -> Series {
    Series::line(label, xs.map(|x| (x, f(x))).filter(|p| p.1 > 0.0 && p.1.is_finite()).collect())
}

fn dense(lo: f64, hi: f64) -> impl Iterator<Item = f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..=400).map(move |i| (a + (b - a) * i as f64 / 400.0).exp())
}

/// (a): k_j × b_j at 1 kHz.
fn gains_map(out: &mut Output, options: &Options) -> Result<GainsMap> {
    let ks = log_grid(1.0, 1e6, options.pick(4, 1));
    let bs = log_grid(0.01, 1e4, options.pick(4, 1));
    let cells = run_map("(a) k_j x b_j at 1 kHz", Part::Gains, &ks, &bs, options)?;
    let period = 1e-3;
    let device_damping = DevicePreset::Paper.params(SceneKind::Planar).damping[0];
    let device_mass = DevicePreset::Paper.spec(SceneKind::Planar).map(|s| s.mass[0]).unwrap_or(1.0);
    let passive_k_max = 2.0 * device_damping / period;
    let overlays = vec![
        curve("Colgate passivity bound, b = 0.02 N s/m", dense(ks[0], passive_k_max * 0.999), |k| {
            device_damping - k * period / 2.0
        }),
        curve("(k_j + K_pc) T/2 = b_j + B_pc", dense(ks[0], ks[ks.len() - 1]), |k| {
            (k + PAPER_KPC) * period / 2.0 - PAPER_BPC
        }),
        curve("b_j + B_pc = 2 m/T (m = 1 kg)", dense(ks[0], ks[ks.len() - 1]), |_| {
            2.0 * device_mass / period - PAPER_BPC
        }),
        Series::markers("paper's gains", vec![(PAPER_KJ, PAPER_BJ)]),
    ];
    out.map(
        "a_kj_bj_1khz",
        &map_with_legend(
            Legend::LowerRight,
            "(a) Joint-constraint gains at 1 kHz: stable (green) / unstable (red)",
            "k_j joint-constraint stiffness (N/m = N/m/kg on the 1 kg device)",
            "b_j joint-constraint damping (N s/m)",
            &cells,
            overlays,
        ),
    )?;
    let best = largest_stable(&cells, |c| c.x);
    let best_k = best.map(|c| c.x);
    let stable_bs_at_best: Vec<f64> =
        cells.iter().filter(|c| Some(c.x) == best_k && c.verdict.stable).map(|c| c.y).collect();
    let at_paper_b: Vec<&Cell> = {
        let b = nearest(&cells, 1.0, PAPER_BJ).map(|c| c.y).unwrap_or(PAPER_BJ);
        cells.iter().filter(|c| c.y == b).collect()
    };
    let best_at_paper_b = at_paper_b.iter().filter(|c| c.verdict.stable).map(|c| c.x).fold(f64::NAN, f64::max);
    let paper_point = nearest(&cells, PAPER_KJ, PAPER_BJ);
    Ok(GainsMap {
        k_j_values_n_per_m: ks,
        b_j_values_ns_per_m: bs,
        haptic_rate_hz: 1000.0,
        units: "per kg of device mass in the paper; the simulated paper device has 1 kg per linear axis, so N/m/kg = N/m".into(),
        largest_stable_k_j_n_per_m: best_k,
        stable_b_j_at_largest_k_j: stable_bs_at_best,
        largest_stable_k_j_at_b_j_near_50_n_per_m: best_at_paper_b.is_finite().then_some(best_at_paper_b),
        passivity_bound: PassivityBound {
            rule: "Colgate and Schenkel: passive iff b > K T/2 + |B|, with b the device's physical viscous damping, K, B the rendered stiffness and damping, T the sample period".into(),
            physical_damping_b_ns_per_m: device_damping,
            largest_passive_k_j_with_b_j_0_n_per_m: passive_k_max,
            note: "with the position channel's B_pc = 70 N s/m also rendered, |B| > b and no k_j is passive; the bound drawn ignores B_pc".into(),
        },
        largest_stable_k_j_over_passivity_bound: best_k.map(|k| round(k / passive_k_max, 1)),
        paper_gains_stable: paper_point.map(|c| c.verdict.stable),
        stable_points: cells.iter().filter(|c| c.verdict.stable).count(),
        points: cells.len(),
        cells: typed_cells(&cells),
    })
}

/// (b): haptic rate × k_j at b_j = 50.
fn rate_map(out: &mut Output, options: &Options) -> Result<RateMap> {
    let rates: Vec<f64> =
        options.pick(vec![250.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0], vec![250.0, 1000.0, 10000.0]);
    let ks = log_grid(10.0, 1e7, options.pick(3, 1));
    let cells = run_map("(b) haptic rate x k_j", Part::Rate, &rates, &ks, options)?;
    let device_damping = DevicePreset::Paper.params(SceneKind::Planar).damping[0];
    let overlays = vec![
        curve("Colgate passivity bound, b_j = 0: k_j = 2 b f", dense(200.0, 12000.0), |f| 2.0 * device_damping * f),
        curve("(k_j + K_pc)/(2f) = b_j + B_pc", dense(200.0, 12000.0), |f| {
            2.0 * (PAPER_BJ + PAPER_BPC) * f - PAPER_KPC
        }),
    ];
    out.map(
        "b_haptic_rate_kj",
        &map(
            "(b) Haptic rate vs joint-constraint stiffness (b_j = 50 N s/m)",
            "haptic loop rate f (Hz)",
            "k_j joint-constraint stiffness (N/m)",
            &cells,
            overlays,
        ),
    )?;
    let per_rate: Vec<RateLimit> = rates
        .iter()
        .map(|&r| {
            let best =
                largest_stable(&cells.iter().filter(|c| c.x == r).cloned().collect::<Vec<_>>(), |c| c.y).map(|c| c.y);
            RateLimit { rate_hz: r, largest_stable_k_j_n_per_m: best }
        })
        .collect();
    let mut rate_chart = Chart::new(
        "(b) Largest stable joint-constraint stiffness against haptic rate (b_j = 50 N s/m)",
        "haptic loop rate (Hz)",
        "largest stable k_j (N/m)",
    )
    .with(Series::line(
        "largest stable k_j (grid value)",
        per_rate.iter().filter_map(|v| Some((v.rate_hz, v.largest_stable_k_j_n_per_m?))).collect(),
    ))
    .with(curve("Colgate passivity bound 2 b f, b = 0.02 N s/m", dense(250.0, 10000.0), |f| 2.0 * device_damping * f))
    .legend(Legend::LowerRight);
    rate_chart.log_x = true;
    rate_chart.log_y = true;
    out.chart("b_largest_stable_kj_vs_rate", &rate_chart)?;
    Ok(RateMap {
        b_j_ns_per_m: PAPER_BJ,
        rates_hz: rates,
        k_j_values_n_per_m: ks,
        largest_stable_k_j_per_rate: per_rate,
        cells: typed_cells(&cells),
    })
}

/// (c): Baumgarte α × VE time step, projection off.
fn baumgarte_map(out: &mut Output, options: &Options) -> Result<BaumgarteMap> {
    let rates: Vec<f64> =
        options.pick(vec![250.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0], vec![250.0, 1000.0, 10000.0]);
    let steps_ms: Vec<f64> = rates.iter().map(|r| 1000.0 / r).collect();
    let alphas = log_grid(1.0, 1e4, options.pick(4, 1));
    let cells = run_map("(c) Baumgarte alpha x step", Part::Baumgarte, &steps_ms, &alphas, options)?;
    out.map(
        "c_baumgarte_alpha_step",
        &map(
            "(c) Baumgarte alpha vs VE time step (no projection, beta = 1)",
            "VE time step h (ms)",
            "Baumgarte alpha (1/s)",
            &cells,
            vec![
                curve("alpha h = 1", dense(steps_ms[steps_ms.len() - 1], steps_ms[0]), |h| 1000.0 / h),
                curve("alpha h = 2", dense(steps_ms[steps_ms.len() - 1], steps_ms[0]), |h| 2000.0 / h),
            ],
        ),
    )?;
    let mut closure = Chart::new(
        "(c) Largest loop-closure error against Baumgarte alpha (no projection, 3 s)",
        "Baumgarte alpha (1/s)",
        "max closure error (m)",
    )
    .legend(Legend::UpperLeft);
    closure.log_x = true;
    closure.log_y = true;
    for &h in &steps_ms {
        closure = closure.with(Series::line(
            format!("h = {} ms", significant(h, 3)),
            cells.iter().filter(|c| c.x == h).map(|c| (c.y, c.verdict.max_closure_error_m.max(1e-18))).collect(),
        ));
    }
    out.chart("c_closure_error_vs_alpha", &closure)?;
    let per_step: Vec<StepLimits> = steps_ms
        .iter()
        .map(|&h| {
            let stable: Vec<&Cell> = cells.iter().filter(|c| c.x == h && c.verdict.stable).collect();
            let best =
                stable.iter().min_by(|a, b| a.verdict.max_closure_error_m.total_cmp(&b.verdict.max_closure_error_m));
            StepLimits {
                step_ms: h,
                stable_alpha_min: stable.iter().map(|c| c.y).reduce(f64::min),
                stable_alpha_max: stable.iter().map(|c| c.y).reduce(f64::max),
                largest_stable_alpha_times_h: stable
                    .iter()
                    .map(|c| c.y * h / 1000.0)
                    .reduce(f64::max)
                    .map(|v| significant(v, 3)),
                alpha_with_smallest_closure_error: best.map(|c| c.y),
                smallest_closure_error_m: best.map(|c| significant(c.verdict.max_closure_error_m, 3)),
            }
        })
        .collect();
    Ok(BaumgarteMap {
        projection: false,
        beta: 1.0,
        alpha_values: alphas,
        steps_ms,
        per_step,
        cells: typed_cells(&cells),
    })
}

/// (d): K_g × B_g with implicit and explicit coupling, angular gains scaled by L²; plus the paper's exact
/// gains (angular 10⁴ N m/rad and 10⁴ N m s/rad) both ways.
fn coupling_maps(out: &mut Output, options: &Options) -> Result<CouplingMaps> {
    let kgs = log_grid(10.0, 1e7, options.pick(3, 1));
    let bgs = log_grid(0.1, 1e5, options.pick(3, 1));
    let length = length_scale(&paper_plan(DURATION_S)?)?;
    let mut maps = Vec::with_capacity(2);
    for (implicit, name) in [(true, "implicit"), (false, "explicit")] {
        let label = format!("(d) K_g x B_g, {name}");
        let part = Part::Coupling { implicit, paper_angular: false };
        let cells = run_map(&label, part, &kgs, &bgs, options)?;
        let exact = judge_point(Part::Coupling { implicit, paper_angular: true }, PAPER_KG, PAPER_BG)?;
        out.map(
            &format!("d_coupling_kg_bg_{name}"),
            &map(
                &format!("(d) Graphics-controller gains K_g, B_g: {name} coupling (1 kHz)"),
                "K_g linear (N/m); angular K_g L^2 (N m/rad)",
                "B_g linear (N s/m); angular B_g L^2 (N m s/rad)",
                &cells,
                vec![Series::markers("paper's linear K_g, B_g (1000, 100)", vec![(PAPER_KG, PAPER_BG)])],
            ),
        )?;
        let best = largest_stable(&cells, |c| c.x);
        let paper = nearest(&cells, PAPER_KG, PAPER_BG);
        maps.push(CouplingMap {
            largest_stable_k_g_n_per_m: best.map(|c| c.x),
            stable_b_g_at_largest_k_g: cells
                .iter()
                .filter(|c| Some(c.x) == best.map(|b| b.x) && c.verdict.stable)
                .map(|c| c.y)
                .collect(),
            paper_linear_gains_with_l2_angular_stable: paper.map(|c| c.verdict.stable),
            paper_exact_gains_stable: exact.verdict.stable,
            paper_exact_gains_reasons: exact.verdict.reasons.iter().map(|r| r.to_string()).collect(),
            stable_points: cells.iter().filter(|c| c.verdict.stable).count(),
            points: cells.len(),
            cells: typed_cells(&cells),
        });
    }
    let (Some(explicit), Some(implicit)) = (maps.pop(), maps.pop()) else {
        anyhow::bail!("both couplings ran");
    };
    Ok(CouplingMaps {
        k_g_values_n_per_m: kgs,
        b_g_values_ns_per_m: bgs,
        length_scale_m: significant(length, 4),
        angular_gains: "K_g L^2 and B_g L^2 on the angular axis (unit-consistent); the paper's own angular gains (10000 N m/rad, 10000 N m s/rad) are judged separately as paper_exact_gains".into(),
        integrator: "semi-implicit Euler at 1 kHz (the only scheme that can treat the coupling implicitly)".into(),
        implicit,
        explicit,
    })
}

/// Runs the experiment.
pub fn run(options: &Options) -> Result<Report> {
    let mut out = Output::new("stability", options)?;
    let gains = gains_map(&mut out, options)?;
    let rate = rate_map(&mut out, options)?;
    let baumgarte = baumgarte_map(&mut out, options)?;
    let coupling = coupling_maps(&mut out, options)?;
    let f = |v: Option<f64>| num(v.unwrap_or(f64::NAN));
    let per_rate: Vec<(f64, f64)> = rate
        .largest_stable_k_j_per_rate
        .iter()
        .map(|p| (p.rate_hz, p.largest_stable_k_j_n_per_m.unwrap_or(f64::NAN)))
        .collect();
    let k_top = per_rate.iter().map(|p| p.1).fold(f64::NAN, f64::max);
    let first_top = per_rate.iter().find(|p| p.1 == k_top).map_or(f64::NAN, |p| p.0);
    let alpha_h: Vec<f64> = baumgarte.per_step.iter().filter_map(|p| p.largest_stable_alpha_times_h).collect();
    let stable_bs: Vec<String> = gains.stable_b_j_at_largest_k_j.iter().map(|&b| num(b)).collect();
    let answer = format!(
        "At 1 kHz the largest stable joint-constraint stiffness on the grid is k_j = {} N/m (N/m/kg on the 1 kg device; \
         stable there for b_j = {} N s/m), {}x Colgate's passivity bound of {} N/m (2 b / T with the device's own \
         0.02 N s/m of viscous damping); the paper's gains are {}. At b_j = 50 N s/m the limit rises from {} N/m at {} Hz \
         to {} N/m at {} Hz and stays there up to {} Hz. Without projection, Baumgarte holds the loop up to alpha h = \
         {:.2}-{:.2}. Explicit coupling is stable up to K_g = {} N/m with unit-consistent angular gains but not at the \
         paper's own gains (angular 10^4); implicit coupling is stable at {} of {} points.",
        f(gains.largest_stable_k_j_n_per_m),
        stable_bs.join(", "),
        f(gains.largest_stable_k_j_over_passivity_bound),
        num(gains.passivity_bound.largest_passive_k_j_with_b_j_0_n_per_m),
        if gains.paper_gains_stable == Some(true) { "stable" } else { "unstable" },
        num(per_rate.first().map_or(f64::NAN, |p| p.1)),
        num(per_rate.first().map_or(f64::NAN, |p| p.0)),
        num(k_top),
        num(first_top),
        num(per_rate.last().map_or(f64::NAN, |p| p.0)),
        alpha_h.iter().copied().fold(f64::INFINITY, f64::min),
        alpha_h.iter().copied().fold(0.0, f64::max),
        f(coupling.explicit.largest_stable_k_g_n_per_m),
        coupling.implicit.stable_points,
        coupling.implicit.points,
    );
    let results = StabilitySummary {
        answer,
        criterion: verdict::criterion_json(),
        setup: StabilitySetup {
            session: "paper testbed, constant wrench (-0.5 N, 0, -0.0025 N m) at link 2, sim:paper device (1 kg), 3 s, perfect network".into(),
            defaults: "1 kHz VE (semi-implicit Euler, projection, implicit coupling, paper K_g and B_g), 1 kHz haptic loop, paper controller gains".into(),
        },
        a_joint_constraint_gains: gains,
        b_haptic_rate: rate,
        c_baumgarte: baumgarte,
        d_coupling: coupling,
    };
    out.finish(
        "Where methods fail: stability maps of joint-constraint gains, haptic rate, Baumgarte stabilization and coupling gains",
        "about 1600 sessions of 3 s; --quick fewer",
        serde_json::to_value(&results)?,
    )
}

/// `summary.json`'s `results` of the stability maps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilitySummary {
    /// The one-line answer.
    pub answer: String,
    /// The stability criterion's rules and thresholds.
    pub criterion: Value,
    /// What every point runs.
    pub setup: StabilitySetup,
    /// Map (a).
    pub a_joint_constraint_gains: GainsMap,
    /// Map (b).
    pub b_haptic_rate: RateMap,
    /// Map (c).
    pub c_baumgarte: BaumgarteMap,
    /// Map (d), both couplings.
    pub d_coupling: CouplingMaps,
}

/// What every point runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilitySetup {
    /// The session.
    pub session: String,
    /// The settings not swept.
    pub defaults: String,
}

/// (a): k_j × b_j at 1 kHz.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GainsMap {
    /// The k_j grid (N/m).
    pub k_j_values_n_per_m: Vec<f64>,
    /// The b_j grid (N s/m).
    pub b_j_values_ns_per_m: Vec<f64>,
    /// The haptic rate (Hz).
    pub haptic_rate_hz: f64,
    /// How the paper's per-kg gains map onto the device.
    pub units: String,
    /// The largest stable k_j of the grid (N/m).
    pub largest_stable_k_j_n_per_m: Option<f64>,
    /// The b_j stable at that k_j (N s/m).
    pub stable_b_j_at_largest_k_j: Vec<f64>,
    /// The largest stable k_j at the grid's b_j nearest the paper's (N/m).
    pub largest_stable_k_j_at_b_j_near_50_n_per_m: Option<f64>,
    /// Colgate's passivity bound.
    pub passivity_bound: PassivityBound,
    /// The largest stable k_j over the bound (1 decimal).
    pub largest_stable_k_j_over_passivity_bound: Option<f64>,
    /// The cell nearest the paper's gains is stable.
    pub paper_gains_stable: Option<bool>,
    /// Stable cells.
    pub stable_points: usize,
    /// All cells.
    pub points: usize,
    /// Every cell.
    pub cells: Vec<GainsCell>,
}

/// Colgate's passivity bound on the device.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PassivityBound {
    /// The rule.
    pub rule: String,
    /// The device's own viscous damping (N s/m).
    pub physical_damping_b_ns_per_m: f64,
    /// The largest passive k_j with no rendered damping (N/m).
    pub largest_passive_k_j_with_b_j_0_n_per_m: f64,
    /// What the bound leaves out.
    pub note: String,
}

/// (b): haptic rate × k_j.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RateMap {
    /// b_j of every cell (N s/m).
    pub b_j_ns_per_m: f64,
    /// The rate grid (Hz).
    pub rates_hz: Vec<f64>,
    /// The k_j grid (N/m).
    pub k_j_values_n_per_m: Vec<f64>,
    /// The largest stable k_j at each rate.
    pub largest_stable_k_j_per_rate: Vec<RateLimit>,
    /// Every cell.
    pub cells: Vec<RateCell>,
}

/// The largest stable k_j at one rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RateLimit {
    /// Haptic rate (Hz).
    pub rate_hz: f64,
    /// Largest stable k_j (N/m), none if no cell is stable.
    pub largest_stable_k_j_n_per_m: Option<f64>,
}

/// (c): Baumgarte α × VE time step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaumgarteMap {
    /// Projection on.
    pub projection: bool,
    /// Baumgarte β.
    pub beta: f64,
    /// The α grid (1/s).
    pub alpha_values: Vec<f64>,
    /// The step grid (ms).
    pub steps_ms: Vec<f64>,
    /// The stable α at each step.
    pub per_step: Vec<StepLimits>,
    /// Every cell.
    pub cells: Vec<BaumgarteCell>,
}

/// The stable α at one VE step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepLimits {
    /// VE time step (ms).
    pub step_ms: f64,
    /// Smallest stable α (1/s).
    pub stable_alpha_min: Option<f64>,
    /// Largest stable α (1/s).
    pub stable_alpha_max: Option<f64>,
    /// Largest stable α h (3 significant digits).
    pub largest_stable_alpha_times_h: Option<f64>,
    /// The stable α with the smallest closure error (1/s).
    pub alpha_with_smallest_closure_error: Option<f64>,
    /// That error (m, 3 significant digits).
    pub smallest_closure_error_m: Option<f64>,
}

/// (d): K_g × B_g, both couplings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CouplingMaps {
    /// The K_g grid (N/m).
    pub k_g_values_n_per_m: Vec<f64>,
    /// The B_g grid (N s/m).
    pub b_g_values_ns_per_m: Vec<f64>,
    /// The testbed's length scale L (m, 4 significant digits).
    pub length_scale_m: f64,
    /// How the angular gains follow the linear ones.
    pub angular_gains: String,
    /// The integrator.
    pub integrator: String,
    /// Implicit coupling.
    pub implicit: CouplingMap,
    /// Explicit coupling.
    pub explicit: CouplingMap,
}

/// One coupling's map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CouplingMap {
    /// The largest stable K_g of the grid (N/m).
    pub largest_stable_k_g_n_per_m: Option<f64>,
    /// The B_g stable at that K_g (N s/m).
    pub stable_b_g_at_largest_k_g: Vec<f64>,
    /// The cell nearest the paper's linear gains is stable.
    pub paper_linear_gains_with_l2_angular_stable: Option<bool>,
    /// The paper's exact gains are stable.
    pub paper_exact_gains_stable: bool,
    /// Why not, if not.
    pub paper_exact_gains_reasons: Vec<String>,
    /// Stable cells.
    pub stable_points: usize,
    /// All cells.
    pub points: usize,
    /// Every cell.
    pub cells: Vec<CouplingCell>,
}
