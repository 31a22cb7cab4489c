//! Servers and clients in child processes, to kill them as a crash or a power cut would (SIGKILL: no close
//! frame, no goodbye), or to run the programs themselves on a command line.
//!
//! The child is this very test binary, re-executed to run only the test that spawned it (`--exact PATH`)
//! with the role in an environment variable: that test calls [`serve_if_child`] first, which runs the role
//! and exits the process. The child thus runs the same drivers as `kinloop-server` / `kinloop-client`
//! (`Server::start` with a certificate directory, `Client::start`), or the programs' very `main` on a
//! command line ([`Role::Program`]), built from the same sources as the test, on a fresh clone and under any
//! cargo invocation; the binaries of the server and client packages are not visible to this package's
//! tests (`CARGO_BIN_EXE_*` names only a package's own binaries) and a copy found in target/ could be stale.
//!
//! A child exits when its stdin closes, so it never outlives its parent, even one killed by its watchdog. It
//! runs in the directory it was given (where a program's default files, such as the server's certificate
//! directory, land) with its stdout and stderr in files there.

use std::io::Read;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use kinloop_client::driver::Client;
use kinloop_protocol::room_key::RoomKey;
use kinloop_server::Identity;
use serde::{Deserialize, Serialize};

use super::live;

const ROLE_VAR: &str = "KINLOOP_E2E_ROLE";
const READY_VAR: &str = "KINLOOP_E2E_READY";
/// A child never lives longer than this, whatever happens to its parent.
const LIFETIME: Duration = Duration::from_secs(90);

/// What a child process runs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum Role {
    /// `kinloop-server --scene paper-testbed(+ops) --listen LISTEN --cert-dir CERT_DIR`.
    Server { listen: SocketAddr, cert_dir: PathBuf },
    /// A server of a room: `kinloop-server --scene paper-testbed(+ops) --listen LISTEN --cert CERT --key KEY
    /// --room-key ROOM_KEY --record RECORD`.
    RoomServer { listen: SocketAddr, cert: PathBuf, key: PathBuf, room_key: PathBuf, record: PathBuf },
    /// `kinloop-client --server SERVER --fingerprint FP --op OP --user constant:WRENCH`.
    Client { server: SocketAddr, fingerprint: String, name: String, op: String, wrench: Vec<f64> },
    /// `PROGRAM ARGS...` through the program's own `main` (`kinloop_server::cli::main`,
    /// `kinloop_client::cli::main` or `kinloop::cli::load::main`): its argument parsing, its output and its exit code.
    Program { program: Program, args: Vec<String> },
}

/// The programs a [`Role::Program`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Program {
    /// `kinloop-server`.
    Server,
    /// `kinloop-client`.
    Client,
    /// `kinloop load`.
    Load,
}

impl Program {
    /// The binary's name (the command's, for `kinloop load`).
    pub fn name(self) -> &'static str {
        match self {
            Program::Server => "kinloop-server",
            Program::Client => "kinloop-client",
            Program::Load => "kinloop load",
        }
    }

    /// The program whose binary is called `name`, if it is one of these.
    pub fn named(name: &str) -> Option<Program> {
        [Program::Server, Program::Client].into_iter().find(|p| p.name() == name)
    }

    /// Runs the program's `main` on `args` (without the program's name) in this process; its exit code.
    fn run(self, args: &[String]) -> i32 {
        let command_line = std::iter::once(self.name().to_owned()).chain(args.iter().cloned());
        let code = match self {
            Program::Server => kinloop_server::cli::main(command_line),
            Program::Client => kinloop_client::cli::main(command_line),
            Program::Load => kinloop::cli::load::main(command_line),
        };
        if code == std::process::ExitCode::SUCCESS {
            0
        } else {
            1
        }
    }
}

/// What a child reports once it runs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Ready {
    /// Where the server listens (server), or the server it joined (client).
    pub addr: SocketAddr,
    /// The server's certificate fingerprint.
    pub fingerprint: String,
    /// The user id the server granted (client).
    pub user_id: u32,
}

/// In a child process: runs its role and exits. In the test process: returns at once.
pub fn serve_if_child() {
    let Ok(role) = std::env::var(ROLE_VAR) else { return };
    let ready = PathBuf::from(std::env::var(READY_VAR).unwrap_or_default());
    let code = match serde_json::from_str::<Role>(&role) {
        Ok(role) => match run(role, &ready) {
            Ok(code) => code,
            Err(e) => {
                eprintln!("e2e child failed: {e}");
                2
            }
        },
        Err(e) => {
            eprintln!("e2e child: bad role {role:?}: {e}");
            2
        }
    };
    std::process::exit(code);
}

/// Runs `role`; the process's exit code.
fn run(role: Role, ready: &Path) -> Result<i32, String> {
    if let Role::Program { program, args } = role {
        // The program sets up its logging as it does on its own. It runs until it ends by itself (or Ctrl-C);
        // a parent that stops it or goes away ends it at once.
        std::thread::spawn(|| {
            until_parent_lets_go();
            std::process::exit(3);
        });
        return Ok(program.run(&args));
    }
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new("info"))
        .with_writer(std::io::stderr)
        .try_init();
    match role {
        Role::Server { listen, cert_dir } => {
            let mut config = live::server_config();
            config.listen = listen;
            config.identity = Identity::CertDir(cert_dir);
            serve_until_released(config, ready)?;
        }
        Role::RoomServer { listen, cert, key, room_key, record } => {
            let mut config = live::server_config();
            config.listen = listen;
            config.identity = Identity::Files { cert, key };
            config.room_key = Some(RoomKey::load(&room_key).map_err(|e| e.to_string())?);
            config.record = Some(record);
            serve_until_released(config, ready)?;
        }
        Role::Client { server, fingerprint, name, op, wrench } => {
            let client = Client::start(live::client_config(server, &fingerprint, &name, &op, &wrench))
                .map_err(|e| e.to_string())?;
            announce(ready, &Ready { addr: server, fingerprint, user_id: client.welcome().user_id })?;
            until_parent_lets_go();
            client.shutdown();
        }
        Role::Program { .. } => {}
    }
    Ok(0)
}

/// Starts a server with `config`, says where it listens, and serves until the parent lets go.
fn serve_until_released(config: kinloop_server::ServerConfig, ready: &Path) -> Result<(), String> {
    let rt = live::runtime();
    let server = {
        let _inside = rt.enter();
        kinloop_server::Server::start(config).map_err(|e| e.to_string())?
    };
    let fingerprint = server.fingerprint().to_owned();
    announce(ready, &Ready { addr: server.local_addr(), fingerprint, user_id: 0 })?;
    until_parent_lets_go();
    live::stop_server(&rt, server);
    Ok(())
}

/// Writes the ready file whole (temporary name, then rename), so the parent never reads half of it.
fn announce(path: &Path, ready: &Ready) -> Result<(), String> {
    let text = serde_json::to_string(ready).map_err(|e| e.to_string())?;
    let partial = path.with_extension("partial");
    std::fs::write(&partial, text).map_err(|e| format!("{}: {e}", partial.display()))?;
    std::fs::rename(&partial, path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Blocks until stdin closes (the parent stopped us or is gone) or the lifetime runs out.
fn until_parent_lets_go() {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = std::io::stdin().read_to_end(&mut Vec::new());
        let _ = tx.send(());
    });
    let _ = rx.recv_timeout(LIFETIME);
}

/// A child process running a [`Role`]; killed when dropped.
pub struct ChildProcess {
    child: Child,
    stdin: Option<ChildStdin>,
    log: PathBuf,
    out: PathBuf,
    ready: PathBuf,
    what: String,
}

/// The path of this binary's test named `name` as `--exact` wants it (`module::name` in a binary whose
/// tests are modules): the binary lists its own tests once, and exactly one must end in `name`.
pub fn test_path(name: &str) -> String {
    static LISTED: OnceLock<Vec<String>> = OnceLock::new();
    let listed = LISTED.get_or_init(|| {
        let exe = std::env::current_exe().expect("the test binary's path");
        let out = Command::new(exe).args(["--list"]).output().expect("the test binary lists its tests");
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| l.strip_suffix(": test"))
            .map(String::from)
            .collect()
    });
    let suffix = format!("::{name}");
    let found: Vec<&String> = listed.iter().filter(|path| *path == name || path.ends_with(&suffix)).collect();
    match found.as_slice() {
        [one] => one.to_string(),
        _ => panic!("{} tests of this binary are named `{name}`: {found:?}", found.len()),
    }
}

impl ChildProcess {
    /// Re-executes this test binary to run `role` inside the test named `test`, in `dir`; its log (stderr),
    /// stdout and ready file go to `dir` under `tag`.
    pub fn spawn(test: &str, role: &Role, dir: &Path, tag: &str) -> Self {
        Self::spawn_with_env(test, role, dir, tag, &[])
    }

    /// [`ChildProcess::spawn`] with these environment variables set in the child.
    pub fn spawn_with_env(test: &str, role: &Role, dir: &Path, tag: &str, env: &[(&str, String)]) -> Self {
        let exe = std::env::current_exe().expect("the test binary's path");
        Self::spawn_command(Command::new(exe), test, role, dir, tag, env)
    }

    /// [`ChildProcess::spawn`] inside the network namespace `netns` (`ip netns exec`; needs root).
    pub fn spawn_in_netns(test: &str, role: &Role, dir: &Path, tag: &str, netns: &str) -> Self {
        let exe = std::env::current_exe().expect("the test binary's path");
        let mut command = Command::new("ip");
        command.args(["netns", "exec", netns]).arg(exe);
        Self::spawn_command(command, test, role, dir, tag, &[])
    }

    fn spawn_command(
        mut command: Command,
        test: &str,
        role: &Role,
        dir: &Path,
        tag: &str,
        env: &[(&str, String)],
    ) -> Self {
        let log = dir.join(format!("{tag}.log"));
        let out = dir.join(format!("{tag}.out"));
        let ready = dir.join(format!("{tag}.ready"));
        let _ = std::fs::remove_file(&ready);
        let child = command
            .args([test_path(test).as_str(), "--exact", "--nocapture", "--test-threads=1"])
            .current_dir(dir)
            .env(ROLE_VAR, serde_json::to_string(role).expect("role as JSON"))
            .env(READY_VAR, &ready)
            .envs(env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::piped())
            .stdout(std::fs::File::create(&out).expect("child stdout file"))
            .stderr(std::fs::File::create(&log).expect("child log file"))
            .spawn()
            .expect("the test binary re-executes");
        let mut process = ChildProcess { child, stdin: None, log, out, ready, what: format!("{tag} ({role:?})") };
        process.stdin = process.child.stdin.take();
        process
    }

    /// Waits for the child's ready file; panics with its log when it exits or takes longer than `limit`.
    pub fn ready(&mut self, limit: Duration) -> Ready {
        let start = Instant::now();
        loop {
            if let Ok(text) = std::fs::read_to_string(&self.ready) {
                return serde_json::from_str(&text).expect("ready file");
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                panic!("child {} exited ({status}) before it was ready:\n{}", self.what, self.log_tail());
            }
            assert!(start.elapsed() < limit, "child {} not ready within {limit:?}:\n{}", self.what, self.log_tail());
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The last lines of the child's log.
    pub fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(30)..].join("\n")
    }

    /// The whole log.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Everything the child wrote to stdout so far (a test binary's child starts with the harness's
    /// `running 1 test` line).
    pub fn stdout(&self) -> String {
        std::fs::read_to_string(&self.out).unwrap_or_default()
    }

    /// Waits until `found` finds what it looks for in the child's stdout; panics naming `what`, with the
    /// child's output, when the child exits first or `limit` passes.
    pub fn wait_for_stdout<T>(&mut self, what: &str, limit: Duration, found: impl Fn(&str) -> Option<T>) -> T {
        let start = Instant::now();
        loop {
            if let Some(found) = found(&self.stdout()) {
                return found;
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                panic!("{what}: child {} exited ({status}) first:\n{}\n{}", self.what, self.stdout(), self.log_tail());
            }
            assert!(start.elapsed() < limit, "{what}: not within {limit:?}:\n{}\n{}", self.stdout(), self.log_tail());
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits for the child to exit by itself; its status. Panics with its output after `limit` (and kills it).
    pub fn exit_status(&mut self, limit: Duration) -> std::process::ExitStatus {
        let start = Instant::now();
        loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status;
            }
            if start.elapsed() >= limit {
                self.kill();
                panic!("child {} still running after {limit:?}:\n{}\n{}", self.what, self.stdout(), self.log_tail());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// SIGINT, what Ctrl-C in its terminal sends.
    pub fn interrupt(&self) {
        self.signal("INT");
    }

    /// SIGTERM, what `kill PID`, systemd and container runtimes send.
    pub fn terminate(&self) {
        self.signal("TERM");
    }

    fn signal(&self, name: &str) {
        let pid = self.child.id().to_string();
        let sent = Command::new("kill").args([&format!("-{name}"), &pid]).status().expect("kill runs");
        assert!(sent.success(), "kill -{name} {pid} failed");
    }

    /// SIGKILL: the process vanishes without a word. Returns when it is gone.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Closes stdin (a clean stop) and waits up to `limit` for the child to exit; kills it after that.
    /// True when it exited by itself with success.
    pub fn stop(&mut self, limit: Duration) -> bool {
        drop(self.stdin.take());
        let start = Instant::now();
        while start.elapsed() < limit {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status.success();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.kill();
        false
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.kill();
        }
    }
}

/// `kinloop-server --scene SCENE` on a free loopback port, a child in `dir`: the child, its address and its
/// certificate's fingerprint once it has printed them.
pub fn spawn_scene_server(test: &str, scene: &str, dir: &Path) -> (ChildProcess, SocketAddr, String) {
    let args = ["--scene", scene, "--listen", "127.0.0.1:0", "--cert-dir", "cert"].map(String::from).to_vec();
    let mut server = ChildProcess::spawn(test, &Role::Program { program: Program::Server, args }, dir, "server");
    let (addr, fingerprint) =
        server.wait_for_stdout("the server prints its address", Duration::from_secs(30), listening);
    (server, addr, fingerprint)
}

/// `defaults` with each of `overrides` in place of the variable of its name (or added after them).
pub fn with_overrides<'a>(
    mut defaults: Vec<(&'a str, String)>,
    overrides: &[(&'a str, String)],
) -> Vec<(&'a str, String)> {
    for (name, value) in overrides {
        defaults.retain(|(n, _)| n != name);
        defaults.push((name, value.clone()));
    }
    defaults
}

/// The address and fingerprint a `kinloop-server` prints, once it has printed both (the test harness's
/// `test NAME ... ` may precede the first on its line).
pub fn listening(stdout: &str) -> Option<(SocketAddr, String)> {
    let after = |label: &str| stdout.lines().find_map(|l| l.split_once(label)).map(|(_, value)| value.trim());
    let addr = after("kinloop-server listening on ")?.parse().ok()?;
    Some((addr, after("certificate fingerprint (sha-256): ")?.to_owned()))
}

/// The JSON object a program printed with `--json` (the test harness's lines around it have no braces).
pub fn json_object(stdout: &str) -> serde_json::Value {
    match (stdout.find('{'), stdout.rfind('}')) {
        (Some(start), Some(end)) if start < end => serde_json::from_str(&stdout[start..=end]).expect("one JSON object"),
        _ => panic!("no JSON object in:\n{stdout}"),
    }
}

/// Starts the programs of test `name` (this test binary re-executed as each, see [`Role::Program`]) for the
/// experiments that run `kinloop-server` and `kinloop-client` themselves (`kinloop::experiments::programs`).
pub fn launch_as_programs_of(name: &'static str) -> Box<kinloop::experiments::programs::Launch> {
    Box::new(move |program: &str, args: &[String]| {
        let program = Program::named(program).unwrap_or_else(|| panic!("{program} is not a kinloop program"));
        let role = Role::Program { program, args: args.to_vec() };
        let mut command = Command::new(std::env::current_exe().expect("the test binary's path"));
        command
            .args([test_path(name).as_str(), "--exact", "--nocapture", "--test-threads=1"])
            .env("KINLOOP_E2E_ROLE", serde_json::to_string(&role).expect("a role"))
            // The child lives while its stdin is open: as long as the runner holds it.
            .stdin(std::process::Stdio::piped());
        command
    })
}
