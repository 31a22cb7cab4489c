//! Servers and clients in child processes, to kill them as a crash or a power cut would (SIGKILL: no close
//! frame, no goodbye).
//!
//! The child is this very test binary, re-executed to run only the test that spawned it (`--exact NAME`)
//! with the role in an environment variable: that test calls [`serve_if_child`] first, which runs the role
//! and exits the process. The child thus runs the same drivers as `kinloop-server` / `kinloop-client`
//! (`Server::start` with a certificate directory, `Client::start`), built from the same sources as the
//! test, on a fresh clone and under any cargo invocation; the binaries of the server and client packages
//! are not visible to this package's tests (`CARGO_BIN_EXE_*` names only a package's own binaries) and a
//! copy found in target/ could be stale.
//!
//! A child exits when its stdin closes, so it never outlives its parent, even one killed by its watchdog.

use std::io::Read;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use kinloop_client::driver::Client;
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
    /// `kinloop-client --server SERVER --fingerprint FP --op OP --user constant:WRENCH`.
    Client { server: SocketAddr, fingerprint: String, name: String, op: String, wrench: Vec<f64> },
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
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new("info"))
        .with_writer(std::io::stderr)
        .try_init();
    let ready = PathBuf::from(std::env::var(READY_VAR).unwrap_or_default());
    let code = match serde_json::from_str::<Role>(&role) {
        Ok(role) => match run(role, &ready) {
            Ok(()) => 0,
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

fn run(role: Role, ready: &Path) -> Result<(), String> {
    match role {
        Role::Server { listen, cert_dir } => {
            let rt = live::runtime();
            let mut config = live::server_config();
            config.listen = listen;
            config.identity = Identity::CertDir(cert_dir);
            let server = {
                let _inside = rt.enter();
                kinloop_server::Server::start(config).map_err(|e| e.to_string())?
            };
            let fingerprint = server.fingerprint().to_owned();
            announce(ready, &Ready { addr: server.local_addr(), fingerprint, user_id: 0 })?;
            until_parent_lets_go();
            live::stop_server(&rt, server);
        }
        Role::Client { server, fingerprint, name, op, wrench } => {
            let client = Client::start(live::client_config(server, &fingerprint, &name, &op, &wrench))
                .map_err(|e| e.to_string())?;
            announce(ready, &Ready { addr: server, fingerprint, user_id: client.welcome().user_id })?;
            until_parent_lets_go();
            client.shutdown();
        }
    }
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
    ready: PathBuf,
    what: String,
}

impl ChildProcess {
    /// Re-executes this test binary to run `role` inside the test named `test`; its log and ready file go
    /// to `dir` under `tag`.
    pub fn spawn(test: &str, role: &Role, dir: &Path, tag: &str) -> Self {
        let log = dir.join(format!("{tag}.log"));
        let ready = dir.join(format!("{tag}.ready"));
        let _ = std::fs::remove_file(&ready);
        let exe = std::env::current_exe().expect("the test binary's path");
        let child = Command::new(exe)
            .args([test, "--exact", "--nocapture", "--test-threads=1"])
            .env(ROLE_VAR, serde_json::to_string(role).expect("role as JSON"))
            .env(READY_VAR, &ready)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("child log file"))
            .spawn()
            .expect("the test binary re-executes");
        let mut process = ChildProcess { child, stdin: None, log, ready, what: format!("{tag} ({role:?})") };
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
