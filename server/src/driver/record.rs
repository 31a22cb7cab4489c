//! `--record FILE`: one CSV row per VE step, written by a plain thread from a ring the VE thread fills.
//!
//! Row layout (the header names every fixed column; the user group repeats `users` times):
//! `t_s, step, q_0.., qd_0.., lambda_0.., closure_error_m, users,` then per user
//! `user_id, op pose (x, y, θ or x, y, z, qw, qx, qy, qz), wrench (k values), constraint_count`.
//! In the ring each row is preceded by its length, and written in one commit; a row that does not fit is
//! dropped and counted (the VE thread never waits for the disk). The file's columns and its writer are the
//! record crate's ([`kinloop_record::VeSchema`]).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_record::{RecordFile, VeSchema};
use rtrb::{Consumer, Producer};

use crate::core::VeCore;

pub use kinloop_record::RecordError;

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

/// The CSV header for a scene of space `S` with `nq` configuration and `n` velocity coordinates and `m`
/// closure rows.
pub fn header<S: Space>(nq: usize, n: usize, m: usize) -> String {
    VeSchema { kind: S::KIND, nq, n, m }.header()
}

/// Starts the writer thread; it drains `ring` into `path` until `stop` is set and the ring is empty, and
/// returns the rows written.
pub fn spawn_writer(
    path: &Path,
    header: String,
    mut ring: Consumer<f64>,
    stop: Arc<AtomicBool>,
) -> Result<JoinHandle<std::io::Result<u64>>, RecordError> {
    let mut out = RecordFile::create(path, &header)?;
    let spawned = std::thread::Builder::new().name("kinloop-record".into()).spawn(move || {
        let mut rows = 0u64;
        loop {
            let stopping = stop.load(Ordering::Acquire);
            let mut wrote = false;
            while let Some(written) = write_next_row(&mut ring, &mut out) {
                written?;
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
        out.finish()?;
        Ok(rows)
    });
    spawned.map_err(|source| RecordError { path: path.to_owned(), source })
}

/// Writes the next complete row of the ring, if there is one.
fn write_next_row(ring: &mut Consumer<f64>, out: &mut RecordFile) -> Option<std::io::Result<()>> {
    let len = ring.peek().ok().copied()? as usize;
    let chunk = ring.read_chunk(len + 1).ok()?;
    let (a, b) = chunk.as_slices();
    let written = out.write_ve_numbers(a.iter().chain(b).skip(1).copied());
    chunk.commit_all();
    Some(written)
}
