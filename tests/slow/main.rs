//! The slow tier (docs/testing.md): real time, real processes, whole tours, in one binary. Each test binary of
//! a release build compiles and optimises its own copy of the generic code it reaches and links the whole
//! tree, so one binary builds far faster than one per file. Every test here holds the shared serial lock
//! (`common::bounded`, `common::serial`) while it runs real time or a heavy loop, so two sessions never share
//! the two cores, as when each file was a binary that cargo ran after the other.

#[path = "../common/mod.rs"]
mod common;

mod demo;
mod device_renderability;
mod dhd_e2e;
mod drain_e2e;
mod e2e_delay;
mod e2e_faults;
mod e2e_latency;
mod guided_slider_crank;
mod hand_run;
mod hd_e2e;
mod resume_e2e;
mod resume_netns;
mod robustness_live;
mod rooms_e2e;
