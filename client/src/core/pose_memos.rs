//! Trigonometric anchors for the pose streams the core converts to and from the wire.

use kinloop_linkage::math::space::Space;

/// One memo per stream of poses the core reads or writes on the wire (see `Space::RotParamsMemo`): each
/// stream moves little from one conversion to the next, which the memo turns into fewer library calls.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PoseMemos<S: Space> {
    pub(super) snapshot_op: S::RotParamsMemo,
    pub(super) uplink_device: S::RotParamsMemo,
    pub(super) uplink_model: S::RotParamsMemo,
}
