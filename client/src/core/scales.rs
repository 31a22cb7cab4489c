//! The mapping's scales between device units and VE units.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::Mapping;

/// How device and VE map onto each other (`protocol::Mapping`): positions by `position` (device metres per VE
/// metre), forces by `force`, torques by `torque = force · position`; angles one to one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scales {
    /// Device metres per VE metre.
    pub position: f64,
    /// Device newtons per VE newton.
    pub force: f64,
    /// Device newton-metres per VE newton-metre.
    pub torque: f64,
}

impl Scales {
    /// From the welcome's mapping.
    pub fn of(mapping: &Mapping) -> Self {
        Scales { position: mapping.position_scale, force: mapping.force_scale, torque: mapping.torque_scale() }
    }

    /// A device twist in the VE.
    pub fn twist_to_ve<S: Space>(&self, twist: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(twist, 1.0 / self.position, 1.0)
    }

    /// A device wrench (the hand's) in the VE.
    pub fn wrench_to_ve<S: Space>(&self, wrench: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(wrench, 1.0 / self.force, 1.0 / self.torque)
    }

    /// A VE wrench on the device.
    pub fn wrench_to_device<S: Space>(&self, wrench: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(wrench, self.force, self.torque)
    }

    /// A device gain (stiffness or damping, per axis) in VE units: `F_ve = F_d / c_f` for a device
    /// displacement `c_p Δx_ve`, so `K_ve = K_d c_p / c_f`; on angular axes `K_ve = K_d / c_τ`.
    pub(super) fn gain_to_ve<S: Space>(&self, gain: &S::OpVec) -> S::OpVec {
        self.per_group::<S>(gain, self.position / self.force, 1.0 / self.torque)
    }

    /// Device masses in VE units (the mass the VE side must give a wrench to move the device as it moves).
    pub(super) fn mass_to_ve<S: Space>(&self, mass: &S::OpVec) -> S::OpVec {
        self.gain_to_ve::<S>(mass)
    }

    fn per_group<S: Space>(&self, v: &S::OpVec, linear: f64, angular: f64) -> S::OpVec {
        let lin = <S::Point as VecOps>::LEN;
        let mut out = *v;
        for i in 0..S::DIM {
            out[i] *= if i < lin { linear } else { angular };
        }
        out
    }
}
