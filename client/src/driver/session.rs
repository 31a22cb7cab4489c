//! One live session on the network side: its control stream, the snapshots it receives for the haptic
//! loop, and the loop's reports it logs (the uplinks leave through `super::uplinks`).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use kinloop_linkage::math::space::Space;
use kinloop_protocol::quic::{ConnectedSession, DatagramReceiver};
use kinloop_protocol::{Control, Datagram, Welcome};

use super::rt_loop::{LoopReport, LoopShared};
use crate::core::HapticCore;

/// Counters the network side keeps.
#[derive(Debug, Default)]
pub(super) struct NetShared {
    pub(super) snapshots_received: AtomicU64,
    pub(super) uplinks_sent: AtomicU64,
    /// Uplinks dropped unsent because newer ones were queued behind them (`uplinks::BACKLOG`).
    pub(super) uplinks_superseded: AtomicU64,
    pub(super) reconnects: AtomicU64,
    pub(super) rtt_ms: Mutex<Vec<f64>>,
    pub(super) last_report: Mutex<Option<LoopReport>>,
    pub(super) fatal: Mutex<Option<String>>,
    /// The newest signed room state a server sent (`Control::RoomState`), offered to the next server.
    pub(super) room_state: Mutex<Option<kinloop_protocol::RoomState>>,
    /// Offered states a server resumed from, and ones it refused.
    pub(super) resumes: AtomicU64,
    pub(super) resumes_refused: AtomicU64,
    /// A session whose server sends nothing for this long is lost (`None`: only when QUIC says so).
    pub(super) silence_limit: Option<Duration>,
    /// What QUIC itself counted, over every session.
    pub(super) quic: QuicTally,
}

/// What QUIC counted of a client's datagrams: frames that left in packets, frames that arrived, packets
/// declared lost. Beside the client's own counts, they tell where an uplink or a snapshot went missing
/// (never queued, dropped from QUIC's send buffer, lost on the way, or dropped from a receive buffer).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct QuicCounts {
    /// Datagram frames sent (uplinks).
    pub datagrams_transmitted: u64,
    /// Datagram frames received (snapshots), before the receive buffer.
    pub datagrams_arrived: u64,
    /// Packets this client sent that QUIC declared lost.
    pub packets_lost: u64,
}

impl QuicCounts {
    fn of(connection: &kinloop_protocol::quic::Connection) -> Self {
        let s = connection.stats();
        QuicCounts {
            datagrams_transmitted: s.frame_tx.datagram,
            datagrams_arrived: s.frame_rx.datagram,
            packets_lost: s.path.lost_packets,
        }
    }

    fn plus(self, other: QuicCounts) -> Self {
        QuicCounts {
            datagrams_transmitted: self.datagrams_transmitted + other.datagrams_transmitted,
            datagrams_arrived: self.datagrams_arrived + other.datagrams_arrived,
            packets_lost: self.packets_lost + other.packets_lost,
        }
    }
}

/// [`QuicCounts`] of the sessions that ended, and of the live one as last looked at.
#[derive(Debug, Default)]
pub(super) struct QuicTally {
    ended: Mutex<QuicCounts>,
    live: Mutex<QuicCounts>,
}

impl QuicTally {
    /// Looks at the live session's counters.
    pub(super) fn observe(&self, connection: &kinloop_protocol::quic::Connection) {
        if let Ok(mut live) = self.live.lock() {
            *live = QuicCounts::of(connection);
        }
    }

    /// The live session ended: its counters join the ended sessions'.
    pub(super) fn session_ended(&self, connection: &kinloop_protocol::quic::Connection) {
        if let (Ok(mut ended), Ok(mut live)) = (self.ended.lock(), self.live.lock()) {
            *ended = ended.plus(QuicCounts::of(connection));
            *live = QuicCounts::default();
        }
    }

    /// Every session's counts so far.
    pub(super) fn total(&self) -> QuicCounts {
        let ended = self.ended.lock().map(|c| *c).unwrap_or_default();
        ended.plus(self.live.lock().map(|c| *c).unwrap_or_default())
    }
}

/// The network side's ends of the rings.
pub(super) struct NetRings<S: Space> {
    pub(super) snapshots: rtrb::Producer<(Instant, kinloop_protocol::Snapshot)>,
    pub(super) spent_snapshots: rtrb::Consumer<kinloop_protocol::Snapshot>,
    pub(super) cores: rtrb::Producer<Box<HapticCore<S>>>,
    pub(super) spent_cores: rtrb::Consumer<Box<HapticCore<S>>>,
    pub(super) reports: rtrb::Consumer<LoopReport>,
}

pub(super) fn drain_reports<S: Space>(rings: &mut NetRings<S>, net: &NetShared) {
    while let Ok(report) = rings.reports.pop() {
        tracing::info!(
            elapsed_s = report.elapsed.as_secs_f64(),
            constraint_count = report.constraint_count,
            gain = report.gain,
            snapshot_age_ms = report.snapshot_age.map(|a| a.as_secs_f64() * 1e3),
            tracking_rms_mm = report.core.tracking_error_rms() * 1e3,
            max_force_ratio = report.core.max_force_ratio,
            "haptic loop"
        );
        if let Ok(mut last) = net.last_report.lock() {
            *last = Some(report);
        }
    }
    while rings.spent_snapshots.pop().is_ok() {}
    while rings.spent_cores.pop().is_ok() {}
}

/// A live session: the connection, the control stream's sending half, and a task reading its other half.
pub(super) struct Session {
    pub(super) connection: kinloop_protocol::quic::Connection,
    send: kinloop_protocol::quic::SendStream,
    control: tokio::sync::mpsc::Receiver<Result<Control, String>>,
    reader: tokio::task::JoinHandle<()>,
    pub(super) welcome: Welcome,
}

impl Session {
    /// Takes over a connected session; its control stream is read by a task of its own so that a frame
    /// half-read when another event wins a `select!` is never lost.
    pub(super) fn adopt(connected: ConnectedSession) -> Self {
        let ConnectedSession { connection, send, mut recv, welcome, .. } = connected;
        let (tx, control) = tokio::sync::mpsc::channel(16);
        let reader = tokio::spawn(async move {
            loop {
                let message = kinloop_protocol::quic::recv_control(&mut recv).await.map_err(|e| e.to_string());
                let failed = message.is_err();
                if tx.send(message).await.is_err() || failed {
                    break;
                }
            }
        });
        Session { connection, send, control, reader, welcome }
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

pub(super) async fn leave(session: &mut Session) {
    let bye = Control::Leave { reason: "client shutting down".into() };
    let _ =
        tokio::time::timeout(Duration::from_millis(200), kinloop_protocol::quic::send_control(&mut session.send, &bye))
            .await;
    session.connection.close(kinloop_protocol::quic::close_codes::NORMAL, b"bye");
}

/// Receives snapshots and answers the control stream until the session ends or the client stops.
pub(super) async fn serve_session<S: Space>(
    session: &mut Session,
    rings: &mut NetRings<S>,
    shared: &LoopShared,
    net: &NetShared,
) -> String {
    // The handshake and the join have measured the round trip already: the core knows the delay from the
    // session's first tick rather than from the first pong, a round trip later (until then it would pull the
    // local model toward the VE as fast as on a LAN).
    shared.set_round_trip(session.connection.rtt());
    let scene = &session.welcome.scene;
    let shape = scene.shape();
    let mut receiver = DatagramReceiver::new(session.connection.clone(), shape);
    let mut ping = tokio::time::interval(Duration::from_millis(250));
    let mut housekeeping = tokio::time::interval(Duration::from_millis(50));
    let epoch = Instant::now();
    let mut nonce = 0u64;
    let mut heard = Instant::now();
    loop {
        tokio::select! {
            datagram = receiver.recv() => match datagram {
                Ok(Datagram::Snapshot(snapshot)) => {
                    heard = Instant::now();
                    net.snapshots_received.fetch_add(1, Ordering::Relaxed);
                    while rings.spent_snapshots.pop().is_ok() {}
                    // A full ring means the loop is behind: this snapshot is dropped, a newer one follows.
                    let _ = rings.snapshots.push((heard, snapshot));
                }
                Ok(Datagram::Uplink(_)) => {}
                Err(e) if e.is_fatal() => return e.to_string(),
                Err(e) => tracing::debug!(error = %e, "datagram refused"),
            },
            message = session.control.recv() => match message {
                Some(Ok(Control::Pong { t_s, .. })) => {
                    let rtt_ms = (epoch.elapsed().as_secs_f64() - t_s) * 1e3;
                    if let Ok(rtt) = Duration::try_from_secs_f64(rtt_ms * 1e-3) {
                        shared.set_round_trip(rtt);
                        if let Ok(mut r) = net.rtt_ms.lock() {
                            if r.len() < 100_000 {
                                r.push(rtt_ms);
                            }
                        }
                    }
                }
                Some(Ok(Control::Ping { nonce, t_s })) => {
                    let _ = kinloop_protocol::quic::send_control(&mut session.send, &Control::Pong { nonce, t_s }).await;
                }
                Some(Ok(Control::RoomState(state))) => {
                    if let Ok(mut newest) = net.room_state.lock() {
                        *newest = Some(state);
                    }
                }
                Some(Ok(Control::Leave { reason })) => return format!("the server left: {reason}"),
                Some(Ok(Control::Error { code, message })) => return format!("the server reported {code}: {message}"),
                Some(Ok(_)) => {}
                Some(Err(e)) => return format!("control stream: {e}"),
                None => return "control stream closed".into(),
            },
            _ = ping.tick() => {
                nonce += 1;
                let message = Control::Ping { nonce, t_s: epoch.elapsed().as_secs_f64() };
                if let Err(e) = kinloop_protocol::quic::send_control(&mut session.send, &message).await {
                    return format!("control stream: {e}");
                }
            },
            _ = housekeeping.tick() => {
                drain_reports(rings, net);
                net.quic.observe(&session.connection);
                if shared.stop.load(Ordering::Relaxed) {
                    return "stopping".into();
                }
                if let Some(limit) = net.silence_limit.filter(|limit| heard.elapsed() > *limit) {
                    return format!("the server sent nothing for {:.2} s (limit {:.2} s)", heard.elapsed().as_secs_f64(), limit.as_secs_f64());
                }
            },
            reason = session.connection.closed() => return reason.to_string(),
        }
    }
}
