//! What a space provides: its kind, its types and its rigid-body algebra (the [`Space`] trait).

use std::fmt::Debug;
use std::ops::{Index, IndexMut, Mul};

use super::algebra::{MatOps, VecOps};

/// Which kind of space a scene lives in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SceneKind {
    /// Motion in the x-y plane: 3-DOF operational space (x, y, θ).
    Planar,
    /// Motion in 3-D: 6-DOF operational space (v, ω).
    Spatial,
}

impl SceneKind {
    /// Dimension of the operational space (and of spatial vectors) for this kind.
    pub fn op_dim(self) -> usize {
        match self {
            SceneKind::Planar => 3,
            SceneKind::Spatial => 6,
        }
    }
    /// Dimension of positions (2 or 3).
    pub fn point_dim(self) -> usize {
        match self {
            SceneKind::Planar => 2,
            SceneKind::Spatial => 3,
        }
    }
    /// Dimension of angular quantities (1 or 3).
    pub fn angular_dim(self) -> usize {
        match self {
            SceneKind::Planar => 1,
            SceneKind::Spatial => 3,
        }
    }
}

/// A space (planar or spatial) and its rigid-body algebra, all in the world frame.
pub trait Space: Copy + Clone + Debug + Default + PartialEq + Send + Sync + 'static {
    /// Which kind this is.
    const KIND: SceneKind;
    /// Dimension of spatial vectors and of the operational space (3 or 6).
    const DIM: usize;

    /// A position or free vector: 2-D or 3-D.
    type Point: VecOps;
    /// An angular velocity or rotation vector: scalar (planar) or 3-D.
    type Angular: VecOps;
    /// An orientation.
    type Rot: Copy + Debug + PartialEq + Send + Sync + 'static;
    /// Rotational inertia about the centre of mass, in body axes: scalar (planar) or 3x3.
    type RotInertia: Copy + Debug + PartialEq + Send + Sync + 'static;
    /// A world-frame spatial motion or force vector, angular part first.
    type Spatial: VecOps;
    /// A world-frame spatial inertia (symmetric).
    type Inertia: MatOps;
    /// An operational-space vector (linear part first): `(x, y, θ)` or `(v, ω)`.
    type OpVec: VecOps + Index<usize, Output = f64> + IndexMut<usize>;
    /// An operational-space matrix such as Λ⁻¹ (3x3 or 6x6).
    type OpMat: MatOps + Mul<Self::OpVec, Output = Self::OpVec>;

    // --- orientations -------------------------------------------------------------------------
    /// The identity orientation.
    fn rot_identity() -> Self::Rot;
    /// Composition `a ∘ b` (apply `b`, then `a`).
    fn rot_mul(a: &Self::Rot, b: &Self::Rot) -> Self::Rot;
    /// Inverse orientation.
    fn rot_inverse(r: &Self::Rot) -> Self::Rot;
    /// Rotates a vector.
    fn rotate(r: &Self::Rot, p: &Self::Point) -> Self::Point;
    /// Rotation by `angle` about a unit `axis` given by its cosine and sine (planar: the axis is z).
    fn rot_about_axis(axis: &Self::Point, cos: f64, sin: f64) -> Self::Rot;
    /// Rotation from a rotation vector (axis times angle); planar: the angle.
    fn rot_from_vector(v: &Self::Angular) -> Self::Rot;
    /// Rotation vector (log map) of an orientation; planar: the angle in (-π, π].
    fn rot_log(r: &Self::Rot) -> Self::Angular;
    /// The chord between two orientations, `2 sin(θ / 2)` for the angle θ between them: the angle to
    /// second order, without trigonometry (a distance for thresholds, not a rotation vector).
    fn rot_chord(a: &Self::Rot, b: &Self::Rot) -> f64;
    /// True when the orientation is made of finite numbers.
    fn rot_is_finite(r: &Self::Rot) -> bool;
    /// Number of parameters of an orientation on the wire: 1 (angle) or 4 (unit quaternion w, x, y, z).
    const ROT_PARAMS: usize;
    /// Writes an orientation's parameters into `out` (length [`Space::ROT_PARAMS`]).
    fn rot_to_params(r: &Self::Rot, out: &mut [f64]);
    /// Reads an orientation from its parameters; `None` unless finite (and, spatial, a unit quaternion
    /// within 1e-6).
    fn rot_from_params(p: &[f64]) -> Option<Self::Rot>;
    /// What [`Space::rot_to_params_memo`] and [`Space::rot_from_params_memo`] keep between calls on one
    /// stream of orientations (planar: trigonometric anchors; spatial: nothing, quaternions need no
    /// trigonometry).
    type RotParamsMemo: Clone + Copy + Debug + Default + PartialEq + Send + Sync + 'static;
    /// As [`Space::rot_to_params`], cheaper for an orientation that moves little between calls with the
    /// same `memo` (a pose written to the wire every tick); agrees with it to a few units in the last place.
    fn rot_to_params_memo(r: &Self::Rot, out: &mut [f64], memo: &mut Self::RotParamsMemo) {
        let _ = memo;
        Self::rot_to_params(r, out)
    }
    /// As [`Space::rot_from_params`], cheaper for parameters that move little between calls with the same
    /// `memo` (a snapshot's pose every millisecond); agrees with it to round-off.
    fn rot_from_params_memo(p: &[f64], memo: &mut Self::RotParamsMemo) -> Option<Self::Rot> {
        let _ = memo;
        Self::rot_from_params(p)
    }

    /// The orientation of a ball joint's unit quaternion `[w, x, y, z]` (see `math::quaternion`; planar
    /// scenes have no ball joints, and take the quaternion's turn about z).
    fn rot_from_quaternion(q: &[f64]) -> Self::Rot;

    // --- reading scenes ----------------------------------------------------------------------
    /// Orientation from a scene's `rotation` numbers (planar: one angle; spatial: roll, pitch, yaw).
    fn rot_from_scene(v: &[f64]) -> Result<Self::Rot, String>;
    /// Rotational inertia about the COM from a scene's `inertia` numbers; checks it is positive definite.
    fn rot_inertia_from_scene(v: &[f64]) -> Result<Self::RotInertia, String>;
    /// The zero rotational inertia (a ball or universal joint's internal, massless bodies).
    fn rot_inertia_zero() -> Self::RotInertia;
    /// A scalar size of a rotational inertia (planar: I; spatial: trace / 3), for the length scale.
    fn rot_inertia_size(i: &Self::RotInertia) -> f64;
    /// Default joint axis in the joint frame (spatial: z; planar prismatic: x).
    fn default_axis() -> Self::Point;
    /// The angular velocity of a unit-rate rotation about a world axis (planar: 1, about z).
    fn axis_as_angular(axis_world: &Self::Point) -> Self::Angular;

    // --- points and angular vectors ----------------------------------------------------------
    /// `ω × p`: the velocity a rotation rate ω gives point p (planar: ω ẑ × p).
    fn ang_cross_point(w: &Self::Angular, p: &Self::Point) -> Self::Point;
    /// `a × b` for two points, as an angular quantity (planar: the z component).
    fn point_cross_point(a: &Self::Point, b: &Self::Point) -> Self::Angular;

    // --- spatial vectors ---------------------------------------------------------------------
    /// Assembles a spatial vector from its angular and linear parts.
    fn spatial(ang: Self::Angular, lin: Self::Point) -> Self::Spatial;
    /// Angular part of a spatial vector.
    fn spatial_ang(s: &Self::Spatial) -> Self::Angular;
    /// Linear part of a spatial vector.
    fn spatial_lin(s: &Self::Spatial) -> Self::Point;
    /// Motion cross product `v × m`.
    fn cross_motion(v: &Self::Spatial, m: &Self::Spatial) -> Self::Spatial;
    /// Force cross product `v ×* f`.
    fn cross_force(v: &Self::Spatial, f: &Self::Spatial) -> Self::Spatial;
    /// Spatial inertia times a motion vector.
    fn inertia_mul(i: &Self::Inertia, m: &Self::Spatial) -> Self::Spatial;
    /// World-frame spatial inertia (about the world origin) of a body of `mass` whose centre of mass
    /// is at `com_world` and whose rotational inertia about the COM is `inertia_com` in body axes `rot`.
    fn inertia_world(
        mass: f64,
        com_world: &Self::Point,
        inertia_com: &Self::RotInertia,
        rot: &Self::Rot,
    ) -> Self::Inertia;

    // --- operational space -------------------------------------------------------------------
    /// Assembles an operational-space vector (linear part first).
    fn op(lin: Self::Point, ang: Self::Angular) -> Self::OpVec;
    /// Linear part of an operational-space vector.
    fn op_lin(v: &Self::OpVec) -> Self::Point;
    /// Angular part of an operational-space vector.
    fn op_ang(v: &Self::OpVec) -> Self::Angular;
    /// Outer product `a bᵀ` of two operational-space vectors.
    #[inline]
    fn op_outer(a: &Self::OpVec, b: &Self::OpVec) -> Self::OpMat {
        let mut m = Self::OpMat::zero();
        for c in 0..Self::DIM {
            for r in 0..Self::DIM {
                m[(r, c)] = a[r] * b[c];
            }
        }
        m
    }
}
