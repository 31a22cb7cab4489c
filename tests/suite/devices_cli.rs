//! `kinloop devices [--check] [--json]` as a user runs it, against the fake DHD library (`fakes/fake-dhd`)
//! found through `KINLOOP_DHD_LIB`: the library, its SDK version and the device's model are reported;
//! `--check` reads positions with forces never enabled and closes the device; and without a library the
//! command fails naming every place it looked and the variables to set.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

/// `kinloop devices ARGS` with the fake as the library, recording into `record`, with `env` on top.
fn devices(args: &[&str], record: &Path, env: &[(&str, &str)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_kinloop"));
    command
        .arg("devices")
        .args(args)
        .env("KINLOOP_DHD_LIB", common::fake_dhd_library())
        .env("FAKE_DHD_RECORD", record)
        .env_remove("FORCEDIM_SDK");
    for (k, v) in env {
        command.env(k, v);
    }
    command.output().expect("kinloop runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn the_fake_library_its_version_and_its_device_model_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("record.txt");
    let out = devices(&[], &record, &[("FAKE_DHD_SYSTEM", "60"), ("FAKE_DHD_VERSION", "3.16.2")]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    let library = common::fake_dhd_library().display().to_string();
    assert!(stdout.contains(&format!("DHD library: {library} (SDK 3.16.2")), "{stdout}");
    assert!(stdout.contains("devices: 1"), "{stdout}");
    // The Falcon's published peak force (Novint's specification: > 2 lbf, 8.9 N).
    assert!(stdout.contains("Novint Falcon") && stdout.contains("peak force 8.9 N"), "{stdout}");

    let out = devices(&["--json"], &record, &[("FAKE_DHD_SYSTEM", "33")]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["library"]["path"], library.as_str());
    assert_eq!(report["library"]["sdk_version"], "3.17.6-0", "the fake's default version");
    assert_eq!(report["device_count"], 1);
    let model = &report["devices"][0]["model"];
    assert_eq!(model["system_type"], 33);
    assert!(model["name"].as_str().is_some_and(|n| n.contains("omega.3")), "{model}");
    // The omega.3's published figures: 12 N, 3 DOF.
    assert_eq!(model["peak_force_n"], 12.0);
    assert_eq!(model["dof"], 3);

    // A device the library cannot open: no device, a failure, and what to check (the USB node's access).
    let out = devices(&[], &record, &[("FAKE_DHD_FAULT", "open")]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(text(&out.stdout).contains("no device found"), "{}", text(&out.stdout));
    assert!(stderr.contains("no usable DHD device"), "{stderr}");
    if cfg!(target_os = "linux") {
        assert!(stderr.contains("/dev/bus/usb"), "{stderr}");
    }
}

#[test]
fn check_reads_positions_with_forces_never_enabled_and_closes_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("record.txt");
    let out = devices(&["--check", "--json"], &record, &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let check = &report["devices"][0]["check"];
    let rate = check["rate_hz"].as_f64().expect("a rate");
    // One second at 1 kHz: the loop ran (a machine loaded several times over its cores has given it under
    // half its ticks, so no speed is asserted here), never faster than its rate.
    assert!((100.0..=1001.0).contains(&rate), "rate {rate} Hz: {check}");
    assert_eq!(check["failed_reads"], 0, "{check}");
    let seen = &check["workspace_seen_mm"];
    let (min, max) = (seen["min"].as_array().expect("min"), seen["max"].as_array().expect("max"));
    let extents: Vec<f64> = (0..3).map(|i| max[i].as_f64().unwrap() - min[i].as_f64().unwrap()).collect();
    assert!(extents.iter().all(|e| e.is_finite() && *e >= 0.0), "{seen}");
    // The fake's hand tours a circle: the handle moves, and the box seen has a width.
    assert!(extents.iter().any(|e| *e > 0.01), "the handle never moved: {seen}");

    let lines: Vec<String> =
        std::fs::read_to_string(&record).expect("the fake's record").lines().map(String::from).collect();
    assert!(!lines.iter().any(|l| l == "E 1"), "forces were enabled: {lines:?}");
    assert_eq!(lines.last().map(String::as_str), Some("C"), "the device is closed last: {lines:?}");

    let out = devices(&["--check"], &record, &[]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(stdout.contains("check (forces off, 1 s):") && stdout.contains("workspace seen from"), "{stdout}");
}

#[test]
fn a_missing_library_fails_listing_every_place_looked_and_the_variables() {
    let dir = tempfile::tempdir().unwrap();
    let sdk = dir.path().join("sdk");
    let out = Command::new(env!("CARGO_BIN_EXE_kinloop"))
        .arg("devices")
        .env_remove("KINLOOP_DHD_LIB")
        .env("FORCEDIM_SDK", &sdk)
        .output()
        .expect("kinloop runs");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let in_sdk = sdk.join("lib").join(format!("{}drd{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX));
    assert!(stderr.contains(&in_sdk.display().to_string()), "{stderr}");
    if cfg!(target_os = "linux") {
        assert!(stderr.contains("/usr/local/lib/libdhd.so") && stderr.contains("/usr/lib/libdrd.so"), "{stderr}");
    }
    assert!(stderr.contains("KINLOOP_DHD_LIB") && stderr.contains("FORCEDIM_SDK"), "{stderr}");

    let missing = dir.path().join("nowhere").join("libdhd.so");
    let out = Command::new(env!("CARGO_BIN_EXE_kinloop"))
        .args(["devices", "--json"])
        .env("KINLOOP_DHD_LIB", &missing)
        .output()
        .expect("kinloop runs");
    assert_eq!(out.status.code(), Some(1));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert!(report["library"].is_null());
    assert_eq!(report["looked"][0], missing.display().to_string().as_str());
}

/// `kinloop devices ARGS` with no DHD library and the fake HD one (its variables `env` on top), in `dir`:
/// the output and the fake's record.
fn hd_only(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> (Output, String) {
    let (record, hd_record) = (dir.join("record.txt"), dir.join("hd.txt"));
    let hd = common::fake_hd_library().display().to_string();
    let hd_record_text = hd_record.display().to_string();
    let mut all = vec![
        ("KINLOOP_DHD_LIB", "/nonexistent/libdhd.so"),
        ("KINLOOP_HD_LIB", hd.as_str()),
        ("FAKE_HD_RECORD", hd_record_text.as_str()),
    ];
    all.extend_from_slice(env);
    let out = devices(args, &record, &all);
    (out, std::fs::read_to_string(&hd_record).unwrap_or_default())
}

#[test]
fn the_openhaptics_library_and_its_device_are_reported_with_force_output_never_enabled() {
    let dir = tempfile::tempdir().unwrap();
    let hd = common::fake_hd_library().display().to_string();
    // No DHD library, an HD one: the HD device is reported and the command succeeds.
    let (out, events) = hd_only(&[], dir.path(), &[]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    assert!(stdout.contains(&format!("HD library (OpenHaptics): {hd}")), "{stdout}");
    // The figures the fake reports through hdGetDoublev, converted: 0.4 N/mm is 400 N/m.
    assert!(stdout.contains("peak force 3.3 N") && stdout.contains("stiffness 400.0 N/m"), "{stdout}");
    assert!(stdout.contains("DHD library: not found"), "{stdout}");
    assert!(!events.lines().any(|l| l == "E 1"), "force output was enabled: {events}");
    assert_eq!(events.lines().last(), Some("D"), "the device is disabled: {events}");
    // A device that needs calibrating says so, and nothing is run to calibrate it.
    let (out, events) = hd_only(&["--json"], dir.path(), &[("FAKE_HD_CALIBRATION", "update")]);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["hd"]["device"]["calibrated"], false, "{report}");
    assert!(!events.lines().any(|l| l == "A"), "calibration ran unasked: {events}");
}

/// `--check` with an HD device: the vendor's servo thread calls a reading callback for a second, forces
/// never enabled, and kinloop's own loop runs beside it in the same command, each loop's lateness reported.
#[test]
fn check_reports_the_servo_threads_lateness_beside_kinloops_own_loop() {
    let dir = tempfile::tempdir().unwrap();
    let (out, events) = hd_only(&["--check", "--json"], dir.path(), &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let check = &report["hd"]["check"];
    let (servo, own) = (&check["servo"], &check["kinloop_loop"]);
    // Frames were read, none failed, and each loop measured its ticks' lateness.
    assert!(servo["reads"].as_u64().is_some_and(|n| n > 0), "{check}");
    assert_eq!(servo["failed_reads"], 0, "{check}");
    for l in [servo, own] {
        assert!(l["ticks"].as_u64().is_some_and(|n| n > 0), "{check}");
        let (p99, max) = (l["lateness_us_p99"].as_f64().unwrap(), l["lateness_us_max"].as_f64().unwrap());
        assert!(p99 >= 0.0 && p99 <= max, "{check}");
    }
    assert!(!events.lines().any(|l| l == "E 1"), "force output was enabled: {events}");
    // Every frame the callbacks ended output nothing.
    let frames: Vec<&str> = events.lines().filter(|l| l.starts_with("F ")).collect();
    assert!(!frames.is_empty(), "the callbacks ended no frame: {events}");
    for f in frames {
        let force: Vec<f64> = f.split_whitespace().skip(2).map(|x| x.parse().unwrap()).collect();
        assert_eq!(force, [0.0; 3], "{f}");
    }
    assert_eq!(events.lines().last(), Some("D"), "the device is disabled: {events}");
}
