//! `kinloop-client --device dhd` end to end, in real processes (`kinloop-server` and `kinloop-client` through
//! their own `main`), against the fake DHD library (`fakes/fake-dhd`) found through `KINLOOP_DHD_LIB`: the
//! same loading, checks and calls as with Force Dimension's library. Each fault the fake can stage is judged
//! on the forces it received (its record): none above the model's limit, zero from the fault on. And every
//! kind of bad library gets one line naming it and what was wrong, and a non-zero exit.
//!
//! The fake is a dev-dependency of this package, so cargo builds its cdylib beside this test's binary under
//! any `cargo test`; the test fails (never skips) when it is not there.

use crate::common;

use std::time::Duration;

use common::child::{spawn_scene_server, with_overrides, ChildProcess, Program, Role};

/// The omega.3's published peak force, the limit kinloop's spec table gives it (N).
const OMEGA3_LIMIT_N: f64 = 12.0;
/// The Falcon's (N).
const FALCON_LIMIT_N: f64 = 8.9;

/// What a client run left.
struct Run {
    success: bool,
    stderr: String,
    /// The fake's record, one line per call that changed its output.
    record: Vec<String>,
    /// Where the client ran (its `--record` file, when asked, is `client.csv` there).
    dir: tempfile::TempDir,
}

impl Run {
    /// The forces commanded, in order: (line index, |F| in N).
    fn forces(&self) -> Vec<(usize, f64)> {
        self.record
            .iter()
            .enumerate()
            .filter_map(|(i, line)| {
                let f: Vec<f64> = line.strip_prefix("F ")?.split(' ').skip(1).filter_map(|x| x.parse().ok()).collect();
                Some((i, f.iter().map(|x| x * x).sum::<f64>().sqrt()))
            })
            .collect()
    }

    /// Where the fault struck in the record.
    fn fault_line(&self) -> usize {
        self.record.iter().position(|l| l.starts_with("X ")).unwrap_or_else(|| panic!("no fault in {:?}", self.record))
    }

    /// The error line the client ended with.
    fn error_line(&self) -> String {
        let lines: Vec<&str> = self.stderr.lines().filter(|l| l.contains("error:")).collect();
        assert!(!lines.is_empty(), "no error line in:\n{}", self.stderr);
        lines.last().map(|l| l.to_string()).unwrap_or_default()
    }
}

/// A server for `scene` and `kinloop-client --device DEVICE` against it for `seconds`, the fake configured by
/// `env` (`KINLOOP_DHD_LIB` defaults to the fake).
fn run_client(test: &'static str, scene: &str, device: &str, seconds: &str, env: &[(&str, String)]) -> Run {
    run_client_signalled(test, scene, device, seconds, env, &[], None)
}

/// A signal sent to the client mid-session, as a person or a service manager stops it.
#[derive(Clone, Copy, Debug)]
enum StopSignal {
    Interrupt,
    Terminate,
}

/// How long a signalled client may take to leave: its loop stops within a tick, its session within the
/// network side's close.
const EXIT_AFTER_SIGNAL: Duration = Duration::from_secs(5);

/// [`run_client`], with `signal` sent to the client once the fake's forces are on (mid-session) when given.
fn run_client_signalled(
    test: &'static str,
    scene: &str,
    device: &str,
    seconds: &str,
    env: &[(&str, String)],
    extra: &[&str],
    signal: Option<StopSignal>,
) -> Run {
    let dir = common::temp_dir();
    let (mut server, addr, fingerprint) = spawn_scene_server(test, scene, dir.path());
    let record = dir.path().join("forces.txt");
    let vars = with_overrides(
        vec![
            ("KINLOOP_DHD_LIB", common::fake_dhd_library().display().to_string()),
            ("FAKE_DHD_RECORD", record.display().to_string()),
        ],
        env,
    );
    let args = [
        "--server",
        &addr.to_string(),
        "--fingerprint",
        &fingerprint,
        "--device",
        device,
        "--duration",
        seconds,
        "--no-realtime",
    ]
    .into_iter()
    .chain(extra.iter().copied())
    .map(String::from)
    .collect();
    let mut client = ChildProcess::spawn_with_env(
        test,
        &Role::Program { program: Program::Client, args },
        dir.path(),
        "client",
        &vars,
    );
    let status = match signal {
        None => client.exit_status(Duration::from_secs(40)),
        Some(signal) => {
            wait_for_forces_on(&record, Duration::from_secs(30));
            match signal {
                StopSignal::Interrupt => client.interrupt(),
                StopSignal::Terminate => client.terminate(),
            }
            // exit_status panics (with the client's log) when the client outlives the limit.
            client.exit_status(EXIT_AFTER_SIGNAL)
        }
    };
    server.stop(Duration::from_secs(5));
    let stderr = client.log();
    assert!(!stderr.contains("panicked"), "{test}: the client panicked:\n{stderr}");
    let record = std::fs::read_to_string(&record).unwrap_or_default().lines().map(String::from).collect();
    Run { success: status.success(), stderr, record, dir }
}

/// Returns once the fake's record shows forces enabled (`E 1`) and some forces commanded after; panics after `limit`.
fn wait_for_forces_on(record: &std::path::Path, limit: Duration) {
    let start = std::time::Instant::now();
    loop {
        let text = std::fs::read_to_string(record).unwrap_or_default();
        if let Some(on) = text.find("\nE 1\n") {
            if text[on..].lines().filter(|l| l.starts_with("F ")).count() > 20 {
                return;
            }
        }
        assert!(start.elapsed() < limit, "forces were not enabled within {limit:?}: {text}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// No force above `limit`, the watchdog armed before forces were enabled, and the device closed with zero
/// force and forces off.
fn assert_safe(what: &str, run: &Run, limit: f64) {
    let forces = run.forces();
    assert!(!forces.is_empty(), "{what}: no force was commanded: {:?}", &run.record[..run.record.len().min(10)]);
    let max = forces.iter().map(|f| f.1).fold(0.0, f64::max);
    assert!(max <= limit + 1e-9, "{what}: a force of {max} N, above the model's {limit} N");
    let watchdog = run.record.iter().position(|l| l == "W 80");
    let enabled = run.record.iter().position(|l| l == "E 1");
    assert!(watchdog.is_some() && watchdog < enabled, "{what}: the watchdog is armed before forces are on");
    let tail: Vec<&str> = run.record.iter().rev().take(3).map(String::as_str).collect();
    assert_eq!(tail[0], "C", "{what}: the device is closed last: {tail:?}");
    assert_eq!(tail[1], "E 0", "{what}: forces are disabled before closing: {tail:?}");
    assert_eq!(forces.last().map(|f| f.1), Some(0.0), "{what}: the last force is zero");
}

#[test]
fn a_dhd_device_renders_the_testbed_end_to_end_and_is_released() {
    const NAME: &str = "a_dhd_device_renders_the_testbed_end_to_end_and_is_released";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(90));
    for (system, limit) in [("33", OMEGA3_LIMIT_N), ("60", FALCON_LIMIT_N)] {
        let run = run_client(NAME, "paper-testbed", "dhd", "3", &[("FAKE_DHD_SYSTEM", system.into())]);
        assert!(run.success, "system {system}: the client fails:\n{}", run.stderr);
        assert_safe(&format!("system {system}"), &run, limit);
        // Forces ramp in: the first commands are small, later ones are not.
        let forces = run.forces();
        let first = forces.iter().find(|f| f.1 > 0.0).map(|f| f.1).unwrap_or(0.0);
        let max = forces.iter().map(|f| f.1).fold(0.0, f64::max);
        assert!(first < 0.05 * max && max > 0.5, "system {system}: ramp from {first} N to {max} N");
        assert!(
            run.stderr.contains("with dhd (") && run.stderr.contains(if system == "60" { "Falcon" } else { "omega.3" })
        );
    }
}

#[test]
fn device_faults_leave_zero_force_from_the_tick_they_strike() {
    const NAME: &str = "device_faults_leave_zero_force_from_the_tick_they_strike";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    for fault in ["lost:1500", "nan:1500"] {
        let run = run_client(NAME, "paper-testbed", "dhd", "4", &[("FAKE_DHD_FAULT", fault.into())]);
        assert!(!run.success, "{fault}: the client must fail:\n{}", run.stderr);
        let fault_at = run.fault_line();
        let after: Vec<f64> = run.forces().iter().filter(|f| f.0 > fault_at).map(|f| f.1).collect();
        assert!(!after.is_empty() && after.iter().all(|&f| f == 0.0), "{fault}: forces after the fault {after:?}");
        let max = run.forces().iter().map(|f| f.1).fold(0.0, f64::max);
        assert!(max > 0.1 && max <= OMEGA3_LIMIT_N, "{fault}: forces before it reach {max} N");
        // The reason, naming the device's library, is said once; the client's last line says it failed.
        let library = common::fake_dhd_library().display().to_string();
        let said = run.stderr.lines().filter(|l| l.contains("communication lost") && l.contains(&library)).count();
        assert_eq!(said, 1, "{fault}:\n{}", run.stderr);
        assert!(run.error_line().contains("the device failed"), "{fault}:\n{}", run.stderr);
        assert_eq!(run.record.last().map(String::as_str), Some("C"), "{fault}: the device is closed");
    }
    // The device's own watchdog expiring (`watchdog:N`): it switches its forces off and says why in
    // `dhdGetStatus`. The client reads that in the same tick and commands zero; then, as after a stall,
    // enables forces again and ramps them in from zero.
    let run = run_client(NAME, "paper-testbed", "dhd", "4", &[("FAKE_DHD_FAULT", "watchdog:1500".into())]);
    assert!(run.success, "watchdog: the session goes on:\n{}", run.stderr);
    assert_safe("watchdog", &run, OMEGA3_LIMIT_N);
    let fault_at = run.fault_line();
    let after: Vec<f64> = run.forces().iter().filter(|f| f.0 > fault_at).map(|f| f.1).collect();
    assert_eq!(after.first().copied(), Some(0.0), "watchdog: zero from the tick it expired: {:?}", &after[..5]);
    let again = run.record.iter().skip(fault_at).position(|l| l == "E 1").map(|i| i + fault_at);
    let again = again.unwrap_or_else(|| panic!("watchdog: forces are enabled again: {:?}", &run.record[fault_at..]));
    let ramp: Vec<f64> = run.forces().iter().filter(|f| f.0 > again).map(|f| f.1).take(400).collect();
    let (first, peak) =
        (ramp.iter().copied().find(|f| *f > 0.0).unwrap_or(0.0), ramp.iter().copied().fold(0.0, f64::max));
    assert!(first < 0.05 * peak, "watchdog: forces ramp in again, from {first} N to {peak} N");
    assert!(run.stderr.contains("watchdog expired"), "watchdog:\n{}", run.stderr);
    // A read that stalls the loop longer than the watchdog: that tick's command (made from the fresh reading)
    // goes out, and the next tick, seeing the gap, commands zero and ramps in again.
    let run = run_client(NAME, "paper-testbed", "dhd", "4", &[("FAKE_DHD_FAULT", "stall:2000:50".into())]);
    assert!(run.success, "stall: the session goes on:\n{}", run.stderr);
    assert_safe("stall", &run, OMEGA3_LIMIT_N);
    let fault_at = run.fault_line();
    let before = run.forces().iter().rfind(|f| f.0 < fault_at).map(|f| f.1).unwrap_or(0.0);
    let next = run.forces().iter().filter(|f| f.0 > fault_at).nth(1).map(|f| f.1);
    assert!(before > 0.0, "stall: a force was being rendered before it ({before} N)");
    assert_eq!(next, Some(0.0), "stall: the command of the tick after it is zero");
}

/// What is wrong, the fake's environment, what the error line says and the library it names.
type BadLibrary = (&'static str, Vec<(&'static str, String)>, &'static str, String);

#[test]
fn bad_dhd_libraries_get_one_line_naming_the_library_and_a_failure() {
    const NAME: &str = "bad_dhd_libraries_get_one_line_naming_the_library_and_a_failure";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    let fake = common::fake_dhd_library().display().to_string();
    let cases: [BadLibrary; 5] = [
        ("open fails", vec![("FAKE_DHD_FAULT", "open".into())], "cannot open device 0", fake.clone()),
        ("too old", vec![("FAKE_DHD_VERSION", "3.2.0".into())], "older than 3.14.0", fake.clone()),
        ("unknown model", vec![("FAKE_DHD_SYSTEM", "999".into())], "system type 999", fake.clone()),
        (
            "missing",
            vec![("KINLOOP_DHD_LIB", "/nonexistent/libdhd.so".into())],
            "KINLOOP_DHD_LIB",
            "/nonexistent/libdhd.so".into(),
        ),
        (
            "not DHD",
            vec![("KINLOOP_DHD_LIB", "libc.so.6".into())],
            "lacks required symbols dhdGetSDKVersion",
            "libc.so.6".into(),
        ),
    ];
    for (what, env, says, library) in cases {
        let run = run_client(NAME, "paper-testbed", "dhd", "2", &env);
        assert!(!run.success, "{what}: the client must fail:\n{}", run.stderr);
        let line = run.error_line();
        assert!(line.contains(says) && line.contains(&library), "{what}: {line}");
        assert_eq!(run.stderr.matches(says).count(), 1, "{what}: said once:\n{}", run.stderr);
        assert!(run.forces().iter().all(|f| f.1 == 0.0), "{what}: no force to a device kinloop cannot use");
    }
    // A fallback only when asked.
    let run = run_client(NAME, "paper-testbed", "dhd,sim:falcon", "1", &[("FAKE_DHD_FAULT", "open".into())]);
    assert!(run.success && run.stderr.contains("using sim:falcon as asked"), "fallback:\n{}", run.stderr);
    assert!(run.stderr.contains("with sim:falcon"), "fallback:\n{}", run.stderr);
}

#[test]
fn ctrl_c_and_sigterm_release_a_dhd_device_with_zero_force() {
    const NAME: &str = "ctrl_c_and_sigterm_release_a_dhd_device_with_zero_force";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    for signal in [StopSignal::Interrupt, StopSignal::Terminate] {
        // A duration far beyond the test's: only the signal can end this run.
        let run = run_client_signalled(NAME, "paper-testbed", "dhd", "600", &[], &[], Some(signal));
        assert!(!run.stderr.contains("panicked"), "{signal:?}: the client panicked:\n{}", run.stderr);
        assert_safe(&format!("{signal:?}"), &run, OMEGA3_LIMIT_N);
    }
}

#[test]
fn button_zero_is_a_clutch_the_output_fades_while_it_is_held() {
    const NAME: &str = "button_zero_is_a_clutch_the_output_fades_while_it_is_held";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(90));
    // Button 0 held from 1.5 s to 2.5 s of the hand's motion.
    let env = [("FAKE_DHD_BUTTON", "1.5:2.5".to_owned())];
    let run = run_client_signalled(NAME, "paper-testbed", "dhd", "4", &env, &["--record", "client.csv"], None);
    assert!(run.success, "the client fails:\n{}", run.stderr);
    assert_safe("clutch", &run, OMEGA3_LIMIT_N);
    common::checks::assert_clutched(&run.record, &run.forces(), &run.dir.path().join("client.csv"));
}

#[test]
fn an_uncalibrated_device_is_refused_unless_auto_init_is_asked_for() {
    const NAME: &str = "an_uncalibrated_device_is_refused_unless_auto_init_is_asked_for";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(90));
    let env = [("FAKE_DHD_CALIBRATED", "0".to_owned())];
    let run = run_client(NAME, "paper-testbed", "dhd", "1", &env);
    assert!(!run.success, "an uncalibrated device must be refused:\n{}", run.stderr);
    let line = run.error_line();
    assert!(line.contains("not calibrated") && line.contains("--dhd-auto-init"), "{line}");
    assert!(!run.record.iter().any(|l| l == "A"), "drdAutoInit never runs unasked: {:?}", run.record);
    assert!(run.forces().iter().all(|f| f.1 == 0.0), "no force to an uncalibrated device");
    // Asked for: drdAutoInit runs once, before forces come on, and the session renders.
    let run = run_client_signalled(NAME, "paper-testbed", "dhd", "1", &env, &["--dhd-auto-init"], None);
    assert!(run.success, "with --dhd-auto-init:\n{}", run.stderr);
    let init = run.record.iter().position(|l| l == "A");
    let enabled = run.record.iter().position(|l| l == "E 1");
    assert!(init.is_some() && init < enabled, "drdAutoInit before forces: {:?}", &run.record[..8]);
    assert_eq!(run.record.iter().filter(|l| *l == "A").count(), 1);
}
