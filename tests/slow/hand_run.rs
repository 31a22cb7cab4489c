//! The session by hand that `docs/hand-run.sh` (quoted by the README) tells a newcomer to run: its `cargo
//! run` lines, read from the file and run as written through the programs' own `main`s in child processes,
//! with only a free port and the fingerprint the server prints put in. A renamed flag, a package `cargo
//! run -p` cannot run, or a client that does not get through fails here.

use crate::common;

use std::time::Duration;

use common::child::{json_object, listening, ChildProcess, Program, Role};
use common::workspace;

const NAME: &str = "the_documented_hand_run_works_as_written";
/// The file the README quotes.
const SCRIPT: &str = include_str!("../../docs/hand-run.sh");
/// Where the script's `$FINGERPRINT` goes.
const FINGERPRINT: &str = "$FINGERPRINT";

/// One `cargo run --release -p PACKAGE -- ARGS...` line of the script.
#[derive(Debug)]
struct Documented {
    line: String,
    program: Program,
    args: Vec<String>,
}

impl Documented {
    /// The value after `flag`, if the line has it.
    fn value(&self, flag: &str) -> Option<&str> {
        self.args.iter().position(|a| a == flag).and_then(|i| self.args.get(i + 1)).map(String::as_str)
    }
}

/// The script's `cargo run` lines. Each must be `cargo run --release -p PACKAGE -- ARGS...` (a newcomer
/// runs cargo from the workspace's top, whose default package is `kinloop`: `--bin` alone finds no server),
/// for a package whose binary `cargo run -p` picks is one of the programs.
fn documented() -> Vec<Documented> {
    SCRIPT
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("cargo run"))
        .map(|line| {
            let words: Vec<String> = line.split_whitespace().map(|w| w.trim_matches('"').to_owned()).collect();
            let (package, args) = match words.iter().map(String::as_str).collect::<Vec<_>>()[..] {
                ["cargo", "run", "--release", "-p", package, "--", ..] => (package.to_owned(), words[6..].to_vec()),
                _ => panic!("{line:?}: write `cargo run --release -p PACKAGE -- ARGS...`"),
            };
            let binary = workspace::binary_run_by(&package);
            let program = Program::named(&binary).unwrap_or_else(|| panic!("{line:?} runs {binary}, not a program"));
            Documented { line: line.to_owned(), program, args }
        })
        .collect()
}

/// `--delay 50ms` in milliseconds.
fn milliseconds(value: &str) -> f64 {
    let ms = value.strip_suffix("ms").and_then(|v| v.parse().ok());
    ms.unwrap_or_else(|| panic!("{value:?}: this test reads delays written in ms"))
}

/// The script's server, then each of its clients, as written: every client exits by itself with success
/// after ticking, receiving snapshots and tracking the linkage (its `--json` output), a client told to
/// delay what it sends sees that delay in its round trip, and Ctrl-C stops the server cleanly.
#[test]
fn the_documented_hand_run_works_as_written() {
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    let commands = documented();
    let (servers, clients): (Vec<&Documented>, Vec<&Documented>) =
        commands.iter().partition(|c| c.program == Program::Server);
    assert_eq!(servers.len(), 1, "the script starts one server: {commands:#?}");
    assert!(clients.len() >= 2 && clients.iter().any(|c| c.value("--delay").is_some()), "{commands:#?}");
    let server = servers[0];
    let listen = server.value("--listen").unwrap_or_else(|| panic!("{}: no --listen", server.line)).to_owned();

    let dir = common::temp_dir();
    // A free port instead of the documented one; the server runs in its own directory, where its default
    // certificate directory lands.
    let args = server.args.iter().map(|a| if *a == listen { "127.0.0.1:0".to_owned() } else { a.clone() }).collect();
    let mut running =
        ChildProcess::spawn(NAME, &Role::Program { program: Program::Server, args }, dir.path(), "server");
    let (addr, fingerprint) =
        running.wait_for_stdout("the server prints its address", Duration::from_secs(30), listening);
    assert!(dir.path().join(".kinloop-server").is_dir(), "the certificate goes to the default --cert-dir");

    for (i, client) in clients.iter().enumerate() {
        assert!(client.args.iter().any(|a| a == FINGERPRINT), "{}: pins the printed fingerprint", client.line);
        assert!(client.args.contains(&listen), "{}: joins the server at {listen}", client.line);
        let mut args: Vec<String> = client
            .args
            .iter()
            .map(|a| match a.as_str() {
                FINGERPRINT => fingerprint.clone(),
                a if a == listen => addr.to_string(),
                a => a.to_owned(),
            })
            .collect();
        args.push("--json".into());
        let role = Role::Program { program: Program::Client, args };
        let mut run = ChildProcess::spawn(NAME, &role, dir.path(), &format!("client{i}"));
        let status = run.exit_status(Duration::from_secs(40));
        assert!(status.success(), "{} exited with {status}:\n{}", client.line, run.log_tail());
        let stats = json_object(&run.stdout());
        println!("{}\n  {stats}", client.line);
        let number = |key: &str| stats[key].as_f64().unwrap_or_else(|| panic!("{key} missing: {stats}"));
        assert!(number("ticks") > 0.0, "{}: {stats}", client.line);
        assert!(number("snapshots_received") > 0.0, "{}: {stats}", client.line);
        let tracking = number("tracking_error_rms_m");
        assert!(tracking.is_finite() && tracking >= 0.0, "{}: tracking {tracking}", client.line);
        assert_eq!(number("non_finite_events"), 0.0, "{}: {stats}", client.line);
        if let Some(delay) = client.value("--delay") {
            let rtt = number("rtt_ms_p50");
            assert!(rtt >= 0.8 * milliseconds(delay), "{}: round trip {rtt} ms", client.line);
        }
    }

    running.interrupt();
    let status = running.exit_status(Duration::from_secs(15));
    assert!(status.success(), "Ctrl-C: the server exited with {status}:\n{}", running.log_tail());
}
