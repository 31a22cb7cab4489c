//! # kinloop-client
//!
//! The haptic side of kinloop: what a user feels is computed here, a thousand times a second.
//!
//! - [`device`]: the [`HapticDevice`](device::HapticDevice) trait, a simulated device plant integrated at
//!   ≥ 10 kHz, and presets (`sim:paper`, `sim:falcon`, `sim:touch`);
//! - [`user`]: simulated users (the paper's constant wrench, a spring-damper hand on a path, a replay);
//! - [`core`]: [`HapticCore`](core::HapticCore), the sans-IO state machine — snapshot intake, the local
//!   model (paper eq 11/13), the controllers of section III / Fig 4, the safety envelope and the uplink;
//! - [`driver`]: the real-time loop thread and the QUIC session around the core
//!   ([`Client::start`](driver::Client::start));
//! - [`bench`](mod@bench): the measurements `kinloop bench` reports;
//! - [`cli`]: the `kinloop-client` program itself (its arguments and what it prints).

#![warn(missing_docs)]

pub mod axes;
pub mod bench;
pub mod cli;
pub mod core;
pub mod device;
pub mod driver;
pub mod user;
