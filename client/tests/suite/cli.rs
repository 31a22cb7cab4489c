//! The binary refuses bad input with a clear message and a failure exit code, never a panic.

use std::process::Command;

fn run(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_kinloop-client")).args(args).output().expect("runs");
    let text = String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("panicked"), "{text}");
    (out.status.success(), text)
}

#[test]
fn bad_flags_addresses_and_trust_fail_cleanly() {
    let fp = "--fingerprint=00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";
    let cases: &[(&[&str], &str)] = &[
        (&["--server", "127.0.0.1:1"], "--ca FILE or --fingerprint HEX"),
        (&["--server", "127.0.0.1:1", fp, "--device", "sim:phantom"], "sim:falcon"),
        (&["--server", "127.0.0.1:1", fp, "--user", "wave:3"], "unknown user"),
        (&["--server", "127.0.0.1:1", fp, "--constraint-mode", "soft"], "stiffness or impedance"),
        (&["--server", "not an address", fp], "server address"),
        (&["--server", "127.0.0.1:1", "--fingerprint", "xyz"], "fingerprint"),
        (&["--server", "127.0.0.1:1", fp, "--duration=-1"], "positive"),
        (&["--server", "127.0.0.1:1", fp, "--duration=nan"], "positive"),
        (&["--server", "127.0.0.1:1", fp, "--duration=1e300"], "fits a clock"),
        (&["--server", "127.0.0.1:1", fp, "--rate", "5"], "between 10 and 20000"),
        (&["--server", "127.0.0.1:1", fp, "--loss", "150%"], "probability"),
    ];
    for (args, expected) in cases {
        let (ok, text) = run(args);
        assert!(!ok, "{args:?} should fail");
        assert!(text.contains(expected), "{args:?}: expected {expected:?} in {text}");
    }
}
