//! Deadline misses judged against the timer floor as what they are: counts of rare events. A ten-second run
//! at 1 kHz on a quiet machine misses a handful of ticks, and the idle loop beside it as few, so the ratio of
//! the two counts moves tenfold between runs a minute apart without the server changing. A goal such as
//! "misses within 1.5x the idle loop's" is decided only when the interval of the ratio of the two rates lies
//! wholly on one side of the bound.
//!
//! **The interval.** Misses are counted as Poisson events over `n` ticks. Given `k₁` misses in `n₁` ticks and
//! `k₂` in `n₂`, conditional on their sum `k = k₁ + k₂` the first count is binomial, `k₁ ~ Bin(k, π)` with
//! `π = n₁ R / (n₁ R + n₂)`, where `R = r₁ / r₂` is the ratio of the rates (the conditional method for a
//! rate ratio, exact in that it never covers less than its level). The Clopper–Pearson interval of `π` maps
//! monotonically onto `R = π n₂ / ((1 − π) n₁)`.
//!
//! **What it assumes.** Independent misses. Each loop counts a miss per late wake-up, not per tick a stall
//! spans (the idle loop skips the deadlines it slept through, the VE runs the ticks due in one iteration), and
//! capacity counts stalls beside misses (runs of late wake-ups, one each) to show it. What stays dependent is
//! the rooms: a stall of an executor thread is a miss in every room on it at once, so pooled over rooms the
//! counts spread more than Poisson counts do and that interval is narrower than the truth; a single room's
//! count (the worst room's ratio) has no such dependence.

use serde::{Deserialize, Serialize};

/// Two-sided level of the intervals.
pub const CONFIDENCE: f64 = 0.95;

/// How a measured rate ratio stands against a bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decision {
    /// The whole interval is at or under the bound: the goal is met.
    Within,
    /// The whole interval is above the bound: the goal is missed.
    Beyond,
    /// The interval straddles the bound: the run was too short (too few events) to tell.
    Undecided,
}

/// The ratio of two event rates with its interval at [`CONFIDENCE`], judged against a bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RateRatio {
    /// Events counted in the measured run, and its ticks.
    pub events: u64,
    /// Ticks of the measured run.
    pub ticks: u64,
    /// Events counted in the reference run (the idle loop), and its ticks.
    pub reference_events: u64,
    /// Ticks of the reference run.
    pub reference_ticks: u64,
    /// `(k₁/n₁) / (k₂/n₂)`; `None` when the reference counted nothing.
    pub ratio: Option<f64>,
    /// Lower end of the interval.
    pub low: f64,
    /// Upper end; `None` when unbounded (the reference counted nothing).
    pub high: Option<f64>,
    /// The bound judged against.
    pub bound: f64,
    /// Where the interval lies against the bound.
    pub decision: Decision,
}

impl RateRatio {
    /// `events` in `ticks` against `reference_events` in `reference_ticks`, judged against `bound`.
    pub fn new(events: u64, ticks: u64, reference_events: u64, reference_ticks: u64, bound: f64) -> Self {
        let (n1, n2) = (ticks.max(1) as f64, reference_ticks.max(1) as f64);
        let (pi_low, pi_high) = clopper_pearson(events, events + reference_events, 1.0 - CONFIDENCE);
        let to_ratio = |pi: f64| if pi >= 1.0 { f64::INFINITY } else { pi * n2 / ((1.0 - pi) * n1) };
        let (low, high) = (to_ratio(pi_low), to_ratio(pi_high));
        let decision = if high <= bound {
            Decision::Within
        } else if low > bound {
            Decision::Beyond
        } else {
            Decision::Undecided
        };
        let finite = |x: f64| Some(x).filter(|x| x.is_finite());
        RateRatio {
            events,
            ticks,
            reference_events,
            reference_ticks,
            ratio: finite((events as f64 / n1) / (reference_events as f64 / n2)),
            low,
            high: finite(high),
            bound,
            decision,
        }
    }

    /// One line for answers and tables: `0.8x (0.3-2.1, undecided)`.
    pub fn describe(&self) -> String {
        let num = |x: Option<f64>| x.map_or("∞".to_string(), |x| format!("{x:.2}"));
        let decision = match self.decision {
            Decision::Within => format!("within {}x", self.bound),
            Decision::Beyond => format!("beyond {}x", self.bound),
            Decision::Undecided => "undecided".to_string(),
        };
        format!("{}x ({}-{}, {decision})", num(self.ratio), num(Some(self.low)), num(self.high))
    }
}

/// The Clopper–Pearson interval of a binomial proportion from `successes` in `trials`, at level `1 − alpha`
/// two-sided: `[p_L, p_U]` with `P(X ≥ k | p_L) = α/2` and `P(X ≤ k | p_U) = α/2`, `p_L = 0` at `k = 0` and
/// `p_U = 1` at `k = n`. No trials say nothing: `[0, 1]`.
pub fn clopper_pearson(successes: u64, trials: u64, alpha: f64) -> (f64, f64) {
    let (k, n) = (successes.min(trials), trials);
    let tail = alpha / 2.0;
    let low = if k == 0 { 0.0 } else { bisect(|p| 1.0 - binomial_cdf(k - 1, n, p) - tail) };
    let high = if k == n { 1.0 } else { bisect(|p| tail - binomial_cdf(k, n, p)) };
    (low, high)
}

/// The root in (0, 1) of an increasing function by bisection, to double precision's resolution of p.
fn bisect(f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `P(X ≤ k)` for `X ~ Bin(n, p)`, summed in logarithms so that thousands of trials neither underflow nor
/// overflow.
pub fn binomial_cdf(k: u64, n: u64, p: f64) -> f64 {
    if k >= n || p <= 0.0 {
        return 1.0;
    }
    if p >= 1.0 {
        return 0.0;
    }
    let (ln_p, ln_q) = (p.ln(), (-p).ln_1p());
    // A running log-sum-exp of the terms `ln C(n, i) + i ln p + (n − i) ln q`.
    let (mut ln_choose, mut top, mut sum) = (0.0f64, f64::NEG_INFINITY, 0.0f64);
    for i in 0..=k {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        let term = ln_choose + i as f64 * ln_p + (n - i) as f64 * ln_q;
        if term > top {
            sum = sum * (top - term).exp() + 1.0;
            top = term;
        } else {
            sum += (term - top).exp();
        }
    }
    (top + sum.ln()).exp().min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The binomial CDF against direct sums of `C(n, i) pⁱ qⁿ⁻ⁱ` on small cases, and on a large one (where
    /// direct sums in floating point underflow) against its complement by symmetry
    /// (`P(X ≤ k | p) = 1 − P(X ≤ n−k−1 | 1−p)`) and an exact rational sum.
    #[test]
    fn the_binomial_cdf_matches_direct_sums_and_its_symmetry() {
        let choose = |n: u64, i: u64| (0..i).fold(1.0, |c, j| c * (n - j) as f64 / (j + 1) as f64);
        for &(k, n, p) in &[(0u64, 5u64, 0.3f64), (2, 5, 0.3), (4, 10, 0.55), (9, 10, 0.9)] {
            let direct: f64 = (0..=k).map(|i| choose(n, i) * p.powi(i as i32) * (1.0 - p).powi((n - i) as i32)).sum();
            assert!((binomial_cdf(k, n, p) - direct).abs() < 1e-12, "k {k} n {n} p {p}");
        }
        let (k, n, p) = (480u64, 2000u64, 0.25f64);
        let sum = binomial_cdf(k, n, p) + binomial_cdf(n - k - 1, n, 1.0 - p);
        assert!((sum - 1.0).abs() < 1e-9, "{sum}");
        // The same sum in exact rational arithmetic (Python's `fractions`, `math.comb`): 0.15695182026602458.
        assert!((binomial_cdf(k, n, p) - 0.156_951_820_266_024_58).abs() < 1e-9, "{}", binomial_cdf(k, n, p));
    }

    /// At the edges the interval has closed forms: `k = 0` gives `[0, 1 − (α/2)^(1/n)]`, `k = n` gives
    /// `[(α/2)^(1/n), 1]`; inside, the bounds solve their tail equations.
    #[test]
    fn the_clopper_pearson_interval_has_its_closed_forms_at_the_edges() {
        let alpha = 0.05;
        let (lo, hi) = clopper_pearson(0, 10, alpha);
        assert_eq!(lo, 0.0);
        assert!((hi - (1.0 - 0.025f64.powf(0.1))).abs() < 1e-12, "{hi}");
        let (lo, hi) = clopper_pearson(10, 10, alpha);
        assert!((lo - 0.025f64.powf(0.1)).abs() < 1e-12, "{lo}");
        assert_eq!(hi, 1.0);
        let (lo, hi) = clopper_pearson(3, 20, alpha);
        assert!((1.0 - binomial_cdf(2, 20, lo) - 0.025).abs() < 1e-9);
        assert!((binomial_cdf(3, 20, hi) - 0.025).abs() < 1e-9);
        assert!(lo < 0.15 && 0.15 < hi);
    }

    /// Few events decide nothing, many decide: 9 misses in 12,000 ticks against 11 in 10,000 (0.68x) straddle
    /// 1.5x; a hundredfold longer run at the same rates lies under it; 3 % against 1 % lies above.
    #[test]
    fn a_ratio_is_decided_only_when_its_interval_lies_on_one_side_of_the_bound() {
        let few = RateRatio::new(9, 12_000, 11, 10_000, 1.5);
        assert!((few.ratio.unwrap() - 0.6818).abs() < 1e-3);
        assert_eq!(few.decision, Decision::Undecided, "{}", few.describe());
        // The same intervals computed apart (Python: binomial sums in log-gamma terms, bisection).
        assert!((few.low - 0.249_730_604_967).abs() < 1e-6 && (few.high.unwrap() - 1.809_835_494_446).abs() < 1e-6);
        let many = RateRatio::new(900, 1_200_000, 1_100, 1_000_000, 1.5);
        assert_eq!(many.decision, Decision::Within, "{}", many.describe());
        let worse = RateRatio::new(300, 10_000, 100, 10_000, 1.5);
        assert_eq!(worse.decision, Decision::Beyond, "{}", worse.describe());
        assert!((worse.low - 2.384_762_330_179).abs() < 1e-6 && (worse.high.unwrap() - 3.800_733_398_087).abs() < 1e-6);
        // A reference that counted nothing bounds the ratio from below only.
        let unbounded = RateRatio::new(2, 10_000, 0, 10_000, 1.5);
        assert_eq!((unbounded.ratio, unbounded.high, unbounded.decision), (None, None, Decision::Undecided));
    }

    /// The interval covers the true ratio at least at its level: simulated pairs of Poisson counts (by a
    /// seeded generator, rates 2e-3 and 1e-3 over 10,000 ticks each) fall outside it in at most 5 % of trials.
    #[test]
    fn the_ratio_interval_covers_the_true_ratio_at_its_level() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // Knuth's multiplication method: fine for means of tens.
        let mut poisson = |mean: f64| {
            let (limit, mut product, mut count) = ((-mean).exp(), 1.0, 0u64);
            loop {
                product *= uniform();
                if product <= limit {
                    return count;
                }
                count += 1;
            }
        };
        let trials = 2000;
        let missed = (0..trials)
            .filter(|_| {
                let r = RateRatio::new(poisson(20.0), 10_000, poisson(10.0), 10_000, 1.5);
                !(r.low <= 2.0 && r.high.is_none_or(|h| 2.0 <= h))
            })
            .count();
        assert!(missed as f64 <= 0.05 * trials as f64, "{missed} of {trials}");
    }
}
