//! The loop's own timing, measured where it happens: a preallocated histogram of lateness (how long after
//! its absolute deadline each tick started) that the real-time thread updates with relaxed atomics (no lock,
//! no allocation) and any other thread reads.

use std::sync::atomic::{AtomicU64, Ordering};

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
}

impl Default for LatenessHistogram {
    fn default() -> Self {
        LatenessHistogram {
            buckets: (0..FINE_BUCKETS_US).map(|_| AtomicU64::new(0)).collect(),
            overflow: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
            ticks: AtomicU64::new(0),
            misses: AtomicU64::new(0),
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
        if us as u64 > MISS_THRESHOLD_US {
            self.misses.fetch_add(1, Ordering::Relaxed);
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
        }
    }
}
