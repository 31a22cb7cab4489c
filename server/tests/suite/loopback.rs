//! What the QUIC tests of the server share: a loopback address, a client endpoint that trusts the server's
//! certificate, and the join the testbed's users send.

use std::net::SocketAddr;

use kinloop_protocol::quic::{client_endpoint, Endpoint, EndpointOptions, Trust};
use kinloop_protocol::{DeviceCaps, Join, LocalModelForm};
use kinloop_server::ServerHandle;

/// An ephemeral port on 127.0.0.1.
pub fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

/// A client endpoint on loopback that trusts `server`'s self-signed certificate.
pub fn endpoint(server: &ServerHandle) -> Endpoint {
    let options = EndpointOptions { client_bind: loopback(), ..EndpointOptions::default() };
    client_endpoint(&Trust::Fingerprint(server.fingerprint().to_string()), &options).unwrap()
}

/// A manipulator's join on the testbed's `link2` with a device of 20 N peak, 10 N continuous.
pub fn join_link2() -> Join {
    Join {
        op: "link2".into(),
        device: DeviceCaps { max_force_n: 20.0, continuous_force_n: 10.0, ..DeviceCaps::generous("sim", 3) },
        form: LocalModelForm::OpSpace,
        mapping: Default::default(),
    }
}
