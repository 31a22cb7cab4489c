//! `kinloop-client --device hd` end to end, in real processes (`kinloop-server` and `kinloop-client` through
//! their own `main`), against the fake OpenHaptics library (`fakes/fake-hd`) found through `KINLOOP_HD_LIB`:
//! the same loading and calls as with 3D Systems' `libHD`, and the fake's servo thread running kinloop's
//! tick (the device-clocked loop). Judged on the forces the fake output (its record): none above the
//! Touch's nominal peak, zero from a fault on, the device disabled last. Bad libraries and a failing
//! `hdInitDevice` get one line naming the library and the HD error code, and a non-zero exit.
//!
//! The fake is a dev-dependency of this package, so cargo builds its cdylib beside this test's binary; the
//! test fails (never skips) when it is not there.

mod common;

use std::time::Duration;

use common::child::{spawn_scene_server, with_overrides, ChildProcess, Program, Role};

/// The Touch's nominal peak force, as the fake reports it (N).
const TOUCH_PEAK_N: f64 = 3.3;

/// A client run: whether it succeeded, its log and stdout, and the fake's record.
struct HdRun {
    success: bool,
    stderr: String,
    stdout: String,
    record: Vec<String>,
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
}

/// A server for the testbed and `kinloop-client --device DEVICE --duration SECONDS --json` against it, the
/// library and the fake configured by `env` (`KINLOOP_HD_LIB` defaults to the fake).
fn run_hd(test: &'static str, device: &str, seconds: &str, env: &[(&str, String)]) -> HdRun {
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
        .map(String::from)
        .collect();
    let role = Role::Program { program: Program::Client, args };
    let mut client = ChildProcess::spawn_with_env(test, &role, dir.path(), "client", &vars);
    let status = client.exit_status(Duration::from_secs(40));
    server.stop(Duration::from_secs(5));
    let stderr = client.log();
    assert!(!stderr.contains("panicked"), "{test}: the client panicked:\n{stderr}");
    let record = std::fs::read_to_string(&record).unwrap_or_default().lines().map(String::from).collect();
    HdRun { success: status.success(), stderr, stdout: client.stdout(), record }
}

/// No force above the Touch's peak, and the device disabled last with a zero force before it.
fn assert_released(what: &str, run: &HdRun) {
    let forces = run.forces();
    let max = forces.iter().map(|f| f.1).fold(0.0, f64::max);
    assert!(max <= TOUCH_PEAK_N + 1e-9, "{what}: a force of {max} N, above the Touch's {TOUCH_PEAK_N} N");
    assert_eq!(run.record.last().map(String::as_str), Some("D"), "{what}: the device is disabled last");
    assert_eq!(forces.last().map(|f| f.1), Some(0.0), "{what}: the last force is zero");
}

#[test]
fn an_hd_device_renders_the_testbed_from_the_vendors_servo_thread() {
    const NAME: &str = "an_hd_device_renders_the_testbed_from_the_vendors_servo_thread";
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(60));
    let tour = "0,0,0;30,20,0;-30,10,0".to_string();
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_TOUR", tour), ("FAKE_HD_HAND", "firm".into())]);
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
    let after: Vec<f64> = run.forces().iter().filter(|f| f.0 > at).map(|f| f.1).collect();
    assert!(!after.is_empty() && after.iter().all(|&f| f == 0.0), "nan: forces after the fault {after:?}");
    assert!(run.forces().iter().any(|f| f.0 < at && f.1 > 0.0), "nan: forces were rendered before it");
    assert_eq!(run.stderr.matches("non-finite reading from the HD library").count(), 1, "{}", run.stderr);
    // The device lost: its frames fail with HD_COMM_ERROR, no force goes out after, the code is said.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "lost:1200".into())]);
    assert!(!run.success, "lost: the client must fail:\n{}", run.stderr);
    let at = run.fault_line();
    assert!(run.forces().iter().all(|f| f.0 < at || f.1 == 0.0), "lost: no force after the fault");
    assert!(run.stderr.contains("0x0302"), "lost: the HD error code is said:\n{}", run.stderr);
    assert_eq!(run.record.last().map(String::as_str), Some("D"), "lost: the device is disabled");
    // The scheduler stalls for 100 ms: the fake's amplifiers drop the held force, and kinloop's next frame,
    // seeing the gap, commands zero and ramps in again; the session goes on.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "stall:1200:100".into())]);
    assert!(run.success, "stall: the session goes on:\n{}", run.stderr);
    assert_released("stall", &run);
    let at = run.fault_line();
    let next = run.forces().iter().find(|f| f.0 > at).map(|f| f.1);
    assert_eq!(next, Some(0.0), "stall: the first frame after it outputs zero");
    // hdInitDevice failing with HD_COMM_ERROR: one line with the library, the code and what to check.
    let run = run_hd(NAME, "hd", "3", &[("FAKE_HD_FAULT", "init".into())]);
    assert!(!run.success && run.forces().is_empty(), "init: the client must fail, no force sent");
    let line = run.stderr.lines().rfind(|l| l.contains("error:")).unwrap_or_default().to_string();
    assert!(line.contains(&fake) && line.contains("0x0302") && line.contains("plugged in"), "init: {line}");
    // ... unless a simulated fallback was asked for.
    let run = run_hd(NAME, "hd,sim:touch", "1", &[("FAKE_HD_FAULT", "init".into())]);
    assert!(run.success && run.stderr.contains("using sim:touch as asked"), "fallback:\n{}", run.stderr);
    // Not an HD library: the fake DHD library lacks every HD symbol; a missing file is named.
    let dhd = common::fake_dhd_library().display().to_string();
    let run = run_hd(NAME, "hd", "1", &[("KINLOOP_HD_LIB", dhd.clone())]);
    let line = run.stderr.lines().rfind(|l| l.contains("error:")).unwrap_or_default().to_string();
    assert!(!run.success && line.contains(&dhd) && line.contains("lacks required symbols hdInitDevice"), "{line}");
    let run = run_hd(NAME, "hd", "1", &[("KINLOOP_HD_LIB", "/nonexistent/libHD.so".into())]);
    let line = run.stderr.lines().rfind(|l| l.contains("error:")).unwrap_or_default().to_string();
    assert!(!run.success && line.contains("/nonexistent/libHD.so") && line.contains("KINLOOP_HD_LIB"), "{line}");
}
