//! What every experiment shares: options, the output directory with its charts and `summary.json`, sweeps
//! over independent points on two threads with a progress bar (results in point order, never completion
//! order), the paper's session, log-spaced grids, Pareto fronts and power-law fits.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::{json, Value};

use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Planar, model::data::Data, model::Model};
use nalgebra::DVector;

use crate::charts::{self, Chart, HeatMap, StabilityMap};
use crate::rounding::{round, significant};
use kinloop_client::device::presets::DevicePreset;
use kinloop_client::user::{HandKind, HandSpec, UserSpec};
use kinloop_harness::{ClientPlan, Recording, SessionPlan, SessionSummary};
use kinloop_linkage::model::scene::Scene;
use kinloop_protocol::emulator::LinkConfig;
use kinloop_server::core::VeConfig;

/// How an experiment runs.
#[derive(Clone, Debug)]
pub struct Options {
    /// Results go to `out/NAME/`.
    pub out: PathBuf,
    /// The small grid (fewer, shorter sessions).
    pub quick: bool,
    /// Draw progress bars on stderr (hidden anyway when stderr is not a terminal).
    pub progress: bool,
    /// Threads a sweep may use (results do not depend on it).
    pub threads: usize,
    /// Simulated (or real, for the live experiments) seconds per session, overriding the experiment's own
    /// length; only the experiments whose sessions are hands touring a linkage take it
    /// ([`super::Name::takes_seconds`]).
    pub seconds: Option<f64>,
}

impl Options {
    /// Full grids, results under `out`, progress bars, two threads.
    pub fn new(out: impl Into<PathBuf>) -> Self {
        Options { out: out.into(), quick: false, progress: true, threads: 2, seconds: None }
    }

    /// The quick grids.
    pub fn quick(mut self) -> Self {
        self.quick = true;
        self
    }

    /// Picks the full or the quick value.
    pub fn pick<T>(&self, full: T, quick: T) -> T {
        if self.quick {
            quick
        } else {
            full
        }
    }

    /// Seconds per session: `--seconds` when given, else the full or the quick length.
    pub fn session_seconds(&self, full: f64, quick: f64) -> f64 {
        self.seconds.unwrap_or_else(|| self.pick(full, quick))
    }
}

/// What an experiment produced.
#[derive(Clone, Debug)]
pub struct Report {
    /// The experiment's name.
    pub name: &'static str,
    /// Its directory (`out/NAME`).
    pub dir: PathBuf,
    /// Files written (relative to `dir`), charts first, `summary.json` last.
    pub files: Vec<String>,
    /// The summary as written.
    pub summary: Value,
    /// Wall-clock seconds.
    pub runtime_s: f64,
}

/// The output directory of one experiment: collects chart files and writes the summary last.
pub struct Output {
    name: &'static str,
    dir: PathBuf,
    files: Vec<String>,
    started: Instant,
    quick: bool,
    seconds: Option<f64>,
}

impl Output {
    /// Creates `options.out/name/`.
    pub fn new(name: &'static str, options: &Options) -> Result<Self> {
        let dir = options.out.join(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating the output directory {}", dir.display()))?;
        Ok(Output {
            name,
            dir,
            files: Vec::new(),
            started: Instant::now(),
            quick: options.quick,
            seconds: options.seconds,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn record(&mut self, written: Vec<PathBuf>) {
        for path in written {
            let name = path.strip_prefix(&self.dir).unwrap_or(&path).display().to_string();
            self.files.push(name);
        }
    }

    /// Writes a line or scatter chart as `stem.svg` and `stem.png`.
    pub fn chart(&mut self, stem: &str, chart: &Chart) -> Result<()> {
        let written = charts::save(chart, &self.dir.join(stem)).with_context(|| format!("chart {stem}"))?;
        self.record(written);
        Ok(())
    }

    /// Writes a stability map as `stem.svg` and `stem.png`.
    pub fn map(&mut self, stem: &str, map: &StabilityMap) -> Result<()> {
        let written = charts::save_map(map, &self.dir.join(stem)).with_context(|| format!("map {stem}"))?;
        self.record(written);
        Ok(())
    }

    /// Writes a heat map as `stem.svg` and `stem.png`.
    pub fn heat_map(&mut self, stem: &str, map: &HeatMap) -> Result<()> {
        let written = charts::save_heat_map(map, &self.dir.join(stem)).with_context(|| format!("heat map {stem}"))?;
        self.record(written);
        Ok(())
    }

    /// Writes `summary.json`: `title`, what the experiment answers, how it ran (command, quick, runtime,
    /// the full run's expected runtime), the charts, then the experiment's own `results`.
    pub fn finish(mut self, title: &str, full_runtime_note: &str, results: Value) -> Result<Report> {
        let runtime_s = self.started.elapsed().as_secs_f64();
        self.files.push("summary.json".into());
        let mut command = format!("kinloop experiment {}{}", self.name, if self.quick { " --quick" } else { "" });
        if let Some(seconds) = self.seconds {
            command += &format!(" --seconds {seconds}");
        }
        let summary = json!({
            "experiment": self.name,
            "title": title,
            "command": command,
            "quick": self.quick,
            "runtime_s": round(runtime_s, 2),
            "full_runtime": full_runtime_note,
            "files": self.files,
            "results": results,
        });
        let path = self.dir.join("summary.json");
        let text = serde_json::to_string_pretty(&summary)?;
        std::fs::write(&path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        Ok(Report { name: self.name, dir: self.dir, files: self.files, summary, runtime_s })
    }
}

/// A progress bar for `len` steps (hidden when `show` is false or stderr is not a terminal).
pub fn progress_bar(label: &str, len: u64, show: bool) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        Some(len),
        if show { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() },
    );
    if let Ok(style) = ProgressStyle::with_template("{prefix:>28} [{bar:32}] {pos}/{len} {elapsed_precise} (eta {eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_prefix(label.to_string());
    bar
}

/// Runs `f` on every point, on up to `threads` threads, with a progress bar; the results are in point order
/// whatever order the points finish in, so a sweep is as deterministic as `f`. The first error stops the
/// sweep (points already running finish) and is returned with the point's index.
pub fn sweep<P, R, F>(label: &str, points: &[P], threads: usize, show: bool, f: F) -> Result<Vec<R>>
where
    P: Sync,
    R: Send,
    F: Fn(&P) -> Result<R> + Sync,
{
    let bar = progress_bar(label, points.len() as u64, show);
    let next = AtomicUsize::new(0);
    let failed = std::sync::atomic::AtomicBool::new(false);
    let slots: Mutex<Vec<Option<Result<R>>>> = Mutex::new((0..points.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, points.len().max(1)) {
            scope.spawn(|| loop {
                if failed.load(Ordering::Relaxed) {
                    break;
                }
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(point) = points.get(i) else { break };
                let result = f(point);
                if result.is_err() {
                    failed.store(true, Ordering::Relaxed);
                }
                if let Ok(mut slots) = slots.lock() {
                    slots[i] = Some(result);
                }
                bar.inc(1);
            });
        }
    });
    bar.finish_and_clear();
    let slots = slots.into_inner().map_err(|_| anyhow!("{label}: a sweep thread panicked"))?;
    let mut out = Vec::with_capacity(points.len());
    for (i, slot) in slots.into_iter().enumerate() {
        match slot {
            Some(Ok(r)) => out.push(r),
            Some(Err(e)) => return Err(e.context(format!("{label}: point {i}"))),
            None => return Err(anyhow!("{label}: point {i} did not run (an earlier point failed)")),
        }
    }
    Ok(out)
}

/// Runs a harness session without progress reports.
pub fn session(plan: &SessionPlan) -> Result<(SessionSummary, Recording)> {
    kinloop_harness::run(plan, &mut |_| {})
}

/// Compute cost of a session: `(VE µs, haptic cores µs)` per simulated second, the best of `reps` runs
/// (the least disturbed by other work on the machine). Run it on one thread for comparable numbers.
pub fn timed_cost(plan: &SessionPlan, reps: usize) -> Result<(f64, f64)> {
    let mut best = (f64::INFINITY, f64::INFINITY);
    for _ in 0..reps.max(1) {
        let (summary, _) = session(plan)?;
        if summary.ve_compute_us_per_s + summary.client_compute_us_per_s < best.0 + best.1 {
            best = (summary.ve_compute_us_per_s, summary.client_compute_us_per_s);
        }
    }
    Ok(best)
}

/// The paper's session (testbed, paper VE, one paper user at 1 kHz, perfect network) for `seconds`,
/// recording every tick (the stability verdict needs every tick).
pub fn paper_plan(seconds: f64) -> Result<SessionPlan> {
    let mut plan = SessionPlan::paper()?;
    plan.duration = Duration::from_secs_f64(seconds);
    plan.record_every = 1;
    Ok(plan)
}

/// One user touring `op` of `scene` with a `hand` of the kind on `device` over `link`, with default flags and
/// the default VE, for `seconds`, recording every tick: the session the renderability and robustness matrices
/// judge a pair by.
pub fn touring_plan(
    scene: Scene,
    op: &str,
    device: DevicePreset,
    hand: HandKind,
    link: LinkConfig,
    seconds: f64,
) -> SessionPlan {
    let mut client = ClientPlan::new("user", op, device);
    client.user = UserSpec::Hand(HandSpec::touring(hand));
    SessionPlan {
        scene,
        ve: VeConfig::default(),
        clients: vec![client.with_link(link)],
        duration: Duration::from_secs_f64(seconds),
        record_every: 1,
    }
}

/// Positions (x, y) of an operational point over time (s, m).
pub type Trajectory = Vec<(f64, [f64; 2])>;

/// The (x, y) position of operational point `op` at configuration `q`.
pub fn op_position(model: &Model<Planar>, data: &mut Data<Planar>, q: &DVector<f64>, op: usize) -> [f64; 2] {
    forward_kinematics(model, data, q);
    let p = OpPose::<Planar>::of_op(model, data, op).position;
    [p[0], p[1]]
}

/// The VE's operational point `op` over a session, from the q recorded after every VE tick.
pub fn ve_op_trajectory(plan: &SessionPlan, rec: &Recording, op: &str) -> Result<Trajectory> {
    let model: Model<Planar> = Model::compile(&plan.scene, &plan.scene.name)?;
    let index = model.op_index(op).ok_or_else(|| anyhow!("no operational point {op}"))?;
    let mut data = Data::new(&model);
    Ok(rec.ve.iter().map(|v| (v.t, op_position(&model, &mut data, &DVector::from_column_slice(&v.q), index))).collect())
}

/// The position of `reference` at time `t`, linearly interpolated (held beyond its ends).
pub fn trajectory_at(reference: &Trajectory, t: f64) -> [f64; 2] {
    let i = reference.partition_point(|s| s.0 <= t);
    if i == 0 {
        return reference.first().map_or([f64::NAN; 2], |s| s.1);
    }
    if i >= reference.len() {
        return reference[reference.len() - 1].1;
    }
    let ((t0, a), (t1, b)) = (reference[i - 1], reference[i]);
    let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
    [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s]
}

/// RMS distance of `trajectory` from `reference` at the trajectory's times (m).
pub fn rms_error(trajectory: &Trajectory, reference: &Trajectory) -> f64 {
    let sum: f64 = trajectory
        .iter()
        .map(|(t, p)| {
            let r = trajectory_at(reference, *t);
            (p[0] - r[0]).powi(2) + (p[1] - r[1]).powi(2)
        })
        .sum();
    (sum / trajectory.len().max(1) as f64).sqrt()
}

/// Length of the path a trajectory travels (m).
pub fn path_length(trajectory: &Trajectory) -> f64 {
    trajectory.windows(2).map(|w| (w[1].1[0] - w[0].1[0]).hypot(w[1].1[1] - w[0].1[1])).sum()
}

/// `per_decade` log-spaced values from `lo` to `hi` inclusive (values rounded to 3 significant digits so
/// they read well in summaries).
pub fn log_grid(lo: f64, hi: f64, per_decade: usize) -> Vec<f64> {
    let (a, b) = (lo.log10(), hi.log10());
    let n = ((b - a) * per_decade as f64).round() as usize;
    (0..=n).map(|i| significant(10f64.powf(a + (b - a) * i as f64 / n.max(1) as f64), 3)).collect()
}

/// Indices of the points not dominated in (cost, error), both minimized, sorted by cost. A point is dominated
/// when another is no worse in both and better in one. Non-finite points are never on the front.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let mut front: Vec<usize> = (0..points.len())
        .filter(|&i| finite(&points[i]))
        .filter(|&i| {
            let (c, e) = points[i];
            !points
                .iter()
                .enumerate()
                .any(|(j, &(cj, ej))| j != i && finite(&(cj, ej)) && cj <= c && ej <= e && (cj < c || ej < e))
        })
        .collect();
    front.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
    front
}

/// Least-squares slope of log y against log x (the exponent of a power law y ∝ x^p), over positive pairs.
pub fn log_log_slope(xs: &[f64], ys: &[f64]) -> Option<f64> {
    let pairs: Vec<(f64, f64)> =
        xs.iter().zip(ys).filter(|(x, y)| **x > 0.0 && **y > 0.0).map(|(x, y)| (x.ln(), y.ln())).collect();
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mx, my) = (pairs.iter().map(|p| p.0).sum::<f64>() / n, pairs.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_non_dominated_points() {
        let points = [(1.0, 5.0), (2.0, 2.0), (3.0, 3.0), (4.0, 1.0), (f64::INFINITY, 0.0), (2.0, 2.0)];
        // (3, 3) is dominated by (2, 2); equal points do not dominate each other.
        assert_eq!(pareto_front(&points), vec![0, 1, 5, 3]);
    }

    #[test]
    fn log_grid_and_slope() {
        assert_eq!(log_grid(10.0, 1000.0, 1), vec![10.0, 100.0, 1000.0]);
        let xs = [1.0, 2.0, 4.0, 8.0];
        let ys: Vec<f64> = xs.iter().map(|x: &f64| 3.0 * x.powi(2)).collect();
        assert!((log_log_slope(&xs, &ys).unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn sweep_returns_results_in_point_order_and_reports_errors() {
        let points: Vec<u64> = (0..50).collect();
        let out = sweep("t", &points, 2, false, |&p| {
            std::thread::sleep(Duration::from_micros((50 - p) * 10));
            Ok(p * p)
        })
        .unwrap();
        assert_eq!(out, points.iter().map(|p| p * p).collect::<Vec<_>>());
        let err = sweep("t", &points, 2, false, |&p| if p == 7 { Err(anyhow!("boom")) } else { Ok(p) });
        assert!(err.is_err());
    }
}
