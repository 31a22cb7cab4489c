//! `kinloop bench`: a fixed suite of the hot paths, each measured as the median over batches in one run.
//! Three outputs of the same suite: plain lines (the default); with `--json`, one object per line
//! (`{"name": ..., "ns_per_call": ..., ...}`); with `--markdown`, one Markdown table after a line naming the
//! machine and the command (what docs/benchmarks.md is made of). Cases with a goal carry
//! `goal_ns` and `meets_goal` (JSON) or a goal cell (Markdown).

use std::fmt::Write as _;
use std::time::Duration;

use anyhow::{ensure, Context, Result};
use kinloop_linkage::algorithms::integrator::Integrator;
use kinloop_linkage::bench::{measure, measure_batches, paper_wrench, Case, DeltaCase, Timing};
use serde_json::{json, Value};

use crate::experiments::renderability_device::Vendor;

/// Arguments of `kinloop bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Print one JSON object per line.
    #[arg(long, conflicts_with = "markdown")]
    pub json: bool,
    /// Print one Markdown table (case, median, p10, p90, goal) after a line naming the machine and the command.
    #[arg(long)]
    pub markdown: bool,
    /// Seconds of measurement per case (the suite has about 20 cases).
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Only run cases whose name contains this text.
    #[arg(long)]
    pub filter: Option<String>,
}

/// One measured case, kept for the Markdown table.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Case name, e.g. `ve_step/testbed`.
    pub name: String,
    /// Median, ns per call.
    pub median_ns: f64,
    /// 10th and 90th percentiles over batches, ns per call (absent where the case measures otherwise).
    pub p10_ns: Option<f64>,
    /// See `p10_ns`.
    pub p90_ns: Option<f64>,
    /// The goal, ns per call.
    pub goal_ns: Option<f64>,
    /// What else the case reports (snapshot bytes, a p99).
    pub note: Option<String>,
}

struct Reporter<'a> {
    args: &'a BenchArgs,
    rows: Vec<Row>,
}

impl Reporter<'_> {
    fn wanted(&self, name: &str) -> bool {
        self.args.filter.as_deref().is_none_or(|f| name.contains(f))
    }

    fn emit(&mut self, row: Row, extra: Value) {
        let mut obj = json!({ "name": row.name, "ns_per_call": row.median_ns });
        if let (Some(o), Value::Object(e)) = (obj.as_object_mut(), extra) {
            o.extend(e);
        }
        if let Some(goal) = row.goal_ns {
            obj["goal_ns"] = json!(goal);
            obj["meets_goal"] = json!(row.median_ns <= goal);
        }
        if self.args.json {
            println!("{obj}");
        } else if !self.args.markdown {
            let rest: Vec<String> = obj
                .as_object()
                .into_iter()
                .flatten()
                .filter(|(k, _)| *k != "name" && *k != "ns_per_call")
                .map(|(k, v)| format!("{k}={v}"))
                .collect();
            println!("{:<36} {:>12.1} ns   {}", row.name, row.median_ns, rest.join(" "));
        }
        self.rows.push(row);
    }

    fn timing(&mut self, name: &str, t: Timing) {
        self.timing_with_goal(name, t, goal_ns(name));
    }

    /// A timing against its goal (ns per call), if it has one: the median must not exceed it.
    fn timing_with_goal(&mut self, name: &str, t: Timing, goal_ns: Option<f64>) {
        let row = Row {
            name: name.to_owned(),
            median_ns: t.median_ns,
            p10_ns: Some(t.p10_ns),
            p90_ns: Some(t.p90_ns),
            goal_ns,
            note: None,
        };
        self.emit(row, timing_fields(&t));
    }

    /// A timing without a goal, with a note (the case's size).
    fn timing_noted(&mut self, name: &str, t: Timing, note: String) {
        let row = Row {
            name: name.to_owned(),
            median_ns: t.median_ns,
            p10_ns: Some(t.p10_ns),
            p90_ns: Some(t.p90_ns),
            goal_ns: None,
            note: Some(note.clone()),
        };
        let mut extra = timing_fields(&t);
        extra["note"] = json!(note);
        self.emit(row, extra);
    }
}

fn timing_fields(t: &Timing) -> Value {
    json!({ "p10_ns": t.p10_ns, "p90_ns": t.p90_ns, "calls": t.calls })
}

/// Users of the `server/ve_tick_users_N` cases.
const VE_TICK_USERS: [usize; 4] = [1, 4, 16, 64];

/// The goal for one VE tick: 1 µs with one user, 0.4 µs more per extra user.
fn ve_tick_goal_ns(users: usize) -> f64 {
    1000.0 + 400.0 * users.saturating_sub(1) as f64
}

/// The goal for one haptic tick on the testbed.
const CLIENT_TICK_GOAL_NS: f64 = 500.0;

/// The goals of the dynamics core and the wire, ns per call.
fn goal_ns(name: &str) -> Option<f64> {
    match name {
        "ve_step/testbed" => Some(400.0),
        "op_space/testbed" => Some(250.0),
        "local_model/testbed" => Some(100.0),
        "ve_step/chain50_loops5" => Some(14_000.0),
        "codec/snapshot_testbed" => Some(1000.0),
        "quic/datagram_oneway_loopback" => Some(150_000.0),
        _ => None,
    }
}

/// Longest measurement per case `--seconds` accepts.
const MAX_SECONDS: f64 = 30.0;

/// Runs the suite and prints it in the form the arguments ask for.
pub fn run(args: &BenchArgs) -> Result<()> {
    let rows = measure_suite(args)?;
    if args.markdown {
        print!("{}", markdown(&rows, &machine(), &command_line(args)));
    }
    Ok(())
}

/// Runs the suite; plain lines or JSON lines are printed as each case finishes (unless `--markdown`).
pub fn measure_suite(args: &BenchArgs) -> Result<Vec<Row>> {
    ensure!(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= MAX_SECONDS,
        "--seconds: must be in (0, {MAX_SECONDS}] s per case, got {}",
        args.seconds
    );
    let mut r = Reporter { args, rows: Vec::new() };
    let budget = Duration::from_secs_f64(args.seconds.max(0.05));

    for scene in ["testbed", "chain20_loops1", "chain20_loops5", "chain50_loops1", "chain50_loops5"] {
        let name = format!("ve_step/{scene}");
        if !r.wanted(&name) {
            continue;
        }
        let mut case = Case::new(if scene == "testbed" { "paper-testbed" } else { scene })
            .ok_or_else(|| anyhow::anyhow!("benchmark scene {scene}"))?;
        let t = measure(budget, || case.ve_step(Integrator::SemiImplicitEuler));
        r.timing(&name, t);
    }
    for (name, balls) in [("ve_step/delta-ball", true), ("ve_step/delta-revolute-built", false)] {
        if r.wanted(name) {
            let mut case = DeltaCase::new(balls).ok_or_else(|| anyhow::anyhow!("{name}"))?;
            let model = &case.model;
            let bodies = (0..model.nv()).filter(|&b| !model.is_internal_body(b)).count();
            // A ball or universal joint's entries share its name: count names, not entries.
            let joints =
                (0..model.nv()).filter(|&i| i == 0 || model.joints[i].name != model.joints[i - 1].name).count();
            let note = format!("{bodies} bodies, {joints} joints; nq = {}, nv = {}", model.nq(), model.nv());
            let t = measure(budget, || case.ve_step());
            r.timing_noted(name, t, note);
        }
    }
    if r.wanted("ve_step_rk4/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        r.timing("ve_step_rk4/testbed", measure(budget, || case.ve_step(Integrator::Rk4)));
    }
    if r.wanted("op_space/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        case.prepare_op_space();
        let t = measure(budget, || {
            std::hint::black_box(case.op_space());
        });
        r.timing("op_space/testbed", t);
    }
    if r.wanted("local_model/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        let mut lm = case.local_model();
        let f = paper_wrench();
        let t = measure(budget, || {
            std::hint::black_box(lm.step(1e-3, &f));
        });
        r.timing("local_model/testbed", t);
    }
    // `ve_tick`: the VE's own stages, against the tick's goal; `ve_loop`: the loop's whole iteration (the tick,
    // encoding, ring pushes, wake-ups, statistics), what the real-time thread does each deadline and what
    // `experiment capacity` reads its real time against. Each batch builds its own VE (set-up not timed) and
    // runs it `calls` times from the paper's start.
    type VeCase = fn(usize, u64) -> Result<f64, kinloop_server::bench::BenchError>;
    let ve_cases: [(&str, VeCase, bool); 2] = [
        ("ve_tick", kinloop_server::bench::ve_tick_users, true),
        ("ve_loop", kinloop_server::bench::ve_loop_users, false),
    ];
    for (case, run_case, has_goal) in ve_cases {
        for users in VE_TICK_USERS {
            let name = format!("server/{case}_users_{users}");
            if !r.wanted(&name) {
                continue;
            }
            let t = measure_batches(budget, |calls| run_case(users, calls)).with_context(|| name.clone())?;
            r.timing_with_goal(&name, t, has_goal.then(|| ve_tick_goal_ns(users)));
        }
    }
    if r.wanted("client/tick_testbed") {
        let t = measure_batches(budget, kinloop_client::bench::client_tick_testbed).context("client/tick_testbed")?;
        r.timing_with_goal("client/tick_testbed", t, Some(CLIENT_TICK_GOAL_NS));
    }
    device_exchanges(&mut r, budget)?;
    if r.wanted("codec/snapshot_testbed") {
        let mut bytes = 0;
        let t = measure_batches(budget, |calls| {
            kinloop_protocol::bench::codec_snapshot_testbed(calls).map(|(ns, b)| {
                bytes = b;
                ns
            })
        })
        .context("codec/snapshot_testbed")?;
        let mut extra = timing_fields(&t);
        extra["bytes"] = json!(bytes);
        let row = Row {
            name: "codec/snapshot_testbed".into(),
            median_ns: t.median_ns,
            p10_ns: Some(t.p10_ns),
            p90_ns: Some(t.p90_ns),
            goal_ns: goal_ns("codec/snapshot_testbed"),
            note: Some(format!("encode + decode of a {bytes} B snapshot")),
        };
        r.emit(row, extra);
    }
    if r.wanted("quic/datagram_oneway_loopback") {
        let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
        let samples = (2000.0 * args.seconds).max(200.0) as usize;
        let (p50, p99) = runtime.block_on(kinloop_protocol::bench::quic_datagram_oneway_loopback(samples))?;
        let row = Row {
            name: "quic/datagram_oneway_loopback".into(),
            median_ns: p50 * 1e3,
            p10_ns: None,
            p90_ns: None,
            goal_ns: goal_ns("quic/datagram_oneway_loopback"),
            note: Some(format!("p99 {} over {samples} datagrams", duration(p99 * 1e3))),
        };
        r.emit(row, json!({ "p50_us": p50, "p99_us": p99, "samples": samples }));
    }
    Ok(r.rows)
}

/// `device/tick_sim_falcon` and `device/tick_dhd_fake`: a haptic tick's device exchange (`read` then
/// `command`) on a simulated Falcon and through the fake DHD library's FFI (the fake's own cost, its plant
/// included: not what a USB device costs). The fake is found as `kinloop experiment renderability-dhd`
/// finds it; without it that row says so and is left out.
fn device_exchanges(r: &mut Reporter, budget: Duration) -> Result<()> {
    if r.wanted("device/tick_sim_falcon") {
        let t =
            measure_batches(budget, kinloop_client::bench::device_tick_sim_falcon).context("device/tick_sim_falcon")?;
        r.timing("device/tick_sim_falcon", t);
    }
    if r.wanted("device/tick_dhd_fake") {
        let library = match crate::experiments::renderability_device::fake_library_beside_this_program(Vendor::Dhd) {
            Ok(library) => library,
            Err(e) => {
                eprintln!("device/tick_dhd_fake left out: {e:#}");
                return Ok(());
            }
        };
        let t = measure_batches(budget, |calls| kinloop_client::bench::device_tick_dhd(&library, calls))
            .context("device/tick_dhd_fake")?;
        let row = Row {
            name: "device/tick_dhd_fake".into(),
            median_ns: t.median_ns,
            p10_ns: Some(t.p10_ns),
            p90_ns: Some(t.p90_ns),
            goal_ns: None,
            note: Some("read + command through the fake DHD library's FFI: the fake's cost, not USB's".into()),
        };
        r.emit(row, timing_fields(&t));
    }
    Ok(())
}

/// The Markdown table: a line naming the machine and the command, then one row per case.
pub fn markdown(rows: &[Row], machine: &str, command: &str) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "Machine: {machine}. Command: `{command}`.\n");
    out.push_str("| case | median | p10 | p90 | goal | note |\n");
    out.push_str("|---|---:|---:|---:|---|---|\n");
    let opt = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), duration);
    for row in rows {
        let goal = row.goal_ns.map_or_else(String::new, |g| {
            format!("≤ {} ({})", duration(g), if row.median_ns <= g { "met" } else { "missed" })
        });
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} |",
            row.name,
            duration(row.median_ns),
            opt(row.p10_ns),
            opt(row.p90_ns),
            goal,
            row.note.as_deref().unwrap_or("")
        );
    }
    out
}

/// A time in ns with a unit that keeps three or four significant digits: `368 ns`, `1.03 µs`, `13.6 µs`.
pub fn duration(ns: f64) -> String {
    // Switch units where the rounded figure would reach 1000 (999.7 ns reads 1.00 µs, not 1000 ns).
    let (value, unit) = if ns < 999.5 {
        (ns, "ns")
    } else if ns < 999.5e3 {
        (ns / 1e3, "µs")
    } else {
        (ns / 1e6, "ms")
    };
    let digits = if value < 9.995 {
        2
    } else if value < 99.95 {
        1
    } else {
        0
    };
    format!("{value:.digits$} {unit}")
}

/// The CPU model and how many logical CPUs this process may use, e.g. `AMD EPYC, 2 logical CPUs`.
pub fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|info| {
        info.lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split_once(':'))
            .map(|(_, v)| v.trim().to_owned())
    });
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{}, {cpus} logical CPU{}", model.unwrap_or_else(|| "unknown CPU".into()), if cpus == 1 { "" } else { "s" })
}

/// The command that makes this table.
fn command_line(args: &BenchArgs) -> String {
    let mut cmd = String::from("kinloop bench --markdown");
    if args.seconds != 1.0 {
        let _ = write!(cmd, " --seconds {}", args.seconds);
    }
    if let Some(f) = &args.filter {
        let _ = write!(cmd, " --filter {f}");
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_keep_three_or_four_digits_and_switch_units_before_1000() {
        let cases = [
            (17.94, "17.9 ns"),
            (366.4, "366 ns"),
            (999.7, "1.00 µs"),
            (9_996.0, "10.0 µs"),
            (13_612.0, "13.6 µs"),
            (150_000.0, "150 µs"),
            (2_180_000.0, "2.18 ms"),
        ];
        for (ns, text) in cases {
            assert_eq!(duration(ns), text, "{ns} ns");
        }
    }

    #[test]
    fn a_row_without_percentiles_or_goal_keeps_six_cells() {
        let row = Row {
            name: "quic/x".into(),
            median_ns: 33_500.0,
            p10_ns: None,
            p90_ns: None,
            goal_ns: Some(150_000.0),
            note: Some("p99 60.2 µs".into()),
        };
        let md = markdown(&[row], "CPU, 2 logical CPUs", "kinloop bench --markdown");
        let last = md.lines().last().unwrap();
        assert_eq!(last, "| `quic/x` | 33.5 µs | – | – | ≤ 150 µs (met) | p99 60.2 µs |");
        assert_eq!(last.matches('|').count(), 7);
    }
}
