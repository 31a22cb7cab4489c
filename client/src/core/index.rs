//! Indexing the device onto the operational point: where the device's handle and the VE's OP coincide
//! ([`DeviceIndex`]), chosen so that the device's workspace holds the OP's reach ([`Boxes`]).

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::OpSummary;

use crate::device::DeviceSpec;

/// Maps device poses into the VE: the device's displacement from where it was indexed, divided by the
/// position scale, from the OP's position then, and a handle-frame orientation offset
/// (`R_ve = R_device R_offset`), so world-frame angular velocities are the same on both sides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct DeviceIndex<S: Space> {
    device_origin: S::Point,
    ve_origin: S::Point,
    rotation: S::Rot,
    position_scale: f64,
}

impl<S: Space> DeviceIndex<S> {
    pub(super) fn identity(position_scale: f64) -> Self {
        DeviceIndex {
            device_origin: S::Point::zero(),
            ve_origin: S::Point::zero(),
            rotation: S::rot_identity(),
            position_scale,
        }
    }

    pub(super) fn between(device: &OpPose<S>, op: &OpPose<S>, position_scale: f64) -> Self {
        DeviceIndex {
            device_origin: device.position,
            ve_origin: op.position,
            rotation: S::rot_mul(&S::rot_inverse(&device.rotation), &op.rotation),
            position_scale,
        }
    }

    /// The workspace's centre onto the reach's centre: the whole reach then fits the workspace (the scale was
    /// chosen for it), wherever the OP is when the session starts. The orientation is indexed as in
    /// `between`.
    pub(super) fn centred(
        device: &OpPose<S>,
        op: &OpPose<S>,
        frames: &(S::Point, S::Point),
        position_scale: f64,
    ) -> Self {
        DeviceIndex { device_origin: frames.0, ve_origin: frames.1, ..Self::between(device, op, position_scale) }
    }

    pub(super) fn apply(&self, pose: &OpPose<S>) -> OpPose<S> {
        OpPose {
            position: self.ve_origin + (pose.position - self.device_origin) * (1.0 / self.position_scale),
            rotation: S::rot_mul(&pose.rotation, &self.rotation),
        }
    }

    /// Where a VE position lies on the device (the inverse of `apply`'s position part).
    pub(super) fn device_point(&self, ve: &S::Point) -> S::Point {
        self.device_origin + (*ve - self.ve_origin) * self.position_scale
    }
}

/// The device's workspace and the OP's reach as boxes (linear axes), to index the device so that the one
/// holds the other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Boxes<S: Space> {
    workspace: (S::Point, S::Point),
    reach: (S::Point, S::Point),
}

impl<S: Space> Boxes<S> {
    /// `None` when the welcome's reach has no extent or does not fit the space.
    pub(super) fn of(device: &DeviceSpec, op: &OpSummary) -> Option<Self> {
        let lin = <S::Point as VecOps>::LEN;
        if op.reach_min.len() != lin || op.reach_max.len() != lin || device.workspace_min.len() < lin {
            return None;
        }
        let extent = (0..lin).map(|a| op.reach_max[a] - op.reach_min[a]).fold(0.0, f64::max);
        if extent.is_nan() || extent <= 0.0 {
            return None;
        }
        let point = |v: &[f64]| S::Point::from_slice(&v[..lin]);
        Some(Boxes {
            workspace: (point(&device.workspace_min), point(&device.workspace_max)),
            reach: (point(&op.reach_min), point(&op.reach_max)),
        })
    }

    pub(super) fn centres(&self) -> (S::Point, S::Point) {
        ((self.workspace.0 + self.workspace.1) * 0.5, (self.reach.0 + self.reach.1) * 0.5)
    }

    /// True when indexing the device where it is onto the OP where it is keeps the whole reach inside the
    /// workspace (then the device need not move to start).
    pub(super) fn fits_from(&self, device: &S::Point, op: &S::Point, scale: f64) -> bool {
        let lo = *device + (self.reach.0 - *op) * scale;
        let hi = *device + (self.reach.1 - *op) * scale;
        let (w_lo, w_hi) = (self.workspace.0.as_slice(), self.workspace.1.as_slice());
        (0..<S::Point as VecOps>::LEN).all(|a| lo.as_slice()[a] >= w_lo[a] && hi.as_slice()[a] <= w_hi[a])
    }
}
