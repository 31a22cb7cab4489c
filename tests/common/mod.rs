//! Shared pieces of the end-to-end tests: one real-time session at a time with a hard time limit, servers
//! and clients in-process over loopback QUIC, the same drivers in child processes (to kill them), and the
//! CSV recordings both sides write; and what cargo knows of the workspace.
#![allow(dead_code)] // each e2e binary uses its own part of this module

pub mod checks;
pub mod child;
pub mod live;
pub mod records;
pub mod resume;
pub mod workspace;

use std::sync::mpsc;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// The machine has two cores and each session spins a VE loop and a haptic loop per client: sessions in
/// one test binary run one after another, as cargo runs one test binary after another.
static SERIAL: Mutex<()> = Mutex::new(());

/// Held for the whole test: the serial lock and a watchdog that ends the process when the test overruns
/// its hard limit (a hung driver must fail the run, not stall CI). Child processes die with the process:
/// they exit when their stdin closes.
pub struct Bounded {
    _serial: MutexGuard<'static, ()>,
    _disarm: mpsc::Sender<()>,
}

/// The serial lock alone, for a test or a part of one that runs real time or a heavy loop without a
/// hard limit of its own.
pub fn serial() -> MutexGuard<'static, ()> {
    // A test that failed while holding the lock poisons it; the next one is still welcome.
    SERIAL.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Starts a test that must finish within `limit` (counted once it holds the serial lock).
pub fn bounded(name: &'static str, limit: Duration) -> Bounded {
    let serial = serial();
    let (disarm, armed) = mpsc::channel::<()>();
    std::thread::spawn(move || {
        if let Err(mpsc::RecvTimeoutError::Timeout) = armed.recv_timeout(limit) {
            eprintln!("e2e: `{name}` exceeded its hard limit of {limit:?}; ending the test process");
            std::process::exit(101);
        }
    });
    Bounded { _serial: serial, _disarm: disarm }
}

/// Largest share of an idle 1 kHz loop's deadlines missed (by more than 500 µs) in one second that counts as
/// a calm host. In calm minutes the idle loop has read 0.5-1.4 %; in spells where it read 9-27 %, eight demo
/// runs in a row missed 9-16 % of their VE deadlines, and a junk flood's VE 18 %.
pub const CALM_MISS_SHARE: f64 = 0.02;

/// Times an idle 1 kHz loop (as `kinloop timer-floor` does) for a second at a time until one second misses at
/// most [`CALM_MISS_SHARE`] of its deadlines or `budget` is spent; returns the shares seen. A real-time test
/// starts in a calm second: this VM's host stalls it for minutes at a time, and a session run in such a spell
/// measures the host. The probe spins under SCHED_FIFO: call it while holding the test's serial lock.
pub fn wait_for_calm(budget: &mut Duration) -> Vec<f64> {
    let mut seen = Vec::new();
    loop {
        let started = Instant::now();
        let (lateness, _) = kinloop_client::driver::rt_loop::timer_floor(1000.0, Duration::from_secs(1), true);
        let share = lateness.misses as f64 / lateness.ticks.max(1) as f64;
        seen.push(share);
        *budget = budget.saturating_sub(started.elapsed());
        if share <= CALM_MISS_SHARE || budget.is_zero() {
            return seen;
        }
    }
}

/// [`wait_for_calm`] before a real-time test (or a part of one) named `what`, saying in the test's output how
/// long it waited and what the idle loop read meanwhile.
pub fn start_when_calm(what: &str, budget: &mut Duration) {
    let probes = wait_for_calm(budget);
    if probes.len() > 1 {
        println!("{what}: waited {} s for a calm second (idle loop missed: {probes:.3?})", probes.len() - 1);
    }
}

/// Polls `done` every 10 ms until it holds; panics naming `what` after `limit`. Returns the time it took.
pub fn wait_until(what: &str, limit: Duration, mut done: impl FnMut() -> bool) -> Duration {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
    start.elapsed()
}

/// A temporary directory under cargo's target/tmp (so even a hard-killed run leaves nothing in /tmp),
/// removed when dropped.
pub fn temp_dir() -> tempfile::TempDir {
    let base = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    std::fs::create_dir_all(base).expect("target tmp dir");
    tempfile::Builder::new().prefix("e2e-").tempdir_in(base).expect("temp dir")
}

/// The fake DHD library (`fakes/fake-dhd`) cargo built beside this test's binary: a dev-dependency of
/// kinloop, so always there under `cargo test`; panics (never skips) when it is not.
pub fn fake_dhd_library() -> std::path::PathBuf {
    fake_library("kinloop_fake_dhd")
}

/// The fake OpenHaptics library (`fakes/fake-hd`), found as [`fake_dhd_library`] finds its own.
pub fn fake_hd_library() -> std::path::PathBuf {
    fake_library("kinloop_fake_hd")
}

/// The cdylib `crate_name` beside this test's binary or its parent folder; panics when it is not there.
fn fake_library(crate_name: &str) -> std::path::PathBuf {
    let name = format!("{}{crate_name}{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX);
    let exe = std::env::current_exe().expect("the test binary's path");
    let deps = exe.parent().expect("the test binary's folder");
    let candidates = [deps.join(&name), deps.parent().map(|p| p.join(&name)).unwrap_or_default()];
    candidates.iter().find(|p| p.is_file()).cloned().unwrap_or_else(|| {
        panic!("the fake library {name} is not in {candidates:?}: cargo builds it as a dev-dependency of kinloop")
    })
}
