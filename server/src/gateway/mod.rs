//! What the driver and the view share, below both: the command ring to the VE thread ([`Command`],
//! [`UserLink`]), the registry of admitted users ([`UserRegistry`]), the snapshot frames a user's ring
//! carries ([`push_frame`], [`take_latest_frame`]) and the VE thread's timing statistics ([`VeLoopStats`]).
//! The driver builds a [`Gateway`] and starts the view with it; neither imports the other's internals.

mod commands;
mod frames;
mod loop_stats;
mod users;

pub use commands::{ArrivedUplink, Command, CommandSender, UserLink};
pub use frames::{prefetch_next_frame, push_frame, take_latest_frame, FRAME_HEADER};
pub use loop_stats::{LatencyHistogram, Percentiles, StageHistograms, StageTimes, VeLoopStats};
pub use users::{PoseTap, UserCounters, UserEntry, UserRegistry};

use std::sync::Arc;

use kinloop_protocol::SessionShape;

/// The network side's handles on a running VE: what a QUIC session and the view's socket both need to
/// admit a user, feed it and let it go.
pub struct Gateway {
    /// Joins and leaves to the VE thread.
    pub commands: Arc<CommandSender>,
    /// Every user admitted since start.
    pub users: UserRegistry,
    /// The sizes of the session's messages (uplink pose, snapshot), for decoding.
    pub shape: SessionShape,
    /// Capacity (bytes) of each user's snapshot ring.
    pub snapshot_ring_bytes: usize,
}
