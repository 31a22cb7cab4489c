//! The floor on the coupling's damping that the OP's modes along its path ask for (see `design`'s module
//! documentation, "The coupling").

use kinloop_linkage::algorithms::reach::{percentile_90, OpReach};
use kinloop_linkage::math::space::Space;

/// The damping ratio the coupling keeps at least on the OP's modes along its path (`path_damping`), on a
/// linkage of one degree of freedom. The stiffness is designed on the OP's lightest mass, but along the path
/// the OP can be many times heavier, and the linkage's own forces at rest (a wound spring, an actuator's PD,
/// gravity through the loops) can hold it several times more stiffly than the coupling does: a damper sized
/// on the lightest mass leaves those modes barely damped (a crank held against a wound spring, with a heavy
/// slider on it), and the loop through the client's model sets them ringing until the device saturates. A
/// damper adds no stiffness and only dissipates, and the VE's coupling is linearly implicit, so a larger one
/// keeps both the port passive and the step stable. Twice critical: measured on the tuning seeds of the
/// robustness grid, critical damping rendered fewer sessions and three times critical made more of them newly
/// unstable (`docs/robustness.md`).
pub const PATH_DAMPING_RATIO: f64 = 2.0;

/// The damping (N·s/m) the OP's modes along its path ask of the coupling's linear axes, whose stiffness is
/// `stiffness`: at each pose of the path (`OpReach::path_modes`), the damper that puts
/// [`PATH_DAMPING_RATIO`] on the OP's inertia there against the coupling's spring and the linkage's own
/// forces at rest, `2 ζ √(m (K + K_rest))` (a hill, `K_rest < 0`, counts as none); the 90th percentile over
/// the poses, since next to a dead point the inertia along the path grows without bound. Zero without a
/// path (a linkage of more degrees of freedom, a swing).
pub(super) fn path_damping<S: Space>(reach: &OpReach<S>, stiffness: f64) -> f64 {
    let mut needed: Vec<f64> = reach
        .path_modes
        .iter()
        .map(|m| 2.0 * PATH_DAMPING_RATIO * (m.mass * (stiffness + m.rest_stiffness.max(0.0))).sqrt())
        .filter(|b| b.is_finite())
        .collect();
    percentile_90(&mut needed)
}
