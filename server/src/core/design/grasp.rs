//! The grasp rule (see the parent module, "The grasp"): where a force scale that pins the grasp rises to the
//! one that holds the OP rigidly.
//!
//! On a device that renders torque the user holds the OP rigidly when the OP's lightest rotational inertia,
//! times the torque scale `c_f c_p`, is within what the device can be made to feel (`renders_rotation`);
//! otherwise as through a pin, and the coupling then holds only the OP's translation. A load that sets a small
//! `c_f` (a position actuator's pull far from its target) does two things at once: the
//! grasp falls to a pin and the hand's force, divided by `c_f`, grows in the VE. Along the linkage's motion
//! at a pose where the OP moves by `(v, ω)` per unit of the motion, a rigid coupling holds it with
//! `K_t |v|² + K_r |ω|²` and a pin with `K_t |v|²` alone; the gains' ratio is the OP's
//! `r_g² = K_r / K_t = I / m` (lightest inertia and mass), so the pin keeps the share `r² / (r² + r_g²)`, with
//! `r = |v| / |ω|` the OP's turning radius there (`OpReach::turning_radius_min_m`). An OP on a link that turns
//! about a fixed pivot (a crank's tip) has `r = r_g` at every pose: the pin keeps half the hold, alike over the
//! whole reach, and holding the OP's position holds the link. Where `r < r_g` the OP moves more by turning than
//! by translating in the coupling's own measure (a coupler point near its instant centre, the far end of a
//! coupler's curve), the pin loses most of the hold there, and under delay a hand pulling toward the far side
//! of the turn drives the VE's linkage round it before the local model and the device (heavy in the VE's
//! units, `M c_p / c_f`) follow. So there ([`moves_by_turning`]) the scale rises to the smallest that holds the
//! OP rigidly ([`held_rigidly`]), where the device can carry what a rigid grasp of that OP asks of it: the
//! static load within its continuous force (the load rule's bound), and within its peak torque (it publishes
//! no continuous one) the static torque and the torque that turns the handle with the OP
//! ([`rigid_grasp_torque`]). Held rigidly, the OP's angle is the handle's, so a hand that only carries the
//! handle along the OP's path turns it as the OP turns: at a pace `v` (device m/s) where the OP turns about
//! its instant centre at `r_min`, `c_p r_min` on the device, the handle turns at `ω = v / (c_p r_min)`. A point
//! passing a fixed centre at distance `r` on a straight line turns by `θ = atan(s / r)`, whose angular
//! acceleration at a steady pace is largest at `s = r / √3`: `(3√3 / 8) v² / r²`. What it turns is the
//! handle's rotational inertia and the OP's as the device renders it (a quarter of the handle's at the rigid
//! scale: whoever supplies the OP's part, it passes through the handle), so
//! ```text
//! τ = τ_static c_f c_p + (1 + 1 / MASS_REDUCTION) I_handle (3√3 / 8) (v / (c_p r_min))²  ≤  τ_peak
//! ```
//! with `v` = [`HAND_PACE_M_S`], a relaxed pace. Near an instant centre the turning part grows as
//! `1 / r_min²` and outgrows the peak: there a rigid grasp would ask the device for more torque than it has
//! (clamped ticks, its controllers fighting the hand's turn of the handle), and the pin stays. A crank's tip
//! turns about the crank's pivot at the crank's length, at a steady rate where the pace is steady; the bound
//! takes the worst turn for its radius alike.

use kinloop_linkage::algorithms::reach::OpReach;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::DeviceCaps;

/// Relative margin below which the OP's smallest turning radius counts as its coupling's `r_g`: an OP on a link
/// about a fixed pivot has the two equal, computed from eq 9's Λ⁻¹ at different poses (round-off).
const TURNING_ROUND_OFF: f64 = 1e-6;

/// Whether the OP somewhere moves more by turning than by translating, weighed by the coupling's gains (module
/// documentation, "The grasp"): its smallest turning radius below `r_g = √(I / m)`, the ratio of its lightest
/// rotational inertia and mass (the coupling's `K_r / K_t`). An OP that never turns does not; one that only
/// turns (no translational coupling) does.
pub(super) fn moves_by_turning<S: Space>(reach: &OpReach<S>) -> bool {
    let (mass, inertia) = lightest(reach);
    if !inertia.is_finite() {
        return false;
    }
    if !mass.is_finite() {
        return true;
    }
    reach.turning_radius_min_m < (inertia / mass).sqrt() * (1.0 - TURNING_ROUND_OFF)
}

/// A relaxed pace of the hand carrying the handle (device m/s), the one the rigid grasp's torque is judged at
/// (module documentation): the simulated touring hand's (`kinloop_client::user::hand`).
pub(super) const HAND_PACE_M_S: f64 = 0.04;

/// Largest angular acceleration of a point passing a fixed centre on a straight line, at unit pace and unit
/// distance: `θ = atan(s)`, `θ'' = −2 s / (1 + s²)²`, largest in magnitude at `s = 1 / √3`, `3√3 / 8`.
pub(super) const PASSING_TURN: f64 = 0.649_519_052_838_329;

/// The peak torque (device N m) a rigid grasp of the OP asks of the device at `position_scale` and
/// `force_scale` (module documentation): the static torque mapped, plus the handle's and the OP's rendered
/// rotational inertia turned as a hand at [`HAND_PACE_M_S`] carries the handle past the OP's nearest instant
/// centre, `(I_handle + I_op c_f c_p) (3√3 / 8) (v / (c_p r_min))²`. Infinite for an OP at its instant centre
/// (it turns without translating).
pub(super) fn rigid_grasp_torque<S: Space>(
    reach: &OpReach<S>,
    device: &DeviceCaps,
    position_scale: f64,
    force_scale: f64,
) -> f64 {
    let (_, inertia) = lightest(reach);
    let torque_scale = force_scale * position_scale;
    let rate = HAND_PACE_M_S / (position_scale * reach.turning_radius_min_m);
    let turning = (handle_inertia::<S>(device) + inertia * torque_scale) * PASSING_TURN * rate * rate;
    reach.static_torque_nm * torque_scale + turning
}

/// The force scale `force_scale` raised, on a device that renders torque, to the smallest that holds the OP
/// rigidly (`renders_rotation`: `c_f = I_handle / (MASS_REDUCTION · I_op · c_p)`), where the pin would lose
/// most of the coupling's hold ([`moves_by_turning`]) and the device can carry what a rigid grasp asks at that
/// scale: the static load within its continuous force (the load rule, `check_holdable`) and the torque of
/// [`rigid_grasp_torque`] within its peak torque (it publishes no continuous one). Unchanged otherwise (a
/// scale already rigid, an OP whose translation carries its motion, an OP too light in rotation to hold
/// rigidly within the device's force, one that turns too near its instant centre for the device's torque, a
/// device that renders no torque).
pub(super) fn held_rigidly<S: Space>(
    reach: &OpReach<S>,
    device: &DeviceCaps,
    position_scale: f64,
    force_scale: f64,
) -> f64 {
    let (_, inertia) = lightest(reach);
    let handle = handle_inertia::<S>(device);
    let applies = device.max_torque_nm > 0.0 && inertia > 0.0 && position_scale > 0.0 && moves_by_turning(reach);
    if !applies {
        return force_scale;
    }
    let rigid = handle / (MASS_REDUCTION * inertia * position_scale);
    let holds_force = reach.static_force_n * rigid <= device.continuous_force_n;
    let holds_torque = rigid_grasp_torque(reach, device, position_scale, rigid) <= device.max_torque_nm;
    if force_scale < rigid && holds_force && holds_torque {
        // A hair above, so that `renders_rotation`'s product, rounded, is not a hair below the handle's.
        rigid * (1.0 + 1e-12)
    } else {
        force_scale
    }
}

/// The lightest effective masses of the reach: translational (kg) and rotational (kg m²); infinite where
/// the OP does not move at all.
pub(super) fn lightest<S: Space>(reach: &OpReach<S>) -> (f64, f64) {
    let inverse = |x: f64| if x > 0.0 { 1.0 / x } else { f64::INFINITY };
    (inverse(reach.inverse_mass_max), inverse(reach.inverse_rotational_inertia_max))
}

/// Largest factor by which a device can be made to feel lighter than it is (the client's impedance
/// control bound, `MAX_MASS_REDUCTION` there).
pub(super) const MASS_REDUCTION: f64 = 4.0;

/// Whether the user holds the OP rigidly: the device renders torque, and the OP's lightest rotational
/// inertia, seen on the device (times the torque scale), is within what the device can be made to feel.
/// Otherwise the OP is held as through a pin: an OP whose rotational inertia on the device is far below the
/// handle's own (a serial arm's tip) turns faster than any controller of the handle can follow, and under
/// delay its angular loop runs away.
pub(super) fn renders_rotation<S: Space>(reach: &OpReach<S>, device: &DeviceCaps, torque_scale: f64) -> bool {
    let (_, inertia) = lightest(reach);
    device.max_torque_nm > 0.0 && inertia * torque_scale * MASS_REDUCTION >= handle_inertia::<S>(device)
}

/// The handle's rotational inertia (kg m²): the device's first angular mass, zero if it has none.
pub(super) fn handle_inertia<S: Space>(device: &DeviceCaps) -> f64 {
    device.mass.get(<S::Point as VecOps>::LEN).copied().unwrap_or(0.0)
}
