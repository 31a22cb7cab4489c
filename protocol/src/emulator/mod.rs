//! A seeded, sans-IO link emulator: delay, jitter, Bernoulli and Gilbert–Elliott loss, reordering,
//! duplication and a bandwidth cap.
//!
//! One core ([`LinkEmulator`]) serves both the virtual-time harness (the caller passes virtual time) and real
//! QUIC traffic (`quic::EndpointOptions::link` wraps the UDP socket so outgoing packets go through it).

mod config;
mod link;

pub use config::{
    parse_bandwidth, parse_burst, parse_duration, parse_probability, GilbertElliott, LinkArgs, LinkConfig,
    LinkConfigError, LinkParseError, MAX_LINK_DELAY, MAX_QUEUE_DELAY, MIN_BANDWIDTH_BPS,
};
pub use link::{LinkEmulator, LinkStats, WireSize};
