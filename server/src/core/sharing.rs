//! How much of the other users' pushes each user's local model takes from its snapshot's bias.
//!
//! A user's b̂ carries what moves its OP besides its own hand, the other users' hands above all, so that its
//! device feels them push (without them the others reach it only through the pull toward the VE). But those
//! pushes arrive a round trip late, and each hand answers what its device does: user i's hand moves user j's
//! model a round trip later, whose hand answers at once and moves i's a round trip after that. With N users
//! that exchange has N − 1 times the gain of one hand on its own model, and with delay it is a loop: the
//! delayed hands' damping can outweigh each user's own. The exchange goes through the linkage's loops too, so
//! it counts every pushing user, on any OP.
//!
//! So the others' share of b̂ is weighted by `w = min(1, g / (N − 1))`, which holds the exchange's gain
//! `(N − 1) w` at `g = exchange delay / round trip` (`VeConfig::exchange_delay_s`, [`EXCHANGE_DELAY_S`] by
//! default). The whole push is kept only while the round trip is short enough that the loop's phase cannot
//! turn; a fixed gain below one would still let the delayed hands make energy that the hands must absorb.
//! The round trip is the longest of the pushing users' (`round_trip`), plus what the jitter buffer holds
//! their uplinks, since every pair's exchange is a loop through both; one not measured yet counts as long.
//! What the weight removes still reaches each user through the VE, which its model is kept on (the client's
//! pull toward each snapshot), as a correction of its state rather than a force.
//!
//! **The load the others no longer carry.** On a linkage under a steady load (gravity) the hands hold it
//! together; a model that takes only `w` of the others' hands would have its own hand hold what the others'
//! hands held in the VE, and the VE, pushed by every hand whole, sits above every model: a steady
//! discrepancy that the pull toward the VE corrects on and on, pumping energy the hands soak up. So each
//! user's b̂ carries its share of the OP's acceleration without any hand (the load), `s = (1 + w (N − 1)) / N`
//! of it: at `w = 1` all of it, at `w = 0` a 1/N share, and with every hand holding an equal share a model at
//! rest stays at rest for any w ([`shared_bias`]).
//!
//! **The others' hands' inertia.** A hand's sensed wrench carries its own mass's reaction, so the others'
//! hands in b̂ feed each device's acceleration back to the others, through the OP's mobility Λ̂⁻¹; light OPs
//! that the mapping scales up make that loop's gain large even without delay. The weight is also held to
//! [`INERTIAL_EXCHANGE_GAIN`] over that loop's gain, `(N − 1) m_hand c_p / c_f max(Λ̂⁻¹_linear)` with a hand
//! of [`HAND_MASS_KG`] mapped into the VE ([`inertial_weight`]).

use kinloop_linkage::math::space::VecOps;

/// The round trip (s) up to which one other user's hands are taken whole (`VeConfig::exchange_delay_s`'s
/// default); shorter round trips allow proportionally more users. Long enough that sixteen users over a LAN
/// (a round trip of a millisecond or so, the jitter buffer's hold included) take one another whole: hands
/// that tour one OP a few milliseconds apart, weighted down, meet each other as corrections of their models'
/// state rather than as forces, and their devices stray from the OP for it. The sharing sweep of `kinloop
/// experiment users` (2-16 users, 0-1000 ms one way) is the check that it stays stable.
pub const EXCHANGE_DELAY_S: f64 = 0.020;

/// The mass of a grasping hand that rides on a handle (kg, device space), within the simulated grasps'.
pub const HAND_MASS_KG: f64 = 0.6;
/// The largest gain allowed to the loop of the others' hands' inertia through the OP (see the module
/// documentation): low enough that devices sharing a light OP do not chatter at their limits, high enough
/// that the users still feel each other push.
pub const INERTIAL_EXCHANGE_GAIN: f64 = 12.0;

/// The largest weight of the others' hands that keeps the loop of their inertia through the OP at
/// [`INERTIAL_EXCHANGE_GAIN`]: `others` other users push an OP of largest linear mobility
/// `linear_mobility` (the largest diagonal entry of Λ̂⁻¹'s linear block, 1/kg in VE units) for a user whose
/// mapping has scales `position_scale` and `force_scale` (a device-space mass m is `m c_p / c_f` in the VE).
pub fn inertial_weight(others: usize, linear_mobility: f64, position_scale: f64, force_scale: f64) -> f64 {
    let gain = others as f64 * HAND_MASS_KG * position_scale / force_scale * linear_mobility;
    if gain.is_finite() && gain > INERTIAL_EXCHANGE_GAIN {
        INERTIAL_EXCHANGE_GAIN / gain
    } else {
        1.0
    }
}

/// A user's b̂ from the OP's acceleration under every hand (`acceleration`, `J q̈ + J̇q̇` of the probe), the
/// part of it every pushing hand makes (`hands`), the user's own (`own`, `Λ̂⁻¹ F_u`), the number of other
/// pushing users and their weight: `acceleration − own − (1 − w) (hands − own) − (1 − s) (acceleration −
/// hands)` with the load share `s = (1 + w (N − 1)) / N` (see the module documentation).
pub fn shared_bias<V: VecOps>(acceleration: &V, hands: &V, own: &V, others: usize, weight: f64) -> V {
    let mut bias = *acceleration - *own;
    if weight < 1.0 {
        let load_share = (1.0 + weight * others as f64) / (others + 1) as f64;
        bias -= (*hands - *own) * (1.0 - weight) + (*acceleration - *hands) * (1.0 - load_share);
    }
    bias
}

/// The weight of the other users' hands in a user's b̂ when `others` other users push and the longest round
/// trip among the pushing users is `round_trip_s` (`None`: not measured yet, taken as long), for the
/// exchange delay `exchange_delay_s` (see the module documentation).
pub fn others_weight(others: usize, round_trip_s: Option<f64>, exchange_delay_s: f64) -> f64 {
    if others == 0 {
        return 1.0;
    }
    let gain = match round_trip_s {
        Some(t) if t > 0.0 => exchange_delay_s / t,
        Some(_) => f64::INFINITY,
        None => 0.0,
    };
    (gain / others as f64).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn with_equal_shares_of_the_load_a_model_at_rest_stays_at_rest_whatever_the_weight() {
        // Four users on one OP of mobility 2/kg under a load of (0, -9.81, 0) m/s² (gravity, say), each hand
        // holding a quarter: the OP does not accelerate. Each model applies its own hand itself: own + b̂ = 0.
        let (users, mobility) = (4, 2.0);
        let load = Vector3::new(0.0, -9.81, 0.0);
        let share = -load / (mobility * users as f64);
        let own = share * mobility;
        let hands = own * users as f64;
        let acceleration = load + hands;
        assert!(acceleration.norm() < 1e-12);
        for weight in [1.0, 0.7, 0.25, 0.0] {
            let bias = shared_bias(&acceleration, &hands, &own, users - 1, weight);
            assert!((own + bias).norm() < 1e-12, "w {weight}: {}", own + bias);
        }
        // Without the load share, taking none of the others' hands leaves the model falling with 3/4 of it.
        let unshared = acceleration - own - (hands - own);
        assert!((own + unshared - load * 0.75).norm() < 1e-12);
        // Whole, b̂ is the OP's acceleration less the user's own hand.
        assert_eq!(shared_bias(&acceleration, &hands, &own, 3, 1.0), acceleration - own);
    }

    #[test]
    fn the_inertial_weight_holds_the_loop_gain() {
        // The four-bar's coupler for the `paper` device: mobility 0.61/kg, scales 1.37 and 0.087.
        let (mobility, cp, cf) = (0.61, 1.37, 0.087);
        let gain = |others: usize| others as f64 * HAND_MASS_KG * cp / cf * mobility;
        assert!(gain(1) < INERTIAL_EXCHANGE_GAIN, "one other user: whole");
        assert_eq!(inertial_weight(1, mobility, cp, cf), 1.0);
        let w = inertial_weight(3, mobility, cp, cf);
        assert!(w < 1.0 && (w * gain(3) - INERTIAL_EXCHANGE_GAIN).abs() < 1e-9, "{w}");
        // Nobody else, or a heavy OP: nothing to hold.
        assert_eq!(inertial_weight(0, mobility, cp, cf), 1.0);
        assert_eq!(inertial_weight(15, 1e-6, cp, cf), 1.0);
    }

    /// An exchange delay of 5 ms, whatever the default: the figures below are this rule's, not the default's.
    const D: f64 = 0.005;

    #[test]
    fn the_exchange_gain_falls_with_the_round_trip() {
        // Alone: nothing to weight.
        assert_eq!(others_weight(0, None, D), 1.0);
        // One other user over a LAN, or the same process, keeps the whole push ...
        assert_eq!(others_weight(1, Some(0.002), D), 1.0);
        assert_eq!(others_weight(1, Some(0.0), D), 1.0);
        // ... over 100 ms, a twentieth of it; unmeasured, none.
        assert!((others_weight(1, Some(0.1), D) - 0.05).abs() < 1e-12);
        assert_eq!(others_weight(3, None, D), 0.0);
        // Fifteen others over 2 ms: a gain of 2.5 shared among them.
        assert!((others_weight(15, Some(0.002), D) * 15.0 - 2.5).abs() < 1e-12);
        // An infinite exchange delay is the paper's b̂: everyone whole at any delay.
        assert_eq!(others_weight(15, Some(1.0), f64::INFINITY), 1.0);
        // The gain never grows with the delay, and never exceeds the bound.
        let mut last = f64::INFINITY;
        for ms in 1..2000 {
            let t = ms as f64 * 1e-3;
            let gain = others_weight(7, Some(t), D) * 7.0;
            assert!(gain <= last && gain <= D / t + 1e-12, "{ms} ms: {gain}");
            last = gain;
        }
    }
}
