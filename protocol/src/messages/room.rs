//! The room's state as its server signs it for the clients, and the answer a server gives a client that
//! offers such a state back when it reconnects (see `docs/resume.md`). Part of the wire like the rest of
//! `messages`: the field order is the format.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The VE's state, signed with the room's key (HMAC-SHA256, see [`crate::room_key`]): a server sends its
/// clients the newest on the control stream ([`crate::Control::RoomState`]); a client that lost its server
/// offers the newest it holds to the next server of the room ([`crate::Control::Resume`]), which takes it
/// up only when the signature verifies, the scene is the same, the state is recent and it closes the loops.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoomState {
    /// Hash of the scene the state belongs to (`room_key::scene_hash`).
    pub scene_hash: u64,
    /// Wall-clock time the server took the state (ms since the Unix epoch): an old state is stale.
    pub taken_unix_ms: u64,
    /// The VE's step counter when taken (for logs).
    pub ve_step: u64,
    /// Generalized coordinates, length `n`.
    pub q: Vec<f64>,
    /// Generalized velocities, length `n`.
    pub qd: Vec<f64>,
    /// HMAC-SHA256 of the fields above in their wire encoding; empty when unsigned.
    pub tag: Vec<u8>,
}

/// Why a server did not take up an offered [`RoomState`]. The client still joins: the room goes on from
/// where it is (its initial state when nobody was there).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ResumeRefusal {
    /// This server was started without a room key, so it can authenticate no state.
    NoRoomKey,
    /// The state carries no signature.
    Unsigned,
    /// The signature does not match the state under this room's key (forged, altered, or another room's).
    BadSignature,
    /// The state belongs to another scene.
    OtherScene {
        /// This server's scene hash.
        expected: u64,
        /// The state's.
        got: u64,
    },
    /// The state is older than a resume may be.
    Stale {
        /// How old (s).
        age_s: f64,
        /// The oldest accepted (s).
        max_age_s: f64,
    },
    /// The state's dimensions or numbers do not fit the scene.
    Shape {
        /// What does not fit.
        what: String,
    },
    /// The state does not close the linkage's loops.
    Loops {
        /// Closure residual of the state (m).
        residual_m: f64,
        /// The largest residual a resume re-assembles from (m).
        tolerance_m: f64,
    },
    /// Users are in the room already: its state is live and wins over any offered one.
    RoomLive {
        /// Users present.
        users: u32,
    },
}

impl fmt::Display for ResumeRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ResumeRefusal::NoRoomKey => f.write_str("this server has no room key"),
            ResumeRefusal::Unsigned => f.write_str("the state is unsigned"),
            ResumeRefusal::BadSignature => f.write_str("the state's signature does not verify under the room key"),
            ResumeRefusal::OtherScene { expected, got } => {
                write!(f, "the state is of scene {got:016x}, this room runs scene {expected:016x}")
            }
            ResumeRefusal::Stale { age_s, max_age_s } => {
                write!(f, "the state is {age_s:.1} s old (at most {max_age_s:.1} s resumes)")
            }
            ResumeRefusal::Shape { what } => write!(f, "the state does not fit the scene: {what}"),
            ResumeRefusal::Loops { residual_m, tolerance_m } => {
                write!(f, "the state breaks the loops: residual {residual_m:.3e} m (at most {tolerance_m:.3e} m)")
            }
            ResumeRefusal::RoomLive { users } => write!(f, "the room is live ({users} users present)"),
        }
    }
}

/// The server's answer to [`crate::Control::Resume`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ResumeAnswer {
    /// The room now runs from the offered state.
    Resumed {
        /// The offered state's step counter.
        ve_step: u64,
    },
    /// The state was refused; the room goes on from where it is.
    Refused(ResumeRefusal),
}
