//! How much of the other users' pushes each user's local model takes from its snapshot's bias.
//!
//! A user's b̂ carries what moves its OP besides its own hand, the other users' hands above all, so that its
//! device feels them push (without them the others reach it only through the pull toward the VE, and on the
//! testbed 2 to 16 users sharing `link2` track 5-10 times worse at zero delay: 1.4-1.5 mm RMS against
//! 0.15-0.2). But those pushes arrive a round trip late, and each hand answers what its device does: user
//! i's hand moves user j's model a round trip later, whose hand answers at once and moves i's a round trip
//! after that. With N users that exchange has N − 1 times the gain of one hand on its own model, and with
//! delay it is a loop: the delayed hands' damping outweighs each user's own. Measured on the testbed's one
//! OP (soft and firm touring hands, `paper` devices, the same delay both ways; "unstable" = devices
//! saturated most of the time): two users were stable to 50 ms one way and unstable from 100 ms; four from
//! 20 ms; sixteen from 4 ms of uplink delay alone. The four-bar's coupler and crank tip, two users on two
//! OPs, were unstable at 20 ms: the exchange goes through the loops too, so it counts every pushing user.
//!
//! So the others' share of b̂ is weighted by `w = min(1, g / (N − 1))`, which holds the exchange's gain
//! `(N − 1) w` at `g = exchange delay / round trip` (`VeConfig::exchange_delay_s`, [`EXCHANGE_DELAY_S`] by
//! default). A fixed gain below one does not do: two users on the testbed at 100 ms one way with a gain of
//! 0.5 or 0.25 no longer saturated, but their hands absorbed 0.07-0.3 J the system had made (the energy
//! growth of `kinloop experiment`'s criterion), while with the others' hands left out none was made at any
//! delay, and tracking was no worse from 50 ms on (3.5 mm RMS at 100 ms against 4.8 with half of them; 9.3
//! against 9.0 at 300 ms). The whole push is kept only while the round trip is short enough that the loop's
//! phase cannot turn: a gain of 1 at 10 ms (the Watt six-bar's light `link5` took a gain of 1 only below a
//! 40 ms round trip), 2.5 at 4 ms. The round trip is the longest of the pushing users' (`round_trip`), plus
//! what the jitter buffer holds their uplinks, since every pair's exchange is a loop through both; one not
//! measured yet counts as long. What the weight removes still reaches each user through the VE, which its
//! model is kept on (`kinloop_client::core::sync`), as a correction of its state rather than a force.

/// The round trip (s) up to which one other user's hands are taken whole (`VeConfig::exchange_delay_s`'s
/// default); shorter round trips allow proportionally more users.
pub const EXCHANGE_DELAY_S: f64 = 0.010;

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

    const D: f64 = EXCHANGE_DELAY_S;

    #[test]
    fn the_exchange_gain_falls_with_the_round_trip() {
        // Alone: nothing to weight.
        assert_eq!(others_weight(0, None, D), 1.0);
        // One other user over a LAN, or the same process, keeps the whole push ...
        assert_eq!(others_weight(1, Some(0.002), D), 1.0);
        assert_eq!(others_weight(1, Some(0.0), D), 1.0);
        // ... over 100 ms, a tenth of it; unmeasured, none.
        assert!((others_weight(1, Some(0.1), D) - 0.1).abs() < 1e-12);
        assert_eq!(others_weight(3, None, D), 0.0);
        // Fifteen others over 4 ms: a gain of 2.5 shared among them.
        assert!((others_weight(15, Some(0.004), D) * 15.0 - 2.5).abs() < 1e-12);
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
