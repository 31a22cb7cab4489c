//! `--record FILE`: one CSV row per VE step, written by a plain thread from a ring the VE thread fills.
//!
//! Row layout (the header names every fixed column; the user group repeats `users` times):
//! `t_s, step, q_0.., qd_0.., lambda_0.., closure_error_m, users,` then per user
//! `user_id, op pose (x, y, θ or x, y, z, qw, qx, qy, qz), wrench (k values), constraint_count`.
//! In the ring each row is preceded by its length, and written in one commit; a row that does not fit is
//! dropped and counted (the VE thread never waits for the disk).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use rtrb::{Consumer, Producer};

use crate::core::VeCore;

/// Numbers a user group can take at most (id, 7 pose, 6 wrench, count).
const USER_GROUP_MAX: usize = 15;

/// Writes the state after the last tick as one row; false when the ring has no room.
pub fn write_row<S: Space>(core: &VeCore<S>, ring: &mut Producer<f64>) -> bool {
    let state = core.state();
    let pose_len = OpPose::<S>::wire_len();
    let group = 1 + pose_len + S::DIM + 1;
    let users = state.users();
    let len = 2 + state.q.len() + state.qd.len() + state.lambda.len() + 2 + users.len() * group;
    let Ok(chunk) = ring.write_chunk_uninit(len + 1) else { return false };
    let head = [len as f64, state.time.as_secs_f64(), state.step as f64];
    let tail = [state.closure_error, users.len() as f64];
    let groups = users.flat_map(move |u| {
        let mut g = [0.0; USER_GROUP_MAX];
        g[0] = f64::from(u.user_id);
        u.op_pose.to_slice(&mut g[1..1 + pose_len]);
        g[1 + pose_len..1 + pose_len + S::DIM].copy_from_slice(u.wrench.as_slice());
        g[group - 1] = f64::from(u.constraint_count);
        g.into_iter().take(group)
    });
    let values = head.into_iter().chain(state.q.iter().copied()).chain(state.qd.iter().copied());
    let values = values.chain(state.lambda.iter().copied()).chain(tail).chain(groups);
    chunk.fill_from_iter(values) == len + 1
}

/// The CSV header for a scene of space `S` with `n` coordinates and `m` closure rows.
pub fn header<S: Space>(n: usize, m: usize) -> String {
    let mut columns = vec!["t_s".to_string(), "step".into()];
    columns.extend((0..n).map(|i| format!("q_{i}")));
    columns.extend((0..n).map(|i| format!("qd_{i}")));
    columns.extend((0..m).map(|i| format!("lambda_{i}")));
    columns.extend(["closure_error_m".to_string(), "users".into(), "user_id".into()]);
    let pose: &[&str] = if S::DIM == 3 { &["x", "y", "theta"] } else { &["x", "y", "z", "qw", "qx", "qy", "qz"] };
    let axes: &[&str] = if S::DIM == 3 { &["fx", "fy", "tz"] } else { &["fx", "fy", "fz", "tx", "ty", "tz"] };
    columns.extend(pose.iter().map(|p| format!("op_{p}")));
    columns.extend(axes.iter().map(|a| format!("wrench_{a}")));
    columns.push("constraint_count".into());
    columns.push("...(user group repeated per user)".into());
    columns.join(",")
}

/// Why recording could not start.
#[derive(Debug, thiserror::Error)]
#[error("cannot record to {path}: {source}")]
pub struct RecordError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub source: std::io::Error,
}

/// Starts the writer thread; it drains `ring` into `path` until `stop` is set and the ring is empty, and
/// returns the rows written.
pub fn spawn_writer(
    path: &Path,
    header: String,
    mut ring: Consumer<f64>,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<std::io::Result<u64>>, RecordError> {
    let file = File::create(path).map_err(|source| RecordError { path: path.to_owned(), source })?;
    let spawned = std::thread::Builder::new().name("kinloop-record".into()).spawn(move || {
        let mut out = BufWriter::new(file);
        writeln!(out, "{header}")?;
        let mut rows = 0u64;
        let mut line = String::new();
        loop {
            let stopping = stop.load(Ordering::Acquire);
            let mut wrote = false;
            while let Some(()) = next_row(&mut ring, &mut line) {
                out.write_all(line.as_bytes())?;
                rows += 1;
                wrote = true;
            }
            if stopping {
                break;
            }
            if !wrote {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        out.flush()?;
        Ok(rows)
    });
    spawned.map_err(|source| RecordError { path: path.to_owned(), source })
}

/// Formats the next complete row into `line` (newline included).
fn next_row(ring: &mut Consumer<f64>, line: &mut String) -> Option<()> {
    use std::fmt::Write as _;
    let len = ring.peek().ok().copied()? as usize;
    let chunk = ring.read_chunk(len + 1).ok()?;
    line.clear();
    let (a, b) = chunk.as_slices();
    for (i, x) in a.iter().chain(b).skip(1).enumerate() {
        if i > 0 {
            line.push(',');
        }
        // Step, user ids and counts are integers; print them without a fraction.
        let _ = if x.fract() == 0.0 && x.abs() < 1e15 { write!(line, "{}", *x as i64) } else { write!(line, "{x}") };
    }
    line.push('\n');
    chunk.commit_all();
    Some(())
}
