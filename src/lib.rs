//! # kinloop
//!
//! The root package: the `kinloop` command line (demo, inspect, simulate, bench, experiment), the
//! virtual-time harness that runs a VE server core and haptic client cores over emulated links, the
//! experiments and their charts.

pub mod charts;
pub mod cli;
pub mod demo;
pub mod experiments;
pub mod generate;
pub mod harness;
pub mod scene_arg;
