//! A linkage of one degree of freedom: the OP's path from the welcome, and where on it the local model and
//! the active snapshot's pose were found last (`CoreConfig::follow_path`).

use kinloop_linkage::algorithms::op_path::{OpPath, PathError};
use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::Welcome;

use super::{CoreConfig, CoreError};

/// The OP's path and where on it the model and the active snapshot's pose were found last.
#[derive(Clone, Debug)]
pub(super) struct PathFollower<S: Space> {
    pub(super) path: OpPath<S>,
    pub(super) model_segment: Option<usize>,
    pub(super) snapshot_segment: Option<usize>,
    /// Unit tangent at the active snapshot's pose (unit-consistent coordinates).
    pub(super) snapshot_tangent: Option<S::OpVec>,
    /// The OP's acceleration at rest at the active snapshot's pose, as the path has it.
    pub(super) snapshot_rest: S::OpVec,
    /// The forces at rest are felt where the model is, not where the snapshot was taken (false when the VE
    /// holds the linkage's weight at this OP: `Mapping::gravity_compensation` takes them out of b̂).
    pub(super) rest_where_model_is: bool,
    /// The grasp is pinned: the path is its positions only, and poses are looked for by position.
    pub(super) pinned: bool,
}

impl<S: Space> PathFollower<S> {
    /// The welcome's path, if it has one and the configuration follows it; `pinned`: the grasp renders no
    /// torque (`HapticCore::pinned`), so the model's angle is the linkage's business, not the hand's, and
    /// the path is followed by position (`OpPath::positions_only`: by the whole pose, a model whose angle
    /// had drifted would be found off where it is on the path, and the forces at rest taken there would
    /// make energy).
    pub(super) fn of(welcome: &Welcome, config: &CoreConfig, pinned: bool) -> Result<Option<Self>, CoreError> {
        let op = &welcome.op;
        if !config.follow_path || op.path.is_empty() {
            return Ok(None);
        }
        let wire = OpPose::<S>::wire_len();
        let mut poses = Vec::with_capacity(op.path.len() / wire);
        for (i, chunk) in op.path.chunks(wire).enumerate() {
            poses.push(OpPose::from_slice(chunk).ok_or(PathError::NonFinite(i))?);
        }
        let path = OpPath::new(poses, op.path_closed, welcome.scene.length_scale)?
            .with_rest_acceleration(op.path_rest_acceleration.clone())?;
        let path = if pinned { path.positions_only()? } else { path };
        Ok(Some(PathFollower {
            path,
            model_segment: None,
            snapshot_segment: None,
            snapshot_tangent: None,
            snapshot_rest: S::OpVec::zero(),
            rest_where_model_is: !welcome.mapping.gravity_compensation,
            pinned,
        }))
    }

    /// Where `pose` is looked for on the path (by position alone when pinned).
    pub(super) fn query(&self, pose: &OpPose<S>) -> OpPose<S> {
        if self.pinned {
            OpPose { position: pose.position, rotation: S::rot_identity() }
        } else {
            *pose
        }
    }
}
