//! One client's session on the network side: handshake (token, then the VE thread's decision), then three
//! tasks: uplinks in, snapshots out, and the control stream (ping, leave, shutdown).

use std::sync::atomic::Ordering;
use std::sync::Arc;

use bytes::Bytes;
use kinloop_protocol::quic::{
    accept_resuming, close_codes, recv_control, send_control, AcceptError, AcceptedSession, DatagramReceiver,
    DatagramSender, Incoming, Route,
};
use kinloop_protocol::{
    uplink_flags, Control, Datagram, RefusalReason, Refused, ResumeAnswer, ResumeRefusal, RoomState,
};
use rtrb::RingBuffer;
use tokio::sync::{oneshot, Notify};

use super::rooms::admin::serve_admin;
use super::rooms::Host;
use super::Shared;
use crate::core::{JoinRequest, UplinkSample};
use crate::gateway::{take_latest_frame, ArrivedUplink, Command, UserCounters, UserEntry, UserLink};

/// Uplinks waiting for the VE thread per user (about 64 ms at 1 kHz).
const UPLINK_RING: usize = 64;

fn refused(reason: RefusalReason) -> Refused {
    Refused { reason, message: String::new() }
}

/// Says why a handshake closed without a session, at a level matching whose doing it was: the server's own
/// failure (a welcome its wire checks reject) is an error, a refusal or a broken handshake a warning, a
/// client that chose to leave an information.
fn log_handshake_end(remote: std::net::SocketAddr, error: &AcceptError) {
    match error {
        AcceptError::InvalidWelcome(_) => tracing::error!(%remote, %error, "handshake ended without a session"),
        AcceptError::Declined(_) => tracing::info!(%remote, %error, "handshake ended without a session"),
        _ => tracing::warn!(%remote, %error, "handshake ended without a session"),
    }
}

/// Serves one incoming connection to its end: a session in the room its hello names, or an admin command.
pub async fn serve(incoming: Incoming, host: Arc<Host>) {
    let remote = incoming.remote_address();
    let mut ends = None;
    let routed: std::sync::OnceLock<Arc<Shared>> = std::sync::OnceLock::new();
    let (slot, routed_ref) = (&mut ends, &routed);
    let admit = |hello: &kinloop_protocol::Hello| {
        let shared = host.route(hello).map_err(refused)?;
        shared.access.admit(&hello.token, hello.role).map_err(refused)?;
        let info = shared.scene_info.clone();
        let _ = routed_ref.set(shared);
        Ok(info)
    };
    let resume = |offer: RoomState| async move {
        match routed_ref.get() {
            Some(shared) => resume(shared, remote, offer).await,
            None => ResumeAnswer::Refused(ResumeRefusal::NoRoomKey),
        }
    };
    let handshake = accept_resuming(incoming, admit, resume, move |hello, join, round_trip| async move {
        let shared = routed_ref.get().ok_or_else(|| refused(RefusalReason::Malformed { what: "no room".into() }))?;
        shared
            .executor
            .admit_user(&shared.cell)
            .map_err(|over| refused(RefusalReason::OverBudget { what: over.what }))?;
        let (uplink_tx, uplink_rx) = RingBuffer::new(UPLINK_RING);
        let (snapshot_tx, snapshot_rx) = RingBuffer::new(shared.gateway.snapshot_ring_bytes);
        let notify = Arc::new(Notify::new());
        let (reply_tx, reply_rx) = oneshot::channel();
        let link = UserLink { uplinks: uplink_rx, snapshots: snapshot_tx, notify: notify.clone() };
        // The round trip QUIC measured over the handshake: the server's own view of the link (see `design`).
        let request = JoinRequest::from_handshake(&hello, &join);
        let command = Command::Join { request, round_trip: Some(round_trip), link, reply: reply_tx };
        let shutting_down = || refused(RefusalReason::Malformed { what: "the server is shutting down".into() });
        shared.gateway.commands.send(command).await.map_err(|_| shutting_down())?;
        let joined = reply_rx.await.map_err(|_| shutting_down())?.map_err(refused)?;
        *slot = Some((joined.user_id, uplink_tx, snapshot_rx, notify));
        Ok(joined.welcome)
    });
    let session = match handshake.await {
        Ok(session) => session,
        Err(AcceptError::Admin(admin)) => return serve_admin(admin, &host).await,
        Err(error) => {
            // The VE may have admitted the user before the handshake failed (the welcome could not be sent:
            // the client had gone); it leaves now, not at the next restart.
            if let (Some((user, ..)), Some(shared)) = (ends, routed.get()) {
                let _ = shared.gateway.commands.send(Command::Leave { user }).await;
            }
            // Never the hello itself: it carries the token.
            log_handshake_end(remote, &error);
            return;
        }
    };
    let (Some((_, uplink_tx, snapshot_rx, notify)), Some(shared)) = (ends, routed.get()) else { return };
    run_session(session, shared.clone(), uplink_tx, snapshot_rx, notify).await;
}

/// Decides on a state a client offers: the room key's checks here, the fit to the linkage in the VE. A
/// refusal is said in the log with what the room goes on from.
async fn resume(shared: &Shared, remote: std::net::SocketAddr, offer: RoomState) -> ResumeAnswer {
    let decided = async {
        let room = shared.room.as_ref().ok_or(ResumeRefusal::NoRoomKey)?;
        room.check(&offer)?;
        let (reply, decision) = oneshot::channel();
        let command = Command::Resume { q: offer.q.clone(), qd: offer.qd.clone(), reply };
        let gone = ResumeRefusal::Shape { what: "the server is shutting down".into() };
        shared.gateway.commands.send(command).await.map_err(|_| gone.clone())?;
        decision.await.map_err(|_| gone)?
    };
    match decided.await {
        Ok(()) => {
            tracing::info!(%remote, ve_step = offer.ve_step, "resuming the room from the state the client offered");
            ResumeAnswer::Resumed { ve_step: offer.ve_step }
        }
        Err(refusal) => {
            let from = if matches!(refusal, ResumeRefusal::RoomLive { .. }) {
                "its live state"
            } else {
                "where it is (q0 when new)"
            };
            tracing::warn!(%remote, %refusal, "refused the offered room state; the room goes on from {from}");
            ResumeAnswer::Refused(refusal)
        }
    }
}

async fn run_session(
    session: AcceptedSession,
    shared: Arc<Shared>,
    mut uplinks: rtrb::Producer<ArrivedUplink>,
    snapshots: rtrb::Consumer<u8>,
    notify: Arc<Notify>,
) {
    let AcceptedSession { connection, mut send, mut recv, hello, join, welcome } = session;
    let user = welcome.user_id;
    let counters = Arc::new(UserCounters::default());
    counters.connected.store(true, Ordering::Relaxed);
    shared.gateway.users.register(UserEntry {
        user_id: user,
        name: hello.client_name.clone(),
        role: hello.role,
        device: join.device.name.clone(),
        op: welcome.scene.op_name.clone(),
        connection: connection.clone(),
        counters: counters.clone(),
    });
    let fleet_user = crate::fleet::user_label(&shared.name, &hello.client_name, user);
    shared.tell_fleet(crate::fleet::FleetEvent::UserJoined { user: fleet_user.clone() });
    tracing::info!(user, name = %hello.client_name, role = ?hello.role, op = %welcome.scene.op_name, position_scale = welcome.mapping.position_scale, force_scale = welcome.mapping.force_scale, coupling_stiffness = ?welcome.coupling.stiffness, coupling_damping = ?welcome.coupling.damping, remote = %connection.remote_address(), "session started");

    let receive = {
        let counters = counters.clone();
        let mut receiver = DatagramReceiver::new(connection.clone(), shared.gateway.shape);
        tokio::spawn(async move {
            let mut last_seq: Option<u64> = None;
            loop {
                match receiver.recv().await {
                    Ok(Datagram::Uplink(uplink)) => {
                        counters.uplinks_received.fetch_add(1, Ordering::Relaxed);
                        match last_seq {
                            Some(last) if uplink.seq > last + 1 => {
                                counters.uplinks_lost.fetch_add(uplink.seq - last - 1, Ordering::Relaxed);
                            }
                            _ => {}
                        }
                        last_seq = Some(last_seq.map_or(uplink.seq, |last| last.max(uplink.seq)));
                        if uplink.flags & uplink_flags::CLAMPED != 0 {
                            counters.uplinks_clamped.fetch_add(1, Ordering::Relaxed);
                        }
                        counters.poses.store(&uplink.device_pose, &uplink.model_pose);
                        let counter = match UplinkSample::from_uplink(&uplink) {
                            Ok(sample) if uplinks.push(ArrivedUplink::now(sample)).is_ok() => None,
                            Ok(_) => Some(&counters.uplinks_dropped),
                            Err(_) => Some(&counters.uplinks_undecodable),
                        };
                        if let Some(counter) = counter {
                            counter.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Ok(Datagram::Snapshot(_)) => drop(counters.uplinks_undecodable.fetch_add(1, Ordering::Relaxed)),
                    Err(error) if error.is_fatal() => break,
                    Err(_) => drop(counters.uplinks_undecodable.fetch_add(1, Ordering::Relaxed)),
                }
            }
        })
    };
    let transmit = spawn_transmit(user, connection.clone(), counters.clone(), snapshots, notify);

    let mut shutdown = shared.shutdown.subscribe();
    let mut room_tick = tokio::time::interval(super::room::ROOM_STATE_PERIOD);
    room_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let reason = loop {
        if *shutdown.borrow() {
            let closed = shared.cell.closed_reason();
            // The newest state first, so that the server the client moves to resumes the room where it is
            // (not when the room's simulation failed: that state is not to be trusted).
            if let Some(state) = shared.room.as_ref().filter(|_| closed.is_none()).and_then(|r| r.signed_latest()) {
                let _ = send_control(&mut send, &Control::RoomState(state)).await;
            }
            let reason = closed.or_else(|| shared.leave_reason.lock().ok().map(|r| r.clone())).unwrap_or_default();
            let _ = send_control(&mut send, &Control::Leave { reason }).await;
            let _ = send.finish();
            let _ = tokio::time::timeout(shared.drain, connection.closed()).await;
            break "room closed";
        }
        tokio::select! {
            message = recv_control(&mut recv) => match message {
                Ok(Control::Leave { .. }) => break "client left",
                Ok(Control::Ping { nonce, t_s }) => {
                    if send_control(&mut send, &Control::Pong { nonce, t_s }).await.is_err() {
                        break "control stream failed";
                    }
                }
                Ok(other) => tracing::debug!(user, message = other.kind_name(), "ignored control message"),
                Err(_) => break "connection lost",
            },
            _ = room_tick.tick(), if shared.room.is_some() => {
                let state = shared.room.as_ref().and_then(|room| room.signed_latest());
                if let Some(state) = state {
                    if send_control(&mut send, &Control::RoomState(state)).await.is_err() {
                        break "control stream failed";
                    }
                }
            }
            _ = shutdown.changed() => {}
        }
    };
    // Best effort: if the VE thread is gone the user is gone with it.
    let _ = shared.gateway.commands.send(Command::Leave { user }).await;
    connection.close(close_codes::NORMAL, b"bye");
    receive.abort();
    transmit.abort();
    let _ = counters.ended.set(reason);
    counters.connected.store(false, Ordering::Relaxed);
    shared.tell_fleet(crate::fleet::FleetEvent::UserLeft { user: fleet_user });
    tracing::info!(user, reason, "session ended");
}

/// The user's snapshot sender: on each notification, the newest encoded snapshot the VE thread left in the
/// user's ring goes out as a datagram (or a stream when too large), counted.
fn spawn_transmit(
    user: u32,
    connection: kinloop_protocol::quic::Connection,
    counters: Arc<UserCounters>,
    mut snapshots: rtrb::Consumer<u8>,
    notify: Arc<Notify>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let sender = DatagramSender::new(connection.clone());
        let mut frame = Vec::new();
        loop {
            tokio::select! {
                _ = notify.notified() => {}
                _ = connection.closed() => break,
            }
            if take_latest_frame(&mut snapshots, &mut frame) == 0 {
                continue;
            }
            match sender.send_encoded(Bytes::copy_from_slice(&frame)) {
                Ok(route) => {
                    counters.snapshots_sent.fetch_add(1, Ordering::Relaxed);
                    counters.snapshot_bytes.fetch_add(frame.len() as u64, Ordering::Relaxed);
                    if route == Route::Stream {
                        counters.snapshots_oversize.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(error) => {
                    tracing::debug!(user, %error, "snapshot not sent; ending the sender");
                    break;
                }
            }
        }
    })
}
