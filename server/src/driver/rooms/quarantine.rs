//! The quarantine's rule and what it reports: rooms that overran a real-time thread's share, stepped in slow
//! motion by the executor's quarantine thread (`super::executor`'s `run_quarantine`) within a CPU budget, so that a room which costs more than its rate allows takes no more of the machine than
//! [`QUARANTINE_SHARE`] of one core (the rest stays with QUIC, the load and the view).
//!
//! - **Slow motion.** A quarantined room is stepped one tick at a time at its own next deadline, however far
//!   behind real time that is ([`Steppable::tick_behind`]): its VE time is what it stepped, never skipped
//!   forward to catch real time up. A room whose deadline is still ahead (it became cheap again) waits for
//!   it, so it never runs ahead of real time.
//! - **Budget.** After each tick the thread sleeps in proportion to the CPU time the tick took
//!   ([`rest_after`]): a tick of `c` is followed by `c (1 − s) / s` of sleep, `s` the share, so the thread's
//!   CPU time over the time it spent ticking and sleeping never passes `s`.
//! - **Release.** A room that has become cheap again is not kept in slow motion for good: once its ticks run
//!   within [`CAUGHT_UP_PERIODS`] periods of real time and its cost average within the release share (the
//!   executor's, half the admission share) for [`CALM_TO_RELEASE`] without a break ([`Calm`]), the executor
//!   hands it back to the least-loaded real-time thread with room for it, and it admits users again. A
//!   transient storm (a page-fault burst, a host that steals the CPU) must not refuse a room's users forever.
//! - **What it reports.** Each room's [`QuarantineReport`]: its CPU share since it was quarantined, its
//!   slowdown (real time over the VE time it stepped) and how far behind real time its last tick was.
//!
//! The thread runs at normal priority and admits no users to its rooms (`Executor::admit_user`).

use std::time::{Duration, Instant};

use serde::Serialize;

/// The most of one core the quarantine thread's rooms take together (CPU time over wall time).
pub const QUARANTINE_SHARE: f64 = 0.25;

/// How long a quarantined room must run calm, without a break, before it is released.
pub const CALM_TO_RELEASE: Duration = Duration::from_secs(2);
/// How far behind its deadline, in periods, a quarantined room's tick may start and still count as caught up
/// with real time: a normal-priority thread's wake-up comes late by a period or more on a busy host, while a
/// room in slow motion falls further behind with every tick.
pub const CAUGHT_UP_PERIODS: u32 = 10;

/// Whether a quarantined room has run calm (caught up with real time, its cost within the release share)
/// long enough to be released: one look after each of its ticks, any look that is not calm starting over.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Calm {
    since: Option<Instant>,
}

impl Calm {
    /// One look at `now`: whether the room is calm; true once it has been calm for [`CALM_TO_RELEASE`].
    pub fn observe(&mut self, now: Instant, calm: bool) -> bool {
        if !calm {
            self.since = None;
            return false;
        }
        let since = *self.since.get_or_insert(now);
        now.saturating_duration_since(since) >= CALM_TO_RELEASE
    }

    /// Whether a tick `behind` its deadline, of a room of `period` whose load is `load` (of a second), is calm
    /// against the release share `release_share`.
    pub fn is_calm(behind: Duration, period: Duration, load: f64, release_share: f64) -> bool {
        behind <= period * CAUGHT_UP_PERIODS && load <= release_share
    }
}

/// How long to sleep after a tick that took `busy` of CPU so that ticking and sleeping together use at most
/// `share` of a core: `busy (1 − share) / share`.
pub fn rest_after(busy: Duration, share: f64) -> Duration {
    let share = share.clamp(1e-3, 1.0);
    busy.mul_f64((1.0 - share) / share)
}

/// What the quarantine counts of one room since it took it.
#[derive(Clone, Copy, Debug)]
pub struct QuarantineTally {
    /// When the quarantine took it.
    pub since: Instant,
    /// CPU time its ticks took on the quarantine thread.
    pub busy: Duration,
    /// Ticks stepped there.
    pub ticks: u64,
    /// How far behind real time its last tick's deadline was.
    pub behind: Duration,
    /// The room's tick period.
    pub period: Duration,
    /// How long it has run calm, toward its release.
    pub calm: Calm,
}

impl QuarantineTally {
    /// A tally starting now for a room of `period`.
    pub fn new(period: Duration) -> Self {
        QuarantineTally {
            since: Instant::now(),
            busy: Duration::ZERO,
            ticks: 0,
            behind: Duration::ZERO,
            period,
            calm: Calm::default(),
        }
    }

    /// The report as of `now`.
    pub fn report(&self, now: Instant) -> QuarantineReport {
        let wall = now.saturating_duration_since(self.since).as_secs_f64();
        let stepped = self.period.as_secs_f64() * self.ticks as f64;
        QuarantineReport {
            cap: QUARANTINE_SHARE,
            share_of_core: if wall > 0.0 { self.busy.as_secs_f64() / wall } else { 0.0 },
            slowdown: if stepped > 0.0 { wall / stepped } else { f64::INFINITY },
            behind_real_time_s: self.behind.as_secs_f64(),
            ticks: self.ticks,
            busy_s: self.busy.as_secs_f64(),
            wall_s: wall,
        }
    }
}

/// A quarantined room as `--json` reports it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct QuarantineReport {
    /// The quarantine thread's cap ([`QUARANTINE_SHARE`]).
    pub cap: f64,
    /// Its ticks' CPU time over the wall time since it was quarantined.
    pub share_of_core: f64,
    /// Real time since it was quarantined over the VE time it stepped there (1: real time; 4: a quarter speed).
    #[serde(serialize_with = "finite_or_null")]
    pub slowdown: f64,
    /// How far its last tick's deadline lay behind real time.
    pub behind_real_time_s: f64,
    /// Ticks stepped in quarantine.
    pub ticks: u64,
    /// Their CPU time.
    pub busy_s: f64,
    /// Wall time since it was quarantined.
    pub wall_s: f64,
}

fn finite_or_null<S: serde::Serializer>(value: &f64, serializer: S) -> Result<S::Ok, S::Error> {
    if value.is_finite() {
        serializer.serialize_f64(*value)
    } else {
        serializer.serialize_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rest_after_a_tick_holds_the_share() {
        let busy = Duration::from_millis(2);
        let rest = rest_after(busy, 0.25);
        assert_eq!(rest, Duration::from_millis(6));
        let share = busy.as_secs_f64() / (busy + rest).as_secs_f64();
        assert!((share - 0.25).abs() < 1e-12, "{share}");
        assert_eq!(rest_after(busy, 1.0), Duration::ZERO);
    }

    /// Calm is counted from the first calm look and starts over at any look that is not: released only
    /// after [`CALM_TO_RELEASE`] of calm without a break.
    #[test]
    fn a_room_is_released_only_after_an_unbroken_calm() {
        let start = Instant::now();
        let at = |ms: u64| start + Duration::from_millis(ms);
        let mut calm = Calm::default();
        assert!(!calm.observe(at(0), true));
        assert!(!calm.observe(at(1999), true));
        assert!(!calm.observe(at(2000), false), "a look that is not calm");
        assert!(!calm.observe(at(2001), true));
        assert!(!calm.observe(at(4000), true), "1999 ms since the break");
        assert!(calm.observe(at(4001), true));
        let period = Duration::from_millis(1);
        assert!(Calm::is_calm(period * CAUGHT_UP_PERIODS, period, 0.35, 0.35));
        assert!(!Calm::is_calm(period * CAUGHT_UP_PERIODS + Duration::from_nanos(1), period, 0.1, 0.35), "behind");
        assert!(!Calm::is_calm(Duration::ZERO, period, 0.36, 0.35), "too costly");
    }

    #[test]
    fn a_tally_reports_share_slowdown_and_lag() {
        let mut tally = QuarantineTally::new(Duration::from_millis(1));
        tally.busy = Duration::from_millis(250);
        tally.ticks = 125;
        tally.behind = Duration::from_millis(875);
        let report = tally.report(tally.since + Duration::from_secs(1));
        assert!((report.share_of_core - 0.25).abs() < 1e-12, "{report:?}");
        assert!((report.slowdown - 8.0).abs() < 1e-12, "{report:?}");
        assert!((report.behind_real_time_s - 0.875).abs() < 1e-12, "{report:?}");
    }
}
