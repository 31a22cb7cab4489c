//! `kinloop-client --device hd` end to end, in real processes (`kinloop-server` and `kinloop-client` through
//! their own `main`), against the fake OpenHaptics library (`fakes/fake-hd`) found through `KINLOOP_HD_LIB`:
//! the same loading and calls as with 3D Systems' `libHD`, and the fake's servo thread running kinloop's
//! tick (the device-clocked loop). Judged on the forces the fake output (its record): none above the
//! Touch's nominal peak, zero from the tick of a fault on (a panic inside the callback included: the
//! client's tests build it with the `fault-injection` feature, which panics on demand), the device disabled
//! last. Bad, missing and old libraries and a failing `hdInitDevice` get one line naming the library and what
//! to check, and a non-zero exit. `kinloop demo --device hd` runs its first user through the same code.
//!
//! The fake is a dev-dependency of this package, so cargo builds its cdylib beside this test's binary; the
//! test fails (never skips) when it is not there.

use crate::common;

use std::time::Duration;

use common::child::{spawn_scene_server, with_overrides, ChildProcess, Program, Role};

/// The Touch's nominal peak force, as the fake reports it (N).
const TOUCH_PEAK_N: f64 = 3.3;

/// A client run: whether it succeeded, its log and stdout, the fake's record, and its folder.
struct HdRun {
    success: bool,
    stderr: String,
    stdout: String,
    record: Vec<String>,
    dir: tempfile::TempDir,
}

impl HdRun {
    /// The forces frames output, in order: (line index, |F| in N).
    fn forces(&self) -> Vec<(usize, f64)> {
        let norm = |line: &str| -> Option<f64> {
            let f: Vec<f64> = line.strip_prefix("F ")?.split(' ').skip(1).filter_map(|x| x.parse().ok()).collect();
            Some(f.iter().map(|x| x * x).sum::<f64>().sqrt())
        };
        self.record.iter().enumerate().filter_map(|(i, l)| Some((i, norm(l)?))).collect()
    }

    /// The line where the fake's fault struck.
    fn fault_line(&self) -> usize {
        self.record.iter().position(|l| l.starts_with("X ")).unwrap_or_else(|| panic!("no fault: {:?}", self.record))
    }

    /// The client's last error line.
    fn error_line(&self) -> String {
        self.stderr.lines().rfind(|l| l.contains("error:")).unwrap_or_default().to_string()
    }
}

/// A server for the testbed and `kinloop-client --device DEVICE --duration SECONDS --json` against it, the
/// library and the fake configured by `env` (`KINLOOP_HD_LIB` defaults to the fake).
fn run_hd(test: &'static str, device: &str, seconds: &str, env: &[(&str, String)]) -> HdRun {
    run_hd_with(test, device, seconds, env, &[])
}

/// [`run_hd`] with `extra` client arguments.
fn run_hd_with(test: &'static str, device: &str, seconds: &str, env: &[(&str, String)], extra: &[&str]) -> HdRun {
    let dir = common::temp_dir();
    let (mut server, addr, fingerprint) = spawn_scene_server(test, "paper-testbed", dir.path());
    let record = dir.path().join("forces.txt");
    let vars = with_overrides(
        vec![
            ("KINLOOP_HD_LIB", common::fake_hd_library().display().to_string()),
            ("FAKE_HD_RECORD", record.display().to_string()),
        ],
        env,
    );
    let args = ["--server", &addr.to_string(), "--fingerprint", &fingerprint, "--device", device]
        .into_iter()
        .chain(["--duration", seconds, "--no-realtime", "--json"])
        .chain(extra.iter().copied())
        .map(String::from)
        .collect();
    let role = Role::Program { program: Program::Client, args };
    let mut client = ChildProcess::spawn_with_env(test, &role, dir.path(), "client", &vars);
    let status = client.exit_status(Duration::from_secs(40));
    server.stop(Duration::from_secs(5));
    let stderr = client.log();
    // No panic but the one injected on demand (see the module documentation).
    let (panics, injected) = (stderr.matches("panicked at").count(), stderr.matches(INJECTED).count());
    assert_eq!(panics, injected, "{test}: the client panicked:\n{stderr}");
    let record = std::fs::read_to_string(&record).unwrap_or_default().lines().map(String::from).collect();
    HdRun { success: status.success(), stderr, stdout: client.stdout(), record, dir }
}

/// What the injected panic says.
const INJECTED: &str = "a panic injected at frame";

/// No force above the Touch's peak, and the device disabled last.
fn assert_within_peak_and_disabled(what: &str, run: &HdRun) {
    let max = run.forces().iter().map(|f| f.1).fold(0.0, f64::max);
    assert!(max <= TOUCH_PEAK_N + 1e-9, "{what}: a force of {max} N, above the Touch's {TOUCH_PEAK_N} N");
    assert_eq!(run.record.last().map(String::as_str), Some("D"), "{what}: the device is disabled last");
}

/// As [`assert_within_peak_and_disabled`], with a zero force last.
fn assert_released(what: &str, run: &HdRun) {
    assert_within_peak_and_disabled(what, run);
    assert_eq!(run.forces().last().map(|f| f.1), Some(0.0), "{what}: the last force is zero");
}

/// A fault that struck at record line `at`: the first frame output after it (the fault's own tick, or the
/// next) is zero, forces were rendered before it, none above the peak, the device disabled last.
fn assert_zero_within_one_tick(what: &str, run: &HdRun, at: usize) {
    assert_within_peak_and_disabled(what, run);
    let forces = run.forces();
    assert!(forces.iter().any(|f| f.0 < at && f.1 > 0.0), "{what}: forces were rendered before the fault");
    let next = forces.iter().find(|f| f.0 > at).map(|f| f.1);
    assert!(next.is_none_or(|f| f == 0.0), "{what}: the first frame after the fault output {next:?} N");
}

#[test]
fn an_hd_device_renders_the_testbed_from_the_vendors_servo_thread() {
    const NAME: &str = "an_hd_device_renders_the_testbed_from_the_vendors_servo_thread";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let tour = "0,0,0;30,20,0;-30,10,0".to_string();
    let unix_s = || std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_secs_f64();
    let before = unix_s();
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_TOUR", tour), ("FAKE_HD_HAND", "firm".into())]);
    let after = unix_s();
    assert!(run.success, "the client fails:\n{}", run.stderr);
    assert_released("session", &run);
    assert!(run.stderr.contains("with hd (Touch (fake))"), "the device is named:\n{}", run.stderr);
    // Force output enabled at open, then forces ramped in from zero once the session renders.
    let forces = run.forces();
    let enabled = run.record.iter().position(|l| l == "E 1").expect("HD_FORCE_OUTPUT enabled");
    assert!(forces.iter().all(|f| f.0 > enabled), "no frame before force output is enabled");
    let first = forces.iter().find(|f| f.1 > 0.0).map_or(0.0, |f| f.1);
    let max = forces.iter().map(|f| f.1).fold(0.0, f64::max);
    assert!(max > 0.05 && first < 0.05 * max, "ramp from {first} N to {max} N");
    // The vendor's thread ran the loop at its 1 kHz: about one frame per millisecond of the session.
    let summary: serde_json::Value = common::child::json_object(&run.stdout);
    let (ticks, rate) = (summary["ticks"].as_f64().unwrap_or(0.0), summary["loop_rate_hz"].as_f64().unwrap_or(0.0));
    assert!((800.0..=1100.0).contains(&rate), "loop rate {rate} Hz over {ticks} ticks");
    assert!(forces.len() as f64 >= 0.9 * ticks, "{} frames for {ticks} ticks", forces.len());
    // The loop's time zero on the system clock (what lines its record up with the server's) fell in the run.
    let epoch = summary["loop_epoch_unix_s"].as_f64().expect("the loop's time zero");
    assert!(before < epoch && epoch < after, "{epoch} outside {before}..{after}");
}

#[test]
fn hd_faults_leave_zero_force_and_bad_libraries_one_line() {
    const NAME: &str = "hd_faults_leave_zero_force_and_bad_libraries_one_line";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    let fake = common::fake_hd_library().display().to_string();
    // A non-finite position: that frame outputs zero and the client ends, saying why once.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "nan:1200".into())]);
    assert!(!run.success, "nan: the client must fail:\n{}", run.stderr);
    assert_released("nan", &run);
    let at = run.fault_line();
    assert_zero_within_one_tick("nan", &run, at);
    let after: Vec<f64> = run.forces().iter().filter(|f| f.0 > at).map(|f| f.1).collect();
    assert!(!after.is_empty() && after.iter().all(|&f| f == 0.0), "nan: forces after the fault {after:?}");
    assert!(run.forces().iter().any(|f| f.0 < at && f.1 > 0.0), "nan: forces were rendered before it");
    assert_eq!(run.stderr.matches("non-finite reading from the HD library").count(), 1, "{}", run.stderr);
    // The device lost: its frames fail with HD_COMM_ERROR, no force goes out after, the code is said.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "lost:1200".into())]);
    assert!(!run.success, "lost: the client must fail:\n{}", run.stderr);
    let at = run.fault_line();
    assert_zero_within_one_tick("lost", &run, at);
    assert!(run.forces().iter().all(|f| f.0 < at || f.1 == 0.0), "lost: no force after the fault");
    assert!(run.stderr.contains("0x0302"), "lost: the HD error code is said:\n{}", run.stderr);
    // The scheduler stalls for 100 ms: the fake's amplifiers drop the held force, and kinloop's next frame,
    // seeing the gap, commands zero and ramps in again; the session goes on.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "stall:1200:100".into())]);
    assert!(run.success, "stall: the session goes on:\n{}", run.stderr);
    assert_released("stall", &run);
    let at = run.fault_line();
    assert_zero_within_one_tick("stall", &run, at);
    let next = run.forces().iter().find(|f| f.0 > at).map(|f| f.1);
    assert_eq!(next, Some(0.0), "stall: the first frame after it outputs zero");
    // hdInitDevice failing with HD_COMM_ERROR: one line with the library, the code and what to check.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "init".into())]);
    assert!(!run.success && run.forces().is_empty(), "init: the client must fail, no force sent");
    let line = run.error_line();
    assert!(line.contains(&fake) && line.contains("0x0302") && line.contains("plugged in"), "init: {line}");
    // ... unless a simulated fallback was asked for.
    let run = run_hd(NAME, "hd,sim:touch", "1", &[("FAKE_HD_FAULT", "init".into())]);
    assert!(run.success && run.stderr.contains("using sim:touch as asked"), "fallback:\n{}", run.stderr);
    // Not an HD library: the fake DHD library lacks every HD symbol; a missing file is named.
    let dhd = common::fake_dhd_library().display().to_string();
    let run = run_hd(NAME, "hd", "1", &[("KINLOOP_HD_LIB", dhd.clone())]);
    let line = run.error_line();
    assert!(!run.success && line.contains(&dhd) && line.contains("lacks required symbols hdInitDevice"), "{line}");
    let run = run_hd(NAME, "hd", "1", &[("KINLOOP_HD_LIB", "/nonexistent/libHD.so".into())]);
    let line = run.error_line();
    assert!(!run.success && line.contains("/nonexistent/libHD.so") && line.contains("KINLOOP_HD_LIB"), "{line}");
}

/// A panic inside kinloop's tick in the vendor's servo thread (injected mid-frame, after `hdBeginFrame`):
/// caught, that very frame ends with zero force, the callback is unscheduled, the client ends with one line
/// saying so, and `hdDisableDevice` runs.
#[test]
fn a_panic_in_the_servo_callback_ends_in_zero_force_and_a_disabled_device() {
    const NAME: &str = "a_panic_in_the_servo_callback_ends_in_zero_force_and_a_disabled_device";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    const FRAME: usize = 1200;
    let tour = "0,0,0;30,20,0;-30,10,0".to_string();
    let env = [("KINLOOP_FAULT_HD_PANIC_AT_FRAME", FRAME.to_string()), ("FAKE_HD_TOUR", tour)];
    let run = run_hd(NAME, "hd", "3", &env);
    assert!(!run.success, "the client must fail:\n{}", run.stderr);
    assert_eq!(run.stderr.matches(INJECTED).count(), 1, "one panic, injected:\n{}", run.stderr);
    assert!(run.stderr.contains("panicked inside the HD servo callback; force zeroed"), "{}", run.stderr);
    assert_released("panic", &run);
    // Every frame ends with one force line: the panicking frame is the FRAME-th, and from it on only zero.
    let forces = run.forces();
    assert!(forces.len() >= FRAME, "{} frames before the end", forces.len());
    assert!(forces[FRAME - 2].1 > 0.0, "forces were rendered before the panic: {:?}", forces[FRAME - 2]);
    let after: Vec<f64> = forces[FRAME - 1..].iter().map(|f| f.1).collect();
    assert!(after.iter().all(|&f| f == 0.0), "forces from the panicking frame on: {after:?}");
    // The callback was unscheduled: no frame came from the servo thread after it (the end's own zero
    // frame and the disable are all that follow).
    assert!(after.len() <= 2, "{} frames from the panicking one on", after.len());
}

/// Button 1 is the clutch, as a DHD device's button 0: held from 1.5 s to 2.5 s, the output fades to zero
/// for about that second and comes back; the device gets only small braking forces meanwhile.
#[test]
fn button_one_is_a_clutch_the_output_fades_while_it_is_held() {
    const NAME: &str = "button_one_is_a_clutch_the_output_fades_while_it_is_held";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let env = [("FAKE_HD_BUTTON", "1.5:2.5".to_owned()), ("FAKE_HD_TOUR", "0,0,0;30,20,0;-30,10,0".into())];
    let run = run_hd_with(NAME, "hd", "4", &env, &["--record", "client.csv"]);
    assert!(run.success, "the client fails:\n{}", run.stderr);
    assert_released("clutch", &run);
    common::checks::assert_clutched(&run.record, &run.forces(), &run.dir.path().join("client.csv"));
}

/// An HDAPI older than 3.0, or one that will not say its version, is refused before any force: one line
/// with the library, what it said and what to check; the device is disabled.
#[test]
fn an_old_or_silent_hd_library_is_refused_with_what_to_check() {
    const NAME: &str = "an_old_or_silent_hd_library_is_refused_with_what_to_check";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let fake = common::fake_hd_library().display().to_string();
    for (version, said) in [("2.0.3", "\"2.0.3\""), ("none", "unknown")] {
        let run = run_hd(NAME, "hd", "1", &[("FAKE_HD_VERSION", version.into())]);
        let line = run.error_line();
        assert!(!run.success && run.forces().is_empty(), "{version}: refused, no force:\n{}", run.stderr);
        assert!(line.contains(&fake) && line.contains(said) && line.contains("OpenHaptics 3.0 or newer"), "{line}");
        assert!(line.contains("KINLOOP_HD_LIB"), "{version}: says what to check: {line}");
        assert!(!run.record.iter().any(|l| l == "E 1"), "{version}: force output never enabled");
        assert_eq!(run.record.last().map(String::as_str), Some("D"), "{version}: the device is disabled");
    }
    // 3.0 itself is new enough.
    let run = run_hd(NAME, "hd", "1", &[("FAKE_HD_VERSION", "3.00.66".into())]);
    assert!(run.success, "3.00.66 is accepted:\n{}", run.stderr);
}

/// `kinloop demo --device hd`: the demo's first user holds the Touch through the client's code (the
/// vendor's servo thread runs its loop), within the Touch's peak, released and disabled at the end.
#[test]
fn the_demo_drives_an_hd_device_through_the_clients_code_path() {
    const NAME: &str = "the_demo_drives_an_hd_device_through_the_clients_code_path";
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let dir = common::temp_dir();
    let record = dir.path().join("forces.txt");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kinloop"))
        .args(["demo", "--device", "hd", "--duration", "2", "--json", "--no-realtime", "--out"])
        .arg(dir.path().join("out"))
        .env("KINLOOP_HD_LIB", common::fake_hd_library())
        .env("FAKE_HD_RECORD", &record)
        .env("FAKE_HD_TOUR", "0,0,0;30,20,0")
        .output()
        .expect("kinloop runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "the demo fails:\n{stderr}");
    let summary: serde_json::Value = common::child::json_object(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(summary["users"], 1, "{summary}");
    let record: Vec<String> =
        std::fs::read_to_string(&record).expect("the fake's record").lines().map(String::from).collect();
    let run = HdRun { success: true, stderr, stdout: String::new(), record, dir };
    assert_released("demo", &run);
    let max = run.forces().iter().map(|f| f.1).fold(0.0, f64::max);
    assert!(max > 0.05, "forces were rendered: up to {max} N");
    assert!(run.record.iter().any(|l| l == "E 1"), "force output enabled");
}
