//! The path of an operational point on a linkage of one degree of freedom, and where a pose lies along it.
//!
//! A 1-DOF linkage moves its OP along one curve in operational space (position and orientation together),
//! which the reach survey walks once (`reach::OpReach::path`). Its tangent is the one direction the joints
//! let the OP move: the free direction of eq 10's SVD of Λ⁻¹, since Λ⁻¹ = J M⁻¹ Jᵀ has rank one along the
//! OP's velocity per unit of the linkage's coordinate. A local model linearized at one pose (eq 11, 13)
//! holds the OP to the tangent *line* there; the path holds it to the curve wherever it has run, so the
//! constrained directions can turn as the linkage's do ([`turn_between`]).
//!
//! A path has one of three shapes ([`PathShape`]): a closed lap (a crank's coupler curve), an open curve
//! end to end (between dead points or stroke ends where the linkage itself stops), or a swing: one sweep,
//! limit to limit, of an OP that swings forth and back while the linkage moves on (a rocker's output as its
//! crank turns). A swing's limits are where the linkage's map from its coordinate to the OP folds: the OP
//! stops there and comes back, whatever way the linkage goes on, so no pose lies beyond them.
//!
//! A path may carry, per pose, the OP's acceleration at rest there (gravity, springs, actuators: what moves
//! the linkage when nothing holds it), which is along the tangent since the OP can only move along the path.
//! A local model that has run ahead of its snapshot along the path feels these forces where it is, not where
//! the snapshot was taken: a position-dependent force felt at a pose a round trip behind acts as a spring
//! rendered late, which makes energy when the hand goes back and forth (a four-bar's weight, 1 s one way:
//! about 1 J per tour). A swing carries none: each of its poses is two configurations (the crank on either
//! side of the fold), whose forces at rest differ, so they are not a function of the pose.
//!
//! Distances and tangents are in the unit-consistent coordinates of `constraint_directions` (`(x, L θ)`,
//! `L` the scene's length scale). Queries allocate nothing and, given the segment of the last answer, look
//! only at its neighbours (a curve that passes near itself, as a coupler curve can, is followed along the
//! branch the OP is on instead of jumping to the other).

use crate::algorithms::constraint_directions::scale_op;
use crate::math::space::OpPose;
use crate::math::space::{MatOps, Space, VecOps};

/// How a path's ends are (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum PathShape {
    /// End to end: the OP's path stops at its ends (a dead point, a stroke's end, where a survey's walk could
    /// go no further).
    Open,
    /// The last pose leads back to the first.
    Closed,
    /// One sweep of an OP that swings forth and back while the linkage goes on: its ends are limits where
    /// the OP turns back, and each pose is two configurations (no forces at rest per pose).
    Swing,
}

/// A sampled OP path: poses in order, with its shape.
#[derive(Clone, Debug, PartialEq)]
pub struct OpPath<S: Space> {
    poses: Vec<OpPose<S>>,
    /// Unit tangent at each pose (unit-consistent coordinates), pointing along the path's order.
    tangents: Vec<S::OpVec>,
    /// Curvature vector at each pose (unit-consistent, 1/m): the tangents' difference across it per unit of arc.
    curvatures: Vec<S::OpVec>,
    /// The OP's acceleration at rest at each pose, along its tangent (unit-consistent, m/s²), when given.
    rest_acceleration: Option<Vec<f64>>,
    shape: PathShape,
    length_scale: f64,
}

/// The point of a path nearest a pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint<S: Space> {
    /// The point (interpolated between two samples).
    pub pose: OpPose<S>,
    /// Unit tangent there (unit-consistent coordinates), along the path's order; interpolated between the
    /// samples' so that it turns continuously.
    pub tangent: S::OpVec,
    /// Distance from the pose asked about (unit-consistent, m).
    pub distance: f64,
    /// The same distance when the point is an end of an open path (the pose is past it, or beside it), else 0.
    pub past_end: f64,
    /// The OP's acceleration at rest there (physical units, linear first), interpolated, when the path
    /// carries it.
    pub rest_acceleration: Option<S::OpVec>,
    /// The path's curvature vector there (unit-consistent, 1/m), interpolated: the turn of the unit tangent
    /// per unit of arc, with which a point moving along the path at speed `v` accelerates across it, `κ v²`.
    pub curvature: S::OpVec,
    /// The segment it lies on (a hint for the next query).
    pub segment: usize,
}

/// Why a path was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PathError {
    /// Fewer than two poses.
    #[error("a path needs at least two poses, got {0}")]
    TooShort(usize),
    /// A pose is not finite, or the length scale is not positive.
    #[error("pose {0} of the path is not finite")]
    NonFinite(usize),
    /// Two consecutive poses coincide: no tangent there.
    #[error("poses {0} and {1} of the path coincide")]
    Repeated(usize, usize),
    /// The length scale is not finite and positive.
    #[error("length scale {0} is not finite and positive")]
    LengthScale(f64),
    /// The accelerations at rest are not one finite value per pose.
    #[error("{got} accelerations at rest for {poses} poses (one finite value per pose)")]
    RestAcceleration {
        /// Values given.
        got: usize,
        /// Poses.
        poses: usize,
    },
    /// Accelerations at rest given to a swing, whose poses are two configurations each.
    #[error("a swing has no acceleration at rest per pose (each pose is two configurations)")]
    RestAccelerationOnSwing,
}

impl<S: Space> OpPath<S> {
    /// A path through `poses` in order, of `shape`, measured with the scene's `length_scale`.
    pub fn new(poses: Vec<OpPose<S>>, shape: PathShape, length_scale: f64) -> Result<Self, PathError> {
        let closed = shape == PathShape::Closed;
        if !(length_scale.is_finite() && length_scale > 0.0) {
            return Err(PathError::LengthScale(length_scale));
        }
        let n = poses.len();
        if n < 2 {
            return Err(PathError::TooShort(n));
        }
        if let Some(i) = poses.iter().position(|p| !(p.position.is_finite() && S::rot_is_finite(&p.rotation))) {
            return Err(PathError::NonFinite(i));
        }
        let scaled = |a: &OpPose<S>, b: &OpPose<S>| scale_op::<S>(&a.difference(b), length_scale);
        let segments = if closed { n } else { n - 1 };
        for k in 0..segments {
            let next = (k + 1) % n;
            if scaled(&poses[next], &poses[k]).norm() <= 1e-12 * length_scale {
                return Err(PathError::Repeated(k, next));
            }
        }
        let tangents = (0..n)
            .map(|k| {
                let (before, after) = difference_neighbours(closed, n, k);
                let d = scaled(&poses[after], &poses[before]);
                d * (1.0 / d.norm())
            })
            .collect::<Vec<_>>();
        let curvatures = (0..n)
            .map(|k| {
                let (before, after) = difference_neighbours(closed, n, k);
                let arc = scaled(&poses[after], &poses[before]).norm();
                (tangents[after] - tangents[before]) * (1.0 / arc)
            })
            .collect();
        Ok(OpPath { rest_acceleration: None, poses, tangents, curvatures, shape, length_scale })
    }

    /// The path with the OP's acceleration at rest at each pose, along the pose's tangent ([`Self::tangent`];
    /// unit-consistent, m/s²). Refused on a swing.
    pub fn with_rest_acceleration(mut self, along: Vec<f64>) -> Result<Self, PathError> {
        if self.shape == PathShape::Swing {
            return Err(PathError::RestAccelerationOnSwing);
        }
        if along.len() != self.poses.len() || along.iter().any(|a| !a.is_finite()) {
            return Err(PathError::RestAcceleration { got: along.len(), poses: self.poses.len() });
        }
        self.rest_acceleration = Some(along);
        Ok(self)
    }

    /// The path as a hand that holds the OP as through a pin sees it: positions only (identity orientations),
    /// since it neither pushes on nor holds the angle, with the accelerations at rest kept in their linear
    /// part (along the position's tangent). An error when the OP turns without moving somewhere along the way.
    pub fn positions_only(&self) -> Result<Self, PathError> {
        let poses = self.poses.iter().map(|p| OpPose { position: p.position, rotation: S::rot_identity() }).collect();
        let path = OpPath::new(poses, self.shape, self.length_scale)?;
        let Some(rest) = &self.rest_acceleration else {
            return Ok(path);
        };
        // a = α t̃: its linear part is α |t̃_lin| along the unit linear tangent.
        let along = (0..self.poses.len()).map(|k| rest[k] * S::op_lin(&self.tangents[k]).norm()).collect();
        path.with_rest_acceleration(along)
    }

    /// The unit tangent at pose `k` (unit-consistent coordinates), along the path's order.
    pub fn tangent(&self, k: usize) -> S::OpVec {
        self.tangents[k]
    }

    /// The accelerations at rest, per pose, along the tangents, when the path carries them.
    pub fn rest_acceleration(&self) -> Option<&[f64]> {
        self.rest_acceleration.as_deref()
    }

    /// The poses.
    pub fn poses(&self) -> &[OpPose<S>] {
        &self.poses
    }

    /// True when the last pose leads back to the first.
    pub fn is_closed(&self) -> bool {
        self.shape == PathShape::Closed
    }

    /// How the path's ends are.
    pub fn shape(&self) -> PathShape {
        self.shape
    }

    fn segments(&self) -> usize {
        if self.is_closed() {
            self.poses.len()
        } else {
            self.poses.len() - 1
        }
    }

    /// The limit at the end of a swing that segment `k` leads to, with the unit direction out of the path
    /// there (unit-consistent coordinates): the first pose and minus its tangent for the first segment, the
    /// last and its tangent for the last. `None` inside, and on other shapes (an open path's end is where a
    /// walk stopped, which a linkage may pass).
    pub fn limit(&self, k: usize) -> Option<(OpPose<S>, S::OpVec)> {
        let last = self.poses.len() - 1;
        match (self.shape, k) {
            (PathShape::Swing, 0) => Some((self.poses[0], -self.tangents[0])),
            (PathShape::Swing, k) if k + 1 == last => Some((self.poses[last], self.tangents[last])),
            _ => None,
        }
    }

    /// Where on segment `k` `pose` is nearest: (scaled displacement from `pose` to that point, fraction along
    /// the segment).
    fn on_segment(&self, k: usize, pose: &OpPose<S>) -> (S::OpVec, f64) {
        let l = self.length_scale;
        let a = scale_op::<S>(&self.poses[k].difference(pose), l);
        let b = scale_op::<S>(&self.poses[(k + 1) % self.poses.len()].difference(pose), l);
        let d = b - a;
        let u = (-a.dot(&d) / d.dot(&d)).clamp(0.0, 1.0);
        (a + d * u, u)
    }

    /// The point of the path nearest `pose`. With `near`, the segment of an earlier answer, the search walks
    /// from there to neighbouring segments while they are nearer (the branch the OP is on); without, it
    /// looks at every segment.
    pub fn nearest(&self, pose: &OpPose<S>, near: Option<usize>) -> PathPoint<S> {
        let segments = self.segments();
        let distance = |k: usize| self.on_segment(k, pose).0.norm();
        let mut best = match near {
            Some(k) if k < segments => k,
            _ => (0..segments).min_by(|&i, &j| distance(i).total_cmp(&distance(j))).unwrap_or(0),
        };
        let mut best_distance = distance(best);
        let neighbours = |k: usize| -> [Option<usize>; 2] {
            if self.is_closed() {
                [Some((k + segments - 1) % segments), Some((k + 1) % segments)]
            } else {
                [k.checked_sub(1), (k + 1 < segments).then_some(k + 1)]
            }
        };
        for _ in 0..segments {
            let step = neighbours(best)
                .into_iter()
                .flatten()
                .map(|k| (k, distance(k)))
                .filter(|(_, d)| *d < best_distance)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match step {
                Some((k, d)) => (best, best_distance) = (k, d),
                None => break,
            }
        }
        let (offset, u) = self.on_segment(best, pose);
        let mut point = *pose;
        point.integrate(&scale_op::<S>(&offset, 1.0 / self.length_scale), 1.0);
        let next = (best + 1) % self.poses.len();
        let blended = self.tangents[best] * (1.0 - u) + self.tangents[next] * u;
        let norm = blended.norm();
        // Opposite tangents at both ends of a segment (a path that doubles back on one segment) blend to
        // nothing: keep the segment's own direction.
        let tangent = if norm > 1e-9 {
            blended * (1.0 / norm)
        } else {
            let d = scale_op::<S>(&self.poses[next].difference(&self.poses[best]), self.length_scale);
            d * (1.0 / d.norm())
        };
        let rest_acceleration = self.rest_acceleration.as_ref().map(|rest| {
            let along = rest[best] * (1.0 - u) + rest[next] * u;
            scale_op::<S>(&(tangent * along), 1.0 / self.length_scale)
        });
        let curvature = self.curvatures[best] * (1.0 - u) + self.curvatures[next] * u;
        let at_end = !self.is_closed() && ((best == 0 && u == 0.0) || (best + 1 == segments && u == 1.0));
        let distance = offset.norm();
        PathPoint {
            pose: point,
            tangent,
            distance,
            past_end: if at_end { distance } else { 0.0 },
            rest_acceleration,
            curvature,
            segment: best,
        }
    }
}

/// The samples a derivative along a path of `n` samples (at least two) takes at sample `k`: its neighbours
/// either side (central differences), wrapping round on a `closed` path, and the sample itself with its one
/// neighbour at the ends of an open one (one-sided).
pub fn difference_neighbours(closed: bool, n: usize, k: usize) -> (usize, usize) {
    match (closed, k) {
        (true, _) => ((k + n - 1) % n, (k + 1) % n),
        (false, 0) => (0, 1),
        (false, k) if k == n - 1 => (n - 2, n - 1),
        (false, k) => (k - 1, k + 1),
    }
}

/// The rotation of operational space (unit-consistent coordinates) that turns unit direction `from` through
/// `fraction` ∈ [0, 1] of the angle θ onto `to`, within the plane the two span and fixing everything
/// orthogonal to it: `R = I + (cos φ − 1)(u uᵀ + w wᵀ) + sin φ (w uᵀ − u wᵀ)` with `φ = fraction θ`, `u = from`,
/// `w` the unit part of `to` orthogonal to `u`. At `fraction` 1, `R from = to`. The identity when they are the
/// same direction; `−I` when opposite and `fraction` is at least a half (a path that doubles back: a projector
/// is unchanged, and what moves along the path is turned round with it).
///
/// Both are tangents taken in the path's order, and the turn keeps it: a twist or an acceleration along
/// `from` arrives along `to` with its sign, forward along the path staying forward, however sharply the path
/// turns between them (a coupler curve's corner turns its tangent by more than a right angle).
pub fn turn_between<S: Space>(from: &S::OpVec, to: &S::OpVec, fraction: f64) -> S::OpMat {
    let cos = from.dot(to).clamp(-1.0, 1.0);
    let orthogonal = *to - *from * cos;
    let sin = orthogonal.norm();
    // Parallel, opposite, or not a number: no plane to turn in.
    if sin.partial_cmp(&1e-12) != Some(std::cmp::Ordering::Greater) {
        return if cos < 0.0 && fraction >= 0.5 { S::OpMat::identity() * -1.0 } else { S::OpMat::identity() };
    }
    let w = orthogonal * (1.0 / sin);
    let u = *from;
    let angle = sin.atan2(cos) * fraction.clamp(0.0, 1.0);
    S::OpMat::identity()
        + (S::op_outer(&u, &u) + S::op_outer(&w, &w)) * (angle.cos() - 1.0)
        + (S::op_outer(&w, &u) - S::op_outer(&u, &w)) * angle.sin()
}

/// `a b` for operational-space matrices.
pub fn product<S: Space>(a: &S::OpMat, b: &S::OpMat) -> S::OpMat {
    let mut out = S::OpMat::zero();
    for c in 0..S::DIM {
        for k in 0..S::DIM {
            let bkc = b[(k, c)];
            if bkc != 0.0 {
                for r in 0..S::DIM {
                    out[(r, c)] += a[(r, k)] * bkc;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::space::Planar;
    use nalgebra::{Vector2, Vector3};

    fn circle(n: usize, radius: f64) -> Vec<OpPose<Planar>> {
        (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / n as f64;
                // A crank's tip: the orientation turns with the position.
                OpPose {
                    position: Vector2::new(radius * a.cos(), radius * a.sin()),
                    rotation: Planar::rot_from_vector(&a),
                }
            })
            .collect()
    }

    #[test]
    fn the_nearest_point_of_a_crank_tips_circle_is_radial_and_its_tangent_turns_with_it() {
        let (r, l) = (0.1, 0.1);
        let path = OpPath::<Planar>::new(circle(360, r), PathShape::Closed, l).unwrap();
        // A pose outside the circle at 100°, turned as the crank is there.
        let a = 100f64.to_radians();
        let pose =
            OpPose { position: Vector2::new(0.12 * a.cos(), 0.12 * a.sin()), rotation: Planar::rot_from_vector(&a) };
        let p = path.nearest(&pose, None);
        assert!((p.pose.position - Vector2::new(r * a.cos(), r * a.sin())).norm() < 1e-5, "{p:?}");
        assert!((p.distance - 0.02).abs() < 1e-5, "{p:?}");
        // Closed form: d/da (r cos a, r sin a, L a) normalized.
        let t = Vector3::new(-r * a.sin(), r * a.cos(), l) / (2.0 * r * r).sqrt();
        assert!((p.tangent - t).norm() < 1e-4, "{:?} against {t:?}", p.tangent);
        // From a hint far away the walk along the circle still gets there (no other branch to stop on).
        let from_hint = path.nearest(&pose, Some(300));
        assert!((from_hint.pose.position - p.pose.position).norm() < 1e-9);
    }

    /// The curvature of a crank tip's path in scaled coordinates, `(r cos a, r sin a, L a)`: a helix, whose
    /// curvature vector points at the crank's pivot with magnitude `r / (r² + L²)` and has no part along the
    /// angle. With the radius unlike the length scale the angle's share shows.
    #[test]
    fn a_crank_tips_curvature_points_at_its_pivot_as_the_helix_s_closed_form() {
        for (r, l) in [(0.1, 0.1), (0.05, 0.2)] {
            let path = OpPath::<Planar>::new(circle(360, r), PathShape::Closed, l).unwrap();
            for degrees in [0.0, 100.0, 227.5] {
                let a = f64::to_radians(degrees);
                let pose =
                    OpPose { position: Vector2::new(r * a.cos(), r * a.sin()), rotation: Planar::rot_from_vector(&a) };
                let p = path.nearest(&pose, None);
                let expected = Vector3::new(-a.cos(), -a.sin(), 0.0) * (r / (r * r + l * l));
                assert!(
                    (p.curvature - expected).norm() < 1e-3 * expected.norm(),
                    "{:?} against {expected:?}",
                    p.curvature
                );
            }
        }
    }

    /// A crank tip's circle seen through a pin: the same positions, no angle, and the acceleration at rest's
    /// linear part (a tangential g cos a, the closed form for a point mass on a massless crank).
    #[test]
    fn a_pinned_hand_sees_the_path_of_positions_with_the_linear_part_of_its_accelerations() {
        let (r, l, g) = (0.1, 0.1, 9.81);
        let poses = circle(360, r);
        let full = OpPath::<Planar>::new(poses, PathShape::Closed, l).unwrap();
        // θ̈ = −(g / r) cos a; the scaled tangent moves √(r² + L²) per radian.
        let along = (0..360)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 360.0;
                -(g / r) * a.cos() * (r * r + l * l).sqrt()
            })
            .collect();
        let full = full.with_rest_acceleration(along).unwrap();
        let pinned = full.positions_only().unwrap();
        let a = 0.7f64;
        let query = OpPose { position: Vector2::new(r * a.cos(), r * a.sin()), rotation: Planar::rot_identity() };
        let p = pinned.nearest(&query, None);
        assert!(p.distance < 1e-4 && p.pose.rotation == Planar::rot_identity(), "{p:?}");
        assert!(p.tangent[2].abs() < 1e-12);
        let expected = Vector2::new(-a.sin(), a.cos()) * (-g * a.cos());
        let rest = p.rest_acceleration.expect("the path carries its forces at rest");
        let got = Vector2::new(rest[0], rest[1]);
        assert!((got - expected).norm() < 1e-3 * g, "{got:?} vs {expected:?}");
        assert_eq!(rest[2], 0.0);
    }

    /// A rocker's swing: a quarter of its tip's circle, limit to limit. It carries no forces at rest and
    /// refuses them; its first and last segments lead to limits whose outward directions point away from
    /// the arc along its end tangents; inner segments have none, nor do an open path's ends.
    #[test]
    fn a_swing_has_limits_at_its_ends_and_no_forces_at_rest() {
        let (r, l) = (0.2, 0.1);
        let arc: Vec<OpPose<Planar>> = circle(360, r).into_iter().take(91).collect();
        let swing = OpPath::<Planar>::new(arc.clone(), PathShape::Swing, l).unwrap();
        assert_eq!(swing.shape(), PathShape::Swing);
        assert!(swing.rest_acceleration().is_none() && !swing.is_closed());
        assert_eq!(swing.clone().with_rest_acceleration(vec![0.0; 91]), Err(PathError::RestAccelerationOnSwing));
        assert_eq!(swing.positions_only().unwrap().shape(), PathShape::Swing);
        // Past the 90° limit along the circle's tangent there (−x, and the angle still turning).
        let beyond = OpPose { position: Vector2::new(-0.01, r), rotation: Planar::rot_from_vector(&1.6) };
        let on = swing.nearest(&beyond, Some(80));
        assert_eq!(on.segment, 89);
        assert!(on.past_end > 0.0 && on.rest_acceleration.is_none(), "{on:?}");
        let (limit, out) = swing.limit(on.segment).expect("the last segment leads to a limit");
        assert!((limit.position - Vector2::new(0.0, r)).norm() < 1e-12);
        // Closed form: d/da (r cos a, r sin a, L a) at 90°, normalized (the end's one-sided chord is half a
        // degree off it).
        assert!((out - Vector3::new(-r, 0.0, l) / (r * r + l * l).sqrt()).norm() < 1e-2, "{out:?}");
        let (start, back) = swing.limit(0).expect("the first segment leads to a limit");
        assert!((start.position - Vector2::new(r, 0.0)).norm() < 1e-12);
        assert!((back - Vector3::new(0.0, -r, -l) / (r * r + l * l).sqrt()).norm() < 1e-2, "{back:?}");
        assert!(swing.limit(45).is_none());
        assert!(OpPath::<Planar>::new(arc, PathShape::Open, l).unwrap().limit(0).is_none());
    }

    #[test]
    fn a_hint_keeps_the_branch_where_a_path_passes_near_itself() {
        // A hairpin: out along y = 0, back along y = 0.01.
        let mut poses: Vec<OpPose<Planar>> = (0..=20)
            .map(|k| OpPose { position: Vector2::new(0.005 * k as f64, 0.0), rotation: Planar::rot_identity() })
            .collect();
        poses.extend(
            (0..=20)
                .rev()
                .map(|k| OpPose { position: Vector2::new(0.005 * k as f64, 0.01), rotation: Planar::rot_identity() }),
        );
        let path = OpPath::<Planar>::new(poses, PathShape::Open, 0.1).unwrap();
        let between = OpPose { position: Vector2::new(0.05, 0.0049), rotation: Planar::rot_identity() };
        assert!(path.nearest(&between, None).pose.position.y < 0.005);
        // Coming from the return leg, the query stays on it.
        let back = path.nearest(&between, Some(30));
        assert!((back.pose.position.y - 0.01).abs() < 1e-12, "{back:?}");
        assert_eq!(back.past_end, 0.0);
        // Past the end of the return leg.
        let beyond = OpPose { position: Vector2::new(-0.03, 0.01), rotation: Planar::rot_identity() };
        let end = path.nearest(&beyond, Some(39));
        assert!((end.past_end - 0.03).abs() < 1e-12 && end.distance == end.past_end, "{end:?}");
    }

    #[test]
    fn the_turn_maps_one_direction_onto_the_other_and_keeps_lengths() {
        let from = Vector3::new(1.0, 0.0, 0.0);
        let to = Vector3::new(0.6, 0.48, 0.64);
        let r = turn_between::<Planar>(&from, &to, 1.0);
        assert!((r * from - to).norm() < 1e-12);
        assert!((product::<Planar>(&r, &r.transpose()) - nalgebra::Matrix3::identity()).norm() < 1e-12);
        // A direction orthogonal to both is left alone.
        let other = Vector3::new(0.0, 0.8, -0.6);
        assert!((r * other - other).norm() < 1e-12);
        // Past a right angle, forward stays forward.
        let back = turn_between::<Planar>(&from, &-to, 1.0);
        assert!((back * from + to).norm() < 1e-12);
        assert_eq!(turn_between::<Planar>(&from, &from, 1.0), nalgebra::Matrix3::identity());
        assert_eq!(turn_between::<Planar>(&from, &-from, 1.0), -nalgebra::Matrix3::identity());
        // Part of the way: half the angle, twice over, is the whole turn; none of it is no turn.
        let half = turn_between::<Planar>(&from, &to, 0.5);
        assert!((half * (half * from) - to).norm() < 1e-12);
        assert!((half * from).dot(&from) > from.dot(&to));
        assert_eq!(turn_between::<Planar>(&from, &to, 0.0), nalgebra::Matrix3::identity());
    }

    #[test]
    fn bad_paths_are_refused_with_what_is_wrong() {
        let mut poses = circle(8, 0.1);
        assert_eq!(OpPath::<Planar>::new(poses[..1].to_vec(), PathShape::Open, 0.1), Err(PathError::TooShort(1)));
        assert_eq!(OpPath::<Planar>::new(poses.clone(), PathShape::Closed, 0.0), Err(PathError::LengthScale(0.0)));
        poses[3] = poses[2];
        assert_eq!(OpPath::<Planar>::new(poses.clone(), PathShape::Closed, 0.1), Err(PathError::Repeated(2, 3)));
        poses[3].position.x = f64::NAN;
        assert_eq!(OpPath::<Planar>::new(poses, PathShape::Closed, 0.1), Err(PathError::NonFinite(3)));
    }
}
