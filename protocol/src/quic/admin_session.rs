//! An admin connection as the handshake hands it back ([`super::AcceptError::Admin`]), below both the handshake
//! that recognises it and the admin module that answers it.

use quinn::{Connection, SendStream};

use crate::messages::AdminRequest;

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
