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

/// The most rates held at once: a horizon is at most the staleness limit (0.1 s by default), a kilohertz
/// of snapshots; past this the oldest are forgotten (the held peak can then only be lower).
const CAPACITY: usize = 256;

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

    /// The weight `1 / (1 + x²)` of b̂ held for `horizon_s` (see the module documentation).
    pub fn weight(&self, horizon_s: f64) -> f64 {
        let Some((_, bias)) = self.last else { return 1.0 };
        bias_weight(self.peak_rate(horizon_s), horizon_s, bias.norm())
    }
}

/// `1 / (1 + x²)` with `x = rate · horizon / size`: one for no change, a half when b̂ changes by its own
/// size within the horizon, toward zero beyond. A zero b̂ has nothing to weigh (one); anything non-finite
/// trusts nothing (zero).
pub(crate) fn bias_weight(rate: f64, horizon_s: f64, size: f64) -> f64 {
    let change = rate * horizon_s.max(0.0);
    if change == 0.0 {
        return 1.0;
    }
    let x = change / size;
    let weight = 1.0 / (1.0 + x * x);
    if weight.is_finite() {
        weight
    } else {
        0.0
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
