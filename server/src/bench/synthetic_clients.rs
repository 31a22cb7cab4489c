//! The client side of synthetic users behind a VE loop's rings: their joins queued on the command ring with
//! the VE's ends of their rings, and each user's turn (drain the snapshot ring, decode the newest frame,
//! answer with an uplink). Shared by the real-time run and the loop's back-to-back benchmark.

use std::sync::Arc;

use kinloop_linkage::math::space::Space;
use kinloop_linkage::model::Model;
use kinloop_protocol::{codec, Datagram, SessionShape};
use rtrb::{Consumer, Producer, RingBuffer};
use tokio::sync::oneshot;

use crate::core::{JoinRequest, Joined};
use crate::driver::ve_thread;
use crate::gateway::{take_latest_frame, ArrivedUplink, Command, UserLink, FRAME_HEADER};
use crate::synthetic::SyntheticUser;

/// The client's side of one synthetic user: its ends of the user's rings and the user who reads the
/// snapshots and writes the uplinks.
pub(super) struct SyntheticClient {
    uplinks: Producer<ArrivedUplink>,
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
            let _ = self.uplinks.push(ArrivedUplink::now(*sample));
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
    /// One join per request, for users of `model`, their snapshot rings sized as the server sizes them (four
    /// of the largest snapshot); `None` when the command ring refuses one.
    pub(super) fn queue<S: Space>(model: &Model<S>, requests: &[JoinRequest]) -> Option<Self> {
        let users = requests.len();
        let (mut command_tx, commands) = RingBuffer::new(users.max(1) + 4);
        let ring_bytes = 4 * (FRAME_HEADER + ve_thread::snapshot_size_bound::<S>(model.nv(), model.nc()));
        let mut clients = Vec::with_capacity(users);
        let mut replies = Vec::with_capacity(users);
        for request in requests {
            let (uplink_tx, uplink_rx) = RingBuffer::new(64);
            let (snapshot_tx, snapshot_rx) = RingBuffer::new(ring_bytes);
            let (reply_tx, reply_rx) = oneshot::channel();
            let link = UserLink { uplinks: uplink_rx, snapshots: snapshot_tx, notify: Arc::default() };
            let command = Command::Join { request: request.clone(), round_trip: None, link, reply: reply_tx };
            command_tx.push(command).ok()?;
            clients.push(SyntheticClient {
                uplinks: uplink_tx,
                snapshots: snapshot_rx,
                user: SyntheticUser::new(users),
            });
            replies.push(reply_rx);
        }
        Some(SyntheticJoins { commands, clients, replies })
    }
}
