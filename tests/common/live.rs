//! Servers and clients in this process, over real QUIC on 127.0.0.1: the drivers the binaries run
//! (`Server::start`, `Client::start`), with the binaries' defaults except that neither asks for SCHED_FIFO
//! (a spinning real-time thread could starve the other engineers' builds on this shared 2-core machine).

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use kinloop_client::device::DevicePreset;
use kinloop_client::driver::{Client, ClientConfig, ClientHandle};
use kinloop_client::user::UserSpec;
use kinloop_linkage::model::builtin::{self, PAPER_WRENCH};
use kinloop_linkage::model::scene::OpSpec;
use kinloop_linkage::{math::space::SceneKind, model::scene::Scene};
use kinloop_protocol::quic::{
    client_endpoint, connect, ConnectError, ConnectedSession, Endpoint, EndpointOptions, Trust,
};
use kinloop_protocol::{Hello, Join, LocalModelForm, MappingRequest, Role, PROTOCOL_VERSION};
use kinloop_server::{Server, ServerConfig, ServerHandle, ServerStats};
use tokio::runtime::Runtime;

/// Any free port on the loopback interface.
pub const LOOPBACK: SocketAddr = SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 0);

/// Operational points of [`testbed`]: the paper's (link 2's COM) and one on each end link.
pub const OPS: [&str; 3] = ["link2", "link1@0.75", "link4@0.5"];

/// The network runtime of an in-process server (the binary uses the same: two workers).
pub fn runtime() -> Runtime {
    tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("tokio runtime")
}

/// The paper's testbed with two more operational points (`OPS`), so that users can hold different links.
pub fn testbed() -> Scene {
    let mut scene = builtin::scene("paper-testbed").expect("built in").expect("parses");
    for (name, body, point) in [("link1@0.75", "link1", [0.03375, 0.0]), ("link4@0.5", "link4", [0.03, 0.0])] {
        scene.ops.push(OpSpec { name: name.into(), body: body.into(), point: point.to_vec() });
    }
    scene
}

/// The paper's hand wrench shared among `users` (each pushes `F / users`).
pub fn paper_share(users: usize) -> Vec<f64> {
    PAPER_WRENCH.iter().map(|w| w / users as f64).collect()
}

/// A server for [`testbed`] on a free loopback port with the paper's VE, open access and a fresh certificate.
pub fn server_config() -> ServerConfig {
    let mut config = ServerConfig::new(testbed(), "paper-testbed+ops", LOOPBACK);
    config.realtime = false;
    config
}

/// Starts a server on `rt` (its network tasks run there; the VE has its own thread).
pub fn start_server(rt: &Runtime, config: ServerConfig) -> ServerHandle {
    let _inside = rt.enter();
    Server::start(config).expect("the server starts")
}

/// Tells the clients, closes, joins the VE thread; the final statistics.
pub fn stop_server(rt: &Runtime, server: ServerHandle) -> ServerStats {
    rt.block_on(server.shutdown()).expect("the server shuts down cleanly")
}

/// A client of the server at `server` (pinned by `fingerprint`) holding `op` with a constant hand wrench,
/// on the scene's default device mapped one to one (the paper's setting, which these sessions compare with
/// the harness's), reporting every 100 ms.
pub fn client_config(server: SocketAddr, fingerprint: &str, name: &str, op: &str, wrench: &[f64]) -> ClientConfig {
    let mut config = ClientConfig::new(server.to_string(), Trust::Fingerprint(fingerprint.to_owned()));
    config.client_name = name.into();
    config.op = Some(op.into());
    config.mapping = MappingRequest { position_scale: Some(1.0), force_scale: Some(1.0), gravity_compensation: false };
    config.user = UserSpec::Constant(wrench.to_vec());
    config.realtime_priority = false;
    config.report_interval = Duration::from_millis(100);
    config
}

/// [`client_config`] for an in-process server.
pub fn client_of(server: &ServerHandle, name: &str, op: &str, wrench: &[f64]) -> ClientConfig {
    client_config(server.local_addr(), server.fingerprint(), name, op, wrench)
}

/// [`client_of`], recording every tick to `record`.
pub fn recorded_client_of(server: &ServerHandle, name: &str, op: &str, wrench: &[f64], record: &Path) -> ClientConfig {
    let mut config = client_of(server, name, op, wrench);
    config.record = Some(record.to_owned());
    config
}

/// Starts a client; panics with the typed error when it cannot.
pub fn start_client(config: ClientConfig) -> ClientHandle {
    let name = config.client_name.clone();
    Client::start(config).unwrap_or_else(|e| panic!("client {name} could not start: {e}"))
}

/// The hello and join `kinloop-client` sends for the simulated paper device at `op` (a raw session built by
/// hand can then misbehave in ways the real client never would).
pub fn paper_handshake(name: &str, op: &str, token: &str) -> (Hello, Join) {
    let hello = Hello {
        version: PROTOCOL_VERSION,
        token: token.into(),
        client_name: name.into(),
        role: Role::Manipulator,
        room: String::new(),
    };
    let join = Join {
        op: op.into(),
        device: DevicePreset::Paper.spec(SceneKind::Planar).expect("paper device").caps(),
        form: LocalModelForm::OpSpace,
        mapping: MappingRequest::default(),
    };
    (hello, join)
}

/// A session opened by hand with `hello` then `join` against `server` (pinned by fingerprint); the endpoint
/// is returned too, to close it when done.
pub fn raw_session(
    rt: &Runtime,
    server: &ServerHandle,
    (hello, join): &(Hello, Join),
) -> (Endpoint, Result<ConnectedSession, ConnectError>) {
    rt.block_on(async {
        let options = EndpointOptions { client_bind: LOOPBACK, ..EndpointOptions::default() };
        let endpoint =
            client_endpoint(&Trust::Fingerprint(server.fingerprint().into()), &options).expect("client endpoint");
        let session = connect(&endpoint, server.local_addr(), "localhost", hello, |_| Ok(join.clone())).await;
        (endpoint, session)
    })
}
