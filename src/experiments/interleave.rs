//! The idle loop and a measured run, alternated in short blocks of equal length, so that the floor a run's
//! deadline misses are judged against is the machine's during the run and not the minute before it. A host's
//! stalls come and go on a scale of minutes (docs/benchmarks.md: the idle loop alone misses 0.019-0.068 % of
//! its ticks from one minute to the next), so a floor timed once before a run can be a third or three times
//! the floor during it, whatever the interval of their ratio says about counting.
//!
//! **Why the pooled counts may still be judged by one interval.** With blocks of equal length on either side,
//! each block pair sees one host rate, whatever it is. Conditional on a pair's total, its run's count is
//! binomial with the same `π = n₁ R / (n₁ R + n₂)` in every pair (`R` the ratio of the rates, which is what
//! the server adds), so the counts summed over pairs are binomial with that `π` too: the exact conditional
//! interval of [`super::rate_ratio`] holds for the pooled counts however the host's rate moved from one pair
//! to the next. The blocks alternate in the order idle, run, run, idle, ... so that a rate drifting steadily
//! over the sitting falls on both sides alike.

use std::time::Duration;

use anyhow::Result;
use kinloop_client::driver::rt_loop::timer_floor_after;
use kinloop_client::driver::timing::LatenessSummary;
use kinloop_server::driver::VeLoopStats;
use serde::{Deserialize, Serialize};

/// The longest block: short enough that a sitting of a minute alternates several times, long enough that a
/// run's start (a server's rooms, its clients' handshakes) is a small part of it.
pub const BLOCK_S: f64 = 10.0;

/// How long each side of a block runs before it counts. Each side starts afresh in every block (a server and
/// its clients connect, a thread is raised to SCHED_FIFO) and the first ticks of a start are late for
/// reasons of their own (page faults, connections, the first wake of a parked worker), not the host's: with
/// blocks of ten seconds, a start's one or two late ticks a block would be as many as the host's own.
pub const WARM_UP: Duration = Duration::from_secs(1);

/// How a point's seconds are cut into blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blocks {
    /// Block pairs (an idle block and a run block each).
    pub count: usize,
    /// Length of every block, on either side.
    pub each: Duration,
}

impl Blocks {
    /// The fewest blocks (and at least `at_least`) of at most [`BLOCK_S`] that cover `seconds` a side, all
    /// of one length.
    pub fn covering(seconds: f64, at_least: usize) -> Self {
        let seconds = if seconds.is_finite() { seconds.max(1e-3) } else { BLOCK_S };
        let count = ((seconds / BLOCK_S).ceil() as usize).max(at_least).max(1);
        Blocks { count, each: Duration::from_secs_f64(seconds / count as f64) }
    }
}

/// One block pair's counts: the idle loop's and the run's (for rooms, the room judged).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BlockPair {
    /// Idle loop: ticks more than 500 µs late.
    pub floor_misses: u64,
    /// Idle loop: runs of late ticks.
    pub floor_stalls: u64,
    /// Idle loop: ticks.
    pub floor_ticks: u64,
    /// The run: late wake-ups.
    pub run_misses: u64,
    /// The run: runs of late wake-ups.
    pub run_stalls: u64,
    /// The run: ticks.
    pub run_ticks: u64,
}

/// The idle loop's blocks, and the run's results in the same order.
pub struct Interleaved<R> {
    /// Each idle block's lateness.
    pub floors: Vec<LatenessSummary>,
    /// Each run block's result.
    pub runs: Vec<R>,
}

impl<R> Interleaved<R> {
    /// The idle loop over every block: (misses, stalls, ticks).
    pub fn floor_totals(&self) -> (u64, u64, u64) {
        self.floors.iter().fold((0, 0, 0), |(m, s, t), f| (m + f.misses, s + f.stalls, t + f.ticks))
    }

    /// Block pairs, the run's counts of each block read by `counts` as (misses, stalls, ticks).
    pub fn pairs(&self, counts: impl Fn(&R) -> (u64, u64, u64)) -> Vec<BlockPair> {
        self.floors
            .iter()
            .zip(&self.runs)
            .map(|(floor, run)| {
                let (run_misses, run_stalls, run_ticks) = counts(run);
                BlockPair {
                    floor_misses: floor.misses,
                    floor_stalls: floor.stalls,
                    floor_ticks: floor.ticks,
                    run_misses,
                    run_stalls,
                    run_ticks,
                }
            })
            .collect()
    }
}

/// Runs the idle 1 kHz loop (SCHED_FIFO when granted, as the loops it is the floor of) and `run` in
/// alternating blocks of `blocks.each`: idle, run, run, idle, idle, run, ... The idle loop runs
/// [`WARM_UP`] uncounted before each of its blocks; `run` is to leave its own start out the same way.
pub fn interleave<R>(blocks: Blocks, run: impl FnMut(Duration) -> Result<R>) -> Result<Interleaved<R>> {
    let idle = |each| timer_floor_after(1000.0, WARM_UP, each, true).0;
    alternate(blocks, idle, run)
}

/// A VE loop's (misses, stalls, ticks) from `start` (its statistics after the warm-up) to `end`; from its
/// beginning without a start.
pub fn counted_since(end: &VeLoopStats, start: Option<&VeLoopStats>) -> (u64, u64, u64) {
    let of = |v: &VeLoopStats| (v.deadline_misses, v.deadline_stalls, v.step_time.samples);
    let (e, s) = (of(end), start.map_or((0, 0, 0), of));
    (e.0.saturating_sub(s.0), e.1.saturating_sub(s.1), e.2.saturating_sub(s.2))
}

/// [`interleave`] with the idle side given.
fn alternate<R>(
    blocks: Blocks,
    mut idle: impl FnMut(Duration) -> LatenessSummary,
    mut run: impl FnMut(Duration) -> Result<R>,
) -> Result<Interleaved<R>> {
    let mut out = Interleaved { floors: Vec::with_capacity(blocks.count), runs: Vec::with_capacity(blocks.count) };
    for i in 0..blocks.count {
        if i % 2 == 0 {
            out.floors.push(idle(blocks.each));
            out.runs.push(run(blocks.each)?);
        } else {
            out.runs.push(run(blocks.each)?);
            out.floors.push(idle(blocks.each));
        }
    }
    Ok(out)
}

/// The median of `values` (the lower of the two middle ones), 0 when there are none.
pub fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len().saturating_sub(1) / 2).copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_the_seconds_in_equal_lengths_no_longer_than_the_block() {
        for (seconds, at_least, count) in
            [(0.5, 1, 1), (0.5, 2, 2), (10.0, 1, 1), (10.5, 1, 2), (60.0, 2, 6), (185.0, 1, 19)]
        {
            let b = Blocks::covering(seconds, at_least);
            assert_eq!(b.count, count, "{seconds} s");
            assert!(b.each.as_secs_f64() <= BLOCK_S + 1e-9, "{seconds} s: {b:?}");
            assert!((b.each.as_secs_f64() * b.count as f64 - seconds).abs() < 1e-6, "{seconds} s: {b:?}");
        }
        // Nonsense lengths still give one block that ends.
        assert_eq!(Blocks::covering(f64::NAN, 0).count, 1);
        assert_eq!(Blocks::covering(-3.0, 1).count, 1);
    }

    #[test]
    fn idle_and_run_blocks_alternate_so_a_drift_falls_on_both_sides() {
        let order = std::cell::RefCell::new(String::new());
        let blocks = Blocks { count: 4, each: Duration::from_millis(3) };
        let idle = |_| {
            order.borrow_mut().push('i');
            LatenessSummary { ticks: 3, misses: 1, stalls: 1, ..Default::default() }
        };
        let out = alternate(blocks, idle, |_| {
            order.borrow_mut().push('r');
            Ok(order.borrow().len())
        })
        .unwrap();
        assert_eq!(order.borrow().as_str(), "irriirri");
        assert_eq!(out.runs, [2, 3, 6, 7]);
        assert_eq!(out.floor_totals(), (4, 4, 12));
        let pairs = out.pairs(|&n| (n as u64, 0, 10));
        assert_eq!(pairs.iter().map(|p| p.run_misses).collect::<Vec<_>>(), [2, 3, 6, 7]);
        assert!(pairs.iter().all(|p| p.floor_ticks == 3 && p.run_ticks == 10));
    }

    #[test]
    fn the_real_idle_loop_ticks_through_its_blocks() {
        let out = interleave(Blocks { count: 2, each: Duration::from_millis(20) }, |_| Ok(())).unwrap();
        let (misses, stalls, ticks) = out.floor_totals();
        assert!((30..=42).contains(&ticks), "{ticks} ticks in 2 x 20 ms at 1 kHz");
        assert!(stalls <= misses && misses <= ticks);
    }

    #[test]
    fn the_median_is_the_middle_value() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.0);
        assert_eq!(median(vec![]), 0.0);
    }
}
