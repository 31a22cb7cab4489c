//! The fake's simulated hand: a grasp modelled as a mass-spring-damper attached to an intended motion, the
//! arm moving its own mass along that intention:
//! ```text
//! F_h = K (x_d − x) + B (ẋ_d − ẋ) + M ẍ_d,   the hand's mass M moving with the handle
//! ```
//! Impedances (per axis), from `shared/haptics-facts.md`:
//! - soft: a relaxed grasp, one participant's arm-and-hand impedance measured on a HapticMaster
//!   (Sci. Rep. 5:18004, 2015): M 0.554 kg, B 6.45 N s/m, K 135 N/m;
//! - firm: a co-contracted grasp, inside the ranges simulated for one (0.5-2 kg, 10-30 N s/m,
//!   500-2000 N/m; stiffness and damping rise with grip force, Hasser & Cutkosky 2002): M 0.8 kg,
//!   B 25 N s/m, K 700 N/m.
//!
//! Intended motion: a tour through waypoints the caller gives (`FAKE_DHD_TOUR`, device frame, metres),
//! visited in order and back again, over and over, on minimum-jerk segments (Flash & Hogan 1985) at a
//! relaxed pace of at most [`TOUR_SPEED_M_S`], each at least [`SEGMENT_MIN_S`] long: a person touring
//! what the linkage lets them reach. Without waypoints, a circle of [`CIRCLE_RADIUS_M`] in the device's
//! y-z plane from where the handle starts: a smoke-test motion, not one within any linkage's reach.

use std::f64::consts::PI;

/// Fastest pace between waypoints (m/s).
pub const TOUR_SPEED_M_S: f64 = 0.04;
/// Shortest segment between waypoints (s).
pub const SEGMENT_MIN_S: f64 = 0.6;
/// Radius (m) and period (s) of the circle toured without waypoints.
pub const CIRCLE_RADIUS_M: f64 = 0.015;
const CIRCLE_PERIOD_S: f64 = 4.0;

/// A grasp's impedance per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grip {
    /// The hand's mass, moving with the handle (kg).
    pub mass: f64,
    /// N s/m.
    pub damping: f64,
    /// N/m.
    pub stiffness: f64,
}

impl Grip {
    /// A relaxed grasp (see the module documentation).
    pub const SOFT: Grip = Grip { mass: 0.554, damping: 6.45, stiffness: 135.0 };
    /// A firm grasp (see the module documentation).
    pub const FIRM: Grip = Grip { mass: 0.8, damping: 25.0, stiffness: 700.0 };
}

/// Where the hand intends the handle to be, and how it moves there.
#[derive(Clone, Debug, PartialEq)]
pub enum Intent {
    /// A circle in the y-z plane from the start.
    Circle,
    /// Waypoints in order and back (device frame, m): `knots` are (start time, point) of each segment.
    Tour { knots: Vec<(f64, [f64; 3])>, period: f64 },
}

/// Intended position, velocity and acceleration at one instant.
pub type Intended = ([f64; 3], [f64; 3], [f64; 3]);

impl Intent {
    /// A tour of `waypoints` there and back; a circle when fewer than two are given.
    pub fn tour(waypoints: &[[f64; 3]]) -> Intent {
        if waypoints.len() < 2 {
            return Intent::Circle;
        }
        let mut path: Vec<[f64; 3]> = waypoints.to_vec();
        path.extend(waypoints.iter().rev().skip(1));
        let mut knots = Vec::with_capacity(path.len());
        let mut t = 0.0;
        for pair in path.windows(2) {
            knots.push((t, pair[0]));
            let d = (0..3).map(|i| (pair[1][i] - pair[0][i]).powi(2)).sum::<f64>().sqrt();
            t += (d / TOUR_SPEED_M_S).max(SEGMENT_MIN_S);
        }
        knots.push((t, path[path.len() - 1]));
        Intent::Tour { knots, period: t }
    }

    /// Parses `FAKE_DHD_TOUR`: `X,Y,Z;X,Y,Z;...` in metres, device frame. `None` when any number is bad.
    pub fn parse_waypoints(text: &str) -> Option<Vec<[f64; 3]>> {
        text.split(';')
            .filter(|p| !p.trim().is_empty())
            .map(|p| {
                let v: Vec<f64> = p.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().ok()?;
                (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| [v[0], v[1], v[2]])
            })
            .collect()
    }

    /// The intention `t` seconds after the hand starts moving, from `start` (where the handle was grasped).
    pub fn at(&self, start: [f64; 3], t: f64) -> Intended {
        let t = t.max(0.0);
        match self {
            Intent::Circle => {
                let w = 2.0 * PI / CIRCLE_PERIOD_S;
                let (s, c) = (w * t).sin_cos();
                let r = CIRCLE_RADIUS_M;
                (
                    [start[0], start[1] + r * s, start[2] + r * (1.0 - c)],
                    [0.0, r * w * c, r * w * s],
                    [0.0, -r * w * w * s, r * w * w * c],
                )
            }
            Intent::Tour { knots, period } => {
                let t = t % period;
                let i = knots.partition_point(|k| k.0 <= t).saturating_sub(1).min(knots.len() - 2);
                let ((t0, a), (t1, b)) = (knots[i], knots[i + 1]);
                let span = t1 - t0;
                let s = ((t - t0) / span).clamp(0.0, 1.0);
                // Minimum jerk: 10s³ − 15s⁴ + 6s⁵ and its derivatives.
                let shape = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
                let rate = 30.0 * s * s * (1.0 - s) * (1.0 - s) / span;
                let curve = 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / (span * span);
                let mut out = ([0.0; 3], [0.0; 3], [0.0; 3]);
                for axis in 0..3 {
                    let d = b[axis] - a[axis];
                    out.0[axis] = a[axis] + d * shape;
                    out.1[axis] = d * rate;
                    out.2[axis] = d * curve;
                }
                out
            }
        }
    }

    /// Where the intention starts: the first waypoint, if any.
    pub fn first(&self) -> Option<[f64; 3]> {
        match self {
            Intent::Circle => None,
            Intent::Tour { knots, .. } => knots.first().map(|k| k.1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tour_goes_there_and_back_smoothly_at_a_relaxed_pace() {
        let tour = Intent::tour(&[[0.0; 3], [0.0, 0.04, 0.0], [0.0, 0.04, 0.02]]);
        let Intent::Tour { knots, period } = &tour else { panic!("a tour") };
        // 40 mm at 40 mm/s: 1 s; 20 mm: the 0.6 s floor; then back the same way.
        assert!((period - 3.2).abs() < 1e-12, "{period}");
        assert_eq!(knots.len(), 5);
        let start = [0.0; 3];
        let (p, v, _) = tour.at(start, 0.0);
        assert_eq!((p, v), ([0.0; 3], [0.0; 3]));
        // Halfway through the first segment: halfway there, at 1.875 times the mean speed (minimum jerk).
        let (p, v, a) = tour.at(start, 0.5);
        assert!((p[1] - 0.02).abs() < 1e-12 && (v[1] - 1.875 * 0.04).abs() < 1e-12 && a[1].abs() < 1e-9);
        let (p, _, _) = tour.at(start, 1.6);
        assert!((p[1] - 0.04).abs() < 1e-12 && (p[2] - 0.02).abs() < 1e-12, "{p:?}");
        // Back at the start after a period, and again after two.
        for t in [3.2, 6.4] {
            let (p, _, _) = tour.at(start, t);
            assert!(p.iter().all(|x| x.abs() < 1e-12), "{t}: {p:?}");
        }
    }

    #[test]
    fn waypoints_parse_or_are_refused() {
        assert_eq!(Intent::parse_waypoints("0,0.01,0.02;1e-3,0,0"), Some(vec![[0.0, 0.01, 0.02], [1e-3, 0.0, 0.0]]));
        assert_eq!(Intent::parse_waypoints("0,0"), None);
        assert_eq!(Intent::parse_waypoints("0,0,NaN"), None);
        assert_eq!(Intent::tour(&[[0.0; 3]]), Intent::Circle);
    }
}
