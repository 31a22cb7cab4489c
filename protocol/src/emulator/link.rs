//! The emulated link itself: a sans-IO delay line with seeded random impairments.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::{LinkConfig, LinkConfigError, MAX_QUEUE_DELAY};

/// Size of an item on the wire, for the bandwidth cap.
pub trait WireSize {
    /// Bytes this item occupies on the link.
    fn wire_bytes(&self) -> usize;
}

impl WireSize for Vec<u8> {
    fn wire_bytes(&self) -> usize {
        self.len()
    }
}

impl WireSize for bytes::Bytes {
    fn wire_bytes(&self) -> usize {
        self.len()
    }
}

/// What happened to the packets sent into a [`LinkEmulator`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Packets handed to [`LinkEmulator::send`].
    pub sent: u64,
    /// Packets lost by the loss model.
    pub dropped: u64,
    /// Packets tail-dropped because the bandwidth backlog was full.
    pub queue_overflow: u64,
    /// Extra copies created.
    pub duplicated: u64,
    /// Packets (copies included) that overtook at least one packet in flight.
    pub reordered: u64,
    /// Packets (copies included) handed out by [`LinkEmulator::poll`].
    pub delivered: u64,
}

/// One direction of a network path, driven by the caller's clock.
///
/// Time is a [`Duration`] since any epoch the caller likes (virtual time in a harness, `Instant - start` on a
/// real socket); it must not go backwards. `send(now, item)` puts an item on the link, `poll(now)` hands out
/// the items due by `now` in delivery order, `poll_timeout()` says when the next one is due. Nothing here
/// reads a clock, sleeps or spawns, and with the same seed and the same calls the outcome is identical.
#[derive(Debug)]
pub struct LinkEmulator<T> {
    config: LinkConfig,
    rng: ChaCha8Rng,
    burst_bad: bool,
    in_flight: BinaryHeap<Reverse<InFlight<T>>>,
    /// Tie-breaker so items due at the same instant leave in the order they were scheduled.
    next_order: u64,
    /// Delivery time of the last packet that went through the delay line: later ones may not overtake it.
    fifo_tail: Duration,
    /// When the bandwidth-capped transmitter finishes the packets already accepted.
    transmitter_free_at: Duration,
    stats: LinkStats,
}

#[derive(Debug)]
struct InFlight<T> {
    deliver_at: Duration,
    order: u64,
    item: T,
}

impl<T> InFlight<T> {
    fn key(&self) -> (Duration, u64) {
        (self.deliver_at, self.order)
    }
}

impl<T> PartialEq for InFlight<T> {
    fn eq(&self, other: &Self) -> bool {
        self.key() == other.key()
    }
}

impl<T> Eq for InFlight<T> {}

impl<T> PartialOrd for InFlight<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl<T> Ord for InFlight<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        self.key().cmp(&other.key())
    }
}

impl<T: Clone> LinkEmulator<T> {
    /// A link with these impairments.
    pub fn new(config: LinkConfig) -> Result<Self, LinkConfigError> {
        config.validate()?;
        Ok(LinkEmulator {
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            config,
            burst_bad: false,
            in_flight: BinaryHeap::new(),
            next_order: 0,
            fifo_tail: Duration::ZERO,
            transmitter_free_at: Duration::ZERO,
            stats: LinkStats::default(),
        })
    }

    /// Sends `item` at `now`; its size for the bandwidth cap comes from [`WireSize`].
    pub fn send(&mut self, now: Duration, item: T)
    where
        T: WireSize,
    {
        let bytes = item.wire_bytes();
        self.send_sized(now, item, bytes);
    }

    /// Sends `item`, occupying `bytes` on the link, at `now`.
    pub fn send_sized(&mut self, now: Duration, item: T, bytes: usize) {
        self.stats.sent += 1;
        if self.lose() {
            self.stats.dropped += 1;
            return;
        }
        let Some(departure) = self.transmit(now, bytes) else {
            self.stats.queue_overflow += 1;
            return;
        };
        if self.chance(self.config.duplicate) {
            self.stats.duplicated += 1;
            self.schedule(departure, item.clone());
        }
        self.schedule(departure, item);
    }

    /// The next item due by `now`, if any, in delivery order.
    pub fn poll(&mut self, now: Duration) -> Option<T> {
        if self.in_flight.peek()?.0.deliver_at > now {
            return None;
        }
        let Reverse(next) = self.in_flight.pop()?;
        self.stats.delivered += 1;
        Some(next.item)
    }

    /// When the next item is due, or `None` when nothing is in flight.
    pub fn poll_timeout(&self) -> Option<Duration> {
        self.in_flight.peek().map(|next| next.0.deliver_at)
    }

    /// Items currently in flight.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Counters so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The impairments this link applies.
    pub fn config(&self) -> &LinkConfig {
        &self.config
    }

    /// Draws whether the packet is lost, advancing the burst channel when there is one.
    fn lose(&mut self) -> bool {
        let Some(burst) = self.config.burst else {
            return self.chance(self.config.loss);
        };
        let lost = self.chance(if self.burst_bad { burst.loss_bad } else { burst.loss_good });
        let switch = self.chance(if self.burst_bad { burst.p_bad_to_good } else { burst.p_good_to_bad });
        self.burst_bad ^= switch;
        lost
    }

    /// When the packet has left the bandwidth-capped transmitter, or `None` when the backlog is full.
    fn transmit(&mut self, now: Duration, bytes: usize) -> Option<Duration> {
        let Some(bps) = self.config.bandwidth_bps else {
            return Some(now);
        };
        let start = self.transmitter_free_at.max(now);
        if start - now > MAX_QUEUE_DELAY {
            return None;
        }
        self.transmitter_free_at = start + Duration::from_secs_f64(bytes as f64 * 8.0 / bps);
        Some(self.transmitter_free_at)
    }

    fn schedule(&mut self, departure: Duration, item: T) {
        let deliver_at = if self.chance(self.config.reorder) {
            // Skips the delay line; it overtakes whatever is still due later.
            if self.fifo_tail > departure && !self.in_flight.is_empty() {
                self.stats.reordered += 1;
            }
            departure
        } else {
            let delayed = departure + self.delay_draw();
            let deliver_at = delayed.max(self.fifo_tail);
            self.fifo_tail = deliver_at;
            deliver_at
        };
        let order = self.next_order;
        self.next_order += 1;
        self.in_flight.push(Reverse(InFlight { deliver_at, order, item }));
    }

    /// `delay + jitter · z`, `z` standard normal, clamped at zero.
    fn delay_draw(&mut self) -> Duration {
        if self.config.jitter.is_zero() {
            return self.config.delay;
        }
        let seconds = self.config.delay.as_secs_f64() + self.config.jitter.as_secs_f64() * self.standard_normal();
        Duration::from_secs_f64(seconds.max(0.0))
    }

    /// Box–Muller; one draw per call keeps the sequence simple to reason about.
    fn standard_normal(&mut self) -> f64 {
        let u1 = 1.0 - self.rng.random::<f64>(); // (0, 1]: ln is finite
        let u2 = self.rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// True with probability `p`; draws nothing when `p` is 0 so a perfect link consumes no randomness.
    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.rng.random::<f64>() < p
    }
}
