//! `--record`: one CSV row per tick, written by an ordinary thread from a ring the real-time loop fills
//! with fixed-size rows (no allocation, no IO on the loop; rows that do not fit are counted, never waited for).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{SceneKind, Space, VecOps};

use crate::axes::{pose_names, wrench_names};
use crate::core::TickReport;

/// One tick, as numbers (planar rows use the first 3 pose / wrench entries, spatial 7 / 6).
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
}

fn pose_array<S: Space>(pose: &OpPose<S>) -> [f64; 7] {
    let mut out = [0.0; 7];
    pose.to_slice(&mut out[..OpPose::<S>::wire_len()]);
    out
}

fn wrench_array<S: Space>(w: &S::OpVec) -> [f64; 6] {
    let mut out = [0.0; 6];
    out[..S::DIM].copy_from_slice(w.as_slice());
    out
}

impl TickRecord {
    /// The row for one tick's report.
    pub fn of<S: Space>(report: &TickReport<S>) -> Self {
        let w = &report.wrenches;
        TickRecord {
            time_s: report.time.as_secs_f64(),
            device_pose: pose_array(&report.device_pose),
            model_pose: pose_array(&report.model_pose),
            hand: wrench_array::<S>(&report.hand_wrench),
            position_channel: wrench_array::<S>(&w.position_channel),
            joint_constraint: wrench_array::<S>(&w.joint_constraint),
            impedance: wrench_array::<S>(&w.impedance),
            contact: wrench_array::<S>(&w.contact),
            command: wrench_array::<S>(&w.command),
            constraint_count: report.constraint_count as u8,
            snapshot_age_s: report.snapshot_age.map_or(f64::NAN, |a| a.as_secs_f64()),
            gain: report.gain,
        }
    }
}

/// The CSV header for a scene of `kind`.
pub fn header(kind: SceneKind) -> String {
    let mut columns = vec!["time_s".to_owned()];
    for prefix in ["device", "model"] {
        columns.extend(pose_names(kind).iter().map(|n| format!("{prefix}_{n}")));
    }
    for prefix in ["hand", "pc", "jc", "imp", "contact", "cmd"] {
        columns.extend(wrench_names(kind).iter().map(|n| format!("{prefix}_{n}")));
    }
    columns.extend(["constraint_count", "snapshot_age_s", "gain"].map(String::from));
    columns.join(",")
}

fn write_row(out: &mut impl Write, r: &TickRecord, kind: SceneKind) -> std::io::Result<()> {
    let (pose_len, k) = (pose_names(kind).len(), kind.op_dim());
    write!(out, "{:.6}", r.time_s)?;
    for v in r.device_pose[..pose_len].iter().chain(&r.model_pose[..pose_len]) {
        write!(out, ",{v:.9}")?;
    }
    for w in [&r.hand, &r.position_channel, &r.joint_constraint, &r.impedance, &r.contact, &r.command] {
        for v in &w[..k] {
            write!(out, ",{v:.6}")?;
        }
    }
    writeln!(out, ",{},{:.6},{:.4}", r.constraint_count, r.snapshot_age_s, r.gain)
}

/// Writes rows from `rows` to `path` until `stop` is set and the ring is empty.
pub fn write_records(
    path: &Path,
    kind: SceneKind,
    mut rows: rtrb::Consumer<TickRecord>,
    stop: Arc<AtomicBool>,
) -> std::io::Result<u64> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(out, "{}", header(kind))?;
    let mut written = 0;
    loop {
        let stopping = stop.load(Ordering::Acquire);
        while let Ok(row) = rows.pop() {
            write_row(&mut out, &row, kind)?;
            written += 1;
        }
        if stopping || rows.is_abandoned() && rows.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    out.flush()?;
    Ok(written)
}
