//! The pose of an operational point (position and orientation, world frame) and its wire form; where an
//! operational point is at a configuration is the kinematics' ([`OpPose::of_op`]).

use super::algebra::VecOps;
use super::definition::Space;

/// Position and orientation of an operational point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpPose<S: Space> {
    /// Position, world frame.
    pub position: S::Point,
    /// Orientation, world frame.
    pub rotation: S::Rot,
}

impl<S: Space> OpPose<S> {
    /// The origin with identity orientation.
    pub fn identity() -> Self {
        OpPose { position: S::Point::zero(), rotation: S::rot_identity() }
    }

    /// Moves the pose along a world-frame twist (linear, angular) for `dt`.
    pub fn integrate(&mut self, twist: &S::OpVec, dt: f64) {
        self.position += S::op_lin(twist) * dt;
        self.rotation = S::rot_mul(&S::rot_from_vector(&(S::op_ang(twist) * dt)), &self.rotation);
    }

    /// `self ⊖ other`: the world-frame displacement (linear, rotation vector) taking `other` to `self`.
    pub fn difference(&self, other: &OpPose<S>) -> S::OpVec {
        S::op(self.position - other.position, S::rot_log(&S::rot_mul(&self.rotation, &S::rot_inverse(&other.rotation))))
    }

    /// Number of numbers on the wire: point dimension + orientation parameters (3 planar, 7 spatial).
    pub fn wire_len() -> usize {
        <S::Point as VecOps>::LEN + S::ROT_PARAMS
    }

    /// Writes `[position, orientation parameters]` into `out` (length [`OpPose::wire_len`]).
    pub fn to_slice(&self, out: &mut [f64]) {
        self.to_slice_memo(out, &mut S::RotParamsMemo::default());
    }

    /// As [`OpPose::to_slice`] for a pose written again and again as it moves (see
    /// [`Space::rot_to_params_memo`]).
    pub fn to_slice_memo(&self, out: &mut [f64], memo: &mut S::RotParamsMemo) {
        let n = <S::Point as VecOps>::LEN;
        out[..n].copy_from_slice(self.position.as_slice());
        S::rot_to_params_memo(&self.rotation, &mut out[n..n + S::ROT_PARAMS], memo);
    }

    /// Reads a pose written by [`OpPose::to_slice`]; `None` when the length is wrong or values invalid.
    pub fn from_slice(v: &[f64]) -> Option<Self> {
        let (position, params) = Self::split_wire(v)?;
        Some(OpPose { position, rotation: S::rot_from_params(params)? })
    }

    /// As [`OpPose::from_slice`] for poses read one after another as they move (see
    /// [`Space::rot_from_params_memo`]).
    pub fn from_slice_memo(v: &[f64], memo: &mut S::RotParamsMemo) -> Option<Self> {
        let (position, params) = Self::split_wire(v)?;
        Some(OpPose { position, rotation: S::rot_from_params_memo(params, memo)? })
    }

    /// The position and the orientation's parameters of a pose on the wire, when the length is right and
    /// the position finite.
    fn split_wire(v: &[f64]) -> Option<(S::Point, &[f64])> {
        let n = <S::Point as VecOps>::LEN;
        if v.len() != n + S::ROT_PARAMS || v[..n].iter().any(|x| !x.is_finite()) {
            return None;
        }
        Some((S::Point::from_slice(&v[..n]), &v[n..]))
    }
}
