//! `<actuator>`: a `position` actuator on a hinge or slide (gear 1) is kinloop's joint PD actuator with the
//! control at zero: τ = kp (0 − q) − kv q̇, clamped to `forcerange` when force-limited. Every other actuator
//! (motor, velocity, general, muscle, ...; tendon or site transmissions) is listed as unusable.

use kinloop_linkage::model::scene::{ActuatorSpec, JointSpec};

use crate::error::MjcfError;
use crate::warnings::Warnings;
use crate::xml::Element;

/// Attaches the actuator `e` (resolved against its defaults) to its joint in `joints`, or lists it.
pub fn read_actuator(
    e: &Element,
    joint_index: &std::collections::HashMap<String, (usize, bool)>,
    joints: &mut [JointSpec],
    warnings: &mut Warnings,
) -> Result<(), MjcfError> {
    let name = e.attr("name").map_or_else(|| format!("{}@{}", e.tag, e.line), str::to_string);
    if e.tag != "position" {
        warnings.unusable(format!("<{}> actuator '{name}'", e.tag));
        return Ok(());
    }
    let Some(joint) = e.attr("joint") else {
        warnings.unusable(format!("position actuator '{name}' (it drives no joint)"));
        return Ok(());
    };
    let &(index, actuable) = joint_index.get(joint).ok_or_else(|| e.error(format!("no joint named '{joint}'")))?;
    let gear = e.numbers("gear")?.unwrap_or_else(|| vec![1.0]);
    if !actuable || gear.first() != Some(&1.0) || gear.iter().skip(1).any(|&g| g != 0.0) {
        warnings.unusable(format!("position actuator '{name}' (on a ball or universal joint, or with a gear)"));
        return Ok(());
    }
    if joints[index].actuator.is_some() {
        warnings.unusable(format!("position actuator '{name}' (joint '{joint}' has one already)"));
        return Ok(());
    }
    let kp = e.number("kp", 1.0)?;
    let kd = e.number("kv", 0.0)?;
    if kp < 0.0 || kd < 0.0 {
        return Err(e.error(format!("kp = {kp} and kv = {kd} must be ≥ 0")));
    }
    let limited = match e.attr("forcelimited").unwrap_or("auto") {
        "false" => false,
        _ => e.attr("forcerange").is_some(),
    };
    let max_effort = match (limited, e.fixed::<2>("forcerange")?) {
        (true, Some([lo, hi])) if lo == -hi && hi > 0.0 => Some(hi),
        (true, Some(range)) => {
            return Err(e.error(format!("forcerange {range:?}: kinloop limits effort symmetrically (−x x, x > 0)")))
        }
        _ => None,
    };
    joints[index].actuator = Some(ActuatorSpec { kp, kd, target: 0.0, max_effort });
    Ok(())
}
