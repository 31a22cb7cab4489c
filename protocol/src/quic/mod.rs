//! QUIC transport: certificates and trust, endpoints, the handshake, control framing and datagrams.
//!
//! One session = one QUIC connection with ALPN [`crate::ALPN`]: a bidirectional control stream opened by the
//! client (Hello → Welcome/Refused, then Leave/Error/Ping/Pong), snapshots and uplinks as datagrams.

mod admin;
mod datagrams;
mod emulated_socket;
mod endpoint;
mod framing;
mod handshake;
mod identity;
mod room_ca;
mod trust;

pub use admin::{admin, answer_admin, AdminSession};
pub use datagrams::{DatagramReceiver, DatagramSender, DeliveryStats, RecvError, Route, SendError};
pub use emulated_socket::{EmulatedSocketStats, EmulatedSocketStatsHandle};
pub use endpoint::{
    client_endpoint, client_endpoint_with_link_stats, server_endpoint, server_endpoint_with_link_stats,
    transport_config, EndpointError, EndpointOptions,
};
pub use framing::{
    body_len, encode_frame, recv_control, recv_frame, send_control, ControlStreamError, FRAME_HEADER_BYTES,
};
pub use handshake::{
    accept, accept_resuming, accept_with, close_codes, connect, connect_resuming, AcceptError, AcceptedSession,
    ConnectError, ConnectedSession, HANDSHAKE_TIMEOUT,
};
pub use identity::{
    fingerprint_hex, normalize_fingerprint, IdentityError, ServerIdentity, CERT_FILE, DEFAULT_NAMES, KEY_FILE,
};
pub use room_ca::RoomCa;
pub use trust::{FingerprintMismatch, Trust, TrustError};

/// Re-exported so callers need not depend on quinn for the types this API hands out.
pub use quinn::{Connection, Endpoint, Incoming, RecvStream, SendStream};
