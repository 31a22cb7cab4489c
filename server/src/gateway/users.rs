//! The user registry: who the sessions have admitted, with their connection and network-side counters, for
//! the stats report, the log and the view's panel.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use kinloop_protocol::quic::Connection;
use kinloop_protocol::Role;

/// Network-side counters of one user, shared with `stats()`.
#[derive(Debug, Default)]
pub struct UserCounters {
    pub uplinks_received: AtomicU64,
    pub uplinks_lost: AtomicU64,
    pub uplinks_undecodable: AtomicU64,
    pub uplinks_dropped: AtomicU64,
    pub snapshots_sent: AtomicU64,
    pub snapshot_bytes: AtomicU64,
    pub snapshots_oversize: AtomicU64,
    pub uplinks_clamped: AtomicU64,
    pub connected: AtomicBool,
    /// Why the session ended, once it has: "connection lost" when the client closed or vanished, "client
    /// left" when it said so, "room closed" when the server told it to move (`session.rs`).
    pub ended: std::sync::OnceLock<&'static str>,
    /// The newest uplink's device and model poses, for the view.
    pub poses: PoseTap,
}

/// The device and local-model poses of a user's newest uplink, as `f64` bits in atomics: the receive task
/// writes them per uplink without a lock, the view's hub reads them a few dozen times per second (a read
/// that straddles a write mixes two neighbouring uplinks, which a picture cannot show).
#[derive(Debug, Default)]
pub struct PoseTap {
    len: AtomicU64,
    device: [AtomicU64; 7],
    model: [AtomicU64; 7],
}

impl PoseTap {
    /// Stores the newest uplink's poses (ignored when their lengths differ or exceed a pose's).
    pub fn store(&self, device: &[f64], model: &[f64]) {
        if device.len() != model.len() || device.len() > 7 {
            return;
        }
        for (slot, v) in self.device.iter().zip(device).chain(self.model.iter().zip(model)) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
        self.len.store(device.len() as u64, Ordering::Release);
    }

    /// `(device pose, model pose)` of the newest uplink, if any came.
    pub fn load(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let len = self.len.load(Ordering::Acquire) as usize;
        let read =
            |slots: &[AtomicU64; 7]| slots[..len].iter().map(|s| f64::from_bits(s.load(Ordering::Relaxed))).collect();
        (len > 0).then(|| (read(&self.device), read(&self.model)))
    }
}

/// A user as the stats see it.
pub struct UserEntry {
    pub user_id: u32,
    pub name: String,
    pub role: Role,
    pub device: String,
    pub op: String,
    pub connection: Connection,
    pub counters: Arc<UserCounters>,
}

/// Every user admitted since start, in order of admission.
#[derive(Default)]
pub struct UserRegistry {
    users: Mutex<Vec<UserEntry>>,
}

impl UserRegistry {
    /// Adds a user whose session has started.
    pub fn register(&self, entry: UserEntry) {
        if let Ok(mut users) = self.users.lock() {
            users.push(entry);
        }
    }

    /// The client name of `user`, or an empty name for one the registry does not know.
    pub fn name_of(&self, user: u32) -> String {
        let users = self.users.lock();
        users.ok().and_then(|u| u.iter().find(|e| e.user_id == user).map(|e| e.name.clone())).unwrap_or_default()
    }

    /// Calls `visit` with every user since start (connected or not), in order of admission.
    pub fn for_each(&self, mut visit: impl FnMut(&UserEntry)) {
        if let Ok(users) = self.users.lock() {
            users.iter().for_each(&mut visit);
        }
    }

    /// How many users' sessions are still open.
    pub fn connected(&self) -> usize {
        let mut count = 0;
        self.for_each(|e| count += usize::from(e.counters.connected.load(Ordering::Relaxed)));
        count
    }
}
