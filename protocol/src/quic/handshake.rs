//! Session set-up on top of QUIC, in two steps on a new bidirectional stream (which stays the session's
//! control stream): the client sends `Hello` (version, token, role), the server answers `SceneInfo` (the
//! scene's space and operational points) or `Refused`; the client, now able to describe its device in the
//! scene's space and to pick an operational point, sends `Join`, and the server answers `Welcome` or
//! `Refused`.

use std::net::SocketAddr;
use std::time::Duration;

use quinn::{Connection, ConnectionError, Endpoint, Incoming, RecvStream, SendStream, TransportErrorCode};

use super::framing::{recv_control, recv_frame, send_control, ControlStreamError};
use super::trust::FingerprintMismatch;
use crate::codec::{self, validate, DecodeError};
use crate::messages::{
    Control, Hello, Join, RefusalReason, Refused, ResumeAnswer, ResumeRefusal, RoomState, SceneInfo, Welcome,
    PROTOCOL_VERSION,
};

/// Longest a handshake (QUIC and Hello/Welcome) may take on either side.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a refusing server waits for the client to read the refusal and close, before closing itself.
const REFUSAL_LINGER: Duration = Duration::from_secs(2);

/// Application close codes kinloop uses.
pub mod close_codes {
    use quinn::VarInt;

    /// Orderly end of a session.
    pub const NORMAL: VarInt = VarInt::from_u32(0);
    /// The server refused the client (the `Refused` message says why).
    pub const REFUSED: VarInt = VarInt::from_u32(1);
    /// The peer broke the protocol.
    pub const PROTOCOL: VarInt = VarInt::from_u32(2);
}

/// TLS alerts (RFC 8446 §6) a client raises when it does not trust the server's certificate: bad, unsupported,
/// revoked, expired or unknown certificate, unknown CA, access denied, and decrypt_error, which rustls raises
/// when a trusted CA's name matches but its signature does not (two self-signed certificates with one name).
const CERTIFICATE_ALERTS: [u8; 8] = [42, 43, 44, 45, 46, 48, 49, 51];
/// TLS alert `no_application_protocol`.
const NO_APPLICATION_PROTOCOL: u8 = 120;

/// A client session the server welcomed.
#[derive(Debug)]
pub struct ConnectedSession {
    /// The QUIC connection (datagrams go here).
    pub connection: Connection,
    /// Sending half of the control stream.
    pub send: SendStream,
    /// Receiving half of the control stream.
    pub recv: RecvStream,
    /// The scene the server hosts.
    pub scene: SceneInfo,
    /// What the client asked for.
    pub join: Join,
    /// What the server granted.
    pub welcome: Welcome,
    /// The server's answer to the state the client offered (`None`: none offered).
    pub resume: Option<ResumeAnswer>,
}

/// Why a client could not start a session. Each cause a user can fix has its own variant.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// Client and server share no application protocol (not a kinloop server, or another major version).
    #[error("the server does not speak {} (no common application protocol)", String::from_utf8_lossy(crate::ALPN))]
    Alpn,
    /// The server's certificate is not the one trusted.
    #[error("untrusted server certificate: expected {expected}, got {got}")]
    UntrustedCertificate {
        /// What the client trusts.
        expected: String,
        /// What the server presented, or why it failed verification.
        got: String,
    },
    /// The server refused the hello.
    #[error("the server {0}")]
    Refused(Refused),
    /// No answer within [`HANDSHAKE_TIMEOUT`] or the idle timeout.
    #[error("the server did not answer in time")]
    Timeout,
    /// The connection could not even be attempted (bad server name, endpoint closed...).
    #[error("cannot connect: {0}")]
    Endpoint(#[from] quinn::ConnectError),
    /// The connection failed for another reason.
    #[error("connection failed: {0}")]
    Connection(ConnectionError),
    /// The control stream failed.
    #[error(transparent)]
    Control(#[from] ControlStreamError),
    /// The server answered with something else than the handshake's next message or `Refused`.
    #[error("the server answered the {step} with {got}")]
    UnexpectedReply {
        /// Which client message was answered.
        step: &'static str,
        /// Which message.
        got: &'static str,
    },
    /// The client could not join the scene the server hosts (its device cannot serve the scene's space, say).
    #[error("{0}")]
    Declined(String),
}

impl From<ConnectionError> for ConnectError {
    /// Sorts a failed connection into the causes a user can act on.
    fn from(error: ConnectionError) -> Self {
        let alert = |code: TransportErrorCode| {
            let code = u64::from(code);
            (code & !0xff == 0x100).then_some((code & 0xff) as u8)
        };
        match &error {
            ConnectionError::TimedOut => ConnectError::Timeout,
            ConnectionError::TransportError(local) if alert(local.code) == Some(NO_APPLICATION_PROTOCOL) => {
                ConnectError::Alpn
            }
            ConnectionError::ConnectionClosed(remote) if alert(remote.error_code) == Some(NO_APPLICATION_PROTOCOL) => {
                ConnectError::Alpn
            }
            ConnectionError::TransportError(local)
                if alert(local.code).is_some_and(|a| CERTIFICATE_ALERTS.contains(&a)) =>
            {
                match FingerprintMismatch::find_in(&local.reason) {
                    Some(FingerprintMismatch { expected, got }) => ConnectError::UntrustedCertificate { expected, got },
                    None => ConnectError::UntrustedCertificate {
                        expected: "a certificate issued by a trusted CA for this server name".into(),
                        got: local.reason.clone(),
                    },
                }
            }
            _ => ConnectError::Connection(error),
        }
    }
}

/// Connects to a kinloop server and performs the handshake: `hello`, then the [`Join`] that `choose` makes
/// from the server's [`SceneInfo`] (an `Err` from it closes the connection and becomes
/// [`ConnectError::Declined`]).
pub async fn connect(
    endpoint: &Endpoint,
    addr: SocketAddr,
    server_name: &str,
    hello: &Hello,
    choose: impl FnOnce(&SceneInfo) -> Result<Join, String>,
) -> Result<ConnectedSession, ConnectError> {
    connect_resuming(endpoint, addr, server_name, hello, None, choose).await
}

/// [`connect`], offering the room's signed `offer` (the newest state a previous server of the room sent)
/// between the scene info and the join, so the server resumes the room from it; its answer is in
/// [`ConnectedSession::resume`].
pub async fn connect_resuming(
    endpoint: &Endpoint,
    addr: SocketAddr,
    server_name: &str,
    hello: &Hello,
    offer: Option<&RoomState>,
    choose: impl FnOnce(&SceneInfo) -> Result<Join, String>,
) -> Result<ConnectedSession, ConnectError> {
    let attempt = async {
        let connection = endpoint.connect(addr, server_name)?.await?;
        let (mut send, mut recv) = connection.open_bi().await?;
        // A control-stream failure is usually the connection failing: report the connection's reason.
        let failed = |e: ControlStreamError| connection.close_reason().map_or(e.into(), ConnectError::from);
        let reply = async {
            send_control(&mut send, &Control::Hello(hello.clone())).await?;
            recv_control(&mut recv).await
        };
        let scene = match reply.await.map_err(failed)? {
            Control::SceneInfo(scene) => scene,
            other => return Err(unexpected(&connection, "hello", other)),
        };
        let mut resume = None;
        if let Some(offer) = offer {
            let reply = async {
                send_control(&mut send, &Control::Resume(offer.clone())).await?;
                recv_control(&mut recv).await
            };
            resume = match reply.await.map_err(failed)? {
                Control::ResumeAnswer(answer) => Some(answer),
                other => return Err(unexpected(&connection, "resume", other)),
            };
        }
        let join = match choose(&scene) {
            Ok(join) => join,
            Err(why) => {
                let leave = Control::Leave { reason: why.clone() };
                if send_control(&mut send, &leave).await.is_ok() {
                    // Closing at once could discard the leave before it is delivered; the server closes on
                    // reading it.
                    let _ = send.finish();
                    let _ = tokio::time::timeout(REFUSAL_LINGER, connection.closed()).await;
                }
                connection.close(close_codes::NORMAL, b"declined");
                return Err(ConnectError::Declined(why));
            }
        };
        let reply = async {
            send_control(&mut send, &Control::Join(join.clone())).await?;
            recv_control(&mut recv).await
        };
        match reply.await.map_err(failed)? {
            Control::Welcome(welcome) => Ok(ConnectedSession { connection, send, recv, scene, join, welcome, resume }),
            other => Err(unexpected(&connection, "join", other)),
        }
    };
    tokio::time::timeout(HANDSHAKE_TIMEOUT, attempt).await.unwrap_or(Err(ConnectError::Timeout))
}

/// A refusal, or a reply out of place: closes the connection and says which.
fn unexpected(connection: &Connection, step: &'static str, reply: Control) -> ConnectError {
    match reply {
        Control::Refused(refused) => {
            connection.close(close_codes::REFUSED, b"refused");
            ConnectError::Refused(refused)
        }
        other => {
            connection.close(close_codes::PROTOCOL, b"unexpected reply");
            ConnectError::UnexpectedReply { step, got: other.kind_name() }
        }
    }
}

/// A server session after a successful handshake.
#[derive(Debug)]
pub struct AcceptedSession {
    /// The QUIC connection (datagrams go here).
    pub connection: Connection,
    /// Sending half of the control stream.
    pub send: SendStream,
    /// Receiving half of the control stream.
    pub recv: RecvStream,
    /// Who the client is.
    pub hello: Hello,
    /// What the client asked for.
    pub join: Join,
    /// What the server granted.
    pub welcome: Welcome,
}

/// Why a server did not start a session with an incoming client.
#[derive(Debug, thiserror::Error)]
pub enum AcceptError {
    /// The QUIC handshake or the connection failed (wrong ALPN, untrusted certificate on the client...).
    #[error("connection failed: {0}")]
    Connection(#[from] ConnectionError),
    /// No hello within [`HANDSHAKE_TIMEOUT`].
    #[error("the client did not complete the handshake in time")]
    Timeout,
    /// The control stream failed.
    #[error(transparent)]
    Control(#[from] ControlStreamError),
    /// The client sent something else than the handshake's next message (`Hello`, then `Join`).
    #[error("the client sent {got} instead of {expected}")]
    UnexpectedMessage {
        /// What the handshake expected.
        expected: &'static str,
        /// Which message.
        got: &'static str,
    },
    /// The client left after seeing the scene (it could not serve it, and said why).
    #[error("the client declined to join: {0}")]
    Declined(String),
    /// The client was refused (and told why).
    #[error("refused the client: {0}")]
    Refused(Refused),
    /// The validator produced a welcome the client would reject (a server bug).
    #[error("the server's own welcome is invalid: {0}")]
    InvalidWelcome(DecodeError),
    /// Not a session: an admin command, for the server to answer with `answer_admin`.
    #[error("an admin command")]
    Admin(super::admin_session::AdminSession),
}

/// Accepts an incoming connection and runs the handshake. The protocol version is checked here; the rest is
/// the server's: `admit` decides on the hello (token, role, capacity) and describes the scene, `decide` on
/// the join (operational point, device, mapping).
pub async fn accept(
    incoming: Incoming,
    admit: impl FnOnce(&Hello) -> Result<SceneInfo, Refused>,
    decide: impl FnOnce(&Hello, &Join) -> Result<Welcome, Refused>,
) -> Result<AcceptedSession, AcceptError> {
    accept_with(incoming, admit, |hello, join, _| std::future::ready(decide(&hello, &join))).await
}

/// [`accept`] with an asynchronous decision on the join, for servers whose admission lives elsewhere (the
/// VE server asks its simulation thread, which owns the users). `decide` gets copies of the hello and the
/// join and the connection's round trip as QUIC measured it so far (the handshake and the hello's exchange:
/// the server's own view of the link, delays emulated below QUIC included); the whole handshake, decisions
/// included, is bounded by [`HANDSHAKE_TIMEOUT`].
pub async fn accept_with<A, F, Fut>(incoming: Incoming, admit: A, decide: F) -> Result<AcceptedSession, AcceptError>
where
    A: FnOnce(&Hello) -> Result<SceneInfo, Refused>,
    F: FnOnce(Hello, Join, Duration) -> Fut,
    Fut: std::future::Future<Output = Result<Welcome, Refused>>,
{
    let no_key = |_| std::future::ready(ResumeAnswer::Refused(ResumeRefusal::NoRoomKey));
    accept_resuming(incoming, admit, no_key, decide).await
}

/// [`accept_with`] for a server of a room: a client may offer a signed [`RoomState`] between the scene info
/// and the join, which `resume` decides on (before the join, so the welcome describes the resumed room);
/// the client is told the answer and goes on to join either way.
pub async fn accept_resuming<A, R, RFut, F, Fut>(
    incoming: Incoming,
    admit: A,
    resume: R,
    decide: F,
) -> Result<AcceptedSession, AcceptError>
where
    A: FnOnce(&Hello) -> Result<SceneInfo, Refused>,
    R: FnOnce(RoomState) -> RFut,
    RFut: std::future::Future<Output = ResumeAnswer>,
    F: FnOnce(Hello, Join, Duration) -> Fut,
    Fut: std::future::Future<Output = Result<Welcome, Refused>>,
{
    let handshake = async {
        let connection = incoming.await?;
        let (mut send, mut recv) = connection.accept_bi().await?;
        let hello = match read_hello(&mut recv).await {
            Ok(hello) => hello,
            Err(HelloProblem::Refuse(refused)) => return Err(refuse(&connection, send, refused).await),
            Err(HelloProblem::Admin(request)) => {
                return Err(AcceptError::Admin(super::admin_session::AdminSession { connection, send, request }))
            }
            Err(HelloProblem::Fail(error)) => {
                connection.close(close_codes::PROTOCOL, b"expected Hello");
                return Err(error);
            }
        };
        let scene = match admit(&hello) {
            Ok(scene) => scene,
            Err(refused) => return Err(refuse(&connection, send, refused).await),
        };
        send_control(&mut send, &Control::SceneInfo(scene)).await?;
        let mut next = recv_control(&mut recv).await;
        if let Ok(Control::Resume(offer)) = next {
            let answer = resume(offer).await;
            send_control(&mut send, &Control::ResumeAnswer(answer)).await?;
            next = recv_control(&mut recv).await;
        }
        let join = match next {
            Ok(Control::Join(join)) => join,
            Ok(Control::Leave { reason }) => {
                connection.close(close_codes::NORMAL, b"declined");
                return Err(AcceptError::Declined(reason));
            }
            Ok(other) => {
                connection.close(close_codes::PROTOCOL, b"expected Join");
                return Err(AcceptError::UnexpectedMessage { expected: "Join", got: other.kind_name() });
            }
            // A join that fails the wire's checks (a device with a negative force, say) is answered as any
            // refused join is, saying what is wrong; closing without a word left the client with "closed by
            // peer: 0".
            Err(ControlStreamError::Decode(error)) => return Err(refuse(&connection, send, invalid_join(&error)).await),
            Err(error) => return Err(error.into()),
        };
        let welcome = match decide(hello.clone(), join.clone(), connection.rtt()).await {
            Ok(welcome) => welcome,
            Err(refused) => return Err(refuse(&connection, send, refused).await),
        };
        if let Err(error) = validate::welcome(&welcome) {
            // The client is told why, as any refused client is; the server's caller logs the cause.
            let reason = RefusalReason::Unservable { what: format!("its welcome would be invalid: {error}") };
            refuse(&connection, send, Refused { reason, message: String::new() }).await;
            return Err(AcceptError::InvalidWelcome(error));
        }
        send_control(&mut send, &Control::Welcome(welcome.clone())).await?;
        Ok(AcceptedSession { connection, send, recv, hello, join, welcome })
    };
    tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake).await.unwrap_or(Err(AcceptError::Timeout))
}

enum HelloProblem {
    /// Tell the client why and close.
    Refuse(Refused),
    /// Not worth an answer.
    Fail(AcceptError),
    /// An admin command instead of a hello.
    Admin(crate::messages::AdminRequest),
}

/// Reads the first frame: a hello of this version, or a reason to refuse.
async fn read_hello(recv: &mut RecvStream) -> Result<Hello, HelloProblem> {
    let body = recv_frame(recv).await.map_err(|e| HelloProblem::Fail(e.into()))?;
    // Checked before decoding: another version's Hello may not decode as ours, and deserves a precise answer.
    if let Some(client) = codec::peek_hello_version(&body).filter(|v| *v != PROTOCOL_VERSION) {
        let reason = RefusalReason::UnsupportedVersion { server: PROTOCOL_VERSION, client };
        return Err(HelloProblem::Refuse(Refused { reason, message: String::new() }));
    }
    match codec::decode_control(&body) {
        Ok(Control::Hello(hello)) => Ok(hello),
        Ok(Control::Admin(request)) => Err(HelloProblem::Admin(request)),
        Ok(other) => {
            Err(HelloProblem::Fail(AcceptError::UnexpectedMessage { expected: "Hello", got: other.kind_name() }))
        }
        Err(error) => {
            let reason = RefusalReason::Malformed { what: error.to_string() };
            Err(HelloProblem::Refuse(Refused { reason, message: String::new() }))
        }
    }
}

/// The refusal of a join the wire's checks reject: the device's numbers or the scales asked for are the
/// device's problem (the user can pick another device or leave the scales to the server), anything else is
/// a malformed request.
fn invalid_join(error: &DecodeError) -> Refused {
    let what = error.to_string();
    let device = error.field().is_some_and(|f| f.path.starts_with("join.device") || f.path.starts_with("join.mapping"));
    let reason = if device { RefusalReason::Device { what } } else { RefusalReason::Malformed { what } };
    Refused { reason, message: String::new() }
}

/// Sends the refusal, gives the client a moment to read it and close, then closes.
async fn refuse(connection: &Connection, mut send: SendStream, refused: Refused) -> AcceptError {
    if send_control(&mut send, &Control::Refused(refused.clone())).await.is_ok() {
        // Closing at once could discard the refusal before it is delivered; the client closes on reading it.
        let _ = send.finish();
        let _ = tokio::time::timeout(REFUSAL_LINGER, connection.closed()).await;
    }
    connection.close(close_codes::REFUSED, b"refused");
    AcceptError::Refused(refused)
}
