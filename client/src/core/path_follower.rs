//! A linkage of one degree of freedom: the OP's path from the welcome, and where on it the local model and
//! the active snapshot's pose were found last (`CoreConfig::follow_path`).

use kinloop_linkage::algorithms::constraint_directions::scale_op;
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
    /// The OP's acceleration at rest at the active snapshot's pose, as the path has it (none on a swing).
    pub(super) snapshot_rest: Option<S::OpVec>,
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
        let path = OpPath::new(poses, op.path_shape, welcome.scene.length_scale)?;
        let path = match &op.path_rest_acceleration {
            Some(rest) => path.with_rest_acceleration(rest.clone())?,
            None => path,
        };
        let path = if pinned { path.positions_only()? } else { path };
        Ok(Some(PathFollower {
            path,
            model_segment: None,
            snapshot_segment: None,
            snapshot_tangent: None,
            snapshot_rest: None,
            rest_where_model_is: !welcome.mapping.gravity_compensation,
            pinned,
        }))
    }

    /// On a swing, the correction (displacement, twist change) that holds a model at `pose` with `twist`,
    /// found last on segment `model_segment`, at the limit that segment leads to: what it has run beyond the
    /// limit along the direction out of the path there, and its speed outward. The OP stops at a limit and
    /// comes back however the linkage goes on (its map from the linkage's coordinate folds there), so a model
    /// past it is where the linkage cannot be. Stopping it takes kinetic energy out of the model and puts
    /// none in. `None` inside the swing, on other shapes, and for a model already held.
    pub(super) fn stop_at_limit(
        &self,
        pose: &OpPose<S>,
        twist: &S::OpVec,
        length_scale: f64,
    ) -> Option<(S::OpVec, S::OpVec)> {
        let (limit, out) = self.path.limit(self.model_segment?)?;
        let beyond = scale_op::<S>(&self.query(pose).difference(&limit), length_scale).dot(&out).max(0.0);
        let outward = scale_op::<S>(twist, length_scale).dot(&out).max(0.0);
        if beyond == 0.0 && outward == 0.0 {
            return None;
        }
        let back = |amount: f64| scale_op::<S>(&(out * -amount), 1.0 / length_scale);
        Some((back(beyond), back(outward)))
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
