//! Shared pieces of the view's tests: headless Chromium through chromedriver (WebDriver, fantoccini), the
//! page's `#status` state, and a QUIC client that pushes the linkage and keeps the VE's OP per step from
//! its snapshots (the independent channel the page is checked against).
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder, Locator};
use kinloop_linkage::model::builtin::PAPER_WRENCH;
use kinloop_protocol::quic::{
    client_endpoint, connect, send_control, DatagramReceiver, DatagramSender, EndpointOptions, Trust,
};
use kinloop_protocol::{
    Control, Datagram, DeviceCaps, Hello, Join, LocalModelForm, Role, SceneKind, SessionShape, Uplink, PROTOCOL_VERSION,
};
use kinloop_server::ServerHandle;
use serde_json::Value;

/// The flags the brief found necessary on a closed network (without them Chromium stalls on start).
const CHROMIUM_FLAGS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--window-size=1200,800",
];

/// One browser at a time: the machine has two cores, and a VE thread to keep on time. (A tokio mutex: each
/// test holds it across its awaits, on its own runtime.)
static ONE_BROWSER: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Holds the browser lock for a test.
pub async fn exclusive() -> tokio::sync::MutexGuard<'static, ()> {
    ONE_BROWSER.lock().await
}

fn find(env: &str, names: &[&str]) -> Option<PathBuf> {
    if let Some(path) = std::env::var_os(env) {
        return Some(PathBuf::from(path));
    }
    let path = std::env::var_os("PATH")?;
    names.iter().flat_map(|n| std::env::split_paths(&path).map(move |dir| dir.join(n))).find(|p| p.is_file())
}

/// Chromium and chromedriver, or a panic saying how to get them (the view's tests never skip).
pub fn browser_paths() -> (PathBuf, PathBuf) {
    let chromium = find("KINLOOP_CHROMIUM", &["chromium", "chromium-browser", "google-chrome"]);
    let driver = find("KINLOOP_CHROMEDRIVER", &["chromedriver"]);
    match (chromium, driver) {
        (Some(c), Some(d)) => (c, d),
        (c, d) => panic!(
            "the view's tests need headless Chromium and chromedriver (found browser: {c:?}, driver: {d:?}). \
             Install them with `apt-get install -y chromium chromium-driver` (.ci/run does), or point \
             KINLOOP_CHROMIUM and KINLOOP_CHROMEDRIVER at them."
        ),
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("a free port")
}

/// A headless Chromium driven through chromedriver; both end with it.
pub struct Browser {
    pub client: Client,
    driver: Child,
    _profile: tempfile::TempDir,
}

impl Browser {
    pub async fn start() -> Browser {
        let (chromium, chromedriver) = browser_paths();
        let port = free_port();
        let driver = Command::new(&chromedriver)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", chromedriver.display()));
        let ready_by = Instant::now() + Duration::from_secs(15);
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(Instant::now() < ready_by, "chromedriver did not listen on port {port} within 15 s");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let profile = tempfile::tempdir().expect("a profile directory");
        let mut args: Vec<String> = CHROMIUM_FLAGS.iter().map(|s| s.to_string()).collect();
        args.push(format!("--user-data-dir={}", profile.path().display()));
        let mut caps = serde_json::Map::new();
        caps.insert(
            "goog:chromeOptions".into(),
            serde_json::json!({ "binary": chromium.display().to_string(), "args": args }),
        );
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        let client = ClientBuilder::new(connector)
            .capabilities(caps)
            .connect(&format!("http://127.0.0.1:{port}"))
            .await
            .unwrap_or_else(|e| panic!("chromedriver at port {port} did not start {}: {e}", chromium.display()));
        Browser { client, driver, _profile: profile }
    }

    /// The page's state (`#status`'s `data-state`).
    pub async fn status(&self) -> Value {
        let el = self.client.find(Locator::Id("status")).await.expect("#status on the page");
        let text = el.attr("data-state").await.expect("data-state").unwrap_or_default();
        serde_json::from_str(&text).unwrap_or(Value::Null)
    }

    /// Polls the status until `ready` holds; panics after `patience` with the last status.
    pub async fn wait_for(&self, what: &str, patience: Duration, ready: impl Fn(&Value) -> bool) -> Value {
        let until = Instant::now() + patience;
        loop {
            let status = self.status().await;
            if ready(&status) {
                return status;
            }
            assert!(Instant::now() < until, "{what}: not within {patience:?}; page status {status}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Saves a screenshot as `dir/name`.
    pub async fn screenshot(&self, dir: &Path, name: &str) -> PathBuf {
        let png = self.client.screenshot().await.expect("a screenshot");
        std::fs::create_dir_all(dir).expect("the screenshot directory");
        let path = dir.join(name);
        std::fs::write(&path, png).expect("the screenshot written");
        path
    }

    pub async fn close(mut self) {
        let _ = self.client.clone().close().await;
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.driver.kill();
    }
}

/// A number at a JSON path, e.g. `num(&s, &["ops", "link2", "0"])`.
pub fn num(v: &Value, path: &[&str]) -> Option<f64> {
    let mut at = v;
    for key in path {
        at = match key.parse::<usize>() {
            Ok(i) => at.get(i)?,
            Err(_) => at.get(key)?,
        };
    }
    at.as_f64()
}

/// A QUIC client on `link2` that follows the VE and pushes with the paper's hand wrench while `push` is
/// set, keeping the VE's OP position for every step it got a snapshot of.
pub struct Pusher {
    pub push: Arc<AtomicBool>,
    pub stop: Arc<AtomicBool>,
    pub ops_by_step: Arc<Mutex<BTreeMap<u64, [f64; 2]>>>,
    task: tokio::task::JoinHandle<()>,
}

impl Pusher {
    pub async fn start(server: &ServerHandle, token: &str, device: DeviceCaps) -> Pusher {
        let options =
            EndpointOptions { client_bind: SocketAddr::from(([127, 0, 0, 1], 0)), ..EndpointOptions::default() };
        let endpoint = client_endpoint(&Trust::Fingerprint(server.fingerprint().to_string()), &options).unwrap();
        let hello = Hello {
            version: PROTOCOL_VERSION,
            token: token.into(),
            client_name: "test pusher".into(),
            role: Role::Manipulator,
            room: String::new(),
        };
        let join = Join { op: "link2".into(), device, form: LocalModelForm::OpSpace, mapping: Default::default() };
        let mut session =
            connect(&endpoint, server.local_addr(), "localhost", &hello, |_| Ok(join)).await.expect("joined");
        let shape = SessionShape { kind: SceneKind::Planar, n: 4, nq: 4, m: 2 };
        let push = Arc::new(AtomicBool::new(true));
        let stop = Arc::new(AtomicBool::new(false));
        let ops_by_step = Arc::new(Mutex::new(BTreeMap::new()));
        let task = {
            let (push, stop, ops) = (push.clone(), stop.clone(), ops_by_step.clone());
            tokio::spawn(async move {
                let sender = DatagramSender::new(session.connection.clone());
                let mut receiver = DatagramReceiver::new(session.connection.clone(), shape);
                let mut seq = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    let Ok(Ok(Datagram::Snapshot(s))) =
                        tokio::time::timeout(Duration::from_millis(200), receiver.recv()).await
                    else {
                        continue;
                    };
                    ops.lock().unwrap().insert(s.ve_step, [s.op_pose[0], s.op_pose[1]]);
                    seq += 1;
                    let hand = if push.load(Ordering::Relaxed) { PAPER_WRENCH.to_vec() } else { vec![0.0; 3] };
                    let uplink = Uplink {
                        seq,
                        client_time_s: seq as f64 * 1e-3,
                        last_snapshot_seq: s.seq,
                        last_snapshot_age_s: 0.0,
                        hand_wrench: hand,
                        device_pose: s.op_pose.clone(),
                        device_twist: s.op_twist.clone(),
                        model_pose: s.op_pose.clone(),
                        model_twist: s.op_twist.clone(),
                        flags: 0,
                        energy: kinloop_protocol::PortEnergy::zero(s.op_twist.len()),
                    };
                    let _ = sender.send(&Datagram::Uplink(uplink));
                }
                let _ = send_control(&mut session.send, &Control::Leave { reason: "test done".into() }).await;
                session.connection.close(0u32.into(), b"bye");
            })
        };
        Pusher { push, stop, ops_by_step, task }
    }

    /// The VE's OP at `step` from a snapshot of that step, or of the nearest step within `slack`.
    pub fn op_at(&self, step: u64, slack: u64) -> Option<(u64, [f64; 2])> {
        let ops = self.ops_by_step.lock().unwrap();
        let lo = step.saturating_sub(slack);
        ops.range(lo..=step + slack).min_by_key(|(s, _)| s.abs_diff(step)).map(|(s, p)| (*s, *p))
    }

    pub async fn leave(self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = tokio::time::timeout(Duration::from_secs(3), self.task).await;
    }
}
