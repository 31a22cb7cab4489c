//! `server/ve_loop_users_N`: the VE loop's whole iteration back to back, as the real-time thread runs it
//! less its wait: the same [`VeLoop`] (the function the driver calls each deadline), its users' rings and
//! their consumers. Between iterations each synthetic client drains its snapshot ring, decodes the newest
//! frame and pushes its next uplink (not timed, and on the same thread: the rings' lines stay in this core's
//! caches, where in real time the consumer's core last held them).

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::{Planar, Space};
use kinloop_linkage::model::Model;
use kinloop_protocol::{codec, Datagram, SessionShape};
use rtrb::{Consumer, Producer, RingBuffer};
use tokio::sync::oneshot;

use super::{join_request, testbed, BenchError};
use crate::core::{Joined, UplinkSample, VeConfig, VeCore, VeEvent};
use crate::driver::ve_thread::{self, VeLoop, VeThreadIo};
use crate::gateway::{take_latest_frame, Command, UserLink, VeLoopStats, FRAME_HEADER};
use crate::synthetic::SyntheticUser;

/// The client's side of one synthetic user: its ends of the user's rings and the user who reads the
/// snapshots and writes the uplinks.
pub(super) struct SyntheticClient {
    uplinks: Producer<UplinkSample>,
    snapshots: Consumer<u8>,
    user: SyntheticUser,
}

impl SyntheticClient {
    /// Takes the newest snapshot in the ring, if any, and answers it with an uplink (sequence `seq`, time
    /// `time_s`); true when there was one.
    pub(super) fn exchange(&mut self, seq: u64, time_s: f64, frame: &mut Vec<u8>, shape: &SessionShape) -> bool {
        if take_latest_frame(&mut self.snapshots, frame) == 0 {
            return false;
        }
        if let Ok(Datagram::Snapshot(s)) = codec::decode_datagram(frame, shape) {
            self.user.on_snapshot(&s);
        }
        if let Some(sample) = self.user.uplink(seq, time_s) {
            let _ = self.uplinks.push(*sample);
        }
        true
    }
}

/// Synthetic users' joins, queued: the VE's end of the command ring (one join per user, carrying the VE's
/// ends of that user's rings), each user's client side, and where each join's answer will come.
pub(super) struct SyntheticJoins {
    /// The VE's end of the command ring.
    pub commands: Consumer<Command>,
    /// Each user's client side, in join order.
    pub clients: Vec<SyntheticClient>,
    /// Each user's join answer, in join order.
    pub replies: Vec<oneshot::Receiver<Result<Joined, kinloop_protocol::RefusalReason>>>,
}

impl SyntheticJoins {
    /// Joins for `users` users of `model`'s first operational point, their snapshot rings sized as the
    /// server sizes them (four of the largest snapshot).
    pub(super) fn queue<S: Space>(model: &Model<S>, users: usize) -> Result<Self, BenchError> {
        let (mut command_tx, commands) = RingBuffer::new(users.max(1) + 4);
        let ring_bytes = 4 * (FRAME_HEADER + ve_thread::snapshot_size_bound::<S>(model.nv(), model.nc()));
        let mut clients = Vec::with_capacity(users);
        let mut replies = Vec::with_capacity(users);
        for i in 0..users {
            let (uplink_tx, uplink_rx) = RingBuffer::new(64);
            let (snapshot_tx, snapshot_rx) = RingBuffer::new(ring_bytes);
            let (reply_tx, reply_rx) = oneshot::channel();
            let link = UserLink { uplinks: uplink_rx, snapshots: snapshot_tx, notify: Arc::default() };
            let command = Command::Join { request: join_request(model, i, S::DIM), link, reply: reply_tx };
            if command_tx.push(command).is_err() {
                return Err(BenchError::Thread("command ring"));
            }
            clients.push(SyntheticClient {
                uplinks: uplink_tx,
                snapshots: snapshot_rx,
                user: SyntheticUser::new(users),
            });
            replies.push(reply_rx);
        }
        Ok(SyntheticJoins { commands, clients, replies })
    }
}

/// The VE loop on the testbed with `users` synthetic users behind its rings (all on `link2`, as
/// [`super::TickBench`]), iterated back to back.
pub struct LoopBench {
    ve: VeLoop<Planar>,
    clients: Vec<SyntheticClient>,
    events: Consumer<VeEvent>,
    stats: Consumer<VeLoopStats>,
    shape: SessionShape,
    frame: Vec<u8>,
    seq: u64,
}

impl LoopBench {
    /// Joins the users (the first iteration serves their joins) and iterates `warm_up` times more; the
    /// loop's timing starts after.
    pub fn new(users: usize, warm_up: u64) -> Result<Self, BenchError> {
        let model = testbed()?;
        let shape = SessionShape::of_model(&model);
        let mut config = VeConfig::paper();
        config.max_users = users.max(1);
        let core = VeCore::new(model.clone(), config)?;
        let joins = SyntheticJoins::queue(&model, users)?;
        let (event_tx, events) = RingBuffer::new(1024);
        let (stats_tx, stats) = RingBuffer::new(4);
        let io = VeThreadIo {
            commands: joins.commands,
            events: event_tx,
            stats: stats_tx,
            record: None,
            view: None,
            room: None,
            stop: Arc::new(AtomicBool::new(false)),
        };
        let ve = VeLoop::new(core, io, Instant::now());
        let mut bench = LoopBench { ve, clients: joins.clients, events, stats, shape, frame: Vec::new(), seq: 0 };
        bench.iterate();
        for (index, mut reply) in joins.replies.into_iter().enumerate() {
            match reply.try_recv() {
                Ok(Ok(_)) => {}
                Ok(Err(reason)) => return Err(BenchError::Refused { index, reason }),
                Err(_) => return Err(BenchError::Thread("VE loop")),
            }
        }
        for _ in 0..warm_up {
            bench.iterate();
        }
        bench.ve.restart_timing();
        Ok(bench)
    }

    /// One timed iteration of the loop, after the clients' turn; returns its time.
    pub fn iterate(&mut self) -> Duration {
        self.seq += 1;
        let time_s = self.seq as f64 * 1e-3;
        for client in &mut self.clients {
            client.exchange(self.seq, time_s, &mut self.frame, &self.shape);
        }
        while self.events.pop().is_ok() {}
        while self.stats.pop().is_ok() {}
        let start = Instant::now();
        self.ve.tick_back_to_back();
        start.elapsed()
    }

    /// The loop's statistics so far (its step and stage percentiles are of the iterations since the
    /// warm-up).
    pub fn finish(self) -> VeLoopStats {
        self.ve.finish()
    }
}

/// Mean ns of one VE loop iteration with `users` users (see [`LoopBench`]), `iters` timed after `iters / 10`
/// of warm-up.
pub fn ve_loop_users(users: usize, iters: u64) -> Result<f64, BenchError> {
    let mut bench = LoopBench::new(users, (iters / 10).max(10))?;
    let total: Duration = (0..iters).map(|_| bench.iterate()).sum();
    Ok(total.as_nanos() as f64 / iters.max(1) as f64)
}

/// The loop's statistics over `iters` back-to-back iterations with `users` users, after `iters / 10` of
/// warm-up: its step's and each stage's percentiles, as the real-time loop reports them.
pub fn ve_loop_stats(users: usize, iters: u64) -> Result<VeLoopStats, BenchError> {
    let mut bench = LoopBench::new(users, (iters / 10).max(10))?;
    for _ in 0..iters {
        bench.iterate();
    }
    Ok(bench.finish())
}
