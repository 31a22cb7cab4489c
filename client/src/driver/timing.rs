//! The loop's own timing, measured where it happens: a preallocated histogram of lateness (how long after
//! its absolute deadline each tick started) that the real-time thread updates with relaxed atomics (no lock,
//! no allocation) and any other thread reads.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Ticks starting more than this late are deadline misses.
pub const MISS_THRESHOLD_US: u64 = 500;

/// 1 µs buckets up to this; later ticks land in the overflow bucket (their exact maximum is kept apart).
const FINE_BUCKETS_US: usize = 20_000;

/// Lateness histogram and counters.
#[derive(Debug)]
pub struct LatenessHistogram {
    buckets: Box<[AtomicU64]>,
    overflow: AtomicU64,
    max_ns: AtomicU64,
    ticks: AtomicU64,
    misses: AtomicU64,
    stalls: AtomicU64,
    /// Whether the last tick recorded was a miss (a stall's later misses are not new stalls).
    last_missed: AtomicBool,
}

impl Default for LatenessHistogram {
    fn default() -> Self {
        LatenessHistogram {
            buckets: (0..FINE_BUCKETS_US).map(|_| AtomicU64::new(0)).collect(),
            overflow: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
            ticks: AtomicU64::new(0),
            misses: AtomicU64::new(0),
            stalls: AtomicU64::new(0),
            last_missed: AtomicBool::new(false),
        }
    }
}

/// A summary of a [`LatenessHistogram`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LatenessSummary {
    /// Ticks recorded.
    pub ticks: u64,
    /// Median lateness (µs).
    pub p50_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Largest (µs).
    pub max_us: f64,
    /// Ticks more than [`MISS_THRESHOLD_US`] late.
    pub misses: u64,
    /// Runs of consecutive missed ticks: one host stall that makes several ticks late counts once, so that
    /// stalls, unlike misses, come one at a time (what a rate's interval assumes).
    pub stalls: u64,
}

impl LatenessHistogram {
    /// Records one tick's lateness (called on the real-time thread).
    pub fn record(&self, lateness_ns: u64) {
        let us = (lateness_ns / 1000) as usize;
        match self.buckets.get(us) {
            Some(bucket) => bucket.fetch_add(1, Ordering::Relaxed),
            None => self.overflow.fetch_add(1, Ordering::Relaxed),
        };
        self.max_ns.fetch_max(lateness_ns, Ordering::Relaxed);
        self.ticks.fetch_add(1, Ordering::Relaxed);
        let missed = us as u64 > MISS_THRESHOLD_US;
        if missed {
            self.misses.fetch_add(1, Ordering::Relaxed);
        }
        // A run of misses is one stall (`kinloop_process::realtime::StallRuns`, kept here in an atomic as
        // the histogram is shared).
        let missed_before = self.last_missed.swap(missed, Ordering::Relaxed);
        if missed && !missed_before {
            self.stalls.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Percentiles so far (bucket resolution 1 µs; an overflowing percentile reads as the maximum).
    pub fn summary(&self) -> LatenessSummary {
        let ticks = self.ticks.load(Ordering::Relaxed);
        let max_us = self.max_ns.load(Ordering::Relaxed) as f64 / 1000.0;
        let percentile = |q: f64| {
            if ticks == 0 {
                return 0.0;
            }
            let rank = ((q * ticks as f64).ceil() as u64).max(1);
            let mut seen = 0;
            for (us, bucket) in self.buckets.iter().enumerate() {
                seen += bucket.load(Ordering::Relaxed);
                if seen >= rank {
                    return (us as f64).min(max_us);
                }
            }
            max_us
        };
        LatenessSummary {
            ticks,
            p50_us: percentile(0.5),
            p99_us: percentile(0.99),
            max_us,
            misses: self.misses.load(Ordering::Relaxed),
            stalls: self.stalls.load(Ordering::Relaxed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Misses count every late tick; stalls count each run of them once, however long.
    #[test]
    fn a_run_of_late_ticks_is_one_stall() {
        let h = LatenessHistogram::default();
        let late = (MISS_THRESHOLD_US + 1) * 1000;
        // On time, a run of three late, on time, one late, a run of two late at the end.
        for ns in [10_000, late, 3 * late, late, 20_000, late, 0, late, late] {
            h.record(ns);
        }
        let s = h.summary();
        assert_eq!((s.ticks, s.misses, s.stalls), (9, 6, 3), "{s:?}");
        // Exactly at the threshold is on time (a miss is strictly later), and ends a run.
        h.record(MISS_THRESHOLD_US * 1000);
        h.record(late);
        assert_eq!((h.summary().misses, h.summary().stalls), (7, 4));
    }
}
