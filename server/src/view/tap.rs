//! The VE thread's side of the view: every few ticks it copies the state a page draws (q, the closure
//! error, each user's OP pose, applied wrench and constraint directions, the loop's timing) into a
//! lock-free ring of `f64`, one length-prefixed frame per commit, and wakes the hub.
//!
//! Like `--record`, it never waits: a frame that does not fit is dropped and counted. The per-user
//! constraint directions come from the snapshots the VE thread already hands out (see
//! [`ViewTap::note_snapshot`]) and are kept in storage sized at start, so a tick allocates nothing.
//!
//! Frame layout (after the length): `t_s, step, closure_error_m, p50_ns, p99_ns, max_ns, misses, n, q_0..,
//! users,` then per user `id, role (0 manipulator, 1 observer), present (0/1), weight, op pose (3 or 7),
//! wrench (k), constraint_count, singular values (k), directions (k·k, column-major)`.

use std::sync::Arc;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_protocol::{Role, Snapshot};
use rtrb::Producer;
use tokio::sync::Notify;

use crate::core::{Presence, VeCore};
use crate::gateway::VeLoopStats;

/// Largest operational dimension.
const K_MAX: usize = 6;
/// Numbers before the coordinates.
pub const HEAD: usize = 8;

/// Numbers of one user's group in a frame of a space with operational dimension `k` and pose length
/// `pose_len`.
pub const fn user_group_len(k: usize, pose_len: usize) -> usize {
    4 + pose_len + k + 1 + k + k * k
}

/// Numbers of a frame (without its length) with `n` coordinates and `users` users.
pub fn frame_len<S: Space>(n: usize, users: usize) -> usize {
    HEAD + n + 1 + users * user_group_len(S::DIM, OpPose::<S>::wire_len())
}

/// The constraint directions of a user's newest snapshot.
#[derive(Clone, Copy, Debug)]
struct UserDirections {
    user: u32,
    count: u8,
    singular_values: [f64; K_MAX],
    directions: [f64; K_MAX * K_MAX],
}

/// The VE thread's end of the view.
pub struct ViewTap {
    ring: Producer<f64>,
    notify: Arc<Notify>,
    every: u64,
    iterations: u64,
    directions: Vec<UserDirections>,
    /// Frames handed to the hub.
    pub published: u64,
    /// Frames the ring had no room for.
    pub dropped: u64,
}

impl ViewTap {
    /// A tap publishing one frame every `every` loop iterations (at least 1), with room for the directions
    /// of `max_users` users (and as many leaving).
    pub fn new(ring: Producer<f64>, notify: Arc<Notify>, every: u64, max_users: usize) -> Self {
        ViewTap {
            ring,
            notify,
            every: every.max(1),
            iterations: 0,
            directions: Vec::with_capacity(2 * max_users),
            published: 0,
            dropped: 0,
        }
    }

    /// Keeps the constraint directions of a snapshot the VE thread is handing out (no allocation: a user
    /// beyond the reserved room is simply not drawn with directions).
    pub fn note_snapshot(&mut self, snapshot: &Snapshot) {
        let k = snapshot.singular_values.len().min(K_MAX);
        if snapshot.directions.len() != k * k {
            return;
        }
        let index = match self.directions.iter().position(|d| d.user == snapshot.user_id) {
            Some(index) => index,
            None if self.directions.len() < self.directions.capacity() => {
                self.directions.push(UserDirections {
                    user: snapshot.user_id,
                    count: 0,
                    singular_values: [0.0; K_MAX],
                    directions: [0.0; K_MAX * K_MAX],
                });
                self.directions.len() - 1
            }
            None => return,
        };
        let d = &mut self.directions[index];
        d.count = snapshot.constraint_count;
        d.singular_values[..k].copy_from_slice(&snapshot.singular_values[..k]);
        d.directions[..k * k].copy_from_slice(&snapshot.directions);
    }

    /// Called once per loop iteration, after the tick: every `every` iterations writes a frame of the state
    /// after the last tick and wakes the hub.
    pub fn after_tick<S: Space>(&mut self, core: &VeCore<S>, stats: &VeLoopStats) {
        self.iterations += 1;
        if !self.iterations.is_multiple_of(self.every) {
            return;
        }
        let state = core.state();
        // Users removed since the last frame take their directions with them (`retain` frees nothing).
        self.directions.retain(|d| state.users().any(|u| u.user_id == d.user));
        let (k, pose_len) = (S::DIM, OpPose::<S>::wire_len());
        let group = user_group_len(k, pose_len);
        let n = state.q.len();
        let len = frame_len::<S>(n, state.users().len());
        let Ok(chunk) = self.ring.write_chunk_uninit(len + 1) else {
            self.dropped += 1;
            return;
        };
        let timing = &stats.step_time;
        let head = [
            len as f64,
            state.time.as_secs_f64(),
            state.step as f64,
            state.closure_error,
            timing.p50_ns as f64,
            timing.p99_ns as f64,
            timing.max_ns as f64,
            stats.deadline_misses as f64,
            n as f64,
        ];
        let directions = &self.directions;
        let groups = state.users().flat_map(move |u| {
            let mut g = [0.0; user_group_len(K_MAX, 7)];
            g[0] = f64::from(u.user_id);
            g[1] = if u.role == Role::Observer { 1.0 } else { 0.0 };
            g[2] = if u.presence == Presence::Present { 1.0 } else { 0.0 };
            g[3] = u.weight;
            u.op_pose.to_slice(&mut g[4..4 + pose_len]);
            let at = 4 + pose_len;
            g[at..at + k].copy_from_slice(u.wrench.as_slice());
            if let Some(d) = directions.iter().find(|d| d.user == u.user_id) {
                g[at + k] = f64::from(d.count);
                g[at + k + 1..at + 2 * k + 1].copy_from_slice(&d.singular_values[..k]);
                g[at + 2 * k + 1..at + 2 * k + 1 + k * k].copy_from_slice(&d.directions[..k * k]);
            }
            g.into_iter().take(group)
        });
        let values = head.into_iter().chain(state.q.iter().copied()).chain([state.users().len() as f64]).chain(groups);
        if chunk.fill_from_iter(values) == len + 1 {
            self.published += 1;
            self.notify.notify_one();
        } else {
            self.dropped += 1;
        }
    }
}
