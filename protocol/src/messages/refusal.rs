//! Why a server refuses a client: [`Refused`] and its [`RefusalReason`].

use std::fmt;

use serde::{Deserialize, Serialize};

/// Why a server refused a client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum RefusalReason {
    /// The client speaks another protocol version.
    UnsupportedVersion {
        /// Version the server speaks.
        server: u16,
        /// Version the client sent.
        client: u16,
    },
    /// The token did not match.
    BadToken,
    /// No room for another user.
    ServerFull {
        /// How many users the server admits.
        max_users: u32,
    },
    /// The requested operational point does not exist or is taken.
    UnknownOp {
        /// What the client asked for.
        requested: String,
        /// What it could have asked for.
        available: Vec<String>,
    },
    /// The requested role is not allowed on this server.
    RoleNotAllowed,
    /// The device or the mapping asked for cannot serve this scene.
    Device {
        /// What is wrong, naming the device's value and the scene's need.
        what: String,
    },
    /// The hello or the join made no sense.
    Malformed {
        /// What was wrong with it.
        what: String,
    },
    /// The server cannot serve this scene to this client: what it would send breaks the wire's checks (a
    /// scene whose numbers the protocol's SI bounds do not carry, a non-finite term). Appended last, so the
    /// other reasons keep their encoding.
    Unservable {
        /// What the server could not send, naming the field and its bound.
        what: String,
    },
    /// The room asked for is not hosted here (or not open to the client's token). Appended after
    /// `Unservable`, so the other reasons keep their encoding.
    UnknownRoom {
        /// What the client asked for.
        requested: String,
        /// The rooms the client's token opens.
        available: Vec<String>,
    },
    /// The server's real-time budget has no room for the newcomer (user or room).
    OverBudget {
        /// The measured load and the share it may not pass.
        what: String,
    },
}

impl fmt::Display for RefusalReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RefusalReason::UnsupportedVersion { server, client } => {
                write!(f, "protocol version {client} is not supported (the server speaks version {server})")
            }
            RefusalReason::BadToken => f.write_str("the access token was not accepted"),
            RefusalReason::ServerFull { max_users } => write!(f, "the server is full ({max_users} users)"),
            RefusalReason::UnknownOp { requested, available } => {
                write!(f, "the scene has no free operational point {requested:?}")?;
                if available.is_empty() {
                    f.write_str(" (none is free)")
                } else {
                    write!(f, " (free: {})", available.join(", "))
                }
            }
            RefusalReason::RoleNotAllowed => f.write_str("that role is not allowed on this server"),
            RefusalReason::Device { what } => write!(f, "the device cannot join: {what}"),
            RefusalReason::Malformed { what } => write!(f, "the request was malformed: {what}"),
            RefusalReason::Unservable { what } => write!(f, "the server cannot serve this scene: {what}"),
            RefusalReason::UnknownRoom { requested, available } => {
                write!(f, "the server hosts no room {requested:?} open to this token")?;
                if available.is_empty() {
                    f.write_str(" (none is)")
                } else {
                    write!(f, " (rooms: {})", available.join(", "))
                }
            }
            RefusalReason::OverBudget { what } => write!(f, "the server is over its real-time budget: {what}"),
        }
    }
}

/// Refusal reply, server → client; the server closes the connection after sending it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refused {
    /// Machine-readable reason.
    pub reason: RefusalReason,
    /// Optional extra words from the server operator (may be empty).
    pub message: String,
}

impl fmt::Display for Refused {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "refused: {}", self.reason)?;
        if !self.message.is_empty() {
            write!(f, " — {}", self.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for Refused {}
