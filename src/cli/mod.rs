//! The `kinloop` command line.

pub mod bench;
pub mod demo;
pub mod devices;
pub mod devices_hd;
pub mod experiment;
pub mod export;
pub mod generate;
pub mod import;
pub mod inspect;
pub mod load;
pub mod simulate;
pub mod timer_floor;
pub mod view;
