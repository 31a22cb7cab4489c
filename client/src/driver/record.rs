//! `--record`: one CSV row per tick, written by an ordinary thread from a ring the real-time loop fills
//! with fixed-size rows (no allocation, no IO on the loop; rows that do not fit are counted, never waited for).
//! The file's columns and its writer are the record crate's ([`kinloop_record::ClientSchema`]).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{SceneKind, Space, VecOps};
use kinloop_record::{ClientSchema, RecordFile};

use crate::core::TickReport;

pub use kinloop_record::TickRecord;

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

/// The row for one tick's report.
pub fn tick_record<S: Space>(report: &TickReport<S>) -> TickRecord {
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
        // The loop knows which session it renders.
        session: 0,
    }
}

/// Writes rows from `rows` to `path` until `stop` is set and the ring is empty.
pub fn write_records(
    path: &Path,
    kind: SceneKind,
    mut rows: rtrb::Consumer<TickRecord>,
    stop: Arc<AtomicBool>,
) -> std::io::Result<u64> {
    let schema = ClientSchema { kind };
    let mut out = RecordFile::create(path, &schema.header()).map_err(|e| e.source)?;
    let mut written = 0;
    loop {
        let stopping = stop.load(Ordering::Acquire);
        while let Ok(row) = rows.pop() {
            out.write_tick(&schema, &row)?;
            written += 1;
        }
        if stopping || rows.is_abandoned() && rows.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    out.finish()?;
    Ok(written)
}
