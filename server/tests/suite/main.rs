//! The server crate's integration tests in one binary: the generic algorithms they exercise are
//! compiled and optimised once rather than once per test file (release builds do not share generic
//! instantiations across crates). Tests that install a counting global allocator keep binaries of their own.

#[path = "../support/mod.rs"]
mod support;

mod bench_hooks;
mod coupling_frequency;
mod join_handover;
mod loopback;
mod passivity;
mod quic_server;
mod random_sessions;
mod resume;
mod rooms;
mod round_trips;
mod synthetic_load;
mod ve_ball_joints;
mod ve_core;
