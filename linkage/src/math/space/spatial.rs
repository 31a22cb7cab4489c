//! Three-dimensional space: 3-vectors, rotation matrices and 6-D spatial algebra.

use nalgebra::{Matrix3, Matrix6, Rotation3, Vector3, Vector6};

use super::algebra::VecOps;
use super::definition::{SceneKind, Space};
use crate::math::trig;

/// Three-dimensional space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spatial;

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

    #[inline]
    fn rot_from_quaternion(q: &[f64]) -> Self::Rot {
        Rotation3::from_matrix_unchecked(crate::math::quaternion::to_matrix(q))
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
    fn rot_inertia_zero() -> Matrix3<f64> {
        Matrix3::zeros()
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
