//! How long a stream of datagrams has recently gone without one: the longest gap between arrivals over the
//! last [`WINDOW`], so that a receiver judges a silence against what its link has been delivering and not
//! against a fixed figure.
//!
//! **Why.** A path with jitter delivers in bunches: it keeps its order (a packet never overtakes one sent
//! before it), so a packet held up holds up every one behind it, and the receiver sees a silence of a few
//! standard deviations of the delay, then the whole bunch at once. Under a long delay with jitter, those
//! silences outlast a fixed staleness limit of 100 ms; judged against it, each faded the force out, and the local model restarted on a VE a round
//! trip behind: the ramp back in released the stretched device-model coupling into the hand, energy nobody put
//! in (docs/robustness.md, "Silences of a jittery link").
//!
//! Two buckets of half the window each keep the longest gap: the receiver forgets a burst of long gaps
//! between one and two half-windows after it, with no allocation and nothing to sort.

use std::time::Duration;

/// How far back the longest gap is remembered (between half of it and all of it).
pub const WINDOW: Duration = Duration::from_secs(10);

/// The longest gap between arrivals over the recent past.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ArrivalGaps {
    /// The last arrival.
    last: Option<Duration>,
    /// Start of the current bucket.
    bucket_start: Duration,
    /// Longest gap that ended in the current bucket.
    current: Duration,
    /// Longest gap that ended in the bucket before it.
    previous: Duration,
}

impl ArrivalGaps {
    /// Nothing has arrived yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A datagram arrived at `now`. Arrivals out of time order (a clock that stepped back) count as no gap.
    pub fn arrived(&mut self, now: Duration) {
        self.roll(now);
        if let Some(last) = self.last {
            self.current = self.current.max(now.saturating_sub(last));
        }
        self.last = Some(self.last.map_or(now, |last| last.max(now)));
    }

    /// The longest gap that ended within the last half-window to window before `now` (zero before two
    /// arrivals).
    pub fn longest(&self, now: Duration) -> Duration {
        let half = WINDOW / 2;
        let since = now.saturating_sub(self.bucket_start);
        if since >= WINDOW {
            Duration::ZERO
        } else if since >= half {
            self.current
        } else {
            self.current.max(self.previous)
        }
    }

    /// Starts a new bucket when the current one is half a window old (two when it is a window old).
    fn roll(&mut self, now: Duration) {
        let half = WINDOW / 2;
        let since = now.saturating_sub(self.bucket_start);
        if since >= WINDOW {
            (self.previous, self.current) = (Duration::ZERO, Duration::ZERO);
            self.bucket_start = now;
        } else if since >= half {
            self.previous = self.current;
            self.current = Duration::ZERO;
            self.bucket_start += half;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// The longest gap is the longest interval between two arrivals, and it is remembered for at least
    /// half a window and forgotten within a whole one.
    #[test]
    fn the_longest_gap_is_remembered_for_half_a_window_and_forgotten_within_one() {
        let mut gaps = ArrivalGaps::new();
        assert_eq!(gaps.longest(ms(0)), Duration::ZERO);
        gaps.arrived(ms(0));
        assert_eq!(gaps.longest(ms(0)), Duration::ZERO, "one arrival makes no gap");
        // Arrivals every 10 ms, then a 180 ms silence, then every 10 ms again.
        let mut t = 0;
        for _ in 0..50 {
            t += 10;
            gaps.arrived(ms(t));
        }
        assert_eq!(gaps.longest(ms(t)), ms(10));
        t += 180;
        gaps.arrived(ms(t));
        let burst_at = t;
        assert_eq!(gaps.longest(ms(t)), ms(180));
        while t < burst_at + WINDOW.as_millis() as u64 * 2 {
            t += 10;
            gaps.arrived(ms(t));
            let remembered = gaps.longest(ms(t)) == ms(180);
            if t < burst_at + WINDOW.as_millis() as u64 / 2 {
                assert!(remembered, "forgot the 180 ms gap at {t} ms");
            }
            if t >= burst_at + WINDOW.as_millis() as u64 {
                assert!(!remembered, "still holds the 180 ms gap at {t} ms");
                assert_eq!(gaps.longest(ms(t)), ms(10));
            }
        }
    }

    /// A long silence with nothing arriving after it leaves nothing remembered once it is a window old, and
    /// a clock that steps back neither panics nor makes a gap.
    #[test]
    fn silence_and_a_clock_stepping_back_are_harmless() {
        let mut gaps = ArrivalGaps::new();
        gaps.arrived(ms(1_000));
        gaps.arrived(ms(1_100));
        assert_eq!(gaps.longest(ms(1_100)), ms(100));
        assert_eq!(gaps.longest(ms(1_100) + WINDOW), Duration::ZERO);
        gaps.arrived(ms(900));
        assert_eq!(gaps.longest(ms(1_100)), ms(100));
        gaps.arrived(ms(1_150));
        assert_eq!(gaps.longest(ms(1_150)), ms(100), "measured from the latest arrival, not the stepped-back one");
    }
}
