//! Scripted paths for a simulated hand's intended motion (see `hand`).
//!
//! Paths are offsets (m) in the device's x-y plane from where the hand grasped the handle (its pose at the
//! first call); the hand holds the grasp orientation. Syntax after `path:` (or a hand's `KIND:`):
//! - `line:X0,Y0,X1,Y1,T` — from offset (X0, Y0) to (X1, Y1) in T seconds (minimum-jerk), then hold;
//! - `circle:R,T` — a counter-clockwise circle of radius R through the grasp point (centre at −R along x),
//!   one turn every T seconds, repeated;
//! - `waypoints:T:X,Y;X,Y;...` — from the grasp point through each offset, T seconds per segment
//!   (minimum-jerk), then hold the last.

use super::{parse_numbers, UserError};

/// A scripted path (see the module documentation for the syntax).
#[derive(Clone, Debug, PartialEq)]
pub enum PathSpec {
    /// A straight line between two offsets.
    Line {
        /// Start offset (m).
        from: [f64; 2],
        /// End offset (m).
        to: [f64; 2],
        /// Duration (s).
        duration_s: f64,
    },
    /// A circle through the grasp point.
    Circle {
        /// Radius (m).
        radius: f64,
        /// Period (s).
        period_s: f64,
    },
    /// Segments through offsets.
    Waypoints {
        /// Duration of each segment (s).
        segment_s: f64,
        /// The offsets (m), after the grasp point.
        points: Vec<[f64; 2]>,
    },
}

impl std::str::FromStr for PathSpec {
    type Err = UserError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let positive = |what: &str, x: f64| {
            if x > 0.0 {
                Ok(x)
            } else {
                Err(UserError::Path(format!("{what} must be positive, got {x}")))
            }
        };
        let count = |what: &'static str, v: &[f64], n: usize| {
            if v.len() == n {
                Ok(())
            } else {
                Err(UserError::Count { what, expected: n.to_string(), got: v.len() })
            }
        };
        if let Some(rest) = s.strip_prefix("line:") {
            let v = parse_numbers("path:line", rest)?;
            count("path:line:X0,Y0,X1,Y1,T", &v, 5)?;
            return Ok(PathSpec::Line { from: [v[0], v[1]], to: [v[2], v[3]], duration_s: positive("T", v[4])? });
        }
        if let Some(rest) = s.strip_prefix("circle:") {
            let v = parse_numbers("path:circle", rest)?;
            count("path:circle:R,T", &v, 2)?;
            return Ok(PathSpec::Circle { radius: positive("R", v[0])?, period_s: positive("T", v[1])? });
        }
        if let Some(rest) = s.strip_prefix("waypoints:") {
            let (t, list) = rest
                .split_once(':')
                .ok_or_else(|| UserError::Path("write waypoints:T:X,Y;X,Y;... (T seconds per segment)".into()))?;
            let segment_s = positive("T", parse_numbers("path:waypoints T", t)?.first().copied().unwrap_or(0.0))?;
            let points = list
                .split(';')
                .map(|p| {
                    let v = parse_numbers("a waypoint", p)?;
                    count("a waypoint X,Y", &v, 2)?;
                    Ok([v[0], v[1]])
                })
                .collect::<Result<Vec<_>, UserError>>()?;
            return Ok(PathSpec::Waypoints { segment_s, points });
        }
        Err(UserError::Path(format!("{s:?} is not line:..., circle:... or waypoints:...")))
    }
}

/// Minimum-jerk progress `10τ³ − 15τ⁴ + 6τ⁵` for τ clamped to [0, 1].
pub(crate) fn minimum_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

fn lerp(a: [f64; 2], b: [f64; 2], s: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s]
}

impl PathSpec {
    /// The offset of the set-point from the grasp point at time `t_s` after the grasp.
    pub fn offset(&self, t_s: f64) -> [f64; 2] {
        match self {
            PathSpec::Line { from, to, duration_s } => lerp(*from, *to, minimum_jerk(t_s / duration_s)),
            PathSpec::Circle { radius, period_s } => {
                let phase = 2.0 * std::f64::consts::PI * t_s / period_s;
                [radius * (phase.cos() - 1.0), radius * phase.sin()]
            }
            PathSpec::Waypoints { segment_s, points } => {
                if points.is_empty() {
                    return [0.0, 0.0];
                }
                let segment = (t_s / segment_s).floor().max(0.0) as usize;
                if segment >= points.len() {
                    return points[points.len() - 1];
                }
                let start = if segment == 0 { [0.0, 0.0] } else { points[segment - 1] };
                lerp(start, points[segment], minimum_jerk(t_s / segment_s - segment as f64))
            }
        }
    }
}
