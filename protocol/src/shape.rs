//! The dimensions a session agrees on in its handshake, which every datagram must then match.

use serde::{Deserialize, Serialize};

/// Planar or spatial, with `op_dim()`, `point_dim()`, `angular_dim()`; the linkage crate owns it.
pub use kinloop_linkage::math::space::SceneKind;

/// Dimensions of one session: fixed by the `Welcome`, checked on every snapshot and uplink.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SessionShape {
    /// Planar or spatial.
    pub kind: SceneKind,
    /// Number of generalized velocities of the scene's tree (nv; q̇ and the columns of every Jacobian).
    pub n: usize,
    /// Number of configuration coordinates (nq ≥ n: a ball joint's orientation is a unit quaternion, four
    /// positions for its three rates).
    pub nq: usize,
    /// Number of loop-closure rows.
    pub m: usize,
}

impl SessionShape {
    /// The shape of every session on `model`.
    pub fn of_model<S: kinloop_linkage::math::space::Space>(model: &kinloop_linkage::model::Model<S>) -> Self {
        SessionShape { kind: S::KIND, n: model.nv(), nq: model.nq(), m: model.nc() }
    }

    /// Operational-space dimension `k` (twists, wrenches): 3 planar, 6 spatial.
    pub fn op_dim(&self) -> usize {
        self.kind.op_dim()
    }
    /// Length of a pose: 3 planar `[x, y, θ]`, 7 spatial `[x, y, z, qw, qx, qy, qz]`.
    pub fn pose_dim(&self) -> usize {
        match self.kind {
            SceneKind::Planar => 3,
            SceneKind::Spatial => 7,
        }
    }
    /// Length of a position: 2 planar, 3 spatial.
    pub fn point_dim(&self) -> usize {
        self.kind.point_dim()
    }
    /// Length of a packed upper triangle of a `k x k` symmetric matrix.
    pub fn op_triangle_len(&self) -> usize {
        triangle_len(self.op_dim())
    }
}

/// Length of the packed upper triangle (row-major, diagonal included) of a `dim x dim` symmetric matrix.
pub fn triangle_len(dim: usize) -> usize {
    dim * (dim + 1) / 2
}
