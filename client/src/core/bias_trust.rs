//! How far b̂ is trusted as a feedforward: the impedance controller (`controllers::impedance_free`) asks the
//! device for `M (Λ̂⁻¹ F_h + b̂) − F_h`, with b̂ from a snapshot that is held for its age plus the one-way
//! delay and reaches the controller through the terms filter, which trails it by its time constant (the
//! *horizon* `h`, `HapticCore::bias_horizon`). A b̂ that changes over that horizon (the OP's `J̇ q̇` on a
//! linkage swinging through a limit flips at twice the swing's frequency) arrives with the wrong sign, and
//! `M b̂` then pumps the swing it came from. So b̂ is weighted by how little it changes over the horizon:
//! ```text
//! x = |ḃ| h / |b̂|,        weight = 1 / (1 + x²)  ∈ (0, 1],
//! ```
//! with `|ḃ|` taken on the VE's clock (the difference of successive snapshots' b̂ over the difference of
//! their `server_time_s`) and held at its peak over the last `h` of that clock, and the norms in
//! unit-consistent coordinates `(a, ℓ α)` (ℓ the scene's length scale). A steady b̂ (gravity on a slow
//! linkage) keeps weight one; a b̂ that changes by its own size within the horizon gets a half. The weight
//! only ever takes some of the feedforward away: the controller never asks for more than without it. It is
//! applied while the user holds the linkage alone (`HapticCore::controllers`): a shared linkage's b̂ carries
//! the other users' hands, which the server weighs by the round trip already.
//!
//! Snapshots whose server time does not advance (repeated, or out of order) are not differenced: they
//! neither divide by zero nor make a rate. A gap (lost snapshots) spreads the change over the gap.

use kinloop_linkage::algorithms::constraint_directions::scale_op;
use kinloop_linkage::math::space::{Space, VecOps};

use super::passive_update::EnergyTank;

/// Most energy the stale share of b̂'s feedforward (`BiasTrust::assess`) may put into the device
/// beyond what the hand put in against it (J at the device): a linkage's own b̂ (gravity, springs) gives back
/// what the hand stored lifting or stretching it, up to this much, while a stale one, in phase with the
/// motion it lags, would keep giving. Past it the device follows the model's pull through the position
/// channels alone. See `HapticCore::pay_bias`.
pub const BIAS_TANK_CAPACITY_J: f64 = 0.01;

/// The most rates held at once: a horizon is at most the staleness limit (0.1 s by default), a kilohertz
/// of snapshots; past this the oldest are forgotten (the held peak can then only be lower).
const CAPACITY: usize = 256;

/// The part of b̂'s feedforward `fed` (a wrench, VE units) that `tank` pays for this tick: the share
/// `at_risk` of its work on the device moving at `twist` over `dt_s`, `fed · ẋ dt`, is drawn from the tank
/// (work against it fills the tank), and what the tank cannot pay is withheld. So over any interval the
/// stale share of the feedforward gives the device at most what the hand gave back to it plus the tank's
/// capacity (see `HapticCore::pay_bias`). A fresh b̂ (`at_risk` zero) is paid in full: it carries more than
/// the linkage's own conservative forces (the VE's coupling pulling the linkage toward the device, which
/// the local model must follow), whose work no tank gets back.
pub(crate) fn paid_bias<S: Space>(
    tank: &mut EnergyTank,
    fed: &S::OpVec,
    at_risk: f64,
    twist: &S::OpVec,
    dt_s: f64,
) -> S::OpVec {
    let fraction = tank.admit(fed.dot(twist) * dt_s * at_risk);
    if fraction < 1.0 {
        *fed * fraction.max(0.0)
    } else {
        *fed
    }
}

/// b̂'s recent rate of change on the VE's clock (see the module documentation). Allocates nothing.
#[derive(Clone, Debug)]
pub(crate) struct BiasTrust<S: Space> {
    /// The newest snapshot's server time (s) and b̂ (scaled), once one has been seen.
    last: Option<(f64, S::OpVec)>,
    /// `(server time, |ḃ|)` of the rates that can still be a peak: a ring, oldest first, the rates
    /// strictly decreasing from oldest to newest (a newer, larger rate makes every older, smaller one moot).
    rates: [(f64, f64); CAPACITY],
    first: usize,
    len: usize,
}

impl<S: Space> BiasTrust<S> {
    pub fn new() -> Self {
        BiasTrust { last: None, rates: [(0.0, 0.0); CAPACITY], first: 0, len: 0 }
    }

    /// Forgets everything (a restart: the model jumps onto the VE, whose b̂ history may not follow on).
    pub fn reset(&mut self) {
        *self = BiasTrust { rates: self.rates, ..BiasTrust::new() };
    }

    fn at(&self, i: usize) -> (f64, f64) {
        self.rates[(self.first + i) % CAPACITY]
    }

    /// Takes a new snapshot's b̂ at server time `server_time_s`; `length_scale` makes its norm
    /// unit-consistent. Rates older than `keep_s` before it are dropped (no horizon is longer).
    pub fn observe(&mut self, server_time_s: f64, bias: &S::OpVec, length_scale: f64, keep_s: f64) {
        let scaled = scale_op::<S>(bias, length_scale);
        if !(server_time_s.is_finite() && scaled.is_finite()) {
            return;
        }
        if let Some((t, b)) = self.last {
            let dt = server_time_s - t;
            if dt <= 0.0 {
                // Repeated or out of order: no rate, and the newest stays the newest.
                return;
            }
            let rate = (scaled - b).norm() / dt;
            if rate.is_finite() {
                while self.len > 0 && self.at(self.len - 1).1 <= rate {
                    self.len -= 1;
                }
                if self.len == CAPACITY {
                    self.first = (self.first + 1) % CAPACITY;
                    self.len -= 1;
                }
                self.rates[(self.first + self.len) % CAPACITY] = (server_time_s, rate);
                self.len += 1;
            }
        }
        self.last = Some((server_time_s, scaled));
        while self.len > 0 && self.at(0).0 < server_time_s - keep_s {
            self.first = (self.first + 1) % CAPACITY;
            self.len -= 1;
        }
    }

    /// The peak `|ḃ|` over the last `horizon_s` of the VE's clock before the newest snapshot.
    pub fn peak_rate(&self, horizon_s: f64) -> f64 {
        let Some((newest, _)) = self.last else { return 0.0 };
        // Oldest first and decreasing: the first rate inside the horizon is its peak.
        (0..self.len).map(|i| self.at(i)).find(|(t, _)| *t >= newest - horizon_s).map_or(0.0, |(_, r)| r)
    }

    /// b̂ held for `horizon_s`, `one_way_delay_s` of it across the network: its weight `1 / (1 + x²)` (see the
    /// module documentation) and the share of it that may be stale (see [`paid_bias`]), the larger of how much
    /// of itself it changed over the horizon on the VE's clock ([`relative_change`]) and the share of the
    /// horizon spent in the network, at most one. A b̂ that crossed the network describes the pose the VE had
    /// when it was sent, which the device has since left by however far the hand took it: a rate on the VE's
    /// clock does not see that. One scan of the held rates serves both (the 1 kHz loop asks for both).
    pub fn assess(&self, horizon_s: f64, one_way_delay_s: f64) -> (f64, f64) {
        let Some((_, bias)) = self.last else { return (1.0, 0.0) };
        let (rate, size) = (self.peak_rate(horizon_s), bias.norm());
        let crossed = if horizon_s > 0.0 { one_way_delay_s.max(0.0) / horizon_s } else { 0.0 };
        (bias_weight(rate, horizon_s, size), relative_change(rate, horizon_s, size).max(crossed).min(1.0))
    }

    /// The weight of [`Self::assess`].
    #[cfg(test)]
    pub fn weight(&self, horizon_s: f64) -> f64 {
        self.assess(horizon_s, 0.0).0
    }

    /// The share at risk of [`Self::assess`].
    #[cfg(test)]
    pub fn share_at_risk(&self, horizon_s: f64, one_way_delay_s: f64) -> f64 {
        self.assess(horizon_s, one_way_delay_s).1
    }
}

/// `1 / (1 + x²)` with `x` = [`relative_change`]: one for no change, a half when b̂ changes by its own size
/// within the horizon, toward zero beyond. A zero b̂ has nothing to weigh (one); anything non-finite trusts
/// nothing (zero).
pub(crate) fn bias_weight(rate: f64, horizon_s: f64, size: f64) -> f64 {
    let x = relative_change(rate, horizon_s, size);
    let weight = 1.0 / (1.0 + x * x);
    if weight.is_finite() {
        weight
    } else {
        0.0
    }
}

/// `x = rate · horizon / size`: how much of itself b̂ may have changed over the horizon it is held (zero for
/// no change, infinite for a change of a zero b̂ or anything non-finite).
pub(crate) fn relative_change(rate: f64, horizon_s: f64, size: f64) -> f64 {
    let change = rate * horizon_s.max(0.0);
    if change == 0.0 {
        return 0.0;
    }
    let x = change / size;
    if x.is_nan() {
        f64::INFINITY
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::Vector3;

    const L: f64 = 0.1;

    /// b̂ = B cos(ω t) sampled at 1 kHz of server time: at the crest (t = 2π k / ω) the rate held over the
    /// horizon h < π / (2ω) is the largest of `B ω |sin ω s|` over `s ∈ [t − h, t]`, `B ω sin(ω h)` (closed
    /// form), so the weight is `1 / (1 + (ω sin(ω h) h)²)`, to the sampling's resolution.
    #[test]
    fn a_sinusoid_at_its_crest_is_weighted_by_its_closed_form_rate() {
        let (b, omega, horizon, dt) = (Vector3::new(3.0, -4.0, 0.0), 2.0 * std::f64::consts::PI * 14.0, 0.015, 1e-3);
        let mut trust = BiasTrust::<Planar>::new();
        let crest = 3.0 * 2.0 * std::f64::consts::PI / omega;
        let steps = (crest / dt).round() as usize;
        for k in 0..=steps {
            let t = k as f64 * dt;
            trust.observe(t, &(b * (omega * t).cos()), L, 0.1);
        }
        let t_end = steps as f64 * dt;
        assert!((omega * t_end).cos() > 0.99, "at a crest");
        let rate = b.norm() * omega * (omega * horizon).sin();
        let expected = 1.0 / (1.0 + (rate * horizon / (b.norm() * (omega * t_end).cos())).powi(2));
        let weight = trust.weight(horizon);
        // A difference quotient over 1 ms of a 14 Hz cosine: within a few per cent of the derivative.
        assert!((weight - expected).abs() < 0.03, "{weight} vs {expected}");
        assert!(weight < 0.5, "a b̂ that flips within the horizon is mostly not trusted: {weight}");
        // The longer it is held, the less it is trusted.
        assert!(trust.weight(0.03) < weight);
    }

    /// A steady b̂ (gravity) keeps weight one over any horizon; so does a b̂ that changes slowly against
    /// its size.
    #[test]
    fn a_steady_bias_keeps_weight_one() {
        let mut trust = BiasTrust::<Planar>::new();
        assert_eq!(trust.weight(0.05), 1.0, "nothing seen yet");
        for k in 0..200 {
            trust.observe(k as f64 * 1e-3, &Vector3::new(0.0, -9.81, 2.0), L, 0.1);
        }
        assert_eq!(trust.weight(0.05), 1.0);
        assert_eq!(trust.weight(0.1), 1.0);
        let mut slow = BiasTrust::<Planar>::new();
        for k in 0..200 {
            slow.observe(k as f64 * 1e-3, &Vector3::new(0.0, -9.81 + 0.01 * k as f64 * 1e-3, 0.0), L, 0.1);
        }
        assert!(slow.weight(0.05) > 1.0 - 1e-6, "{}", slow.weight(0.05));
        assert_eq!(bias_weight(0.0, 0.05, 0.0), 1.0);
        assert_eq!(bias_weight(1.0, 0.05, 0.0), 0.0, "a change of a zero b̂: x is infinite");
        assert_eq!(bias_weight(f64::NAN, 0.05, 1.0), 0.0);
        assert!((bias_weight(2.0, 0.5, 1.0) - 0.5).abs() < 1e-15);
    }

    /// b̂'s feedforward paid from its tank, against the work it does (closed forms on one axis, 1 kHz): a
    /// stale b̂ in phase with the motion (`F = A sin ωt` on a device moving at `V sin ωt`) would put
    /// `A V / 2` watts into the device; paid, it puts in no more than the tank held. A constant weight on a
    /// device moved up and back down: the way up is paid in full and fills the tank (to its capacity), and
    /// the way down is paid in full until the weight has given back what the tank holds, then withheld.
    #[test]
    fn the_tank_gives_back_what_was_stored_and_starves_a_pumping_bias() {
        let capacity = 0.01;
        let dt = 1e-3;
        let mut tank = EnergyTank::new(capacity, 1.0);
        let (amplitude, speed, omega) = (2.0, 0.1, 2.0 * std::f64::consts::PI * 3.0);
        let mut given = 0.0;
        for k in 0..10_000 {
            let t = k as f64 * dt;
            let fed = Vector3::new(amplitude * (omega * t).sin(), 0.0, 0.0);
            let twist = Vector3::new(speed * (omega * t).sin(), 0.0, 0.0);
            let paid = paid_bias::<Planar>(&mut tank, &fed, 1.0, &twist, dt);
            assert!(paid[0].abs() <= fed[0].abs() + 1e-15);
            given += paid.dot(&twist) * dt;
        }
        let unpaid = amplitude * speed / 2.0 * 10.0;
        assert!(given <= capacity * (1.0 + 1e-9), "given {given} J, unpaid it would be {unpaid} J");
        assert!(given > 0.9 * capacity, "the tank's content is given: {given}");

        // Emptied first, so that what the way down may give is what the way up stored.
        let mut tank = EnergyTank::new(capacity, 1.0);
        let (weight, speed) = (Vector3::new(0.0, -5.0, 0.0), 0.2);
        let _ = paid_bias::<Planar>(&mut tank, &weight, 1.0, &Vector3::new(0.0, -1.0, 0.0), 1.0);
        let stored_per_tick = 5.0 * speed * dt;
        for k in 0..1_000 {
            let paid = paid_bias::<Planar>(&mut tank, &weight, 1.0, &Vector3::new(0.0, speed, 0.0), dt);
            assert_eq!(paid, weight, "up, tick {k}");
        }
        let mut given_back = 0.0;
        for k in 0..1_000 {
            let down = Vector3::new(0.0, -speed, 0.0);
            let paid = paid_bias::<Planar>(&mut tank, &weight, 1.0, &down, dt);
            if (k as f64 + 1.0) * stored_per_tick <= capacity * (1.0 - 1e-9) {
                assert_eq!(paid, weight, "down, tick {k}: paid in full");
            }
            given_back += paid.dot(&down) * dt;
        }
        assert!((given_back - capacity).abs() < 1e-12, "the way down gives back the tank: {given_back}");

        // A fresh b̂ (nothing at risk) is paid in full however much it gives; a quarter at risk gives four
        // times the tank before it is withheld.
        for (at_risk, most) in [(0.0, f64::INFINITY), (0.25, 4.0 * capacity)] {
            let mut tank = EnergyTank::new(capacity, 1.0);
            let mut given = 0.0;
            for k in 0..10_000 {
                let t = k as f64 * dt;
                let fed = Vector3::new(amplitude * (omega * t).sin(), 0.0, 0.0);
                let twist = Vector3::new(speed * (omega * t).sin(), 0.0, 0.0);
                let paid = paid_bias::<Planar>(&mut tank, &fed, at_risk, &twist, dt);
                if at_risk == 0.0 {
                    assert_eq!(paid, fed, "tick {k}");
                }
                given += paid.dot(&twist) * dt;
            }
            let unpaid = amplitude * speed / 2.0 * 10.0;
            assert!(given <= most * (1.0 + 1e-9) && given > 0.9 * most.min(unpaid), "at risk {at_risk}: {given} J");
        }
    }

    /// The share at risk: b̂'s change over the horizon relative to itself, or the share of the horizon spent
    /// in the network, whichever is larger, at most one; nothing before any b̂.
    #[test]
    fn the_share_at_risk_is_the_change_over_the_horizon_or_the_network_share() {
        let mut trust = BiasTrust::<Planar>::new();
        assert_eq!(trust.share_at_risk(0.05, 0.05), 0.0, "no b̂ yet");
        let b = |y: f64| Vector3::new(0.0, y, 0.0);
        // |b̂| 10 changing at 20 per second: over 10 ms a fiftieth of itself, over 0.1 s a fifth.
        for k in 0..=100 {
            trust.observe(1.0 + k as f64 * 1e-3, &b(-10.0 - 0.02 * (k % 2) as f64), L, 0.2);
        }
        assert!((trust.share_at_risk(0.01, 0.0) - 0.02).abs() < 1e-9, "{}", trust.share_at_risk(0.01, 0.0));
        assert!((trust.share_at_risk(0.1, 0.0) - 0.2).abs() < 1e-9);
        assert!((trust.share_at_risk(0.01, 0.005) - 0.5).abs() < 1e-12, "half the horizon in the network");
        assert_eq!(trust.share_at_risk(0.1, 0.5), 1.0, "at most one");
        assert!((trust.share_at_risk(0.1, 0.01) - 0.2).abs() < 1e-9, "the change is the larger");
    }

    /// Rates are taken on the server's clock: a repeated server time or one that goes back makes no rate
    /// (no division by zero, no rate inflated by a tiny or negative interval), a gap spreads the change over
    /// the gap, and a rate older than the horizon stops counting.
    #[test]
    fn repeated_or_out_of_order_server_times_make_no_rate() {
        let mut trust = BiasTrust::<Planar>::new();
        let b = |y: f64| Vector3::new(0.0, y, 0.0);
        trust.observe(1.000, &b(-9.0), L, 0.1);
        trust.observe(1.000, &b(-1.0), L, 0.1);
        assert_eq!(trust.peak_rate(0.05), 0.0, "the same server time twice");
        trust.observe(0.999, &b(-2.0), L, 0.1);
        assert_eq!(trust.peak_rate(0.05), 0.0, "going back");
        // A 10 ms gap: the change over the gap, from the newest b̂ kept (-9, not the repeated -1).
        trust.observe(1.010, &b(-8.0), L, 0.1);
        assert!((trust.peak_rate(0.05) - 100.0).abs() < 1e-9, "{}", trust.peak_rate(0.05));
        // Held over the horizon, then forgotten once older than it.
        trust.observe(1.011, &b(-8.0), L, 0.1);
        assert!((trust.peak_rate(0.005) - 100.0).abs() < 1e-9);
        trust.observe(1.020, &b(-8.0), L, 0.1);
        assert_eq!(trust.peak_rate(0.005), 0.0);
        assert!((trust.peak_rate(0.05) - 100.0).abs() < 1e-9, "still within a longer horizon");
        trust.observe(f64::NAN, &b(5.0), L, 0.1);
        trust.observe(1.021, &Vector3::new(f64::INFINITY, 0.0, 0.0), L, 0.1);
        assert!(trust.peak_rate(0.05).is_finite());
        trust.reset();
        assert_eq!(trust.weight(0.05), 1.0);
    }
}
