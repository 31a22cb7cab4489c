//! What a ball or a universal joint may and must say in a scene file (the keys checked, the universal's two
//! axes read); `multi_rate` builds their entries.

use super::Compiler;
use crate::error::SceneError;
use crate::math::space::{SceneKind, Space, VecOps};
use crate::model::scene::JointKindSpec;

impl<S: Space> Compiler<'_, S> {
    /// Checks what ball and universal joints forbid and need (spatial scenes only; a ball takes no axis, a
    /// universal two non-parallel `axes`; neither takes q0, q̇0, a spring, an actuator or a range, whose
    /// one number would not say which rate), and returns a universal joint's unit axes.
    pub(super) fn multi_rate_axes(&self, ji: usize) -> Result<Option<[S::Point; 2]>, SceneError> {
        let j = &self.scene.joints[ji];
        let jkey = format!("joint[{ji}] ({})", j.name);
        let name = match j.kind {
            JointKindSpec::Ball => "ball",
            JointKindSpec::Universal => "universal",
            _ => {
                return match j.axes {
                    Some(_) => {
                        Err(self.invalid(format!("{jkey}.axes"), "only universal joints take `axes`; use `axis`"))
                    }
                    None => Ok(None),
                }
            }
        };
        if S::KIND != SceneKind::Spatial {
            return Err(self.invalid(format!("{jkey}.kind"), format!("a {name} joint needs a spatial scene")));
        }
        let unsupported = [
            ("q0", j.q0 != 0.0, "set the joint frame's `rotation` instead"),
            ("qd0", j.qd0 != 0.0, "it starts at rest"),
            ("spring", j.spring.is_some(), "not available on a multi-rate joint"),
            ("actuator", j.actuator.is_some(), "not available on a multi-rate joint"),
            ("range", j.range.is_some(), "not available on a multi-rate joint"),
        ];
        if let Some((key, _, why)) = unsupported.iter().find(|(_, given, _)| *given) {
            return Err(self.invalid(format!("{jkey}.{key}"), format!("a {name} joint takes no `{key}`: {why}")));
        }
        if let Some(axis) = &j.axis {
            let hint = if j.kind == JointKindSpec::Ball { "it turns about every axis" } else { "give its two `axes`" };
            return Err(
                self.invalid(format!("{jkey}.axis"), format!("a {name} joint takes no `axis` {axis:?}: {hint}"))
            );
        }
        if j.kind == JointKindSpec::Ball {
            return match j.axes {
                Some(_) => {
                    Err(self.invalid(format!("{jkey}.axes"), "a ball joint takes no `axes`: it turns about every axis"))
                }
                None => Ok(None),
            };
        }
        let axes = j
            .axes
            .as_ref()
            .ok_or_else(|| self.invalid(format!("{jkey}.axes"), "a universal joint needs two `axes`"))?;
        if axes.len() != 2 {
            return Err(self.invalid(format!("{jkey}.axes"), format!("expected two axes, got {}", axes.len())));
        }
        let first = self.unit(&format!("{jkey}.axes[0]"), &axes[0])?;
        let second = self.unit(&format!("{jkey}.axes[1]"), &axes[1])?;
        let cos = first.dot(&second);
        // Parallel axes are one revolute joint: D would be singular.
        if cos.abs() > 1.0 - 1e-6 {
            return Err(self.invalid(
                format!("{jkey}.axes"),
                format!(
                    "the two axes {:?} and {:?} are parallel; a universal joint needs two different ones",
                    axes[0], axes[1]
                ),
            ));
        }
        Ok(Some([first, second]))
    }
}
