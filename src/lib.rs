//! # kinloop
//!
//! The root package: the `kinloop` command line (demo, inspect, simulate, bench, experiment), the
//! experiments (each in virtual time on the `kinloop-harness` crate, or in real time) and their
//! charts.

pub mod charts;
pub mod cli;
pub mod demo;
pub mod experiments;
pub mod generate;
pub mod load;
pub mod rounding;
pub mod scene_arg;
