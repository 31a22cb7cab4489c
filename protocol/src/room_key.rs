//! The room's key: the secret the servers of one room share (`--room-key FILE`), with which each signs the
//! state it sends its clients (HMAC-SHA256) and checks a state a client offers back, so a client can carry a
//! linkage's state from a dead server to its replacement but cannot move the linkage by lying about it.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use ring::{digest, hmac};

use crate::messages::{ResumeRefusal, RoomState};

/// Fewest bytes a room key holds (HMAC-SHA256's own output length).
pub const MIN_KEY_BYTES: usize = 32;

/// Oldest state a server resumes from: a client reconnects within seconds, and an older state would move a
/// linkage that others may have moved since (a replay).
pub const MAX_RESUME_AGE: Duration = Duration::from_secs(30);

/// The secret of one room.
#[derive(Clone, Debug)]
pub struct RoomKey {
    key: hmac::Key,
}

/// Why a room key could not be used.
#[derive(Debug, thiserror::Error)]
pub enum RoomKeyError {
    /// The key file could not be read.
    #[error("room key file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The key is too short to be a secret.
    #[error("room key {what}: {bytes} bytes, at least {MIN_KEY_BYTES} needed (e.g. `head -c 32 /dev/urandom > FILE`)")]
    TooShort {
        /// Which key (a file's path).
        what: String,
        /// How long it is.
        bytes: usize,
    },
}

impl RoomKey {
    /// A key of these bytes (at least [`MIN_KEY_BYTES`]).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RoomKeyError> {
        if bytes.len() < MIN_KEY_BYTES {
            return Err(RoomKeyError::TooShort { what: "given".into(), bytes: bytes.len() });
        }
        Ok(RoomKey { key: hmac::Key::new(hmac::HMAC_SHA256, bytes) })
    }

    /// The key in `path`: its whole content, bytes as they are.
    pub fn load(path: &Path) -> Result<Self, RoomKeyError> {
        let bytes = std::fs::read(path).map_err(|source| RoomKeyError::Io { path: path.into(), source })?;
        RoomKey::from_bytes(&bytes)
            .map_err(|_| RoomKeyError::TooShort { what: path.display().to_string(), bytes: bytes.len() })
    }

    /// Signs `state` in place (its tag).
    pub fn sign(&self, state: &mut RoomState) {
        state.tag = hmac::sign(&self.key, &signed_bytes(state)).as_ref().to_vec();
    }

    /// Checks an offered state's signature, scene and age (at wall-clock time `now`); its fit to the
    /// linkage is the VE's to check.
    pub fn check(&self, state: &RoomState, scene_hash: u64, now: SystemTime) -> Result<(), ResumeRefusal> {
        if state.tag.is_empty() {
            return Err(ResumeRefusal::Unsigned);
        }
        hmac::verify(&self.key, &signed_bytes(state), &state.tag).map_err(|_| ResumeRefusal::BadSignature)?;
        if state.scene_hash != scene_hash {
            return Err(ResumeRefusal::OtherScene { expected: scene_hash, got: state.scene_hash });
        }
        let age_s = (unix_ms(now) as f64 - state.taken_unix_ms as f64) * 1e-3;
        // A state from the future by more than clock skew between a room's servers is as suspect as an old one.
        if age_s > MAX_RESUME_AGE.as_secs_f64() || age_s < -MAX_RESUME_AGE.as_secs_f64() {
            return Err(ResumeRefusal::Stale { age_s, max_age_s: MAX_RESUME_AGE.as_secs_f64() });
        }
        Ok(())
    }
}

/// Milliseconds since the Unix epoch (0 before it).
pub fn unix_ms(at: SystemTime) -> u64 {
    at.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64)
}

/// A scene's identity for resumes: the first 8 bytes of the SHA-256 of its description (`bytes`, the compiled
/// scene as the server serializes it).
pub fn scene_hash(bytes: &[u8]) -> u64 {
    let digest = digest::digest(&digest::SHA256, bytes);
    let mut first = [0u8; 8];
    first.copy_from_slice(&digest.as_ref()[..8]);
    u64::from_le_bytes(first)
}

/// What the tag covers: every field but the tag, in their wire encoding.
fn signed_bytes(state: &RoomState) -> Vec<u8> {
    let fields = (state.scene_hash, state.taken_unix_ms, state.ve_step, &state.q, &state.qd);
    // Encoding plain numbers and vectors into a Vec cannot fail.
    bincode::serde::encode_to_vec(fields, bincode::config::standard()).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(now: SystemTime) -> RoomState {
        RoomState {
            scene_hash: 7,
            taken_unix_ms: unix_ms(now),
            ve_step: 3,
            q: vec![1.0, -0.5],
            qd: vec![0.0, 0.25],
            tag: Vec::new(),
        }
    }

    #[test]
    fn a_signed_state_checks_and_any_change_to_it_does_not() {
        let now = SystemTime::now();
        let key = RoomKey::from_bytes(&[9u8; 32]).unwrap();
        let mut signed = state(now);
        assert_eq!(key.check(&signed, 7, now), Err(ResumeRefusal::Unsigned));
        key.sign(&mut signed);
        assert_eq!(signed.tag.len(), 32);
        assert_eq!(key.check(&signed, 7, now), Ok(()));
        let mut moved = signed.clone();
        moved.q[0] += 1e-9;
        assert_eq!(key.check(&moved, 7, now), Err(ResumeRefusal::BadSignature));
        let other_room = RoomKey::from_bytes(&[8u8; 32]).unwrap();
        assert_eq!(other_room.check(&signed, 7, now), Err(ResumeRefusal::BadSignature));
        assert!(matches!(key.check(&signed, 8, now), Err(ResumeRefusal::OtherScene { expected: 8, got: 7 })));
        let later = now + MAX_RESUME_AGE + Duration::from_secs(1);
        assert!(matches!(key.check(&signed, 7, later), Err(ResumeRefusal::Stale { age_s, .. }) if age_s > 30.0));
    }

    #[test]
    fn a_short_key_is_refused_naming_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("room.key");
        std::fs::write(&path, b"short").unwrap();
        let error = RoomKey::load(&path).unwrap_err().to_string();
        assert!(error.contains("room.key") && error.contains("5 bytes"), "{error}");
        let missing = RoomKey::load(&dir.path().join("none")).unwrap_err().to_string();
        assert!(missing.contains("none"), "{missing}");
    }
}
