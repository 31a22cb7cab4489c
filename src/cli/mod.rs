//! The `kinloop` command line.

pub mod bench;
pub mod inspect;
pub mod simulate;
