//! `kinloop bench`: a fixed suite of the hot paths, each measured as the median over batches in one run.
//! With `--json`, one object per line: `{"name": ..., "ns_per_call": ..., ...}`. Cases with a goal in the
//! issues (`server/ve_tick_users_N`, `client/tick_testbed`) also carry `goal_ns` and `meets_goal`.

use std::time::Duration;

use anyhow::{ensure, Context, Result};
use kinloop_linkage::bench::{measure, measure_batches, paper_wrench, Case, Timing};
use kinloop_linkage::Integrator;
use serde_json::{json, Value};

/// Arguments of `kinloop bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Print one JSON object per line.
    #[arg(long)]
    pub json: bool,
    /// Seconds of measurement per case (the suite has about 20 cases).
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Only run cases whose name contains this text.
    #[arg(long)]
    pub filter: Option<String>,
}

struct Reporter<'a> {
    args: &'a BenchArgs,
}

impl Reporter<'_> {
    fn wanted(&self, name: &str) -> bool {
        self.args.filter.as_deref().is_none_or(|f| name.contains(f))
    }

    fn emit(&self, name: &str, ns_per_call: f64, extra: Value) {
        let mut obj = json!({ "name": name, "ns_per_call": ns_per_call });
        if let (Some(o), Value::Object(e)) = (obj.as_object_mut(), extra) {
            o.extend(e);
        }
        if self.args.json {
            println!("{obj}");
        } else {
            let rest: Vec<String> = obj
                .as_object()
                .into_iter()
                .flatten()
                .filter(|(k, _)| *k != "name" && *k != "ns_per_call")
                .map(|(k, v)| format!("{k}={v}"))
                .collect();
            println!("{name:<36} {:>12.1} ns   {}", ns_per_call, rest.join(" "));
        }
    }

    fn timing(&self, name: &str, t: Timing) {
        self.emit(name, t.median_ns, timing_fields(&t));
    }

    /// A timing against its goal (ns per call): the median must not exceed it.
    fn timing_with_goal(&self, name: &str, t: Timing, goal_ns: f64) {
        let mut extra = timing_fields(&t);
        extra["goal_ns"] = json!(goal_ns);
        extra["meets_goal"] = json!(t.median_ns <= goal_ns);
        self.emit(name, t.median_ns, extra);
    }
}

fn timing_fields(t: &Timing) -> Value {
    json!({ "p10_ns": t.p10_ns, "p90_ns": t.p90_ns, "calls": t.calls })
}

/// Users of the `server/ve_tick_users_N` cases (issue 4).
const VE_TICK_USERS: [usize; 4] = [1, 4, 16, 64];

/// Issue 4's goal for one VE tick: 1 µs with one user, 0.4 µs more per extra user.
fn ve_tick_goal_ns(users: usize) -> f64 {
    1000.0 + 400.0 * users.saturating_sub(1) as f64
}

/// Issue 5's goal for one haptic tick on the testbed.
const CLIENT_TICK_GOAL_NS: f64 = 500.0;

/// Longest measurement per case `--seconds` accepts.
const MAX_SECONDS: f64 = 30.0;

/// Runs the suite.
pub fn run(args: &BenchArgs) -> Result<()> {
    ensure!(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= MAX_SECONDS,
        "--seconds: must be in (0, {MAX_SECONDS}] s per case, got {}",
        args.seconds
    );
    let r = Reporter { args };
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
    if r.wanted("ve_step_rk4/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        r.timing("ve_step_rk4/testbed", measure(budget, || case.ve_step(Integrator::Rk4)));
    }
    if r.wanted("op_space/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        case.prepare_op_space();
        r.timing(
            "op_space/testbed",
            measure(budget, || {
                std::hint::black_box(case.op_space());
            }),
        );
    }
    if r.wanted("local_model/testbed") {
        let mut case = Case::new("paper-testbed").ok_or_else(|| anyhow::anyhow!("testbed"))?;
        let mut lm = case.local_model();
        let f = paper_wrench();
        r.timing(
            "local_model/testbed",
            measure(budget, || {
                std::hint::black_box(lm.step(1e-3, &f));
            }),
        );
    }
    for users in VE_TICK_USERS {
        let name = format!("server/ve_tick_users_{users}");
        if !r.wanted(&name) {
            continue;
        }
        // Each batch builds its own VE (set-up not timed) and ticks it `calls` times from the paper's start.
        let t = measure_batches(budget, |calls| kinloop_server::bench::ve_tick_users(users, calls))
            .with_context(|| name.clone())?;
        r.timing_with_goal(&name, t, ve_tick_goal_ns(users));
    }
    if r.wanted("client/tick_testbed") {
        let t = measure_batches(budget, kinloop_client::bench::client_tick_testbed).context("client/tick_testbed")?;
        r.timing_with_goal("client/tick_testbed", t, CLIENT_TICK_GOAL_NS);
    }
    if r.wanted("codec/snapshot_testbed") {
        let iters = (200_000.0 * args.seconds).max(1000.0) as u64;
        let (ns, bytes) = kinloop_protocol::bench::codec_snapshot_testbed(iters)?;
        r.emit("codec/snapshot_testbed", ns, json!({ "bytes": bytes }));
    }
    if r.wanted("quic/datagram_oneway_loopback") {
        let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
        let samples = (2000.0 * args.seconds).max(200.0) as usize;
        let (p50, p99) = runtime.block_on(kinloop_protocol::bench::quic_datagram_oneway_loopback(samples))?;
        r.emit("quic/datagram_oneway_loopback", p50 * 1e3, json!({ "p50_us": p50, "p99_us": p99, "samples": samples }));
    }
    Ok(())
}
