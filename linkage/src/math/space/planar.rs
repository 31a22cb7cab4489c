//! The plane: 2-vectors, scalars and 3x3 matrices, never 6-D algebra.

use nalgebra::{Matrix3, UnitComplex, Vector2, Vector3};

use super::algebra::VecOps;
use super::definition::{SceneKind, Space};
use crate::math::trig;

/// The plane: positions `(x, y)`, orientation an angle about z.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Planar;

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

    fn rot_from_quaternion(q: &[f64]) -> Self::Rot {
        // (w + z k)² as a complex number: the turn about z, twice the half angle.
        let c = nalgebra::Complex::new(q[0] * q[0] - q[3] * q[3], 2.0 * q[0] * q[3]);
        UnitComplex::from_complex(c)
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
    fn rot_inertia_zero() -> f64 {
        0.0
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
