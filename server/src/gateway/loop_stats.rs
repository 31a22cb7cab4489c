//! Timing statistics of the VE thread, kept there without allocating and copied out a few times per second
//! for the driver's stats report and the view's panel.

use serde::Serialize;

use crate::core::VeMetrics;

/// Sub-buckets per power of two: 16 gives ≤ 6 % relative resolution.
const SUB_BITS: u32 = 4;
const SUB: usize = 1 << SUB_BITS;
/// Powers of two covered: up to 2⁴⁰ ns ≈ 18 min.
const OCTAVES: usize = 41;

/// Log-linear histogram of durations in nanoseconds, fixed size, allocation-free after construction.
#[derive(Clone, Debug)]
pub struct LatencyHistogram {
    counts: Box<[u64; OCTAVES * SUB]>,
    count: u64,
    max_ns: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        LatencyHistogram { counts: Box::new([0; OCTAVES * SUB]), count: 0, max_ns: 0 }
    }
}

impl LatencyHistogram {
    fn bucket(ns: u64) -> usize {
        if ns < SUB as u64 {
            return ns as usize;
        }
        let octave = 63 - ns.leading_zeros(); // ≥ SUB_BITS
        let sub = (ns >> (octave - SUB_BITS)) as usize & (SUB - 1);
        (((octave - SUB_BITS + 1) as usize) * SUB + sub).min(OCTAVES * SUB - 1)
    }

    /// Upper edge of a bucket (ns).
    fn bucket_value(index: usize) -> u64 {
        if index < SUB {
            return index as u64;
        }
        let octave = (index / SUB) as u32 + SUB_BITS - 1;
        let sub = (index % SUB) as u64;
        ((SUB as u64 + sub + 1) << (octave - SUB_BITS)).saturating_sub(1)
    }

    /// Records one duration.
    pub fn record(&mut self, ns: u64) {
        self.counts[Self::bucket(ns)] += 1;
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    /// The value below which a fraction `p` of the samples lie (bucket resolution).
    pub fn percentile(&self, p: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let rank = ((p * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (index, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Self::bucket_value(index).min(self.max_ns);
            }
        }
        self.max_ns
    }

    /// p50, p99, max.
    pub fn summary(&self) -> Percentiles {
        Percentiles {
            p50_ns: self.percentile(0.5),
            p99_ns: self.percentile(0.99),
            max_ns: self.max_ns,
            samples: self.count,
        }
    }
}

/// Percentiles of a duration (ns).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50_ns: u64,
    /// 99th percentile.
    pub p99_ns: u64,
    /// Largest.
    pub max_ns: u64,
    /// Samples.
    pub samples: u64,
}

/// Where an iteration of the VE loop goes, stage by stage in the order the loop runs them: each a
/// distribution over iterations of that stage's time (ns), so a stage's p50 can be set beside the back-to-back
/// benchmark of the same work.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    /// Joins and leaves served, every user's uplinks popped and handed to the core.
    pub intake: Percentiles,
    /// The integrator step(s) due (`VeCore::run_due_ticks`).
    pub step: Percentiles,
    /// Every user's local-model terms (`VeCore::build_due_snapshots`); zero on iterations without a round.
    pub snapshot_terms: Percentiles,
    /// Every user's snapshot encoded (bincode) into the loop's buffer.
    pub encode: Percentiles,
    /// The encoded frames pushed into the users' rings.
    pub ring_push: Percentiles,
    /// The users' network tasks woken (one notification per user that got a frame).
    pub wake: Percentiles,
    /// Events moved to the log's ring and the recorder's row.
    pub events_record: Percentiles,
    /// The web view's tap (its per-snapshot note and per-tick frame), when a view is served.
    pub view: Percentiles,
    /// The loop's own bookkeeping: room-state publication and the step-time histogram.
    pub stats: Percentiles,
}

/// One fixed-size histogram per stage of [`StageTimes`], allocation-free after construction.
#[derive(Clone, Debug, Default)]
pub struct StageHistograms {
    /// See [`StageTimes::intake`].
    pub intake: LatencyHistogram,
    /// See [`StageTimes::step`].
    pub step: LatencyHistogram,
    /// See [`StageTimes::snapshot_terms`].
    pub snapshot_terms: LatencyHistogram,
    /// See [`StageTimes::encode`].
    pub encode: LatencyHistogram,
    /// See [`StageTimes::ring_push`].
    pub ring_push: LatencyHistogram,
    /// See [`StageTimes::wake`].
    pub wake: LatencyHistogram,
    /// See [`StageTimes::events_record`].
    pub events_record: LatencyHistogram,
    /// See [`StageTimes::view`].
    pub view: LatencyHistogram,
    /// See [`StageTimes::stats`].
    pub stats: LatencyHistogram,
}

impl StageHistograms {
    /// Each stage's percentiles.
    pub fn summary(&self) -> StageTimes {
        StageTimes {
            intake: self.intake.summary(),
            step: self.step.summary(),
            snapshot_terms: self.snapshot_terms.summary(),
            encode: self.encode.summary(),
            ring_push: self.ring_push.summary(),
            wake: self.wake.summary(),
            events_record: self.events_record.summary(),
            view: self.view.summary(),
            stats: self.stats.summary(),
        }
    }
}

/// What the VE thread reports (copied out a few times per second).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct VeLoopStats {
    /// Time per VE loop iteration: uplinks in, tick(s), snapshots encoded and handed over.
    pub step_time: Percentiles,
    /// The same iterations stage by stage.
    pub stages: StageTimes,
    /// CPU time the VE thread used (s), sleeping excluded; beside `wall_s` it shows what the loop's hybrid
    /// sleep spends spinning (`None` where the platform has no per-thread CPU clock).
    pub cpu_s: Option<f64>,
    /// Seconds since the loop started.
    pub wall_s: f64,
    /// The loop's time zero (VE time 0, what the record's times count from) on the system clock, seconds
    /// since the Unix epoch: for a reader that lines the record up with another program's.
    pub epoch_unix_s: f64,
    /// Wake-ups later than half a period after their deadline.
    pub deadline_misses: u64,
    /// Runs of consecutive late wake-ups, each counted once: a host stall makes a loaded loop late for as
    /// long as it takes to catch up (several misses), and stalls, unlike misses, come one at a time.
    pub deadline_stalls: u64,
    /// Latest wake-up after its deadline (ns).
    pub max_lateness_ns: u64,
    /// Whether SCHED_FIFO was granted.
    pub realtime_priority: bool,
    /// Snapshots dropped because a user's ring was full (its network task is not keeping up).
    pub snapshots_dropped: u64,
    /// Rows the recorder could not take.
    pub record_rows_dropped: u64,
    /// Rows handed to the recorder.
    pub record_rows: u64,
    /// Frames handed to the view's hub.
    pub view_frames: u64,
    /// Frames the view's ring had no room for (its hub is not keeping up).
    pub view_frames_dropped: u64,
    /// The core's counters.
    pub core: VeMetrics,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_within_bucket_resolution() {
        let mut h = LatencyHistogram::default();
        for ns in 1..=10_000u64 {
            h.record(ns * 100);
        }
        let s = h.summary();
        assert_eq!(s.max_ns, 1_000_000);
        assert!((s.p50_ns as f64 - 500_000.0).abs() < 0.07 * 500_000.0, "{s:?}");
        assert!((s.p99_ns as f64 - 990_000.0).abs() < 0.07 * 990_000.0, "{s:?}");
        assert_eq!(LatencyHistogram::default().summary(), Percentiles::default());
    }
}
