//! QUIC endpoints for the server and clients, with one shared transport tuning and optional link emulation.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use quinn::crypto::rustls::{QuicClientConfig, QuicServerConfig};
use quinn::{AsyncUdpSocket, Endpoint, EndpointConfig, IdleTimeout, Runtime, TokioRuntime, TransportConfig};

use super::emulated_socket::{EmulatedSocket, EmulatedSocketStatsHandle};
use super::identity::ServerIdentity;
use super::trust::{crypto_provider, Trust, TrustError};
use crate::emulator::{LinkConfig, LinkConfigError};
use crate::messages::ALPN;

/// Transport settings shared by server and client endpoints.
#[derive(Clone, Debug)]
pub struct EndpointOptions {
    /// A connection silent this long is dead (both sides must agree within reason).
    pub idle_timeout: Duration,
    /// Ping interval that keeps an idle session alive; well under `idle_timeout`.
    pub keep_alive: Duration,
    /// Received datagrams waiting for the application, in bytes; oldest are dropped beyond it (latest wins).
    pub datagram_receive_buffer: usize,
    /// Datagrams waiting to be sent, in bytes; oldest are dropped beyond it, so nothing stale queues up.
    pub datagram_send_buffer: usize,
    /// Impairments applied to every packet this endpoint sends; `None` (or a transparent link) for none.
    pub link: Option<LinkConfig>,
    /// Application protocols offered in TLS; [`ALPN`] unless testing a mismatch.
    pub alpn_protocols: Vec<Vec<u8>>,
    /// Local address a client endpoint binds (the server binds its `listen` address).
    pub client_bind: SocketAddr,
    /// Receive and send buffer asked of the OS for the endpoint's UDP socket, in bytes (Linux grants up to
    /// `net.core.rmem_max` / `wmem_max`). One socket carries every connection of the endpoint: a server's 32
    /// users at 1 kHz are 32,000 datagrams a second, and the OS's default (about 90 small datagrams on Linux)
    /// overflows whenever the runtime reading it is held up for 3 ms.
    pub socket_buffer: usize,
}

/// The socket buffer endpoints ask for (see [`EndpointOptions::socket_buffer`]).
pub const SOCKET_BUFFER_BYTES: usize = 4 * 1024 * 1024;

impl Default for EndpointOptions {
    fn default() -> Self {
        EndpointOptions {
            idle_timeout: Duration::from_secs(5),
            keep_alive: Duration::from_secs(1),
            datagram_receive_buffer: 16 * 1024,
            datagram_send_buffer: 8 * 1024,
            link: None,
            alpn_protocols: vec![ALPN.to_vec()],
            client_bind: SocketAddr::from(([0, 0, 0, 0], 0)),
            socket_buffer: SOCKET_BUFFER_BYTES,
        }
    }
}

/// Why an endpoint could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    /// The UDP socket could not be bound or wrapped.
    #[error("cannot use UDP socket {addr}: {source}")]
    Socket {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The client's trust settings are unusable.
    #[error(transparent)]
    Trust(#[from] TrustError),
    /// rustls refused the server's certificate or key.
    #[error("TLS configuration: {0}")]
    Tls(#[from] rustls::Error),
    /// quinn refused the TLS configuration.
    #[error("QUIC crypto configuration: {0}")]
    QuicCrypto(String),
    /// The idle timeout does not fit QUIC's encoding.
    #[error("idle timeout {0:?} is too long")]
    IdleTimeout(Duration),
    /// Endpoints need a tokio runtime (socket registration, the emulated link's release task).
    #[error("QUIC endpoints must be created inside a tokio runtime")]
    NoRuntime,
    /// The link emulation settings contradict themselves.
    #[error("link emulation: {0}")]
    Link(#[from] LinkConfigError),
}

/// The congestion window a connection starts with (bytes): a second's worth of the largest 1 kHz datagram
/// stream over a 2 s round trip (1 kHz x 2 KB x 2 s). BBR paces its start-up at the initial window per round
/// trip and grows it only as acknowledgements return, so with quinn's 240 KB a 1 kHz snapshot stream (~0.4 MB/s)
/// over a 1 s round trip loses a large share of its datagrams for its first seconds: the client's force fades
/// and its model restarts on stale poses (`tests/slow/e2e_latency.rs` runs such a session in real time). The streams
/// are rate-limited by the application (latest-wins, one datagram a tick), so the larger window admits the
/// designed rate at once, not a burst.
pub const INITIAL_WINDOW_BYTES: u64 = 4 * 1024 * 1024;

/// The transport tuning both sides use.
pub fn transport_config(opts: &EndpointOptions) -> Result<TransportConfig, EndpointError> {
    let idle = IdleTimeout::try_from(opts.idle_timeout).map_err(|_| EndpointError::IdleTimeout(opts.idle_timeout))?;
    let mut transport = TransportConfig::default();
    transport
        .max_idle_timeout(Some(idle))
        .keep_alive_interval(Some(opts.keep_alive))
        .datagram_receive_buffer_size(Some(opts.datagram_receive_buffer))
        .datagram_send_buffer_size(opts.datagram_send_buffer)
        // The default (Cubic) takes random loss for congestion and throttles the 1 kHz datagram streams far
        // below what the loss alone leaves, so that under bursty loss the client's force fades for want of
        // snapshots (tests/slow/e2e_faults.rs holds a session at 30 % bursty loss without stale ticks), and its slow
        // start starves a delayed session's first moments. BBR is model-based, not loss-based; quinn marks it
        // experimental, so this is one line to revert.
        .congestion_controller_factory(std::sync::Arc::new({
            let mut bbr = quinn::congestion::BbrConfig::default();
            bbr.initial_window(INITIAL_WINDOW_BYTES);
            bbr
        }));
    Ok(transport)
}

/// A server endpoint listening on `listen` with `identity`. Must run inside a tokio runtime.
pub fn server_endpoint(
    listen: SocketAddr,
    identity: &ServerIdentity,
    opts: &EndpointOptions,
) -> Result<Endpoint, EndpointError> {
    server_endpoint_with_link_stats(listen, identity, opts).map(|(endpoint, _)| endpoint)
}

/// [`server_endpoint`], also returning the emulated link's counters when `opts.link` emulates one.
pub fn server_endpoint_with_link_stats(
    listen: SocketAddr,
    identity: &ServerIdentity,
    opts: &EndpointOptions,
) -> Result<(Endpoint, Option<EmulatedSocketStatsHandle>), EndpointError> {
    let mut tls = rustls::ServerConfig::builder_with_provider(crypto_provider())
        .with_protocol_versions(&[&rustls::version::TLS13])?
        .with_no_client_auth()
        .with_single_cert(identity.cert_chain.clone(), identity.key.clone_key())?;
    tls.alpn_protocols = opts.alpn_protocols.clone();
    let crypto = QuicServerConfig::try_from(tls).map_err(|e| EndpointError::QuicCrypto(e.to_string()))?;
    let mut config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
    config.transport_config(Arc::new(transport_config(opts)?));
    let (socket, stats) = bind(listen, opts)?;
    let endpoint = Endpoint::new_with_abstract_socket(EndpointConfig::default(), Some(config), socket, runtime())
        .map_err(|source| EndpointError::Socket { addr: listen, source })?;
    Ok((endpoint, stats))
}

/// A client endpoint that trusts servers as `trust` says. Must run inside a tokio runtime.
pub fn client_endpoint(trust: &Trust, opts: &EndpointOptions) -> Result<Endpoint, EndpointError> {
    client_endpoint_with_link_stats(trust, opts).map(|(endpoint, _)| endpoint)
}

/// [`client_endpoint`], also returning the emulated link's counters when `opts.link` emulates one.
pub fn client_endpoint_with_link_stats(
    trust: &Trust,
    opts: &EndpointOptions,
) -> Result<(Endpoint, Option<EmulatedSocketStatsHandle>), EndpointError> {
    let tls = trust.client_crypto(&opts.alpn_protocols)?;
    let crypto = QuicClientConfig::try_from(tls).map_err(|e| EndpointError::QuicCrypto(e.to_string()))?;
    let mut config = quinn::ClientConfig::new(Arc::new(crypto));
    config.transport_config(Arc::new(transport_config(opts)?));
    let (socket, stats) = bind(opts.client_bind, opts)?;
    let mut endpoint = Endpoint::new_with_abstract_socket(EndpointConfig::default(), None, socket, runtime())
        .map_err(|source| EndpointError::Socket { addr: opts.client_bind, source })?;
    endpoint.set_default_client_config(config);
    Ok((endpoint, stats))
}

fn runtime() -> Arc<dyn Runtime> {
    Arc::new(TokioRuntime)
}

/// Binds a UDP socket, behind the link emulator when `opts.link` impairs anything.
fn bind(
    addr: SocketAddr,
    opts: &EndpointOptions,
) -> Result<(Arc<dyn AsyncUdpSocket>, Option<EmulatedSocketStatsHandle>), EndpointError> {
    tokio::runtime::Handle::try_current().map_err(|_| EndpointError::NoRuntime)?;
    let socket_error = |source| EndpointError::Socket { addr, source };
    let std_socket = std::net::UdpSocket::bind(addr).map_err(socket_error)?;
    size_buffers(&std_socket, opts.socket_buffer);
    let socket = TokioRuntime.wrap_udp_socket(std_socket).map_err(socket_error)?;
    match &opts.link {
        Some(link) if !link.is_transparent() => {
            let (emulated, stats) = EmulatedSocket::wrap(socket, link.clone())?;
            Ok((emulated, Some(stats)))
        }
        _ => Ok((socket, None)),
    }
}

/// Asks the OS for `bytes` of receive and send buffer on `socket`. A refusal keeps the OS's default and is
/// said once: the endpoint works, only with less room for a stalled reader.
fn size_buffers(socket: &std::net::UdpSocket, bytes: usize) {
    let sized = quinn::udp::UdpSocketState::new(socket.into()).and_then(|state| {
        state.set_recv_buffer_size(socket.into(), bytes)?;
        state.set_send_buffer_size(socket.into(), bytes)
    });
    if let Err(e) = sized {
        tracing::warn!(bytes, error = %e, "the UDP socket keeps the OS's default buffers");
    }
}
