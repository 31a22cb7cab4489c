//! The page's protocol: JSON text messages over one WebSocket, tagged by `type`.
//!
//! ```text
//! server                                  page
//! hello {auth: "token"|"none", mode} ──►
//!                                    ◄──  auth {token?}
//! welcome {role, can_grab, scene, ..} ──►   (or refused {message}, then close)
//! frame {...} (live: at the frame rate) ──►
//!                                    ◄──  grab {op} / drag {target} / release      (live, manipulators)
//! grabbed / released / error {message} ──►
//!                                    ◄──  seek {t}                                  (replay)
//! ```
//! Nothing about the scene is sent before `welcome`: a refused page learns only why.

use serde::{Deserialize, Serialize};

use super::draw::{Drawn, SceneInfo};

/// Version of this protocol, in `hello`.
pub const VERSION: u32 = 1;

/// What a page may send.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum FromPage {
    /// The token, or none when the server asks for none.
    Auth {
        /// The token.
        #[serde(default)]
        token: Option<String>,
    },
    /// Take hold of an operational point (live, manipulators).
    Grab {
        /// Its name.
        op: String,
    },
    /// Where the held point should go, world frame (2 or 3 numbers).
    Drag {
        /// Target position (m).
        target: Vec<f64>,
    },
    /// Let go.
    Release,
    /// Show the recording at time `t` (replay).
    Seek {
        /// Seconds on the recording's clock.
        t: f64,
    },
}

/// What the server sends.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ToPage<'a> {
    /// First message: whether a token is needed and what is served.
    Hello {
        /// `token` or `none`.
        auth: &'static str,
        /// `live` or `replay`.
        mode: &'static str,
        /// Protocol version.
        version: u32,
        /// Longest message the server reads (bytes).
        max_message_bytes: usize,
    },
    /// Admitted.
    Welcome(Box<Welcome>),
    /// Not admitted; the socket closes after this.
    Refused {
        /// Why, for people.
        message: String,
    },
    /// The page now holds `op` as VE user `user`.
    Grabbed {
        /// VE user id.
        user: u32,
        /// The operational point.
        op: &'a str,
    },
    /// The page let go (or was made to).
    Released {
        /// Why.
        reason: &'a str,
    },
    /// A message was not used.
    Error {
        /// Why, for people.
        message: String,
    },
    /// One picture of the linkage.
    Frame(&'a Frame),
}

/// What an admitted page learns once.
#[derive(Clone, Debug, Serialize)]
pub struct Welcome {
    /// `manipulator` or `observer`.
    pub role: &'static str,
    /// Whether `grab` will be honoured.
    pub can_grab: bool,
    /// The scene.
    pub scene: SceneInfo,
    /// Frames per second the server aims for (live).
    pub frame_rate_hz: f64,
    /// How far from its operational point a drag target may lie (m); farther targets are pulled in.
    pub grab_reach_m: f64,
    /// The recording, in replay mode.
    pub replay: Option<ReplayInfo>,
}

/// A recording's extent.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ReplayInfo {
    /// File name.
    pub file: String,
    /// `server` (one row per VE step) or `client` (one row per haptic tick).
    pub source: &'static str,
    /// First time (s).
    pub t0: f64,
    /// Last time (s).
    pub t1: f64,
    /// Rows.
    pub rows: usize,
}

/// One user on the page.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct UserView {
    /// VE user id.
    pub id: u32,
    /// Client name (empty when unknown).
    pub name: String,
    /// Device (`DeviceCaps.name`), `mouse` for a page.
    pub device: String,
    /// `manipulator` or `observer`.
    pub role: &'static str,
    /// Operational point name (empty when unknown).
    pub op: String,
    /// A page grabbing with the mouse.
    pub browser: bool,
    /// Still present (false while fading out after leaving).
    pub present: bool,
    /// Coupling fade weight.
    pub weight: f64,
    /// The user's OP in the VE.
    pub pose: Vec<f64>,
    /// Wrench the VE applied at the OP (the coupling force), N and N·m.
    pub wrench: Vec<f64>,
    /// Constrained directions at the OP.
    pub count: u8,
    /// Singular values of the scaled Λ̃⁻¹ (empty when unknown).
    pub sv: Vec<f64>,
    /// Singular directions (column-major, `(v, L ω)`), the last `count` constrained (empty when unknown).
    pub dirs: Vec<f64>,
    /// Device pose in the VE, from the user's uplinks.
    pub device_pose: Option<Vec<f64>>,
    /// Local-model OP pose, from the user's uplinks.
    pub model_pose: Option<Vec<f64>>,
    /// QUIC round trip (ms).
    pub rtt_ms: Option<f64>,
    /// Fraction of the user's uplinks flagged `CLAMPED`.
    pub clamped: Option<f64>,
}

/// The VE loop's numbers on the panel.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct LoopView {
    /// Median loop iteration (µs).
    pub p50_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Largest (µs).
    pub max_us: f64,
    /// Deadline misses.
    pub misses: u64,
}

/// One picture.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Frame {
    /// Frame counter of the source (live: since the server started; replay: row index).
    pub seq: u64,
    /// VE time (s) or the recording's time.
    pub t: f64,
    /// VE step (0 when unknown).
    pub step: u64,
    /// Closure residual (m).
    pub closure_error: Option<f64>,
    /// The linkage (empty when the source has no coordinates).
    pub linkage: Drawn,
    /// Users.
    pub users: Vec<UserView>,
    /// The VE loop (live).
    #[serde(rename = "loop")]
    pub ve_loop: Option<LoopView>,
}
