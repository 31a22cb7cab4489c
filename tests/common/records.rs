//! The CSV recordings of planar sessions, read back by column name: the client's one row per haptic tick
//! (`kinloop-client --record`) and the server's one row per VE step (`kinloop-server --record`), read by the
//! record crate and kept to what the tests compare.

use std::path::Path;

use kinloop_linkage::math::space::SceneKind;

/// One haptic tick.
#[derive(Clone, Copy, Debug)]
pub struct Tick {
    /// Time since the client's loop started (s).
    pub t: f64,
    /// Device pose in the VE frame (x, y, θ).
    pub device: [f64; 3],
    /// Commanded wrench (fx, fy, τz).
    pub command: [f64; 3],
    /// Age of the snapshot in use (s), NaN before the first.
    pub snapshot_age: f64,
    /// Output gain in [0, 1].
    pub gain: f64,
    /// The server session rendered: 1, 2, ... (one more per move), 0 between servers.
    pub session: u32,
}

/// One user's part of a VE step.
#[derive(Clone, Copy, Debug)]
pub struct UserStep {
    /// Id in the VE.
    pub user_id: u32,
    /// Operational point pose (x, y, θ).
    pub op: [f64; 3],
    /// Wrench the step applied at the OP (fx, fy, τz), fade included.
    pub wrench: [f64; 3],
}

/// One VE step.
#[derive(Clone, Debug)]
pub struct Step {
    /// VE time (s).
    pub t: f64,
    /// Loop-closure residual (m).
    pub closure_error: f64,
    /// The users present.
    pub users: Vec<UserStep>,
}

/// A client's recording.
pub fn client_ticks(path: &Path) -> Vec<Tick> {
    let rows = kinloop_record::read::read_client(path, SceneKind::Planar).unwrap_or_else(|e| panic!("{e}"));
    rows.iter()
        .map(|r| Tick {
            t: r.time_s,
            device: first_three(&r.device_pose),
            command: first_three(&r.command),
            snapshot_age: r.snapshot_age_s,
            gain: r.gain,
            session: r.session,
        })
        .collect()
}

/// A server's recording.
pub fn ve_steps(path: &Path) -> Vec<Step> {
    let (_, rows) = kinloop_record::read::read_ve(path, SceneKind::Planar).unwrap_or_else(|e| panic!("{e}"));
    rows.iter()
        .map(|r| Step {
            t: r.t_s,
            closure_error: r.closure_error,
            users: r
                .users
                .iter()
                .map(|u| UserStep { user_id: u.user_id, op: first_three(&u.op_pose), wrench: first_three(&u.wrench) })
                .collect(),
        })
        .collect()
}

fn first_three(v: &[f64]) -> [f64; 3] {
    [v[0], v[1], v[2]]
}

/// Linear magnitude of a planar wrench or pose difference.
pub fn linear(v: [f64; 3]) -> f64 {
    v[0].hypot(v[1])
}

/// The step a user appears in at VE time `t` (the last step at or before it).
pub fn user_at(steps: &[Step], t: f64, user_id: u32) -> Option<&UserStep> {
    let i = steps.partition_point(|s| s.t <= t).checked_sub(1)?;
    steps[i].users.iter().find(|u| u.user_id == user_id)
}

/// RMS and largest distance between a client's device and its operational point in the VE at the same
/// moment, over the client's ticks with full output gain; `offset_s` maps client loop time to VE time.
pub fn device_op_distance(ticks: &[Tick], steps: &[Step], user_id: u32, offset_s: f64) -> (f64, f64, usize) {
    let (mut sum_sq, mut max, mut n) = (0.0, 0.0f64, 0);
    for tick in ticks.iter().filter(|t| t.gain >= 1.0) {
        if let Some(u) = user_at(steps, tick.t + offset_s, user_id) {
            let d = (tick.device[0] - u.op[0]).hypot(tick.device[1] - u.op[1]);
            sum_sq += d * d;
            max = max.max(d);
            n += 1;
        }
    }
    ((sum_sq / n.max(1) as f64).sqrt(), max, n)
}
