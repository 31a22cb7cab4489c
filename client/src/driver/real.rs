//! A vendor's device the client opened before connecting (DHD or OpenHaptics), and the spec it describes in
//! every join.

use kinloop_linkage::math::space::SceneKind;

use crate::device::dhd::specs::ModelSpec;
use crate::device::dhd::OpenedDhd;
use crate::device::hd::{HdSpec, OpenedHd};
use crate::device::DeviceSpec;

/// An opened vendor device.
pub enum OpenedDevice {
    /// Force Dimension, polled by kinloop's loop.
    Dhd(OpenedDhd),
    /// OpenHaptics, whose servo thread runs the loop.
    Hd(OpenedHd),
}

/// What an opened device describes in a join.
#[derive(Clone, Debug)]
pub enum RealSpec {
    /// A DHD model's published figures.
    Dhd(&'static ModelSpec),
    /// The figures an HD device reported.
    Hd(HdSpec),
}

impl OpenedDevice {
    /// Its spec.
    pub fn spec(&self) -> RealSpec {
        match self {
            OpenedDevice::Dhd(d) => RealSpec::Dhd(d.model()),
            OpenedDevice::Hd(d) => RealSpec::Hd(d.spec().clone()),
        }
    }
}

impl RealSpec {
    /// The spec kinloop designs for in a scene of `kind`.
    pub fn device_spec(&self, kind: SceneKind) -> DeviceSpec {
        match self {
            RealSpec::Dhd(model) => model.device_spec(kind),
            RealSpec::Hd(spec) => spec.device_spec(kind),
        }
    }

    /// The name the client reports (`dhd (MODEL)`, `hd (MODEL)`).
    pub fn label(&self) -> String {
        match self {
            RealSpec::Dhd(model) => format!("dhd ({})", model.name),
            RealSpec::Hd(spec) => format!("hd ({})", spec.model),
        }
    }
}
