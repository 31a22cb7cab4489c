//! Unit quaternions `(w, x, y, z)` as ball joints store them in q: the rotation matrix, the exponential
//! update `q ← q ⊗ exp(θ / 2)` by a body-axes rotation vector θ, the logarithm of the relative rotation
//! (the inverse of the update), and the inverse right Jacobian of SO(3) that turns a body angular velocity
//! into the rate of a rotation vector (what RK4's stages need to stay fourth order on the sphere).
//!
//! All of them are smooth everywhere on the unit sphere (the point of a quaternion: no gimbal lock); the
//! only expansions are about θ = 0, where the closed forms divide by |θ| and their Taylor series take over.

use nalgebra::{Matrix3, Vector3};

/// Below this |θ| the closed forms give way to their Taylor series (whose next terms are below 1e-17).
const SMALL_ANGLE: f64 = 1e-4;

/// The rotation matrix of a unit quaternion `[w, x, y, z]` (normalized here, so round-off in q never
/// shears the bodies).
pub fn to_matrix(q: &[f64]) -> Matrix3<f64> {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let (w, x, y, z) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// `q ← q ⊗ exp(θ / 2)`, renormalized: the orientation after turning by the rotation vector θ about body
/// axes (the ball joint's configuration update, as Pinocchio's `integrate` for SO(3)).
pub fn integrate(q: &mut [f64], theta: &Vector3<f64>) {
    let angle = theta.norm();
    let half = 0.5 * angle;
    // exp(θ/2) = (cos |θ|/2, sin(|θ|/2) θ/|θ|); sin(a)/a → 1 - a²/6 for small a.
    let (c, s_over) = if angle < SMALL_ANGLE {
        (1.0 - half * half / 2.0, 0.5 * (1.0 - half * half / 6.0))
    } else {
        (half.cos(), half.sin() / angle)
    };
    let (ew, ex, ey, ez) = (c, theta.x * s_over, theta.y * s_over, theta.z * s_over);
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let r = [
        w * ew - x * ex - y * ey - z * ez,
        w * ex + x * ew + y * ez - z * ey,
        w * ey - x * ez + y * ew + z * ex,
        w * ez + x * ey - y * ex + z * ew,
    ];
    let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]).sqrt();
    for (dst, v) in q.iter_mut().zip(r) {
        *dst = v / n;
    }
}

/// The body-axes rotation vector θ with `b = a ⊗ exp(θ / 2)` (|θ| ≤ π): the inverse of [`integrate`].
pub fn difference(a: &[f64], b: &[f64]) -> Vector3<f64> {
    // a⁻¹ ⊗ b for unit a: conjugate a.
    let (w, x, y, z) = (a[0], -a[1], -a[2], -a[3]);
    let (bw, bx, by, bz) = (b[0], b[1], b[2], b[3]);
    let mut r = [
        w * bw - x * bx - y * by - z * bz,
        w * bx + x * bw + y * bz - z * by,
        w * by - x * bz + y * bw + z * bx,
        w * bz + x * by - y * bx + z * bw,
    ];
    // q and -q are one rotation: take the short way.
    if r[0] < 0.0 {
        r.iter_mut().for_each(|v| *v = -*v);
    }
    let v = Vector3::new(r[1], r[2], r[3]);
    let s = v.norm();
    if s < 0.5 * SMALL_ANGLE {
        // θ = 2 atan2(s, w) v/s ≈ (2/w)(1 - s²/(3w²)) v.
        return v * (2.0 / r[0]) * (1.0 - s * s / (3.0 * r[0] * r[0]));
    }
    v * (2.0 * s.atan2(r[0]) / s)
}

/// `J_r⁻¹(θ) ω`: the rate of the rotation vector θ (with R = R₀ exp(θ)) when the body turns at ω in its
/// own axes, `J_r⁻¹(θ) = I + ½[θ]× + (1/|θ|² − (1 + cos|θ|) / (2|θ| sin|θ|)) [θ]×²`.
pub fn right_jacobian_inv_mul(theta: &Vector3<f64>, omega: &Vector3<f64>) -> Vector3<f64> {
    let a2 = theta.norm_squared();
    let a = a2.sqrt();
    // The coefficient → 1/12 + a²/720 as a → 0.
    let c = if a < SMALL_ANGLE { 1.0 / 12.0 + a2 / 720.0 } else { 1.0 / a2 - (1.0 + a.cos()) / (2.0 * a * a.sin()) };
    let t_w = theta.cross(omega);
    omega + t_w * 0.5 + theta.cross(&t_w) * c
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(v: [f64; 4]) -> [f64; 4] {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.map(|x| x / n)
    }

    /// Integrating the difference lands on the target, for large and tiny rotations alike.
    #[test]
    fn difference_inverts_integrate() {
        let a = unit([0.3, -0.5, 0.7, 0.2]);
        for theta in [Vector3::new(0.4, -1.1, 2.0), Vector3::new(1e-7, 2e-7, -3e-8), Vector3::new(0.0, 0.0, 3.0)] {
            let mut b = a;
            integrate(&mut b, &theta);
            let back = difference(&a, &b);
            assert!((back - theta).norm() < 1e-12, "{theta} came back as {back}");
        }
    }

    /// The matrix of `a ⊗ exp(θ/2)` is the matrix of a times Rodrigues' exp(θ) (a second formulation).
    #[test]
    fn integrate_is_a_body_axes_rotation() {
        let a = unit([0.9, 0.1, -0.3, 0.2]);
        let theta = Vector3::new(0.3, 0.8, -0.5);
        let mut b = a;
        integrate(&mut b, &theta);
        let expected = to_matrix(&a) * nalgebra::Rotation3::new(theta).matrix();
        assert!((to_matrix(&b) - expected).norm() < 1e-14);
        assert!((to_matrix(&b) * to_matrix(&b).transpose() - Matrix3::identity()).norm() < 1e-14);
    }

    /// `J_r⁻¹(θ) ω` equals the finite-difference rate of `difference(a, a ⊗ exp(θ) ⊗ exp(ω h))`.
    #[test]
    fn right_jacobian_inverse_matches_finite_differences() {
        let a = unit([0.5, 0.5, -0.1, 0.7]);
        let omega = Vector3::new(0.7, -0.2, 0.4);
        for theta in [Vector3::new(0.9, -0.4, 1.3), Vector3::new(2e-5, -1e-5, 3e-5)] {
            let mut q = a;
            integrate(&mut q, &theta);
            let h = 1e-6;
            let (mut plus, mut minus) = (q, q);
            integrate(&mut plus, &(omega * h));
            integrate(&mut minus, &(omega * -h));
            let fd = (difference(&a, &plus) - difference(&a, &minus)) / (2.0 * h);
            let rate = right_jacobian_inv_mul(&theta, &omega);
            assert!((fd - rate).norm() < 1e-8, "{fd} vs {rate}");
        }
    }
}
