//! One page's WebSocket: hello, admission, then a writer task (frames and replies) beside the reader loop
//! (messages, and a grab's snapshots from the VE, which pace the grab's uplinks).
//!
//! Bad input never ends the server's day: an unparsable, oversized or senseless message gets an `error`
//! reply and is counted; drag and seek events over [`MAX_EVENTS_PER_S`] are dropped and counted (one
//! notice per second); [`MAX_MALFORMED`] bad messages close the page.

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket};
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use kinloop_protocol::{codec, Datagram, LocalModelForm, Role};
use rtrb::RingBuffer;
use tokio::sync::{mpsc, oneshot, Notify};

use super::compose::UserInfo;
use super::grab::Grip;
use super::messages::{FromPage, ToPage, Welcome, VERSION};
use super::{short, Counter, Source, ViewShared, MAX_EVENTS_PER_S, MAX_MESSAGE_BYTES};
use crate::core::JoinRequest;
use crate::gateway::{take_latest_frame, ArrivedUplink, Command, Gateway, UserLink};

/// A page has this long to send `auth`.
const AUTH_PATIENCE: Duration = Duration::from_secs(30);
/// Bad messages a page may send before it is closed.
pub const MAX_MALFORMED: u32 = 100;
/// Replies waiting for a page's writer.
const OUTBOX: usize = 32;
/// Longest wait for the VE to admit a grab.
const JOIN_PATIENCE: Duration = Duration::from_secs(2);
/// A grab's uplinks waiting for the VE thread.
const UPLINK_RING: usize = 64;
/// Burst of drag/seek events allowed above the steady rate.
const EVENT_BURST: f64 = 10.0;

type Sink = SplitSink<WebSocket, Message>;
type Stream = SplitStream<WebSocket>;

fn text(message: &ToPage<'_>) -> Message {
    // Every `ToPage` serializes (no maps with non-string keys, no failing Serialize impls).
    Message::Text(serde_json::to_string(message).unwrap_or_default().into())
}

/// Serves one page to its end.
pub(crate) async fn serve(socket: WebSocket, view: Arc<ViewShared>) {
    view.counters.bump(Counter::PagesTotal);
    view.counters.bump(Counter::PagesOpen);
    let (mut sink, mut stream) = socket.split();
    let hello = ToPage::Hello {
        auth: if view.access.is_open() { "none" } else { "token" },
        mode: match view.source {
            Source::Live { .. } => "live",
            Source::Replay(_) => "replay",
        },
        version: VERSION,
        max_message_bytes: MAX_MESSAGE_BYTES,
    };
    if sink.send(text(&hello)).await.is_ok() {
        match tokio::time::timeout(AUTH_PATIENCE, admit(&mut stream, &view)).await {
            Ok(Ok(role)) => run(sink, stream, &view, role).await,
            Ok(Err(why)) => refuse(sink, &view, why).await,
            Err(_) => refuse(sink, &view, "no auth message within 30 s".into()).await,
        }
    }
    view.counters.drop_one(Counter::PagesOpen);
}

async fn refuse(mut sink: Sink, view: &ViewShared, message: String) {
    view.counters.bump(Counter::PagesRefused);
    let _ = sink.send(text(&ToPage::Refused { message })).await;
    let close = CloseFrame { code: 4003, reason: Utf8Bytes::from_static("refused") };
    let _ = sink.send(Message::Close(Some(close))).await;
}

/// Waits for `auth` and decides: `Ok(role)` or the refusal's text.
async fn admit(stream: &mut Stream, view: &ViewShared) -> Result<Role, String> {
    loop {
        let message = match stream.next().await {
            Some(Ok(Message::Text(t))) => t,
            Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return Err("the page closed".into()),
            Some(Ok(_)) => continue,
        };
        if message.len() > MAX_MESSAGE_BYTES {
            view.counters.bump(Counter::Oversize);
            return Err(format!("message of {} bytes; at most {MAX_MESSAGE_BYTES}", message.len()));
        }
        let token = match serde_json::from_str::<FromPage>(&message) {
            Ok(FromPage::Auth { token }) => token.unwrap_or_default(),
            Ok(_) => return Err("the first message must be auth".into()),
            Err(e) => {
                view.counters.bump(Counter::Malformed);
                return Err(short(format_args!("malformed auth message: {e}")));
            }
        };
        if view.access.is_open() {
            return Ok(if view.config.grab_without_token { Role::Manipulator } else { Role::Observer });
        }
        // A token without a role, or with `manipulator`, may grab; `observer` may watch.
        return match view.access.admit(&token, Role::Manipulator) {
            Ok(()) => Ok(Role::Manipulator),
            Err(_) if view.access.admit(&token, Role::Observer).is_ok() => Ok(Role::Observer),
            Err(_) => Err("unknown token: this view needs a valid token".into()),
        };
    }
}

async fn run(mut sink: Sink, mut stream: Stream, view: &Arc<ViewShared>, role: Role) {
    let can_grab = role == Role::Manipulator && matches!(&view.source, Source::Live { server: Some(_), .. });
    let replay = match &view.source {
        Source::Replay(r) => r.lock().ok().map(|r| r.info().clone()),
        Source::Live { .. } => None,
    };
    let welcome = Welcome {
        role: if role == Role::Manipulator { "manipulator" } else { "observer" },
        can_grab,
        scene: view.info.clone(),
        frame_rate_hz: view.config.frame_rate_hz,
        grab_reach_m: view.config.grab_reach_m,
        replay,
    };
    if sink.send(text(&ToPage::Welcome(Box::new(welcome)))).await.is_err() {
        return;
    }
    let (outbox, replies) = mpsc::channel(OUTBOX);
    let mut writer = tokio::spawn(write(sink, replies, view.clone()));
    let mut page = Page {
        view: view.clone(),
        outbox,
        can_grab,
        grab: None,
        epoch: Instant::now(),
        bucket: EVENT_BURST,
        bucket_at: Instant::now(),
        malformed: 0,
        last_drop_notice: None,
        frame: Vec::new(),
    };
    let mut shutdown = view.shutdown.subscribe();
    loop {
        let snapshots = page.grab.as_ref().map(|g| g.notify.clone());
        tokio::select! {
            message = stream.next() => match message {
                Some(Ok(Message::Text(t))) => page.handle(&t).await,
                Some(Ok(Message::Binary(_))) => page.malformed("binary messages are not understood".into()),
                Some(Ok(Message::Close(_))) | None => break,
                Some(Ok(_)) => {}
                Some(Err(error)) => {
                    // The transport's own limit ([`super::TRANSPORT_MAX_BYTES`]) or a broken socket.
                    if error.to_string().contains("too long") || error.to_string().contains("limit") {
                        view.counters.bump(Counter::Oversize);
                    }
                    break;
                }
            },
            _ = wait(snapshots) => page.pump(),
            _ = shutdown.changed() => break,
        }
        if page.malformed > MAX_MALFORMED {
            page.reply(ToPage::Error { message: format!("more than {MAX_MALFORMED} bad messages: closing") });
            break;
        }
    }
    page.release("the page closed");
    drop(page);
    // The writer ends once the outbox is closed and drained, unless the page stopped reading.
    if tokio::time::timeout(Duration::from_secs(1), &mut writer).await.is_err() {
        writer.abort();
    }
}

async fn wait(notify: Option<Arc<Notify>>) {
    match notify {
        Some(n) => n.notified().await,
        None => std::future::pending().await,
    }
}

/// Sends replies and (live) the hub's newest frame whenever it changes.
async fn write(mut sink: Sink, mut replies: mpsc::Receiver<Message>, view: Arc<ViewShared>) {
    let mut frames = match &view.source {
        Source::Live { frames, .. } => Some(frames.clone()),
        Source::Replay(_) => None,
    };
    if let Some(f) = frames.as_mut() {
        // The newest frame goes out at once: the first picture does not wait for the next tick.
        f.mark_changed();
    }
    loop {
        let message = tokio::select! {
            reply = replies.recv() => match reply {
                Some(m) => m,
                None => break,
            },
            changed = async {
                match frames.as_mut() {
                    Some(f) => f.changed().await,
                    None => std::future::pending().await,
                }
            } => {
                let Ok(()) = changed else { break };
                let newest = frames.as_mut().and_then(|f| f.borrow_and_update().clone());
                let Some(frame) = newest else { continue };
                view.counters.bump(Counter::FramesSent);
                Message::Text(frame.text)
            },
        };
        if sink.send(message).await.is_err() {
            return;
        }
    }
    let _ = sink.send(Message::Close(None)).await;
}

/// A grab in progress: the VE user and its rings. Dropping it (release, a closed page, a server shutting
/// down) tells the VE the user left.
struct Grab {
    server: Arc<Gateway>,
    user: u32,
    op: String,
    uplinks: rtrb::Producer<ArrivedUplink>,
    snapshots: rtrb::Consumer<u8>,
    notify: Arc<Notify>,
    grip: Grip,
    snapshot_period_s: f64,
}

impl Drop for Grab {
    fn drop(&mut self) {
        self.server.commands.leave_soon(self.user);
    }
}

struct Page {
    view: Arc<ViewShared>,
    outbox: mpsc::Sender<Message>,
    can_grab: bool,
    grab: Option<Grab>,
    epoch: Instant,
    bucket: f64,
    bucket_at: Instant,
    malformed: u32,
    last_drop_notice: Option<Instant>,
    frame: Vec<u8>,
}

impl Page {
    fn reply(&self, message: ToPage<'_>) {
        if self.outbox.try_send(text(&message)).is_err() {
            self.view.counters.bump(Counter::RepliesDropped);
        }
    }

    fn malformed(&mut self, message: String) {
        self.malformed += 1;
        self.view.counters.bump(Counter::Malformed);
        self.reply(ToPage::Error { message });
    }

    /// Takes one drag/seek token; false (counted, one notice per second) when over the rate.
    fn take_event(&mut self) -> bool {
        let now = Instant::now();
        let refill = now.duration_since(self.bucket_at).as_secs_f64() * MAX_EVENTS_PER_S;
        self.bucket = (self.bucket + refill).min(EVENT_BURST);
        self.bucket_at = now;
        if self.bucket >= 1.0 {
            self.bucket -= 1.0;
            self.view.counters.bump(Counter::EventsUsed);
            return true;
        }
        self.view.counters.bump(Counter::EventsDropped);
        if self.last_drop_notice.is_none_or(|at| now.duration_since(at) >= Duration::from_secs(1)) {
            self.last_drop_notice = Some(now);
            self.reply(ToPage::Error {
                message: format!("more than {MAX_EVENTS_PER_S} drag/seek events per second: extra events are dropped"),
            });
        }
        false
    }

    async fn handle(&mut self, message: &str) {
        if message.len() > MAX_MESSAGE_BYTES {
            self.view.counters.bump(Counter::Oversize);
            self.malformed += 1;
            self.reply(ToPage::Error {
                message: format!("message of {} bytes not read; at most {MAX_MESSAGE_BYTES}", message.len()),
            });
            return;
        }
        let parsed = match serde_json::from_str::<FromPage>(message) {
            Ok(parsed) => parsed,
            Err(e) => return self.malformed(short(format_args!("malformed message: {e}"))),
        };
        match parsed {
            FromPage::Auth { .. } => self.malformed("already admitted".into()),
            FromPage::Grab { op } => self.grab(op).await,
            FromPage::Drag { target } => {
                if !self.take_event() {
                    return;
                }
                let now = self.epoch.elapsed();
                let result = match self.grab.as_mut() {
                    Some(g) => g.grip.set_target(now, &target).map_err(|e| e.to_string()),
                    None => Err("drag without a grab: send grab first".into()),
                };
                if let Err(why) = result {
                    self.malformed(why);
                }
            }
            FromPage::Release => self.release("released"),
            FromPage::Seek { t } => {
                if self.take_event() {
                    self.seek(t);
                }
            }
        }
    }

    fn seek(&mut self, t: f64) {
        let Source::Replay(replay) = &self.view.source else {
            return self.malformed("seek is for recordings; this view is live".into());
        };
        if !t.is_finite() {
            return self.malformed("seek needs a finite time".into());
        }
        let text = replay.lock().map(|mut r| r.frame_text(t)).unwrap_or_default();
        if self.outbox.try_send(Message::Text(text.into())).is_err() {
            self.view.counters.bump(Counter::RepliesDropped);
        } else {
            self.view.counters.bump(Counter::FramesSent);
        }
    }

    async fn grab(&mut self, op: String) {
        let (server, shape) = match &self.view.source {
            Source::Live { server, shape, .. } => (server.clone(), *shape),
            Source::Replay(_) => {
                self.view.counters.bump(Counter::GrabsRefused);
                return self.malformed("a recording cannot be grabbed".into());
            }
        };
        let Some(server) = server else {
            self.view.counters.bump(Counter::GrabsRefused);
            return self.reply(ToPage::Error { message: "this server takes no grabs (synthetic users)".into() });
        };
        if !self.can_grab {
            self.view.counters.bump(Counter::GrabsRefused);
            let message = if self.view.access.is_open() {
                "this view is watch-only (start the server with --view-grab to allow grabbing)"
            } else {
                "grabbing needs a manipulator token"
            };
            return self.reply(ToPage::Error { message: message.into() });
        }
        if !self.view.info.ops.contains(&op) {
            self.view.counters.bump(Counter::UnknownOps);
            let known = self.view.info.ops.join(", ");
            return self.malformed(short(format_args!("unknown operational point {op:?}; this scene has: {known}")));
        }
        self.release("grabbing another point");
        let (uplinks, uplink_rx) = RingBuffer::new(UPLINK_RING);
        let (snapshot_tx, snapshots) = RingBuffer::new(server.snapshot_ring_bytes);
        let notify = Arc::new(Notify::new());
        let (reply, decision) = oneshot::channel();
        let request = JoinRequest {
            name: format!("browser {}", self.view.counters.snapshot().grabs + 1),
            role: Role::Manipulator,
            op: op.clone(),
            form: LocalModelForm::OpSpace,
            device: None,
            mapping: Default::default(),
        };
        let link = UserLink { uplinks: uplink_rx, snapshots: snapshot_tx, notify: notify.clone() };
        let name = request.name.clone();
        let decided = match server.commands.send(Command::Join { request, round_trip: None, link, reply }).await {
            Ok(()) => tokio::time::timeout(JOIN_PATIENCE, decision).await,
            Err(()) => return self.reply(ToPage::Error { message: "the VE is not running".into() }),
        };
        let joined = match decided {
            Ok(Ok(Ok(joined))) => joined,
            Ok(Ok(Err(refusal))) => {
                self.view.counters.bump(Counter::GrabsRefused);
                return self
                    .reply(ToPage::Error { message: short(format_args!("the VE refused the grab: {refusal}")) });
            }
            _ => {
                self.view.counters.bump(Counter::GrabsRefused);
                return self.reply(ToPage::Error { message: "the VE did not answer the grab".into() });
            }
        };
        let user = joined.user_id;
        self.view.counters.bump(Counter::Grabs);
        if let Ok(mut browsers) = self.view.browsers.lock() {
            browsers.push(UserInfo {
                id: user,
                name,
                device: "mouse".into(),
                op: op.clone(),
                browser: true,
                ..UserInfo::default()
            });
        }
        let grip = Grip::new(shape.kind.op_dim(), self.view.config.grab_reach_m);
        let snapshot_period_s = 1.0 / joined.welcome.snapshot_rate_hz.max(1.0);
        self.grab = Some(Grab { server, user, op, uplinks, snapshots, notify, grip, snapshot_period_s });
        let op = self.grab.as_ref().map(|g| g.op.clone()).unwrap_or_default();
        self.reply(ToPage::Grabbed { user, op: &op });
    }

    /// The grab's newest snapshot arrived: one uplink toward the drag target.
    fn pump(&mut self) {
        let Source::Live { shape, .. } = &self.view.source else { return };
        let Some(g) = self.grab.as_mut() else { return };
        if take_latest_frame(&mut g.snapshots, &mut self.frame) == 0 {
            return;
        }
        let Ok(Datagram::Snapshot(snapshot)) = codec::decode_datagram(&self.frame, shape) else { return };
        let Some(sample) = g.grip.uplink(self.epoch.elapsed(), &snapshot, g.snapshot_period_s) else { return };
        if g.uplinks.push(ArrivedUplink::now(sample)).is_err() {
            self.view.counters.bump(Counter::UplinksDropped);
        }
    }

    fn release(&mut self, reason: &str) {
        let Some(g) = self.grab.take() else { return };
        if let Ok(mut browsers) = self.view.browsers.lock() {
            browsers.retain(|b| b.id != g.user);
        }
        drop(g);
        self.reply(ToPage::Released { reason });
    }
}
