//! `kinloop demo --device dhd`: the demo's first user holds a Force Dimension device through the same code
//! as `kinloop-client --device dhd` (library search, checks, safety), here the fake DHD library
//! (`fakes/fake-dhd`) found through `KINLOOP_DHD_LIB`; judged on the forces the fake received.

use crate::common;

use std::process::{Command, Output};
use std::time::Duration;

/// `kinloop demo ARGS` with `env`, writing under `dir`.
fn demo(dir: &std::path::Path, args: &[&str], env: &[(&str, String)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_kinloop"));
    command.arg("demo").args(args).arg("--out").arg(dir.join("out")).env_remove("FORCEDIM_SDK");
    for (k, v) in env {
        command.env(k, v);
    }
    command.output().expect("kinloop runs")
}

#[test]
fn the_demo_drives_a_dhd_device_through_the_clients_code_path() {
    let _bounded =
        common::bounded("the_demo_drives_a_dhd_device_through_the_clients_code_path", Duration::from_secs(60));
    let dir = common::temp_dir();
    let record = dir.path().join("forces.txt");
    let env = [
        ("KINLOOP_DHD_LIB", common::fake_dhd_library().display().to_string()),
        ("FAKE_DHD_RECORD", record.display().to_string()),
        // As a Falcon: its 8.9 N is the limit every command must keep to.
        ("FAKE_DHD_SYSTEM", "60".to_owned()),
    ];
    let out = demo(dir.path(), &["--device", "dhd", "--duration", "2", "--json", "--no-realtime"], &env);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "the demo fails:\n{stderr}");
    let summary: serde_json::Value =
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
    assert_eq!(summary["users"], 1, "{summary}");
    let record: Vec<String> =
        std::fs::read_to_string(&record).expect("the fake's record").lines().map(String::from).collect();
    let forces: Vec<f64> = record
        .iter()
        .filter_map(|l| l.strip_prefix("F "))
        .map(|l| l.split(' ').skip(1).filter_map(|x| x.parse::<f64>().ok()).map(|x| x * x).sum::<f64>().sqrt())
        .collect();
    let max = forces.iter().copied().fold(0.0, f64::max);
    assert!(max > 0.1 && max <= 8.9 + 1e-9, "forces reach {max} N (the Falcon's limit is 8.9 N)");
    assert!(record.iter().any(|l| l == "W 80") && record.iter().any(|l| l == "E 1"), "{:?}", &record[..5]);
    assert_eq!(record.last().map(String::as_str), Some("C"), "the device is closed at the end");
    assert_eq!(forces.last().copied(), Some(0.0), "the last force is zero");

    // Without a library: one line naming the variable, a failure, no fallback unless asked.
    let missing = [("KINLOOP_DHD_LIB", "/nonexistent/libdhd.so".to_owned())];
    let out = demo(dir.path(), &["--device", "dhd", "--duration", "1", "--no-realtime"], &missing);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("KINLOOP_DHD_LIB"), "{stderr}");
    // The fallback is said as a warning (`kinloop` logs errors only unless RUST_LOG asks for more).
    let warn = [missing[0].clone(), ("RUST_LOG", "warn".to_owned())];
    let out = demo(dir.path(), &["--device", "dhd,sim:falcon", "--duration", "1", "--no-realtime"], &warn);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && stderr.contains("using sim:falcon as asked"), "{stderr}");
}
