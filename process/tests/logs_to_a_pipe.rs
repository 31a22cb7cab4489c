//! A program's logs written to a pipe carry no ANSI escape codes: the test runs itself again as a child
//! (this test binary, filtered to the child's test) with stderr to a pipe, lets [`run_program`] set up the
//! logs there and log a line, and reads the child's stderr.

use std::process::{Command, Stdio};

use kinloop_process::report::run_program;

/// Set in the child's environment: the child logs instead of spawning.
const CHILD: &str = "KINLOOP_PROCESS_LOG_CHILD";
const LINE: &str = "a line for the pipe";

#[test]
fn logs_to_a_pipe_carry_no_escape_codes() {
    if std::env::var_os(CHILD).is_some() {
        let _ = run_program("info", || {
            tracing::info!("{LINE}");
            Ok::<(), std::io::Error>(())
        });
        return;
    }
    let me = std::env::current_exe().expect("the test binary's path");
    let child = Command::new(me)
        .args(["--exact", "logs_to_a_pipe_carry_no_escape_codes", "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .env_remove("NO_COLOR")
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("the child runs");
    assert!(child.status.success(), "child failed: {}", String::from_utf8_lossy(&child.stderr));
    let stderr = String::from_utf8_lossy(&child.stderr);
    assert!(stderr.contains(LINE), "the child logged its line to stderr: {stderr:?}");
    assert!(!child.stderr.contains(&0x1b), "an ESC byte in logs written to a pipe: {stderr:?}");
}
