//! What the resume tests share (docs/resume.md): a room's files (CA, two servers' certificates, the room key)
//! and what a session that moved from a killed server A to server B measured in their records.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use tempfile::TempDir;

use kinloop_client::driver::ClientHandle;
use kinloop_protocol::quic::{RoomCa, Trust};
use kinloop_protocol::room_key::RoomKey;
use kinloop_server::{Identity, ServerConfig};

use super::child::{self, Role};
use super::live::{self, OPS};
use super::records::{self, Step, Tick};
use super::Bounded;

/// The resume goals: the linkage resumed within 1 mm and 1° of where it was, the client back within
/// 2 s of the kill, and no force step above 0.2 N at the reconnection.
pub const MAX_RESUME_OFFSET_M: f64 = 1e-3;
pub const MAX_RESUME_OFFSET_RAD: f64 = 1.0 * std::f64::consts::PI / 180.0;
pub const MAX_BACK_S: f64 = 2.0;
pub const MAX_FORCE_STEP_N: f64 = 0.2;

/// The hand: it carries the OP 18 mm from where the linkage starts (over 1 s) and holds it there.
pub const HAND: &str = "firm:line:0,0,-0.01,0.015,1";

/// The client that holds the OP with [`HAND`]: on server A first with B as its fallback, trusting the
/// room's CA (`ca.pem` in `dir`), recording to `client.csv` there.
pub fn start_holder(dir: &Path, a: SocketAddr, b: SocketAddr) -> ClientHandle {
    let mut config = live::client_config(a, "", "holder", OPS[0], &[0.0; 3]);
    config.trust = Trust::CaFile(dir.join("ca.pem"));
    config.fallback_servers = vec![b.to_string()];
    config.user = HAND.parse().expect("a hand that moves and holds");
    config.record = Some(dir.join("client.csv"));
    live::start_client(config)
}

/// Server SIDE (`a` or `b`) of the room whose files are in `dir`, listening on `listen`: its certificate
/// `SIDE.pem`/`SIDE.key`, the room's key, and its record `SIDE.csv`.
pub fn server_role(dir: &Path, side: &str, listen: SocketAddr) -> Role {
    Role::RoomServer {
        listen,
        cert: dir.join(format!("{side}.pem")),
        key: dir.join(format!("{side}.key")),
        room_key: dir.join("room.key"),
        record: dir.join(format!("{side}.csv")),
    }
}

/// `config` as server SIDE (`a` or `b`) of the room whose files are in `dir`: its certificate
/// `SIDE.pem`/`SIDE.key`, the room's key, and its record `SIDE.csv`.
pub fn room_server(mut config: ServerConfig, dir: &Path, side: &str) -> ServerConfig {
    config.identity = Identity::Files { cert: dir.join(format!("{side}.pem")), key: dir.join(format!("{side}.key")) };
    config.room_key = Some(RoomKey::load(&dir.join("room.key")).expect("room key"));
    config.record = Some(dir.join(format!("{side}.csv")));
    config
}

/// What a resume test stands on: this binary serving as the child it was started as (if it was), the serial
/// lock and a minute's hard limit, and a fresh directory holding a room's files ([`room_files`]).
pub struct Stage {
    pub dir: TempDir,
    /// The room key's bytes.
    pub secret: Vec<u8>,
    _bounded: Bounded,
}

impl Stage {
    pub fn set(test: &'static str) -> Stage {
        child::serve_if_child();
        let bounded = super::bounded(test, Duration::from_secs(60));
        let dir = super::temp_dir();
        let secret = room_files(dir.path());
        Stage { dir, secret, _bounded: bounded }
    }

    /// A file in the stage's directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

/// A room's files in `dir`: `ca.pem`, `a.pem`/`a.key` and `b.pem`/`b.key` (issued by the CA for
/// localhost) and `room.key`; the key's bytes.
pub fn room_files(dir: &Path) -> Vec<u8> {
    let path = |name: &str| dir.join(name);
    let ca = RoomCa::generate("kinloop room").expect("CA");
    ca.write(&path("ca.pem"), &["localhost"], &path("a.pem"), &path("a.key")).expect("A's certificate");
    ca.write(&path("ca.pem"), &["localhost"], &path("b.pem"), &path("b.key")).expect("B's certificate");
    let secret: Vec<u8> = (0..32u8).map(|i| i.wrapping_mul(37).wrapping_add(11)).collect();
    std::fs::write(path("room.key"), &secret).expect("room key file");
    secret
}

/// What a moved session measured.
#[derive(Debug)]
pub struct Moved {
    /// How far the hand had moved the OP from its start on A (m).
    pub moved_m: f64,
    /// Distance and angle between the OP on A's last step and on B's first step with the client (m, rad).
    pub offset_m: f64,
    pub offset_rad: f64,
    /// Largest tick-to-tick change of the commanded force from the first tick at zero after the kill to the
    /// end (N).
    pub step_n: f64,
    /// The same over the fade-out on losing A (N), and the force held before the kill (N).
    pub fade_out_n: f64,
    pub held_n: f64,
}

impl Moved {
    /// Reads A's record (`a`; SIGKILL may have cut its last row), B's (`b`; the client is the last user to
    /// join B) and the client's (`client`, the kill at its time `t_kill`); `a_user` is the client's id on A.
    pub fn measure(a: &Path, b: &Path, client: &Path, a_user: u32, t_kill: f64) -> Moved {
        let a_steps = complete_rows(a, &a.with_extension("complete.csv"));
        let start = user_op(a_steps.iter(), a_user).expect("the client on A");
        let was = user_op(a_steps.iter().rev(), a_user).expect("the client on A");
        let b_steps = records::ve_steps(b);
        let b_user = b_steps.iter().flat_map(|s| s.users.iter().map(|u| u.user_id)).max().expect("a user on B");
        let resumed = user_op(b_steps.iter(), b_user).expect("the client on B");
        let ticks = records::client_ticks(client);
        let zero = ticks.iter().position(|t| t.t >= t_kill && t.gain == 0.0).expect("the force faded out");
        let before = ticks.iter().position(|t| t.t >= t_kill - 0.05).unwrap_or(zero);
        Moved {
            moved_m: (was[0] - start[0]).hypot(was[1] - start[1]),
            offset_m: (resumed[0] - was[0]).hypot(resumed[1] - was[1]),
            offset_rad: angle_between(resumed[2], was[2]),
            step_n: largest_step(&ticks[zero..]),
            fade_out_n: largest_step(&ticks[before..=zero]),
            held_n: ticks[before].command[0].hypot(ticks[before].command[1]),
        }
    }

    /// Checks the goals, and that the hand had moved the linkage (a resume from the start would pass
    /// unnoticed otherwise).
    pub fn assert_goals(&self, back_s: f64) {
        assert!(self.moved_m >= 0.01, "the OP moved {} m: a resume from the start would pass unnoticed", self.moved_m);
        assert!(self.offset_m <= MAX_RESUME_OFFSET_M, "resumed {} m from where it was", self.offset_m);
        assert!(self.offset_rad <= MAX_RESUME_OFFSET_RAD, "resumed {} rad from where it was", self.offset_rad);
        assert!(back_s <= MAX_BACK_S, "back {back_s} s after the kill");
        assert!(self.step_n <= MAX_FORCE_STEP_N, "force step {} N at the reconnection", self.step_n);
    }
}

impl std::fmt::Display for Moved {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the hand moved the OP {:.1} mm from its start; the linkage resumed {:.3} mm and {:.3} deg from where it \
             was; largest force step at the reconnection {:.4} N (in the fade-out on losing A {:.4} N, holding \
             {:.3} N before the kill)",
            self.moved_m * 1e3,
            self.offset_m * 1e3,
            self.offset_rad.to_degrees(),
            self.step_n,
            self.fade_out_n,
            self.held_n
        )
    }
}

/// A VE record cut by SIGKILL may end mid-row: its complete rows (written to `into` to be read).
fn complete_rows(path: &Path, into: &PathBuf) -> Vec<Step> {
    let text = std::fs::read_to_string(path).expect("server A's record");
    let end = text.rfind('\n').map_or(0, |i| i + 1);
    std::fs::write(into, &text[..end]).expect("cut record");
    records::ve_steps(into)
}

/// The OP pose of user `user` in the first of `steps` that has it.
fn user_op<'a>(mut steps: impl Iterator<Item = &'a Step>, user: u32) -> Option<[f64; 3]> {
    steps.find_map(|s| s.users.iter().find(|u| u.user_id == user)).map(|u| u.op)
}

fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

fn largest_step(ticks: &[Tick]) -> f64 {
    let step = |w: &[Tick]| (w[1].command[0] - w[0].command[0]).hypot(w[1].command[1] - w[0].command[1]);
    ticks.windows(2).map(step).fold(0.0, f64::max)
}
