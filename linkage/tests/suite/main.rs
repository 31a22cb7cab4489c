//! The linkage crate's integration tests in one binary: the generic algorithms they exercise are
//! compiled and optimised once rather than once per test file (release builds do not share generic
//! instantiations across crates). Tests that install a counting global allocator keep binaries of their own.

#[path = "../common/mod.rs"]
mod common;

mod ball_joints;
mod constraints;
mod dead_centres;
mod energy_guard;
mod implicit_joint_forces;
mod joint_loads;
mod layers;
mod local_model;
mod mutated_scenes;
mod new_scenes;
mod physics;
mod random_linkages;
mod reach;
mod scenes;
mod velocity_product;
