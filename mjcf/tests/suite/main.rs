//! The importer's tests in one binary (docs/testing.md): bad input, the export's round trip, and agreement with
//! MuJoCo itself (in a Python venv the tests make once, under a lock).

#[path = "../common/mod.rs"]
mod common;

mod bad_input;
mod export_roundtrip;
mod mujoco_agreement;
