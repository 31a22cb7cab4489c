//! The harness crate's integration tests in one binary: the generic algorithms they exercise are
//! compiled and optimised once rather than once per test file (release builds do not share generic
//! instantiations across crates). Tests that install a counting global allocator keep binaries of their own.

mod paper_manipulation;
mod passive_update;
mod random_sessions;
mod safety;
