//! The server's stats report: the VE thread's numbers, each user's network-side numbers and the view's.

use serde::Serialize;

use crate::gateway::VeLoopStats;

/// Network-side numbers of one user.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct UserStats {
    /// Id in the VE.
    pub user_id: u32,
    /// Client name.
    pub name: String,
    /// `manipulator` or `observer`.
    pub role: String,
    /// QUIC's smoothed round-trip time (ms).
    pub rtt_ms: f64,
    /// Uplinks received (decoded).
    pub uplinks_received: u64,
    /// Uplinks missing from the sequence numbers received.
    pub uplinks_lost: u64,
    /// `lost / (received + lost)`.
    pub uplink_loss: f64,
    /// Datagrams the codec refused.
    pub uplinks_undecodable: u64,
    /// Uplinks received that the VE's ring had no room for.
    pub uplinks_dropped: u64,
    /// Datagram frames QUIC took off the wire from this user (uplinks). More than `uplinks_received`: the
    /// rest waited in QUIC's receive buffer longer than newer ones let them (oldest dropped).
    pub datagrams_arrived: u64,
    /// Datagram frames QUIC put on the wire to this user (snapshots).
    pub datagrams_transmitted: u64,
    /// Packets the server sent on this connection that QUIC declared lost.
    pub packets_lost: u64,
    /// Snapshots sent.
    pub snapshots_sent: u64,
    /// Bytes of snapshots sent.
    pub snapshot_bytes: u64,
    /// Snapshots that went on a stream because they exceeded the datagram size.
    pub snapshots_oversize: u64,
    /// Uplinks flagged `CLAMPED` (the client clamped its command to the device's limits).
    pub uplinks_clamped: u64,
    /// Still connected.
    pub connected: bool,
    /// Why the session ended, once it has (the reason `session ended` logs).
    pub ended: Option<&'static str>,
}

/// Everything `--stats-every` logs and `--json` prints.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ServerStats {
    /// Seconds since start.
    pub uptime_s: f64,
    /// VE rate (Hz).
    pub ve_rate_hz: f64,
    /// The VE thread.
    pub ve: VeLoopStats,
    /// Users present now.
    pub users: u32,
    /// QUIC connections open now: the users' and those of clients still in (or just out of) their handshake.
    pub connections: usize,
    /// Every user since start.
    pub per_user: Vec<UserStats>,
    /// The web view (`--view`), when served.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub view: Option<crate::view::ViewStats>,
}
