//! Haptic devices: what the core needs to know about one ([`DeviceSpec`]), what it reads
//! ([`DeviceState`]) and how it commands one ([`HapticDevice`]), with errors split the way vendor SDKs
//! split them: a recoverable force error (the device refused or limited one command) and a fatal
//! communication error (the device is gone).
//!
//! [`simulated`] holds a device plant integrated at ≥ 10 kHz inside each haptic tick; [`presets`] its
//! published-spec parameter sets; [`rig`] couples a simulated device with a simulated user; [`dhd`] drives
//! Force Dimension devices through their SDK and [`hd`] 3D Systems devices through OpenHaptics, both
//! loaded at run time; [`request`] is what `--device` asks for.

pub mod dhd;
mod haptic_device;
pub mod hd;
pub mod presets;
pub mod request;
pub mod rig;
pub mod simulated;
pub mod vendor_search;

pub use haptic_device::{DeviceError, DeviceSpec, DeviceState, HapticDevice};
pub use presets::DevicePreset;
pub use request::{DeviceRequest, DhdRequest, HdRequest};
pub use rig::{SimulatedRig, SimulatedUser};
pub use simulated::{SimulatedDevice, SimulatedDeviceParams};
