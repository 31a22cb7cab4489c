//! # kinloop-server
//!
//! The VE host: one linkage with kinematic loops, simulated exactly, that several people grab at once through
//! their haptic devices.
//!
//! - [`core`]: [`VeCore`], the virtual environment as a sans-IO state machine (users, couplings, passivity,
//!   guards, snapshots), driven with time as an argument;
//! - [`access`]: tokens and roles, compared in constant time;
//! - [`gateway`]: what the driver and the view share, below both: the command ring to the VE thread, the
//!   registry of admitted users, snapshot frames, the VE thread's timing statistics;
//! - [`driver`]: the thin real-time shell: the VE thread with absolute deadlines, tokio + quinn for the
//!   network, lock-free rings between them; [`Server::start`] runs it in-process;
//! - [`fleet`]: the edge toward a fleet manager (Agones): readiness, health from the VE's heartbeat, counts;
//! - [`view`]: the web page that draws the linkage live (and lets a visitor grab it) or replays a recording;
//! - [`bench`](mod@bench): the numbers `kinloop bench` reports;
//! - [`synthetic`]: the in-process users those numbers and `--synthetic-users` drive;
//! - [`cli`]: the `kinloop-server` program itself (its arguments and what it prints).

pub mod bench;
pub mod cli;
pub mod core;
pub mod synthetic;

pub use crate::core::{
    JoinRequest, Joined, UplinkRejection, UplinkSample, UserId, VeConfig, VeCore, VeEvent, VeMetrics,
};
pub mod access;
pub mod driver;
pub mod fleet;
pub mod gateway;
pub mod view;

pub use crate::access::Access;
pub use crate::driver::{Identity, Server, ServerConfig, ServerError, ServerHandle, ServerStats};
