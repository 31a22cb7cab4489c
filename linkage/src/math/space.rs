//! The two spaces a linkage can live in, and their spatial algebra.
//!
//! All rigid-body algorithms in this crate are written once, generic over [`Space`], and run in the
//! **world frame** (Featherstone's "ground frame" formulation, as MuJoCo does with its global `cdof` and
//! `cinert`): motion subspaces, velocities and composite inertias are all expressed at the world origin,
//! so composite inertias add without transforms and the mass matrix needs no Plücker transforms at all.
//!
//! Spatial vectors follow Featherstone's order, angular part first:
//! - planar: motion `(ω, vx, vy)`, force `(τ, fx, fy)`, 3-D;
//! - spatial: motion `(ω, v)`, force `(n, f)`, 6-D.
//!
//! Operational-space vectors (what a user or device sees) use the conventions of `../shared/design.md`
//! instead, linear part first: planar `(x, y, θ)`, spatial `(v, ω)`.
//!
//! A planar scene never touches 6-D algebra: [`Planar`] works on 2-vectors, scalars and 3x3 matrices.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Index, IndexMut, Mul, Neg, Sub, SubAssign};

use nalgebra::{Matrix3, Matrix6, Rotation3, UnitComplex, Vector2, Vector3, Vector6};

use crate::math::trig;

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

/// Small fixed-size vectors: the arithmetic the generic algorithms need.
pub trait VecOps:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + Mul<f64, Output = Self>
    + AddAssign
    + SubAssign
{
    /// Number of components.
    const LEN: usize;
    /// The zero vector.
    fn zero() -> Self;
    /// Euclidean dot product.
    fn dot(&self, other: &Self) -> f64;
    /// Components, in order.
    fn as_slice(&self) -> &[f64];
    /// Mutable components, in order.
    fn as_mut_slice(&mut self) -> &mut [f64];
    /// Builds from exactly `LEN` components (callers guarantee the length).
    #[inline]
    fn from_slice(v: &[f64]) -> Self {
        let mut out = Self::zero();
        out.as_mut_slice().copy_from_slice(&v[..Self::LEN]);
        out
    }
    /// Euclidean norm.
    #[inline]
    fn norm(&self) -> f64 {
        self.dot(self).sqrt()
    }
    /// True when every component is finite.
    #[inline]
    fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|x| f64::is_finite(*x))
    }
}

impl VecOps for f64 {
    const LEN: usize = 1;
    #[inline]
    fn zero() -> Self {
        0.0
    }
    #[inline]
    fn dot(&self, other: &Self) -> f64 {
        self * other
    }
    #[inline]
    fn as_slice(&self) -> &[f64] {
        std::slice::from_ref(self)
    }
    #[inline]
    fn as_mut_slice(&mut self) -> &mut [f64] {
        std::slice::from_mut(self)
    }
}

macro_rules! impl_vec_ops {
    ($t:ty, $n:expr) => {
        impl VecOps for $t {
            const LEN: usize = $n;
            #[inline]
            fn zero() -> Self {
                <$t>::zeros()
            }
            #[inline]
            fn dot(&self, other: &Self) -> f64 {
                nalgebra::Matrix::dot(self, other)
            }
            #[inline]
            fn as_slice(&self) -> &[f64] {
                nalgebra::Matrix::as_slice(self)
            }
            #[inline]
            fn as_mut_slice(&mut self) -> &mut [f64] {
                nalgebra::Matrix::as_mut_slice(self)
            }
        }
    };
}
impl_vec_ops!(Vector2<f64>, 2);
impl_vec_ops!(Vector3<f64>, 3);
impl_vec_ops!(Vector6<f64>, 6);

/// Small fixed-size square matrices used for spatial inertias and operational-space inertias.
pub trait MatOps:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + AddAssign
    + Mul<f64, Output = Self>
    + Index<(usize, usize), Output = f64>
    + IndexMut<(usize, usize)>
{
    /// Number of rows (= columns).
    const DIM: usize;
    /// The zero matrix.
    fn zero() -> Self;
    /// The identity matrix.
    fn identity() -> Self;
    /// Components, column-major.
    fn as_slice(&self) -> &[f64];
    /// Mutable components, column-major.
    fn as_mut_slice(&mut self) -> &mut [f64];
    /// Transpose.
    fn transpose(&self) -> Self;
    /// True when every component is finite.
    #[inline]
    fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|x| f64::is_finite(*x))
    }
}

macro_rules! impl_mat_ops {
    ($t:ty, $n:expr) => {
        impl MatOps for $t {
            const DIM: usize = $n;
            #[inline]
            fn zero() -> Self {
                <$t>::zeros()
            }
            #[inline]
            fn identity() -> Self {
                <$t>::identity()
            }
            #[inline]
            fn as_slice(&self) -> &[f64] {
                nalgebra::Matrix::as_slice(self)
            }
            #[inline]
            fn as_mut_slice(&mut self) -> &mut [f64] {
                nalgebra::Matrix::as_mut_slice(self)
            }
            #[inline]
            fn transpose(&self) -> Self {
                nalgebra::Matrix::transpose(self)
            }
        }
    };
}
impl_mat_ops!(Matrix3<f64>, 3);
impl_mat_ops!(Matrix6<f64>, 6);

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

    // --- reading scenes ----------------------------------------------------------------------
    /// Orientation from a scene's `rotation` numbers (planar: one angle; spatial: roll, pitch, yaw).
    fn rot_from_scene(v: &[f64]) -> Result<Self::Rot, String>;
    /// Rotational inertia about the COM from a scene's `inertia` numbers; checks it is positive definite.
    fn rot_inertia_from_scene(v: &[f64]) -> Result<Self::RotInertia, String>;
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

/// The rotation-vector part of the displacement `d` (angle θ about u, θ ≤ π as a logarithm gives it) turned
/// into the equivalent `u (θ + 2πk)` nearest `previous`'s: consecutive displacements along a path that turns
/// through ±π then stay continuous instead of jumping by 2π (a tour interpolated between the jumps would
/// spin the long way round).
pub fn unwrap_rotation_near<S: Space>(d: &mut S::OpVec, previous: &S::OpVec) {
    let lin = <S::Point as VecOps>::LEN;
    let theta = (lin..S::DIM).map(|i| d[i] * d[i]).sum::<f64>().sqrt();
    if !(theta.is_finite() && theta > 0.0) {
        return;
    }
    // `previous` along u, in turns of 2π beyond θ.
    let along = (lin..S::DIM).map(|i| previous[i] * d[i] / theta).sum::<f64>();
    let turns = ((along - theta) / std::f64::consts::TAU).round();
    if turns.is_finite() && turns != 0.0 {
        let scale = (theta + turns * std::f64::consts::TAU) / theta;
        for i in lin..S::DIM {
            d[i] *= scale;
        }
    }
}

/// The wrench with its force and its torque each scaled back to at most `max_force` and `max_torque`
/// (each keeps its direction), and the scales applied. Force and torque are limited apart, as a force sensor
/// saturates and as a device's peaks are rated: a wrist torque past its range says nothing about the force.
pub fn clip_wrench_parts<S: Space>(wrench: &S::OpVec, max_force: f64, max_torque: f64) -> (S::OpVec, PartScales) {
    let scale = |magnitude: f64, limit: f64| if magnitude > limit { limit / magnitude } else { 1.0 };
    let scales = PartScales {
        force: scale(S::op_lin(wrench).norm(), max_force),
        torque: scale(S::op_ang(wrench).norm(), max_torque),
    };
    (scales.apply::<S>(wrench), scales)
}

/// Separate scales on a wrench's force (linear part) and torque (angular part).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartScales {
    /// On the force.
    pub force: f64,
    /// On the torque.
    pub torque: f64,
}

impl PartScales {
    /// The smaller: 1 when nothing was cut.
    pub fn min(self) -> f64 {
        self.force.min(self.torque)
    }

    /// Whether either part was cut.
    pub fn clipped(self) -> bool {
        self.min() < 1.0
    }

    /// `w` with its force and torque scaled as these say.
    pub fn apply<S: Space>(self, w: &S::OpVec) -> S::OpVec {
        let linear = <S::Point as VecOps>::LEN;
        let mut out = *w;
        for i in 0..S::DIM {
            out[i] *= if i < linear { self.force } else { self.torque };
        }
        out
    }
}

/// The plane: positions `(x, y)`, orientation an angle about z.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Planar;

/// Three-dimensional space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spatial;

/// The anchors of [`Space::rot_to_params_memo`] and [`Space::rot_from_params_memo`] for planar angles.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarAngleMemo {
    to_angle: trig::AnchoredAtan2,
    from_angle: trig::AnchoredSinCos,
}

impl Space for Planar {
    const KIND: SceneKind = SceneKind::Planar;
    const DIM: usize = 3;
    type Point = Vector2<f64>;
    type Angular = f64;
    type Rot = UnitComplex<f64>;
    type RotInertia = f64;
    type Spatial = Vector3<f64>;
    type Inertia = Matrix3<f64>;
    type OpVec = Vector3<f64>;
    type OpMat = Matrix3<f64>;

    #[inline]
    fn rot_identity() -> Self::Rot {
        UnitComplex::identity()
    }
    #[inline]
    fn rot_mul(a: &Self::Rot, b: &Self::Rot) -> Self::Rot {
        a * b
    }
    #[inline]
    fn rot_inverse(r: &Self::Rot) -> Self::Rot {
        r.inverse()
    }
    #[inline]
    fn rotate(r: &Self::Rot, p: &Self::Point) -> Self::Point {
        r * p
    }
    #[inline]
    fn rot_about_axis(_axis: &Self::Point, cos: f64, sin: f64) -> Self::Rot {
        UnitComplex::from_cos_sin_unchecked(cos, sin)
    }
    #[inline]
    fn rot_from_vector(v: &f64) -> Self::Rot {
        let (sin, cos) = trig::sin_cos(*v);
        UnitComplex::from_cos_sin_unchecked(cos, sin)
    }
    #[inline]
    fn rot_log(r: &Self::Rot) -> f64 {
        trig::atan2(r.im, r.re)
    }
    #[inline]
    fn rot_chord(a: &Self::Rot, b: &Self::Rot) -> f64 {
        // |e^{iα} − e^{iβ}| = 2 sin(|α − β| / 2).
        let (dc, ds) = (a.re - b.re, a.im - b.im);
        (dc * dc + ds * ds).sqrt()
    }
    #[inline]
    fn rot_is_finite(r: &Self::Rot) -> bool {
        r.re.is_finite() && r.im.is_finite()
    }
    const ROT_PARAMS: usize = 1;
    #[inline]
    fn rot_to_params(r: &Self::Rot, out: &mut [f64]) {
        out[0] = r.angle();
    }
    #[inline]
    fn rot_from_params(p: &[f64]) -> Option<Self::Rot> {
        match p {
            [a] if a.is_finite() => Some(UnitComplex::new(*a)),
            _ => None,
        }
    }
    type RotParamsMemo = PlanarAngleMemo;
    #[inline]
    fn rot_to_params_memo(r: &Self::Rot, out: &mut [f64], memo: &mut PlanarAngleMemo) {
        out[0] = memo.to_angle.eval(r.im, r.re);
    }
    #[inline]
    fn rot_from_params_memo(p: &[f64], memo: &mut PlanarAngleMemo) -> Option<Self::Rot> {
        match p {
            [a] if a.is_finite() => {
                let (sin, cos) = memo.from_angle.eval(*a);
                Some(UnitComplex::from_cos_sin_unchecked(cos, sin))
            }
            _ => None,
        }
    }

    fn rot_from_scene(v: &[f64]) -> Result<Self::Rot, String> {
        match v {
            [angle] => Ok(UnitComplex::new(*angle)),
            _ => Err(format!("expected one angle (rad) for a planar scene, got {} numbers", v.len())),
        }
    }
    fn rot_inertia_from_scene(v: &[f64]) -> Result<f64, String> {
        match v {
            [i] if *i > 0.0 => Ok(*i),
            [i] => Err(format!("inertia must be positive, got {i}")),
            _ => Err(format!("expected one number (kg m² about z) for a planar scene, got {}", v.len())),
        }
    }
    #[inline]
    fn rot_inertia_size(i: &f64) -> f64 {
        *i
    }
    #[inline]
    fn default_axis() -> Self::Point {
        Vector2::new(1.0, 0.0)
    }
    #[inline]
    fn axis_as_angular(_axis_world: &Self::Point) -> f64 {
        1.0
    }

    #[inline]
    fn ang_cross_point(w: &f64, p: &Self::Point) -> Self::Point {
        Vector2::new(-w * p.y, w * p.x)
    }
    #[inline]
    fn point_cross_point(a: &Self::Point, b: &Self::Point) -> f64 {
        a.x * b.y - a.y * b.x
    }

    #[inline]
    fn spatial(ang: f64, lin: Self::Point) -> Self::Spatial {
        Vector3::new(ang, lin.x, lin.y)
    }
    #[inline]
    fn spatial_ang(s: &Self::Spatial) -> f64 {
        s[0]
    }
    #[inline]
    fn spatial_lin(s: &Self::Spatial) -> Self::Point {
        Vector2::new(s[1], s[2])
    }
    #[inline]
    fn cross_motion(v: &Self::Spatial, m: &Self::Spatial) -> Self::Spatial {
        // crm(v) = [[0,0,0],[vy,0,-ω],[-vx,ω,0]] (Featherstone's planar algebra).
        Vector3::new(0.0, v[2] * m[0] - v[0] * m[2], -v[1] * m[0] + v[0] * m[1])
    }
    #[inline]
    fn cross_force(v: &Self::Spatial, f: &Self::Spatial) -> Self::Spatial {
        // crf(v) = -crm(v)ᵀ = [[0,-vy,vx],[0,0,-ω],[0,ω,0]].
        Vector3::new(-v[2] * f[1] + v[1] * f[2], -v[0] * f[2], v[0] * f[1])
    }
    #[inline]
    fn inertia_mul(i: &Self::Inertia, m: &Self::Spatial) -> Self::Spatial {
        i * m
    }
    #[inline]
    fn inertia_world(mass: f64, c: &Self::Point, inertia_com: &f64, _rot: &Self::Rot) -> Self::Inertia {
        // Kinetic energy ½ m |v + ω ẑ×c|² + ½ I_c ω² written as ½ (ω,v)ᵀ M (ω,v).
        let mc_x = mass * c.x;
        let mc_y = mass * c.y;
        Matrix3::new(inertia_com + mass * (c.x * c.x + c.y * c.y), -mc_y, mc_x, -mc_y, mass, 0.0, mc_x, 0.0, mass)
    }

    #[inline]
    fn op(lin: Self::Point, ang: f64) -> Self::OpVec {
        Vector3::new(lin.x, lin.y, ang)
    }
    #[inline]
    fn op_lin(v: &Self::OpVec) -> Self::Point {
        Vector2::new(v[0], v[1])
    }
    #[inline]
    fn op_ang(v: &Self::OpVec) -> f64 {
        v[2]
    }
}

/// The skew-symmetric matrix `[v]×` with `[v]× u = v × u`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl Space for Spatial {
    const KIND: SceneKind = SceneKind::Spatial;
    const DIM: usize = 6;
    type Point = Vector3<f64>;
    type Angular = Vector3<f64>;
    type Rot = Rotation3<f64>;
    type RotInertia = Matrix3<f64>;
    type Spatial = Vector6<f64>;
    type Inertia = Matrix6<f64>;
    type OpVec = Vector6<f64>;
    type OpMat = Matrix6<f64>;

    #[inline]
    fn rot_identity() -> Self::Rot {
        Rotation3::identity()
    }
    #[inline]
    fn rot_mul(a: &Self::Rot, b: &Self::Rot) -> Self::Rot {
        a * b
    }
    #[inline]
    fn rot_inverse(r: &Self::Rot) -> Self::Rot {
        r.inverse()
    }
    #[inline]
    fn rotate(r: &Self::Rot, p: &Self::Point) -> Self::Point {
        r * p
    }
    #[inline]
    fn rot_about_axis(axis: &Self::Point, cos: f64, sin: f64) -> Self::Rot {
        // Rodrigues: R = I + s [a]× + (1 - c) [a]×², for a unit axis a.
        let k = skew(axis);
        Rotation3::from_matrix_unchecked(Matrix3::identity() + k * sin + k * k * (1.0 - cos))
    }
    #[inline]
    fn rot_from_vector(v: &Self::Angular) -> Self::Rot {
        Rotation3::new(*v)
    }
    #[inline]
    fn rot_chord(a: &Self::Rot, b: &Self::Rot) -> f64 {
        // ‖A − B‖_F² = 2 tr(I − AᵀB) = 4 (1 − cos θ) = 8 sin²(θ / 2).
        (a.matrix() - b.matrix()).norm() * std::f64::consts::FRAC_1_SQRT_2
    }
    fn rot_log(r: &Self::Rot) -> Self::Angular {
        // sin θ · axis from the skew part and cos θ from the trace: atan2 keeps full relative accuracy for
        // small angles (acos of the trace, as in `scaled_axis`, loses half the digits there).
        let m = r.matrix();
        let v = Vector3::new(m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]) * 0.5;
        let sin = v.norm();
        let cos = (m.trace() - 1.0) * 0.5;
        if cos > -0.9 {
            let angle = trig::atan2(sin, cos);
            if sin < 1e-12 {
                v * (1.0 + angle * angle / 6.0)
            } else {
                v * (angle / sin)
            }
        } else {
            // Near π the skew part vanishes; the axis comes from the symmetric part.
            r.scaled_axis()
        }
    }
    #[inline]
    fn rot_is_finite(r: &Self::Rot) -> bool {
        r.matrix().iter().all(|x| x.is_finite())
    }
    const ROT_PARAMS: usize = 4;
    type RotParamsMemo = ();
    #[inline]
    fn rot_to_params(r: &Self::Rot, out: &mut [f64]) {
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(r);
        out[..4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
    }
    #[inline]
    fn rot_from_params(p: &[f64]) -> Option<Self::Rot> {
        match p {
            [w, x, y, z] if p.iter().all(|v| v.is_finite()) => {
                let q = nalgebra::Quaternion::new(*w, *x, *y, *z);
                if (q.norm() - 1.0).abs() > 1e-6 {
                    return None;
                }
                Some(nalgebra::UnitQuaternion::from_quaternion(q).to_rotation_matrix())
            }
            _ => None,
        }
    }

    fn rot_from_scene(v: &[f64]) -> Result<Self::Rot, String> {
        match v {
            [r, p, y] => Ok(Rotation3::from_euler_angles(*r, *p, *y)),
            _ => Err(format!("expected [roll, pitch, yaw] (rad) for a spatial scene, got {} numbers", v.len())),
        }
    }
    fn rot_inertia_from_scene(v: &[f64]) -> Result<Matrix3<f64>, String> {
        let m = match v {
            [xx, yy, zz] => Matrix3::from_diagonal(&Vector3::new(*xx, *yy, *zz)),
            [xx, yy, zz, xy, xz, yz] => Matrix3::new(*xx, *xy, *xz, *xy, *yy, *yz, *xz, *yz, *zz),
            _ => {
                return Err(format!(
                    "expected [ixx, iyy, izz] or [ixx, iyy, izz, ixy, ixz, iyz] for a spatial scene, got {} numbers",
                    v.len()
                ))
            }
        };
        if m.cholesky().is_none() {
            return Err(format!("inertia {v:?} is not positive definite"));
        }
        Ok(m)
    }
    #[inline]
    fn rot_inertia_size(i: &Matrix3<f64>) -> f64 {
        i.trace() / 3.0
    }
    #[inline]
    fn default_axis() -> Self::Point {
        Vector3::new(0.0, 0.0, 1.0)
    }
    #[inline]
    fn axis_as_angular(axis_world: &Self::Point) -> Self::Angular {
        *axis_world
    }

    #[inline]
    fn ang_cross_point(w: &Self::Angular, p: &Self::Point) -> Self::Point {
        w.cross(p)
    }
    #[inline]
    fn point_cross_point(a: &Self::Point, b: &Self::Point) -> Self::Angular {
        a.cross(b)
    }

    #[inline]
    fn spatial(ang: Self::Angular, lin: Self::Point) -> Self::Spatial {
        Vector6::new(ang.x, ang.y, ang.z, lin.x, lin.y, lin.z)
    }
    #[inline]
    fn spatial_ang(s: &Self::Spatial) -> Self::Angular {
        Vector3::new(s[0], s[1], s[2])
    }
    #[inline]
    fn spatial_lin(s: &Self::Spatial) -> Self::Point {
        Vector3::new(s[3], s[4], s[5])
    }
    #[inline]
    fn cross_motion(v: &Self::Spatial, m: &Self::Spatial) -> Self::Spatial {
        let (w, vl) = (Self::spatial_ang(v), Self::spatial_lin(v));
        let (mw, ml) = (Self::spatial_ang(m), Self::spatial_lin(m));
        Self::spatial(w.cross(&mw), w.cross(&ml) + vl.cross(&mw))
    }
    #[inline]
    fn cross_force(v: &Self::Spatial, f: &Self::Spatial) -> Self::Spatial {
        let (w, vl) = (Self::spatial_ang(v), Self::spatial_lin(v));
        let (n, fl) = (Self::spatial_ang(f), Self::spatial_lin(f));
        Self::spatial(w.cross(&n) + vl.cross(&fl), w.cross(&fl))
    }
    #[inline]
    fn inertia_mul(i: &Self::Inertia, m: &Self::Spatial) -> Self::Spatial {
        i * m
    }
    #[inline]
    fn inertia_world(mass: f64, c: &Self::Point, inertia_com: &Matrix3<f64>, rot: &Self::Rot) -> Self::Inertia {
        // I_O = [[R I_c Rᵀ + m [c]×[c]×ᵀ, m [c]×], [m [c]×ᵀ, m 1]].
        let r = rot.matrix();
        let cx = skew(c);
        let top_left = r * inertia_com * r.transpose() + cx * cx.transpose() * mass;
        let top_right = cx * mass;
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&top_left);
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&top_right);
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&top_right.transpose());
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&(Matrix3::identity() * mass));
        out
    }

    #[inline]
    fn op(lin: Self::Point, ang: Self::Angular) -> Self::OpVec {
        Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    }
    #[inline]
    fn op_lin(v: &Self::OpVec) -> Self::Point {
        Vector3::new(v[0], v[1], v[2])
    }
    #[inline]
    fn op_ang(v: &Self::OpVec) -> Self::Angular {
        Vector3::new(v[3], v[4], v[5])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chord is 2 sin(θ/2) for the angle θ between two orientations, computed here from the angles the
    /// orientations were built with (planar) and from an axis and angle composed onto an arbitrary start
    /// (spatial).
    #[test]
    fn the_chord_between_orientations_is_two_sines_of_the_half_angle() {
        for (a, b) in [(0.3, 0.3), (0.3, 0.5), (-3.0, 3.0), (1.0, -2.5)] {
            let (ra, rb) = (Planar::rot_from_vector(&a), Planar::rot_from_vector(&b));
            let theta = (b - a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            let expected = 2.0 * (theta.abs() / 2.0).sin();
            assert!((Planar::rot_chord(&ra, &rb) - expected).abs() < 1e-9, "{a} {b}");
        }
        let start = Spatial::rot_from_vector(&Vector3::new(0.4, -1.1, 0.7));
        let axis = Vector3::new(2.0, -1.0, 2.0) / 3.0;
        for theta in [0.0, 1e-4, 0.5, 2.0, 3.1] {
            let turned = Spatial::rot_mul(&Spatial::rot_from_vector(&(axis * theta)), &start);
            let expected = 2.0 * (theta / 2.0).sin();
            assert!((Spatial::rot_chord(&start, &turned) - expected).abs() < 1e-9, "{theta}");
        }
    }

    /// A planar tour through ±π: the wrapped angles 2.9, −3.1 (0.28 rad apart the short way) unwrap to 2.9,
    /// 3.18, and a whole further turn keeps counting; a spatial rotation vector unwraps along its axis.
    #[test]
    fn rotations_unwrap_to_the_turn_nearest_the_previous() {
        let mut d = Vector3::new(0.1, 0.2, -3.1);
        unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 2.9));
        assert!((d[2] - (-3.1 + std::f64::consts::TAU)).abs() < 1e-12 && d[0] == 0.1 && d[1] == 0.2);
        let mut d = Vector3::new(0.0, 0.0, 0.5);
        unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 6.6));
        assert!((d[2] - (0.5 + std::f64::consts::TAU)).abs() < 1e-12);
        let mut d = Vector3::new(0.0, 0.0, 0.3);
        unwrap_rotation_near::<Planar>(&mut d, &Vector3::new(0.0, 0.0, 0.1));
        assert_eq!(d[2], 0.3, "already nearest");
        let axis = Vector3::new(1.0, 2.0, 2.0) / 3.0;
        let mut d = Vector6::zeros();
        d.fixed_rows_mut::<3>(3).copy_from(&(axis * -3.0));
        let mut previous = Vector6::zeros();
        previous.fixed_rows_mut::<3>(3).copy_from(&(axis * 3.0));
        unwrap_rotation_near::<Spatial>(&mut d, &previous);
        let expected = axis * (std::f64::consts::TAU - 3.0);
        assert!((d.fixed_rows::<3>(3) - expected).norm() < 1e-12, "{d:?}");
    }

    /// Force and torque saturate apart: a torque past its limit is scaled back without touching the
    /// force, each part keeps its direction, and a zero limit zeroes its part.
    #[test]
    fn wrench_parts_clip_independently_keeping_direction() {
        let w = Vector3::new(3.0, 4.0, 2.0); // planar: force (3, 4), |f| = 5; torque 2
        let (out, scales) = clip_wrench_parts::<Planar>(&w, 10.0, 0.5);
        assert!(scales.clipped());
        assert_eq!((out[0], out[1]), (3.0, 4.0));
        assert!((out[2] - 0.5).abs() < 1e-15);
        let (out, scales) = clip_wrench_parts::<Planar>(&w, 2.5, 0.0);
        assert!(scales.clipped());
        assert!((out[0] - 1.5).abs() < 1e-15 && (out[1] - 2.0).abs() < 1e-15 && out[2] == 0.0);
        let (out, scales) = clip_wrench_parts::<Planar>(&w, 5.0, 2.0);
        assert!(!scales.clipped());
        assert_eq!(out, w);
    }

    /// Kinetic energy from the world-frame spatial inertia equals ½ m |v_c|² + ½ ωᵀ I ω computed directly.
    #[test]
    fn spatial_inertia_gives_rigid_body_kinetic_energy() {
        let c = Vector3::new(0.3, -0.2, 0.5);
        let ic = Matrix3::new(0.2, 0.01, 0.02, 0.01, 0.3, 0.03, 0.02, 0.03, 0.4);
        let rot = Rotation3::new(Vector3::new(0.1, 0.7, -0.3));
        let m = 2.5;
        let inertia = Spatial::inertia_world(m, &c, &ic, &rot);
        let w = Vector3::new(0.4, -1.1, 0.7);
        let v_origin = Vector3::new(0.2, 0.9, -0.5);
        let motion = Spatial::spatial(w, v_origin);
        let ke_spatial = 0.5 * motion.dot(&(inertia * motion));
        let v_com = v_origin + w.cross(&c);
        let i_world = rot.matrix() * ic * rot.matrix().transpose();
        let ke_direct = 0.5 * m * v_com.norm_squared() + 0.5 * w.dot(&(i_world * w));
        assert!((ke_spatial - ke_direct).abs() < 1e-12, "{ke_spatial} vs {ke_direct}");
    }

    #[test]
    fn planar_inertia_gives_rigid_body_kinetic_energy() {
        let c = Vector2::new(0.3, -0.2);
        let m = 1.7;
        let ic = 0.05;
        let inertia = Planar::inertia_world(m, &c, &ic, &UnitComplex::new(0.3));
        let (w, v) = (0.8, Vector2::new(-0.4, 1.2));
        let motion = Planar::spatial(w, v);
        let ke = 0.5 * motion.dot(&(inertia * motion));
        let v_com = v + Planar::ang_cross_point(&w, &c);
        let direct = 0.5 * m * v_com.norm_squared() + 0.5 * ic * w * w;
        assert!((ke - direct).abs() < 1e-12);
    }

    /// The planar algebra is the spatial algebra restricted to the plane: (ω_z, v_x, v_y).
    #[test]
    fn planar_cross_products_match_spatial_ones_restricted_to_the_plane() {
        let lift = |p: &Vector3<f64>| Vector6::new(0.0, 0.0, p[0], p[1], p[2], 0.0);
        let v = Vector3::new(0.7, -0.3, 1.1);
        let m = Vector3::new(-0.4, 0.9, 0.2);
        let planar = Planar::cross_motion(&v, &m);
        let spatial = Spatial::cross_motion(&lift(&v), &lift(&m));
        assert!((lift(&planar) - spatial).norm() < 1e-14);
        let planar_f = Planar::cross_force(&v, &m);
        let spatial_f = Spatial::cross_force(&lift(&v), &lift(&m));
        assert!((lift(&planar_f) - spatial_f).norm() < 1e-14);
    }

    #[test]
    fn rotation_log_is_accurate_for_small_and_large_angles() {
        for angle in [1e-9, 1e-6, 0.3, 2.0, 3.0] {
            let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
            let log = Spatial::rot_log(&Rotation3::new(axis * angle));
            assert!((log - axis * angle).norm() < 1e-13 * angle.max(1e-3), "angle {angle}: {log}");
        }
    }

    #[test]
    fn rodrigues_matches_nalgebra_axis_angle() {
        let axis = Vector3::new(1.0, 2.0, -0.5).normalize();
        let angle: f64 = 0.83;
        let ours = Spatial::rot_about_axis(&axis, angle.cos(), angle.sin());
        let theirs = Rotation3::new(axis * angle);
        assert!((ours.matrix() - theirs.matrix()).norm() < 1e-14);
    }
}
