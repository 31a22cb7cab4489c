//! One session in real processes: a `kinloop-server --scene S` and a `kinloop-client --op OP --device D`
//! started as a user starts them (their own `main`, default flags, loopback QUIC), each writing its
//! `--record` and `--json`, and what the two left judged by the matrices' bounds. The experiments that run
//! the programs themselves (`renderability-dhd`, `renderability-hd`, `robustness-live`) share it.
//!
//! The two records' clocks are matched by the time zero each program reports on the system clock (the
//! server's `ve.epoch_unix_s`, the client's `loop_epoch_unix_s`), which both programs read on this one
//! machine. Matching them by when each printed a line is late by whatever the host delays the reading (and
//! the client's loop starts on its own thread), and a touring hand turns each 10 ms of mismatch into about
//! half a millimetre of RMS.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;

use kinloop_linkage::math::space::SceneKind;

/// How long the server outlives the client's session: its start-up, the connection and the leave (s).
const SERVER_MARGIN_S: f64 = 2.5;

/// How a program is started: its name (`kinloop-server`, `kinloop-client`) and arguments to a command.
pub type Launch = dyn Fn(&str, &[String]) -> Command + Sync;

/// Starts `kinloop-server` and `kinloop-client`.
pub struct Launcher {
    launch: Box<Launch>,
}

impl Launcher {
    /// Programs started by `launch` (tests re-execute their own binary as each program).
    pub fn launched_by(launch: Box<Launch>) -> Launcher {
        Launcher { launch }
    }

    /// The programs beside this executable (cargo puts `kinloop`, `kinloop-server` and `kinloop-client` in
    /// one folder).
    pub fn beside_this_program() -> Result<Launcher> {
        let exe = std::env::current_exe().context("this program's path")?;
        let dir = exe.parent().context("this program's folder")?.to_owned();
        for name in ["kinloop-server", "kinloop-client"] {
            let path = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
            if !path.is_file() {
                bail!("{} is missing: build the workspace (cargo build --release --workspace)", path.display());
            }
        }
        let launch = move |program: &str, args: &[String]| {
            let mut command = Command::new(dir.join(format!("{program}{}", std::env::consts::EXE_SUFFIX)));
            command.args(args);
            command
        };
        Ok(Launcher { launch: Box::new(launch) })
    }

    fn command(&self, program: &str, args: Vec<String>) -> Command {
        (self.launch)(program, &args)
    }
}

/// The `kinloop` program: this one, or the one beside it (a test's executable is in cargo's `deps`, one
/// folder below the programs).
pub fn kinloop_beside_this_program() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("this program's path")?;
    let name = format!("kinloop{}", std::env::consts::EXE_SUFFIX);
    if exe.file_name().is_some_and(|n| n == name.as_str()) {
        return Ok(exe);
    }
    let dir = exe.parent().context("this program's folder")?;
    let candidates = [Some(dir.join(&name)), dir.parent().map(|up| up.join(&name))];
    candidates.into_iter().flatten().find(|p| p.is_file()).with_context(|| {
        format!("{name} is not beside {} nor one folder up: build it (cargo build --release -p kinloop)", exe.display())
    })
}

/// One session: what the server is told to host and what the client is told to hold, with what.
pub struct Pair {
    /// `--scene`: a built-in name or a scene file (relative paths from the session's folder).
    pub scene: String,
    /// `--op`.
    pub op: String,
    /// `--device`.
    pub device: String,
    /// The client's other flags (`--user soft`, ...).
    pub client_flags: Vec<String>,
    /// The client's environment beyond this process's (a vendor library's variables).
    pub client_env: Vec<(String, String)>,
    /// The emulated link of what each side sends (`--delay`, `--jitter`, `--seed`): server, client.
    pub links: [Vec<String>; 2],
}

/// The flags of a link of mean one-way `delay` and `jitter` (standard deviation), seeded with `seed`;
/// none for a perfect one.
pub fn link_flags(delay: Duration, jitter: Duration, seed: u64) -> Vec<String> {
    if delay.is_zero() && jitter.is_zero() {
        return Vec::new();
    }
    let ms = |d: Duration| format!("{}ms", d.as_millis());
    vec!["--delay".into(), ms(delay), "--jitter".into(), ms(jitter), "--seed".into(), seed.to_string()]
}

/// What the two programs left: the server's JSON statistics, the client's, its log, and the clock offset.
pub struct Ran {
    /// The server's `--json`.
    pub server: Value,
    /// The client's `--json` (`Null` when it printed none).
    pub client: Value,
    /// The client's standard error.
    pub client_log: String,
    /// The client exited well, held the OP, and both clocks' zeros are known.
    pub client_ok: bool,
    /// The client's time zero minus the server's (s).
    pub offset_s: f64,
}

/// Runs the server and the client of `pair` for `seconds` in `dir` (the server's certificate, both records,
/// both logs land there).
pub fn run(pair: &Pair, seconds: f64, launcher: &Launcher, dir: &Path) -> Result<Ran> {
    let mut args: Vec<String> = ["--scene", &pair.scene, "--listen", "127.0.0.1:0", "--cert-dir", "cert"]
        .into_iter()
        .chain(["--record", "ve.csv", "--json", "--stats-every", "0", "--duration"])
        .map(String::from)
        .collect();
    args.push((seconds + SERVER_MARGIN_S).to_string());
    args.extend(pair.links[0].iter().cloned());
    let mut server = launcher
        .command("kinloop-server", args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::from(std::fs::File::create(dir.join("server.log"))?))
        .spawn()
        .context("starting kinloop-server")?;
    let mut out = BufReader::new(server.stdout.take().context("the server's stdout")?);
    let log_tail = |dir: &Path| {
        let text = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
        text.lines().rev().take(5).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n")
    };
    let address = line_starting(&mut out, "kinloop-server listening on")
        .with_context(|| format!("the server's log ends:\n{}", log_tail(dir)))?;
    let fingerprint = line_starting(&mut out, "certificate fingerprint")?;
    let last_word = |l: &str| l.split_whitespace().last().unwrap_or("").to_owned();
    let (address, fingerprint) = (last_word(&address), last_word(&fingerprint));
    let mut args: Vec<String> = ["--server", &address, "--fingerprint", &fingerprint, "--device", &pair.device]
        .into_iter()
        .chain(["--op", &pair.op, "--json", "--record", "client.csv", "--duration"])
        .map(String::from)
        .collect();
    args.push(seconds.to_string());
    args.extend(pair.client_flags.iter().cloned());
    args.extend(pair.links[1].iter().cloned());
    let mut client = launcher
        .command("kinloop-client", args)
        .envs(pair.client_env.iter().map(|(k, v)| (k.as_str(), v.as_str())))
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting kinloop-client")?;
    let (log, reader) = collect_lines(client.stderr.take().context("the client's stderr")?);
    let mut client_out = String::new();
    client.stdout.take().context("the client's stdout")?.read_to_string(&mut client_out)?;
    let status = wait_bounded(&mut client, Duration::from_secs_f64(seconds + 30.0), "kinloop-client")?;
    let _ = reader.join();
    let server_status = wait_bounded(&mut server, Duration::from_secs_f64(seconds + 30.0), "kinloop-server")?;
    let mut server_out = String::new();
    out.read_to_string(&mut server_out)?;
    let lines = log.lock().map_err(|_| anyhow!("the client's log"))?.clone();
    let client_log: String = lines.iter().map(|(_, l)| format!("{l}\n")).collect();
    std::fs::write(dir.join("client.log"), &client_log)?;
    let holding = lines.iter().any(|(_, l)| l.contains("kinloop-client: holding"));
    if !server_status.success() {
        bail!("kinloop-server failed (see {})", dir.join("server.log").display());
    }
    let server = json_in(&server_out).context("the server's JSON statistics")?;
    let client = json_in(&client_out).unwrap_or(Value::Null);
    let epochs = (client["loop_epoch_unix_s"].as_f64(), server["ve"]["epoch_unix_s"].as_f64());
    let offset_s = match epochs {
        (Some(client), Some(ve)) => client - ve,
        _ => f64::NAN,
    };
    Ok(Ran { server, client, client_ok: status.success() && holding && offset_s.is_finite(), client_log, offset_s })
}

/// What a session in real processes measured, read from what the programs left.
#[derive(Clone, Debug)]
pub struct Measured {
    /// Failures that are not a bound: the client did not get through, or the session was unstable (a VE
    /// restore, a withheld snapshot, a non-finite value).
    pub failures: Vec<String>,
    /// Fraction of the client's active ticks clamped at the device's limit.
    pub clamped_fraction: f64,
    /// Device-OP RMS against the VE's OP at the same instant, device space (m); NaN when the client failed.
    pub device_op_rms_m: f64,
    /// The client's own device-to-local-model RMS, device space (m).
    pub device_model_rms_m: f64,
    /// Largest closure error (the scene's length unit).
    pub max_closure_error: f64,
    /// VE restores.
    pub ve_restores: u64,
}

impl Measured {
    /// Reads the session `ran` left in `dir` (a scene of `kind`).
    pub fn of(ran: &Ran, dir: &Path, kind: SceneKind) -> Result<Measured> {
        let core = &ran.server["ve"]["core"];
        let count = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
        let (restores, withheld) = (count(&core["state_restores"]), count(&core["snapshots_withheld"]));
        let c = &ran.client;
        let non_finite = count(&c["non_finite_events"]);
        let mut failures = Vec::new();
        if !ran.client_ok {
            let last = ran.client_log.lines().rfind(|l| l.contains("error")).unwrap_or("no error line");
            failures.push(format!("the client failed: {last}"));
        }
        if !(restores == 0.0 && withheld == 0.0 && non_finite == 0.0) {
            failures.push(format!(
                "unstable: {restores} VE restores, {withheld} snapshots withheld, {non_finite} non-finite"
            ));
        }
        let scale = count(&c["session"]["position_scale"]);
        let rms = if ran.client_ok { device_op_rms(dir, kind, ran.offset_s, scale)? } else { f64::NAN };
        Ok(Measured {
            failures,
            clamped_fraction: count(&c["clamped_fraction"]),
            device_op_rms_m: rms,
            device_model_rms_m: count(&c["tracking_error_rms_m"]),
            max_closure_error: count(&core["max_closure_error"]),
            ve_restores: restores as u64,
        })
    }
}

type Lines = Arc<Mutex<Vec<(Instant, String)>>>;

/// Reads `stream` line by line on a thread, timestamping each line.
fn collect_lines(stream: impl Read + Send + 'static) -> (Lines, std::thread::JoinHandle<()>) {
    let lines: Lines = Arc::new(Mutex::new(Vec::new()));
    let sink = lines.clone();
    let handle = std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(|l| l.ok()) {
            if let Ok(mut v) = sink.lock() {
                v.push((Instant::now(), line));
            }
        }
    });
    (lines, handle)
}

/// Waits for `child` up to `limit`, killing it after.
fn wait_bounded(child: &mut Child, limit: Duration, what: &str) -> Result<std::process::ExitStatus> {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            bail!("{what} did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Reads lines from `out` until one holds `prefix`; that line from `prefix` on (a launcher may print
/// before it, as a test harness does).
fn line_starting(out: &mut impl BufRead, prefix: &str) -> Result<String> {
    let mut line = String::new();
    loop {
        line.clear();
        if out.read_line(&mut line)? == 0 {
            bail!("the server ended before printing {prefix:?}");
        }
        if let Some(at) = line.find(prefix) {
            return Ok(line[at..].trim_end().to_owned());
        }
    }
}

/// The JSON object a program printed last on its stdout (anything before it is skipped).
fn json_in(text: &str) -> Result<Value> {
    let start = text.find('{').context("no JSON object")?;
    Ok(serde_json::from_str(&text[start..])?)
}

/// Device-OP RMS in device space (m): the client's ticks with output against the VE's OP at the same
/// instant, over the scene's linear axes.
fn device_op_rms(dir: &Path, kind: SceneKind, offset_s: f64, position_scale: f64) -> Result<f64> {
    let mut samples = crate::demo::records::read_client(&dir.join("client.csv"), kind)?;
    let ve = crate::demo::records::read_ve(&dir.join("ve.csv"), kind)?;
    let user = ve.iter().find_map(|v| v.users.first().map(|u| u.0)).context("the user in the VE's record")?;
    crate::demo::records::merge(&mut samples, &ve, user, offset_s);
    let linear = kind.point_dim();
    let squares: Vec<f64> = samples
        .iter()
        .filter(|s| s.gain > 0.0)
        .filter_map(|s| {
            let op = s.ve_op.as_ref()?;
            Some((0..linear).map(|i| (s.device[i] - op[i]).powi(2)).sum::<f64>())
        })
        .collect();
    if squares.is_empty() {
        bail!("no tick with output to compare");
    }
    Ok((squares.iter().sum::<f64>() / squares.len() as f64).sqrt() * position_scale)
}
