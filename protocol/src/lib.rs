//! kinloop-protocol: what travels between the VE server and haptic clients, and how.
//!
//! - [`messages`]: the wire types (control messages and datagrams);
//! - [`codec`]: bytes ⇄ messages with size limits and validation (the only place that knows bincode);
//! - [`quic`]: QUIC endpoints, certificates and trust, the handshake, control framing and datagrams;
//! - [`emulator`]: a seeded, sans-IO link emulator (delay, jitter, loss, bursts, reordering, duplication,
//!   bandwidth) for virtual-time harnesses and, through a socket wrapper, real QUIC traffic;
//! - [`passivity`]: the two-port's energy books both ends keep and send, the check of a peer's books, and the
//!   output scale both ends' passivity controllers use;
//! - [`wrench_limits`]: a device's peak force and torque, and the clipping both ends do against them;
//! - [`arrival_gaps`]: the longest recent gap between a stream's arrivals, what a silence is judged against;
//! - [`bench`](mod@bench): measurements the `kinloop bench` command reports.

pub mod arrival_gaps;
pub mod bench;
pub mod codec;
pub mod emulator;
pub mod messages;
pub mod passivity;
pub mod quic;
pub mod room_key;
mod shape;
pub mod wrench_limits;

pub use messages::*;
pub use shape::{triangle_len, SceneKind, SessionShape};
