//! Sine, cosine and arctangent by short series: of small angles directly, and of angles that move slowly
//! relative to a remembered anchor. A haptic loop turns poses into twists and back several times a tick
//! (pose differences, integration over one tick, prediction over a snapshot's age: small angles) and writes
//! and reads absolute angles that move a little each tick (joint angles, poses on the wire): there a dozen
//! multiply-adds replace a library call. All agree with the library to round-off (the series' truncation
//! errors are below 2⁻⁵⁸ relative, against 2⁻⁵³ for one rounding).

use std::f64::consts::PI;

use crate::math::dense::mul_add;

/// Largest |angle| (and |tan|) the series here take: 1/32 rad, where the first omitted terms are below
/// 2⁻⁵⁸ relative (sine's d⁹/9!, the largest).
pub const SMALL_ANGLE: f64 = 1.0 / 32.0;

/// `(sin d, cos d - 1)` for |d| ≤ [`SMALL_ANGLE`], by Taylor series truncated after d⁷ (sin) and d⁸ (cos);
/// `cos d - 1` keeps full relative accuracy where `cos d` rounds to one.
#[inline]
pub fn small_sin_cos_minus_1(d: f64) -> (f64, f64) {
    let d2 = d * d;
    // sin δ = δ (1 - δ²/6 (1 - δ²/20 (1 - δ²/42))), cos δ = 1 - δ²/2 (1 - δ²/12 (1 - δ²/30 (1 - δ²/56))).
    let sin = mul_add(d * d2, mul_add(d2, mul_add(d2, -1.0 / 5040.0, 1.0 / 120.0), -1.0 / 6.0), d);
    let cos_minus_1 = d2 * mul_add(d2, mul_add(d2, mul_add(d2, 1.0 / 40320.0, -1.0 / 720.0), 1.0 / 24.0), -0.5);
    (sin, cos_minus_1)
}

/// `(sin a, cos a)`: the series for a small angle, the library otherwise.
#[inline]
pub fn sin_cos(a: f64) -> (f64, f64) {
    if a.abs() <= SMALL_ANGLE {
        let (sin, cos_minus_1) = small_sin_cos_minus_1(a);
        (sin, 1.0 + cos_minus_1)
    } else {
        a.sin_cos()
    }
}

/// `atan2(y, x)`: for an angle within [`SMALL_ANGLE`] of zero (x > 0, |y| ≤ x/32) the series
/// `atan t = t - t³/3 + t⁵/5 - … - t¹¹/11` in `t = y / x`, the library otherwise.
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    // Infinite x falls to the library (∞/∞ would make the series NaN).
    if x > 0.0 && x < f64::INFINITY && y.abs() <= SMALL_ANGLE * x {
        let t = y / x;
        let t2 = t * t;
        let tail = mul_add(
            t2,
            mul_add(t2, mul_add(t2, mul_add(t2, -1.0 / 11.0, 1.0 / 9.0), -1.0 / 7.0), 1.0 / 5.0),
            -1.0 / 3.0,
        );
        mul_add(t * t2, tail, t)
    } else {
        y.atan2(x)
    }
}

/// `sin q` and `cos q` from the exact values at an anchor `a = round(16 q) / 16` and a short Taylor series
/// in `δ = q - a` (|δ| ≤ 1/32): `sin q = sin a cos δ + cos a sin δ`, `cos q = cos a cos δ - sin a sin δ`.
/// The anchor's sin and cos come from the library and are kept until the angle moves to another anchor,
/// which at the speeds of a haptic linkage (a few rad/s, 1 kHz) is every few dozen evaluations; in between
/// an evaluation costs a dozen multiply-adds instead of a library `sin_cos`. The result depends on q alone
/// (not on which angles were evaluated before), and agrees with `q.sin_cos()` to round-off: both a and δ are
/// exact, the series is truncated after δ⁷ (sin) and δ⁸ (cos), whose next terms are below 1e-19.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnchoredSinCos {
    /// `16 a` (an integer), NaN before the first evaluation.
    anchor: f64,
    sin: f64,
    cos: f64,
}

impl Default for AnchoredSinCos {
    fn default() -> Self {
        AnchoredSinCos { anchor: f64::NAN, sin: 0.0, cos: 1.0 }
    }
}

impl AnchoredSinCos {
    /// Anchors per radian (a power of two, so `a` and `δ` are exact).
    const PER_RADIAN: f64 = 16.0;

    /// `(sin q, cos q)`.
    #[inline]
    pub fn eval(&mut self, q: f64) -> (f64, f64) {
        let anchor = (q * Self::PER_RADIAN).round();
        let a = anchor / Self::PER_RADIAN;
        if anchor != self.anchor {
            if a.is_nan() || a.abs() >= 1e15 {
                // Huge or not a number: no series (and no caching) worth having.
                return q.sin_cos();
            }
            (self.sin, self.cos) = a.sin_cos();
            self.anchor = anchor;
        }
        let (sin_d, cos_d_minus_1) = small_sin_cos_minus_1(q - a);
        let sin = mul_add(self.cos, sin_d, mul_add(self.sin, cos_d_minus_1, self.sin));
        let cos = mul_add(-self.sin, sin_d, mul_add(self.cos, cos_d_minus_1, self.cos));
        (sin, cos)
    }
}

/// `atan2(y, x)` of a direction that moves slowly, relative to the last direction the library was asked
/// about (the anchor z₀ = (x₀, y₀), whose angle a₀ it returned): with `z z̄₀ = (u, v)`,
/// `atan2(y, x) = a₀ + atan(v / u)` (mod 2π), and while the direction stays within [`SMALL_ANGLE`] of the
/// anchor that arctangent is the series of [`atan2`]. For a pose written to the wire every tick. The result
/// is in (-π, π] and agrees with the library to a few units in the last place; it can depend on the anchor
/// by that much, not more.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnchoredAtan2 {
    /// The anchor direction, NaN before the first evaluation.
    x: f64,
    y: f64,
    /// Its angle, from the library.
    angle: f64,
}

impl Default for AnchoredAtan2 {
    fn default() -> Self {
        AnchoredAtan2 { x: f64::NAN, y: f64::NAN, angle: 0.0 }
    }
}

impl AnchoredAtan2 {
    /// `atan2(y, x)`.
    #[inline]
    pub fn eval(&mut self, y: f64, x: f64) -> f64 {
        let u = mul_add(x, self.x, y * self.y);
        let v = mul_add(y, self.x, -x * self.y);
        // False for a NaN anchor or input, and infinite ones: those go to the library.
        if u > 0.0 && u < f64::INFINITY && v.abs() <= SMALL_ANGLE * u {
            let a = self.angle + atan2(v, u);
            return if a > PI {
                a - 2.0 * PI
            } else if a <= -PI {
                a + 2.0 * PI
            } else {
                a
            };
        }
        let a = y.atan2(x);
        if a.is_finite() && (x != 0.0 || y != 0.0) {
            (self.x, self.y, self.angle) = (x, y, a);
        }
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The anchored sin and cos agree with the library's to round-off, for angles that step slowly (the
    /// cache at work), jump, sit on and next to anchors, are tiny, negative or large.
    #[test]
    fn anchored_sin_cos_matches_the_library() {
        let mut cache = AnchoredSinCos::default();
        let mut check = |q: f64| {
            let (s, c) = cache.eval(q);
            let (s_ref, c_ref) = q.sin_cos();
            assert!(
                (s - s_ref).abs() <= 3e-16 && (c - c_ref).abs() <= 3e-16,
                "q = {q}: ({s}, {c}) vs ({s_ref}, {c_ref})"
            );
        };
        let mut q = -7.0;
        while q < 7.0 {
            check(q);
            q += 0.000_731;
        }
        for q in [0.0, 1e-300, -1e-12, 1.0 / 32.0, -1.0 / 32.0, 0.5 - 1e-17, 3.0, -1234.567, 1e14, 1e20, 0.0625] {
            check(q);
        }
        assert!(cache.eval(f64::NAN).0.is_nan());
    }

    /// Within two units in the last place of the library's results, inside and at the edge of the series'
    /// range, and the library's results outside it.
    #[test]
    fn series_match_the_library() {
        let ulps = |a: f64, b: f64| (a - b).abs() / (f64::EPSILON * b.abs().max(f64::MIN_POSITIVE));
        for i in -2000..=2000 {
            let a = i as f64 / 2000.0 * SMALL_ANGLE * 1.5 + 1e-7;
            let (s, c) = sin_cos(a);
            let (s_ref, c_ref) = a.sin_cos();
            assert!(ulps(s, s_ref) <= 2.0 && ulps(c, c_ref) <= 2.0, "{a}: ({s}, {c}) vs ({s_ref}, {c_ref})");
            let (s1, cm1) = small_sin_cos_minus_1(a.clamp(-SMALL_ANGLE, SMALL_ANGLE));
            let a = a.clamp(-SMALL_ANGLE, SMALL_ANGLE);
            assert!(ulps(s1, a.sin()) <= 2.0, "{a}");
            // cos a - 1 = -2 sin²(a/2), computed accurately.
            let exact = -2.0 * (a / 2.0).sin().powi(2);
            assert!((cm1 - exact).abs() <= 4.0 * f64::EPSILON * exact.abs() + 1e-300, "{a}: {cm1} vs {exact}");
            for r in [1.0, 0.3, 1e-200, 1e200] {
                let (y, x) = (r * s_ref, r * c_ref);
                let angle = atan2(y, x);
                assert!(ulps(angle, y.atan2(x)) <= 2.0, "atan2({y}, {x}): {angle} vs {}", y.atan2(x));
            }
        }
        assert_eq!(atan2(0.0, 1.0), 0.0);
        assert_eq!(atan2(0.0, -1.0), std::f64::consts::PI);
        assert!(atan2(f64::NAN, 1.0).is_nan() && atan2(1.0, f64::NAN).is_nan());
        let inf = f64::INFINITY;
        assert_eq!((atan2(inf, inf), atan2(1.0, inf), atan2(-inf, inf)), (inf.atan2(inf), 0.0, -inf.atan2(inf)));
        assert!(sin_cos(f64::NAN).0.is_nan() && sin_cos(f64::INFINITY).1.is_nan());
    }

    /// The anchored arctangent agrees with the library for directions that turn slowly (the anchor at
    /// work), across ±π, after jumps, at any radius, and passes zero and NaN inputs to the library.
    #[test]
    fn anchored_atan2_matches_the_library() {
        let mut memo = AnchoredAtan2::default();
        let mut check = |a: f64, r: f64| {
            let (y, x) = (r * a.sin(), r * a.cos());
            let (ours, theirs) = (memo.eval(y, x), y.atan2(x));
            assert!((ours - theirs).abs() <= 8.0 * f64::EPSILON, "angle {a}, radius {r}: {ours} vs {theirs}");
            assert!(ours > -PI && ours <= PI, "{ours} outside (-π, π]");
        };
        let mut a = -9.0;
        while a < 9.0 {
            check(a, 1.0 + 0.1 * a.sin());
            a += 0.000_913;
        }
        for (a, r) in [(PI, 1.0), (-PI + 1e-12, 2.0), (PI - 1e-12, 1e-150), (0.3, 1e150), (-2.0, 1.0), (1e-300, 1.0)] {
            check(a, r);
        }
        assert_eq!(memo.eval(0.0, 0.0), 0.0_f64.atan2(0.0));
        assert!(memo.eval(f64::NAN, 1.0).is_nan() && memo.eval(1.0, f64::INFINITY) == 1.0_f64.atan2(f64::INFINITY));
    }
}
