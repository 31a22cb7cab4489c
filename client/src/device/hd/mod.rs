//! 3D Systems devices (Touch, Touch X, Phantom Premium) through OpenHaptics' HD API, loaded at run time:
//! [`library`] finds and loads `libHD` (and never unloads it), [`units`] converts the device's millimetres
//! and per-millimetre figures to kinloop's SI, [`device`] opens a device, reads its spec from it and is the
//! [`HapticDevice`] the vendor's servo thread drives through `hdScheduleAsynchronous`
//! (`crate::driver::device_clock`).
//!
//! [`HapticDevice`]: super::HapticDevice

pub mod device;
pub mod library;
pub mod units;

pub use device::{HdDevice, HdSpec, OpenedHd};
pub use library::{HdError, HdLibrary};
