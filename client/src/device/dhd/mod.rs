//! Force Dimension devices (omega, delta, sigma, lambda, Novint Falcon) through the DHD SDK, loaded at run
//! time: [`library`] finds and checks the vendor library, [`specs`] maps `dhdGetSystemType` to published
//! specs, [`frames`] converts the device's frame and units to kinloop's, [`device`] is the [`HapticDevice`]
//! the loop drives.
//!
//! [`HapticDevice`]: super::HapticDevice

pub mod device;
pub mod frames;
pub mod library;
pub mod specs;

pub use device::{DhdDevice, OpenedDhd};
pub use library::{DhdError, DhdLibrary};
