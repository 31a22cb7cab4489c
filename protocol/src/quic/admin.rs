//! The admin command over QUIC: the client opens a control stream, sends [`Control::Admin`] as its first
//! frame and reads one [`Control::AdminAnswer`]; the server's handshake hands such a connection back as an
//! [`AdminSession`] (see [`super::AcceptError::Admin`]) for the server to decide and answer.

use std::net::SocketAddr;
use std::time::Duration;

use quinn::{Connection, Endpoint, SendStream};

use super::framing::{recv_control, send_control};
use super::handshake::{close_codes, ConnectError, HANDSHAKE_TIMEOUT};
use crate::messages::{AdminAnswer, AdminRequest, Control};

/// How long the server waits for the admin to read the answer and close.
const ANSWER_LINGER: Duration = Duration::from_secs(2);

/// An admin connection the server has not answered yet.
#[derive(Debug)]
pub struct AdminSession {
    /// The connection.
    pub connection: Connection,
    /// Sending half of the control stream.
    pub send: SendStream,
    /// What the admin asked.
    pub request: AdminRequest,
}

/// Sends the answer, gives the admin a moment to read it, then closes.
pub async fn answer_admin(session: AdminSession, answer: AdminAnswer) {
    let AdminSession { connection, mut send, .. } = session;
    if send_control(&mut send, &Control::AdminAnswer(answer)).await.is_ok() {
        let _ = send.finish();
        let _ = tokio::time::timeout(ANSWER_LINGER, connection.closed()).await;
    }
    connection.close(close_codes::NORMAL, b"admin answered");
}

/// Sends `request` to the server at `addr` and returns its answer.
pub async fn admin(
    endpoint: &Endpoint,
    addr: SocketAddr,
    server_name: &str,
    request: &AdminRequest,
) -> Result<AdminAnswer, ConnectError> {
    let attempt = async {
        let connection = endpoint.connect(addr, server_name)?.await?;
        let (mut send, mut recv) = connection.open_bi().await?;
        send_control(&mut send, &Control::Admin(request.clone())).await?;
        let reply = recv_control(&mut recv).await;
        connection.close(close_codes::NORMAL, b"done");
        match reply? {
            Control::AdminAnswer(answer) => Ok(answer),
            other => Err(ConnectError::UnexpectedReply { step: "admin command", got: other.kind_name() }),
        }
    };
    tokio::time::timeout(HANDSHAKE_TIMEOUT, attempt).await.unwrap_or(Err(ConnectError::Timeout))
}
