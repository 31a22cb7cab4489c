//! `kinloop demo` in-process: a real server and real clients over loopback QUIC in real time. The summary
//! must be sane, the charts and `summary.json` written, the linkage must move as the virtual-time harness
//! (the same cores without threads, sockets or clocks) says it does, and an emulated delay must show in the
//! round trip. Demos run one at a time (each is a VE thread and a 1 kHz thread per user on two cores) and
//! each is bounded in time.

use crate::common;

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use kinloop::demo::{self, records, DemoOptions, DemoReport, DemoSummary};
use kinloop::experiments::common::{trajectory_at, ve_op_trajectory, Trajectory};
use kinloop_client::device::DevicePreset;
use kinloop_client::user::UserSpec;
use kinloop_harness::{ClientPlan, SessionPlan};
use kinloop_linkage::math::space::SceneKind;
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use serde_json::Value;

/// Longest a demo of a couple of seconds may take, start-up and charts included.
const BOUND: Duration = Duration::from_secs(60);

fn options(out: &Path, users: usize, seconds: f64) -> DemoOptions {
    let mut o = DemoOptions::new(out).unwrap();
    o.users = users;
    o.duration = Duration::from_secs_f64(seconds);
    o.progress = false;
    // These tests compare the real-time session with the harness's paper session: the paper's push.
    o.paper_push = true;
    o
}

fn run_bounded(options: DemoOptions) -> DemoReport {
    let _turn = common::serial();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(demo::run(&options));
    });
    match rx.recv_timeout(BOUND) {
        Ok(result) => result.unwrap_or_else(|e| panic!("the demo failed: {e:#}")),
        Err(_) => panic!("the demo took longer than {BOUND:?}"),
    }
}

/// Loop lateness (µs) beyond which a run does not count as on time for the tracking and the harness's path.
/// A client whose loop is held up past the stale-snapshot age (100 ms) fades its force to zero by design, and
/// any loop held up for tens of ms lets the coupling springs stretch and kick, moving the real-time path off
/// the harness's by millimetres, where runs late by less stay within a fraction of a millimetre.
const STALL_US: f64 = 25_000.0;

/// Largest share of the VE's ticks that may miss their deadline in a run that counts as on time. The VE
/// thread stalls too, and a run whose VE missed a sizeable share of its ticks strays from the harness's path
/// even when its client loops were on time.
const VE_MISS_SHARE: f64 = 0.05;

/// Attempts [`run_on_time`] makes at most.
const ATTEMPTS: u32 = 8;

/// How long [`run_on_time`] may wait, in all, for calm seconds before its attempts (bad spells of this host
/// have lasted minutes; a cold CI run is about 10 minutes, so this keeps it well under 20).
const CALM_WAIT: Duration = Duration::from_secs(300);

/// A demo run, and whether it ran on time; when no attempt did, the one with the fewest VE misses.
struct Attempted {
    report: DemoReport,
    on_time: bool,
    stalls: Vec<String>,
}

/// Runs a demo of `users` for `seconds` until one run is on time (no client ticked on a stale snapshot, no
/// loop later than [`STALL_US`], VE misses within [`VE_MISS_SHARE`]), at most [`ATTEMPTS`] times, each
/// started in a calm second of the host (`common::wait_for_calm`, within [`CALM_WAIT`] in all): this VM's host
/// sometimes stalls it for minutes (an idle 1 kHz loop has missed 10-54 % of its deadlines in a bad hour), and
/// the fine claims checked on the result (tracking, the harness's path) are claims about a session that ran
/// on time. Every run, stalled or not, must be sane: device limits, closure, files.
fn run_on_time(dir: &Path, make: impl Fn(&Path) -> DemoOptions) -> Attempted {
    let mut stalls = Vec::new();
    let mut least_missed: Option<(f64, DemoReport)> = None;
    let mut calm_budget = CALM_WAIT;
    for attempt in 0..ATTEMPTS {
        let probes = {
            let _turn = common::serial();
            common::wait_for_calm(&mut calm_budget)
        };
        if probes.len() > 1 {
            let worst = probes.iter().copied().fold(0.0, f64::max);
            stalls.push(format!(
                "waited {} s for a calm second (idle loop up to {:.0} % missed)",
                probes.len() - 1,
                100.0 * worst
            ));
        }
        let out = dir.join(format!("attempt{attempt}"));
        std::fs::create_dir_all(&out).unwrap();
        let options = make(&out);
        let users = options.users;
        let report = run_bounded(options);
        assert_sane(&report, users);
        let s = &report.summary;
        let stale: u64 = s
            .per_user
            .iter()
            .map(|u| u.client["stale_ticks"].as_u64().expect("client statistics carry stale_ticks"))
            .sum();
        let ve_misses = s.ve_deadline_misses as f64 / s.ve_ticks.max(1) as f64;
        if stale == 0 && s.loop_lateness_us_max < STALL_US && ve_misses <= VE_MISS_SHARE {
            return Attempted { report, on_time: true, stalls };
        }
        stalls.push(format!(
            "{stale} stale ticks, loops up to {:.0} µs late, VE misses {} of {} ticks",
            s.loop_lateness_us_max, s.ve_deadline_misses, s.ve_ticks
        ));
        if least_missed.as_ref().is_none_or(|(share, _)| ve_misses < *share) {
            least_missed = Some((ve_misses, report));
        }
    }
    let (_, report) = least_missed.expect("ATTEMPTS is at least one");
    Attempted { report, on_time: false, stalls }
}

/// What every demo must satisfy whatever the network: the device limit, the closure, and files written.
fn assert_sane(report: &DemoReport, users: usize) {
    let s = &report.summary;
    assert_eq!(s.users, users);
    assert_eq!(s.per_user.len(), users);
    assert!(!s.cancelled);
    assert!(s.max_force_ratio > 0.0 && s.max_force_ratio <= 1.0, "max force ratio {}", s.max_force_ratio);
    assert!(s.max_closure_error <= 1e-6, "closure error {} m", s.max_closure_error);
    assert!(s.ve_ticks > 0 && s.loop_ticks > 0, "{s:?}");
    assert_eq!(s.uplinks_rejected, 0);
    for u in &s.per_user {
        let server = u.server.as_ref().unwrap_or_else(|| panic!("the server saw {}", u.name));
        assert!(server.uplinks_received > 0 && server.snapshots_sent > 0, "{server:?}");
        assert!(u.client["snapshots_received"].as_u64().is_some_and(|n| n > 0), "{}", u.client);
    }
    let mut ids: Vec<u32> = s.per_user.iter().map(|u| u.user_id).collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), users, "distinct users");

    for stem in ["fig6a_constraint_count", "fig6b_trajectories", "fig6c_joint_constraint_wrench", "device_op_distance"]
    {
        for (ext, least) in [("svg", 1_000), ("png", 5_000)] {
            let file = format!("{stem}.{ext}");
            assert!(s.files.contains(&file), "{file} listed in {:?}", s.files);
            let len = std::fs::metadata(report.dir.join(&file)).map(|m| m.len()).unwrap_or(0);
            assert!(len > least, "{file} has {len} bytes");
        }
    }
    let text = std::fs::read_to_string(report.dir.join("summary.json")).expect("summary.json written");
    let written: Value = serde_json::from_str(&text).expect("summary.json is JSON");
    for key in [
        "users",
        "ve_tick_us_p99",
        "ve_deadline_misses",
        "loop_lateness_us_p99",
        "loop_misses",
        "rtt_ms_p50",
        "max_closure_error",
        "max_force_ratio",
    ] {
        assert!(written.get(key).is_some(), "summary.json has {key}: {text}");
    }
    assert_eq!(written["users"], users);
    for stage in ["intake", "step", "snapshot_terms", "encode", "ring_push", "wake", "stats"] {
        let samples = written["ve_stages"][stage]["samples"].as_u64().unwrap_or(0);
        assert!(samples > 100, "summary.json's ve_stages.{stage} has {samples} samples: {text}");
    }
    assert_eq!(written["per_user"].as_array().map(Vec::len), Some(users));
}

fn rtt_ms(s: &DemoSummary) -> f64 {
    let rtt = s.rtt_ms_p50.expect("some ping was answered");
    assert!(rtt.is_finite() && rtt > 0.0, "rtt {rtt}");
    rtt
}

/// The VE's OP of `user` in the demo's record, on the time since that user joined the VE.
fn demo_op_path(report: &DemoReport, user: u32) -> Trajectory {
    let ve = records::read_ve(&report.dir.join("ve.csv"), SceneKind::Planar).unwrap();
    let rows = ve.iter().filter_map(|v| v.users.iter().find(|u| u.0 == user).map(|u| (v.t, [u.1[0], u.1[1]])));
    let rows: Vec<(f64, [f64; 2])> = rows.collect();
    let joined = rows.first().expect("the user is in the VE's record").0;
    rows.into_iter().map(|(t, p)| (t - joined, p)).collect()
}

#[test]
fn two_users_over_loopback_quic_move_the_testbed_as_the_harness_does() {
    let dir = tempfile::tempdir().unwrap();
    let seconds = 1.5;
    let run = run_on_time(dir.path(), |out| options(out, 2, seconds));
    if !run.on_time {
        println!("the host stalled all {ATTEMPTS} runs, so only the coarse bounds are checked: {:?}", run.stalls);
    }
    let report = &run.report;
    let s = &report.summary;
    let rtt = rtt_ms(s);
    assert!(rtt < 20.0, "loopback round trip {rtt} ms");
    // Stiffness control keeps each device near the OP it holds (the paper's Fig 6b; the harness gives a
    // fraction of a millimetre for the paper's single user with the default gains). A loop held up for tens of ms lets the
    // coupling stretch: a stalled run is held to a bound that still fails a device left behind.
    let device_bound = if run.on_time { 3.0 } else { 10.0 };
    for u in &s.per_user {
        let rms = u.device_op_rms_mm.expect("distances from the records");
        assert!(rms < device_bound, "{}: device-OP RMS {rms} mm", u.name);
    }

    // The same session in virtual time: two paper users on link2, each pushing half the paper's wrench,
    // the second joining when it joined here. The real-time VE must trace the same path.
    let (first, second) = (&s.per_user[0], &s.per_user[1]);
    let mut plan = SessionPlan::paper().unwrap();
    plan.duration = Duration::from_secs_f64(seconds);
    // The demo's server and clients run with the defaults: designed gains and mapping.
    plan.ve = kinloop_server::core::VeConfig::default();
    let half: Vec<f64> = PAPER_WRENCH.iter().map(|w| w / 2.0).collect();
    let lag = (second.record_offset_s - first.record_offset_s).max(0.0);
    plan.clients = (0..2)
        .map(|i| {
            let mut c = ClientPlan::new(&format!("user{}", i + 1), "link2", DevicePreset::Paper);
            c.user = UserSpec::Constant(half.clone());
            c.join_at = Duration::from_secs_f64(if i == 0 { 0.0 } else { lag }).min(Duration::from_millis(500));
            c
        })
        .collect();
    let (_, recording) = kinloop_harness::run(&plan, &mut |_| {}).unwrap();
    let reference = ve_op_trajectory(&plan, &recording, "link2").unwrap();
    let path = demo_op_path(report, first.user_id);
    let travelled = {
        let (a, b) = (path[0].1, path[path.len() - 1].1);
        (a[0] - b[0]).hypot(a[1] - b[1])
    };
    assert!(travelled > 0.005, "the paper's wrench moves the OP by about 14 mm in {seconds} s, not {travelled} m");
    let compared: Vec<f64> = path
        .iter()
        .filter(|(t, _)| *t <= seconds - 0.1)
        .map(|(t, p)| {
            let r = trajectory_at(&reference, *t);
            (p[0] - r[0]).hypot(p[1] - r[1])
        })
        .collect();
    let rms = (compared.iter().map(|d| d * d).sum::<f64>() / compared.len() as f64).sqrt();
    // On time, a few ms of scheduling noise shifts the path by hundredths of a millimetre. A stalled run (the
    // VE catching up late ticks without the clients' uplinks shakes the linkage) strays by millimetres: it is
    // held to a quarter of the distance travelled, which a wrong sign, a lost coupling or a
    // missing user exceed by far.
    let bound = if run.on_time { 0.5e-3 } else { 0.25 * travelled };
    assert!(
        rms < bound,
        "real-time OP path {:.3} mm RMS from the harness's (second user {lag:.3} s after the first; VE ticks \
         {}, {} deadline misses, {:.0} µs longest; loops up to {:.0} µs late)",
        rms * 1e3,
        s.ve_ticks,
        s.ve_deadline_misses,
        s.ve_tick_us_max,
        s.loop_lateness_us_max
    );
}

#[test]
fn an_emulated_delay_of_20_ms_each_way_shows_in_the_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let mut o = options(dir.path(), 1, 1.5);
    o.link.delay = Duration::from_millis(20);
    let report = run_bounded(o);
    assert_sane(&report, 1);
    let rtt = rtt_ms(&report.summary);
    assert!((35.0..80.0).contains(&rtt), "round trip {rtt} ms with 20 ms added each way");
    assert_eq!(report.summary.delay_ms, 20.0);
}

#[test]
fn bad_settings_are_refused_before_anything_starts() {
    let dir = tempfile::tempdir().unwrap();
    let refused = |edit: &dyn Fn(&mut DemoOptions), says: &str| {
        let mut o = options(dir.path(), 1, 1.0);
        edit(&mut o);
        let e = demo::run(&o).map(|_| ()).expect_err(says);
        assert!(format!("{e:#}").contains(says), "{e:#} should mention {says:?}");
    };
    refused(&|o| o.users = 0, "--users 0");
    refused(&|o| o.users = demo::MAX_USERS + 1, "--users 65");
    refused(&|o| o.duration = Duration::ZERO, "--duration");
    refused(&|o| o.link.loss = 1.5, "loss");
    refused(&|o| o.scene.ops.clear(), "no operational point");
    assert!(!dir.path().join("demo").exists(), "nothing written");
}

/// `kinloop timer-floor` times an idle loop as the haptic loop times itself and reports the same keys; a
/// bad rate is refused with the flag's name.
#[test]
fn timer_floor_reports_an_idle_loops_lateness() {
    // Its loop spins under SCHED_FIFO: beside a demo it would take a core from the demo's real-time loops.
    let _turn = common::serial();
    let bin = env!("CARGO_BIN_EXE_kinloop");
    let out = std::process::Command::new(bin).args(["timer-floor", "--duration", "0.3", "--json"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {v}"));
    // 300 deadlines at 1 kHz; a stalled machine skips some rather than bursting (this host has stalled the
    // whole VM for over 150 ms, so no lower bound but one tick).
    assert!((1.0..=301.0).contains(&f("ticks")), "{v}");
    assert!(f("loop_lateness_us_p50") <= f("loop_lateness_us_p99"), "{v}");
    assert!(f("loop_lateness_us_p99") <= f("loop_lateness_us_max"), "{v}");
    assert!(f("loop_misses") <= f("ticks") && (f("miss_rate") - f("loop_misses") / f("ticks")).abs() < 1e-12);
    // Stalls are runs of misses: no more of them than misses, and one at least while there is a miss.
    assert!(f("loop_stalls") <= f("loop_misses") && (f("loop_stalls") > 0.0) == (f("loop_misses") > 0.0), "{v}");
    assert_eq!(f("miss_threshold_us"), 500.0);
    let bad = std::process::Command::new(bin).args(["timer-floor", "--rate", "0"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && stderr.contains("--rate") && !stderr.contains("panicked"), "{stderr}");
}

/// What `kinloop-server --scene S` and `kinloop-client --op OP --device D` do with default flags, in real
/// time over loopback QUIC (the programs' own drivers): a subset of the renderability matrix (the
/// experiment runs all of it in virtual time) chosen to cover every scene kind, every device, both
/// networks, four hands and three scenes nobody tuned for. Each pair must render by the experiment's
/// bounds: stable (no VE restore, no withheld snapshot, loops closed within 1e-6 m, no non-finite value),
/// the device at its force limit on at most 5 % of its ticks, and within 5 mm RMS of its OP on a perfect
/// network, 10 mm at 50 ms one-way with 5 ms jitter (device space). A run the host stalled is held to the
/// stability bounds only and tried again.
#[test]
fn shipped_linkages_render_with_default_flags_in_real_time() {
    use kinloop::experiments::renderability::{judge_live, live_options, Network, Point};
    use kinloop_client::user::HandKind;

    // scene, OP, device, hand, network
    const PAIRS: [(&str, &str, DevicePreset, HandKind, Network); 8] = [
        ("fourbar-crank-rocker", "coupler", DevicePreset::Touch, HandKind::Soft, Network::Delayed50),
        ("watt-six-bar", "link5", DevicePreset::Paper, HandKind::Firm, Network::Perfect),
        ("parallelogram", "coupler", DevicePreset::Falcon, HandKind::Soft, Network::Delayed50),
        ("spherical-four-bar", "coupler", DevicePreset::Touch, HandKind::Firm, Network::Perfect),
        ("stephenson-six-bar", "output", DevicePreset::Falcon, HandKind::Release, Network::Perfect),
        ("five-bar-robot", "effector", DevicePreset::Touch, HandKind::Poke, Network::Delayed50),
        ("bennett-linkage", "coupler", DevicePreset::Falcon, HandKind::Soft, Network::Delayed50),
        ("slider-crank", "slider", DevicePreset::Paper, HandKind::Soft, Network::Delayed50),
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for (i, &(scene, op, device, hand, network)) in PAIRS.iter().enumerate() {
        let point = Point { scene: scene.into(), op: op.into(), device, network, hand };
        let label = format!("{scene}:{op} {} {} hand, {}", device.name(), hand.name(), network.name());
        let run = run_on_time(&dir.path().join(format!("pair{i}")), |out| live_options(&point, 4.0, out).unwrap());
        let r = judge_live(&point, &run.report).unwrap();
        println!(
            "{label}: clamped {:.1} %, device-OP RMS {:.2} mm, closure {:.1e} m, restores {}{}",
            r.clamped_fraction * 100.0,
            r.device_op_rms_m * 1e3,
            r.max_closure_error_m,
            r.ve_restores,
            if run.on_time { "" } else { " (host stalled every attempt)" }
        );
        // A run the host stalled is held to stability and closure only.
        let broken = if run.on_time {
            r.failures
        } else {
            r.failures.into_iter().filter(|f| f.starts_with("unstable") || f.starts_with("closure")).collect()
        };
        if !broken.is_empty() {
            failures.push(format!("{label}: {}", broken.join(", ")));
        }
    }
    assert!(failures.is_empty(), "pairs that do not render with default flags:\n{}", failures.join("\n"));
}
