//! The server's side of a room that survives its server (see `docs/resume.md`): the VE thread copies its
//! state here a few dozen times a second; each session signs the newest with the room's key and sends it to
//! its client; an offered state is checked here (signature, scene, age) before the VE checks its fit.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, SystemTime};

use kinloop_linkage::math::space::Space;
use kinloop_protocol::room_key::{unix_ms, RoomKey};
use kinloop_protocol::{ResumeRefusal, RoomState};

use crate::core::VeCore;

/// How often the VE thread publishes its state and sessions send it: the newest a client holds is at most
/// this old when its server dies.
pub const ROOM_STATE_PERIOD: Duration = Duration::from_millis(20);

/// The VE's state as last published (buffers sized once, so publishing does not allocate).
#[derive(Debug, Default)]
pub struct RoomSample {
    step: u64,
    taken_unix_ms: u64,
    q: Vec<f64>,
    qd: Vec<f64>,
}

/// What the network side of a room shares: its key, its scene's hash, the newest state and the counts.
#[derive(Debug)]
pub struct Room {
    key: RoomKey,
    scene_hash: u64,
    latest: Mutex<RoomSample>,
    /// Offers refused before the VE saw them (signature, scene, age).
    pub refused_unseen: AtomicU64,
}

impl Room {
    /// A room of `key` for the scene of hash `scene_hash`, whose VE has `n` coordinates and `nv` velocities.
    pub fn new(key: RoomKey, scene_hash: u64, n: usize, nv: usize) -> Self {
        let sample = RoomSample { step: 0, taken_unix_ms: 0, q: vec![0.0; n], qd: vec![0.0; nv] };
        Room { key, scene_hash, latest: Mutex::new(sample), refused_unseen: AtomicU64::new(0) }
    }

    /// From the VE thread: copies the core's state, unless a session is reading it (then the next period's
    /// copy serves). Never blocks, never allocates.
    pub fn publish<S: Space>(&self, core: &VeCore<S>) {
        let Ok(mut sample) = self.latest.try_lock() else { return };
        let state = core.state();
        sample.step = state.step;
        sample.taken_unix_ms = unix_ms(SystemTime::now());
        sample.q.copy_from_slice(state.q.as_slice());
        sample.qd.copy_from_slice(state.qd.as_slice());
    }

    /// The newest published state, signed; `None` before the VE published any.
    pub fn signed_latest(&self) -> Option<RoomState> {
        let mut state = {
            let sample = self.latest.lock().ok()?;
            if sample.taken_unix_ms == 0 {
                return None;
            }
            RoomState {
                scene_hash: self.scene_hash,
                taken_unix_ms: sample.taken_unix_ms,
                ve_step: sample.step,
                q: sample.q.clone(),
                qd: sample.qd.clone(),
                tag: Vec::new(),
            }
        };
        self.key.sign(&mut state);
        Some(state)
    }

    /// Checks an offer's signature, scene and age; a refusal is counted.
    pub fn check(&self, offer: &RoomState) -> Result<(), ResumeRefusal> {
        let checked = self.key.check(offer, self.scene_hash, SystemTime::now());
        if checked.is_err() {
            self.refused_unseen.fetch_add(1, Ordering::Relaxed);
        }
        checked
    }
}
