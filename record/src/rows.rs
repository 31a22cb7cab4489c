//! One row of each kind of record, as numbers.

/// One haptic tick of a client's record (planar rows use the first 3 pose / wrench entries, spatial 7 / 6).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TickRecord {
    /// Time since the loop started (s).
    pub time_s: f64,
    /// Device pose in the VE.
    pub device_pose: [f64; 7],
    /// Local-model OP pose.
    pub model_pose: [f64; 7],
    /// Hand wrench (measured or estimated).
    pub hand: [f64; 6],
    /// Position channels.
    pub position_channel: [f64; 6],
    /// Joint constraint.
    pub joint_constraint: [f64; 6],
    /// Impedance (free directions).
    pub impedance: [f64; 6],
    /// Contact force channel.
    pub contact: [f64; 6],
    /// Commanded.
    pub command: [f64; 6],
    /// Constrained directions (core's count).
    pub constraint_count: u8,
    /// Age of the snapshot in use (s), NaN before the first.
    pub snapshot_age_s: f64,
    /// Output gain.
    pub gain: f64,
    /// The server session the tick renders: 1 for the first server, 2 after the first move to another, ...;
    /// 0 between servers (from losing one until the next session's core takes over), so a recording shows
    /// where the client was between servers as a marked gap, not a silent jump.
    pub session: u32,
}

/// One user's part of a VE step (planar rows use the first 3 pose / wrench entries, spatial 7 / 6).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VeUserRow {
    /// Id in the VE.
    pub user_id: u32,
    /// Operational point pose.
    pub op_pose: [f64; 7],
    /// Wrench the step applied at the OP, fade included.
    pub wrench: [f64; 6],
    /// Constrained directions of the user's snapshot.
    pub constraint_count: u8,
}

/// One VE step of the server's record.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VeRow {
    /// VE time (s).
    pub t_s: f64,
    /// Step number.
    pub step: u64,
    /// Coordinates.
    pub q: Vec<f64>,
    /// Velocities.
    pub qd: Vec<f64>,
    /// Closure-constraint multipliers.
    pub lambda: Vec<f64>,
    /// Loop-closure residual (m).
    pub closure_error: f64,
    /// The users present.
    pub users: Vec<VeUserRow>,
}
