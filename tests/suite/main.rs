//! The root package's fast tests in one binary: each test binary of a release build compiles and optimises its
//! own copy of the generic code it reaches, so one binary builds far faster than one per file. The slow tier
//! is `tests/slow/` and `tests/experiments.rs`.

#[path = "../common/mod.rs"]
mod common;

mod bench_markdown;
mod devices_cli;
mod dhd_demo;
mod e2e_refusals;
mod e2e_session;
mod generate;
mod harness;
mod renderability;
mod robustness;
mod rust_version;
mod scene_cli;
mod unit_invariance;
mod units_regressions;
mod view_cli;
