//! The compile stage of what acts on a joint's or cut's freedom: ranges on tree joints, and on cuts the
//! freedom itself, springs, dampers, ranges and the revolute cut's `axis_b` check. Every bad value is an
//! error naming the file, the key and the value.

use nalgebra::DVector;

use super::{Compiler, PosesAtQ0};
use crate::algorithms::cut_forces::freedom_state;
use crate::error::SceneError;
use crate::math::space::{SceneKind, Space, VecOps};
use crate::model::scene::{CutKindSpec, CutSpec, SpringSpec};
use crate::model::{Attachment, CutFreedom, Joint, JointKind, Range, Spring};

/// What acts on a cut's freedom, compiled.
pub(super) struct CutLoads<S: Space> {
    pub freedom: CutFreedom<S>,
    pub spring: Option<Spring>,
    pub damping: f64,
    pub range: Option<Range>,
}

impl<S: Space> Compiler<'_, S> {
    /// `[lo, hi]` at `key`, with walls from the scene's contact parameters (times `length_scale²` for an
    /// angle, see `joint_limits`); `position0` (the position at q0) must lie inside.
    fn range(
        &self,
        key: &str,
        spec: Option<[f64; 2]>,
        angular: bool,
        position0: f64,
        length_scale: f64,
    ) -> Result<Option<Range>, SceneError> {
        let Some([lo, hi]) = spec else { return Ok(None) };
        let lo = self.finite(&format!("{key}[0]"), lo)?;
        let hi = self.finite(&format!("{key}[1]"), hi)?;
        if lo >= hi {
            return Err(self.invalid(key.to_string(), format!("must be [lo, hi] with lo < hi, got [{lo}, {hi}]")));
        }
        if position0 < lo || position0 > hi {
            return Err(self.invalid(
                key.to_string(),
                format!("the position at q0, {position0}, lies outside the range [{lo}, {hi}]"),
            ));
        }
        let scale = if angular { length_scale * length_scale } else { 1.0 };
        let (stiffness, damping) = (self.scene.contact.stiffness * scale, self.scene.contact.damping * scale);
        Ok(Some(Range { lo, hi, stiffness, damping }))
    }

    /// Fills in each tree joint's range (file joint `file_joint[i]` carries tree joint `i`).
    pub(super) fn joint_ranges(
        &self,
        joints: &mut [Joint<S>],
        file_joint: impl Iterator<Item = usize>,
        q0: &DVector<f64>,
        length_scale: f64,
    ) -> Result<(), SceneError> {
        for (i, ji) in file_joint.enumerate() {
            let j = &self.scene.joints[ji];
            let key = format!("joint[{ji}] ({}).range", j.name);
            let angular = joints[i].kind == JointKind::Revolute;
            joints[i].range = self.range(&key, j.range, angular, q0[joints[i].q_index], length_scale)?;
        }
        Ok(())
    }

    /// A spring at `key` with its stiffness ≥ 0 and a finite rest position.
    pub(super) fn spring(&self, key: &str, s: &SpringSpec) -> Result<Spring, SceneError> {
        Ok(Spring {
            stiffness: self.non_negative(&format!("{key}.stiffness"), s.stiffness)?,
            rest: self.finite(&format!("{key}.rest"), s.rest)?,
        })
    }

    /// The freedom of cut `c` (at `key`) between `a` and `b`, with its spring, damper and range.
    pub(super) fn cut_loads(
        &self,
        key: &str,
        c: &CutSpec,
        (a, b): (Attachment<S>, Attachment<S>),
        axis_a: Option<&S::Point>,
        at_q0: &PosesAtQ0<'_, S>,
        length_scale: f64,
    ) -> Result<CutLoads<S>, SceneError> {
        let (body_a, body_b) = (a.body, b.body);
        let relative = S::rot_mul(&S::rot_inverse(&at_q0.pose(body_a).0), &at_q0.pose(body_b).0);
        let hinge = |axis_a: S::Point| CutFreedom::Hinge { body_a, body_b, axis_a, relative };
        let freedom = match (c.kind, axis_a) {
            (CutKindSpec::Slider, Some(u)) => CutFreedom::Slide { a, b, axis_a: *u },
            (CutKindSpec::Revolute, Some(u)) => hinge(*u),
            (CutKindSpec::Pin, _) => hinge(S::default_axis()),
            (CutKindSpec::Spherical, _) => CutFreedom::Rotation { body_a, body_b, relative },
            _ => CutFreedom::Locked,
        };
        let spring = match &c.spring {
            None => None,
            Some(s) => Some(self.spring(&format!("{key}.spring"), s)?),
        };
        let damping = self.non_negative(&format!("{key}.damping"), c.damping)?;
        let locked = |what: &str| {
            self.invalid(
                format!("{key}.{what}"),
                format!("a {:?} cut leaves nothing free to act on", c.kind).to_lowercase(),
            )
        };
        match freedom {
            CutFreedom::Locked if spring.is_some() => return Err(locked("spring")),
            CutFreedom::Locked if damping > 0.0 => return Err(locked("damping")),
            CutFreedom::Locked | CutFreedom::Rotation { .. } if c.range.is_some() => {
                return Err(self
                    .invalid(format!("{key}.range"), "a range needs a cut with one freedom (slider, pin or revolute)"))
            }
            CutFreedom::Rotation { .. } if spring.is_some_and(|s| s.rest != 0.0) => {
                return Err(self.invalid(
                    format!("{key}.spring.rest"),
                    "a spherical cut's spring pulls toward the pose at q0; rest must be 0 (or omitted)",
                ))
            }
            _ => {}
        }
        let position0 = freedom_state(&freedom, &at_q0.data.kin).map_or(0.0, |s| s.position);
        let range = self.range(&format!("{key}.range"), c.range, !c.kind.slides(), position0, length_scale)?;
        Ok(CutLoads { freedom, spring, damping, range })
    }

    /// A spatial revolute cut's `axis_b`, when given, must point along `axis` at q0: within
    /// `closure_tolerance` radians (the same unit-free number bounds the closure residual in units of
    /// `length_scale`). Otherwise the loop would close about an axis neither body turns about, and lock.
    pub(super) fn check_axis_b(
        &self,
        key: &str,
        c: &CutSpec,
        (body_a, body_b): (Option<usize>, Option<usize>),
        axis_a: Option<&S::Point>,
        at_q0: &PosesAtQ0<'_, S>,
    ) -> Result<(), SceneError> {
        let Some(given) = &c.axis_b else { return Ok(()) };
        let key_b = format!("{key}.axis_b");
        let (Some(axis_a), CutKindSpec::Revolute, SceneKind::Spatial) = (axis_a, c.kind, S::KIND) else {
            return Err(self.invalid(key_b, "only spatial revolute cuts take axis_b"));
        };
        let axis_b = self.unit(&key_b, given)?;
        let world_a = at_q0.dir_to_world(body_a, axis_a);
        let world_b = at_q0.dir_to_world(body_b, &axis_b);
        let angle = S::point_cross_point(&world_a, &world_b).norm().atan2(world_a.dot(&world_b));
        let tolerance = self.scene.closure_tolerance.unwrap_or(1e-6);
        if angle > tolerance || !angle.is_finite() {
            let show = |v: &S::Point| format!("{:.4?}", v.as_slice());
            return Err(self.invalid(
                key_b,
                format!(
                    "cut '{}': at q0 its axis on body b points along {} (world) but `axis` on body a along {} \
                     (world), {angle:.4} rad ({:.2}°) apart, beyond the tolerance {tolerance:.1e} rad \
                     (closure_tolerance); the loop would lock",
                    c.name,
                    show(&world_b),
                    show(&world_a),
                    angle.to_degrees()
                ),
            ));
        }
        Ok(())
    }
}
