//! What a link does to packets, and how users say it on the command line (`--delay 50ms --loss 2%`).

use std::str::FromStr;
use std::time::Duration;

/// Two-state burst-loss channel (Gilbert–Elliott). Before each packet the channel is in the good or the bad
/// state; the packet is lost with that state's loss probability, then the state changes with the transition
/// probability. With `loss_good = 0` and `loss_bad = 1` (the Gilbert model), losses come in bursts of mean
/// length `1 / p_bad_to_good` and the long-run loss rate is `p_good_to_bad / (p_good_to_bad + p_bad_to_good)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GilbertElliott {
    /// Probability of moving from good to bad after a packet.
    pub p_good_to_bad: f64,
    /// Probability of moving from bad to good after a packet.
    pub p_bad_to_good: f64,
    /// Loss probability in the good state.
    pub loss_good: f64,
    /// Loss probability in the bad state.
    pub loss_bad: f64,
}

impl GilbertElliott {
    /// Long-run fraction of packets lost.
    pub fn stationary_loss(&self) -> f64 {
        let total = self.p_good_to_bad + self.p_bad_to_good;
        if total == 0.0 {
            return self.loss_good;
        }
        let bad_share = self.p_good_to_bad / total;
        bad_share * self.loss_bad + (1.0 - bad_share) * self.loss_good
    }
}

impl FromStr for GilbertElliott {
    type Err = LinkParseError;

    /// `P_GB,P_BG` (Gilbert: loss only in the bad state) or `P_GB,P_BG,LOSS_GOOD,LOSS_BAD`; each a probability
    /// such as `1%` or `0.01`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        let p = |i: usize| parse_probability(parts[i]);
        match parts.len() {
            2 => Ok(GilbertElliott { p_good_to_bad: p(0)?, p_bad_to_good: p(1)?, loss_good: 0.0, loss_bad: 1.0 }),
            4 => Ok(GilbertElliott { p_good_to_bad: p(0)?, p_bad_to_good: p(1)?, loss_good: p(2)?, loss_bad: p(3)? }),
            _ => Err(LinkParseError::Burst { input: s.to_owned() }),
        }
    }
}

/// Impairments of one direction of a link.
///
/// Each packet, in this order: it may be lost (`loss`, or `burst` when set); it waits for the bandwidth cap
/// (`bandwidth_bps`: serialization at that rate behind earlier packets, tail-dropped when the backlog exceeds
/// [`MAX_QUEUE_DELAY`]); it may be duplicated (`duplicate`: one extra copy with its own delay draw); then each
/// copy is delayed by `delay + jitter · z`, with `z` standard normal and the result clamped at zero, i.e.
/// **jitter is the standard deviation of the per-packet one-way delay**. Jitter never reorders: like a real
/// FIFO path a packet never leaves before one sent earlier, so packets spaced closer than the jitter bunch up
/// behind a slow one. Reordering comes only from `reorder`: such a packet skips the delay line (as netem does)
/// and overtakes everything still in flight.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// Mean one-way delay added to every packet.
    pub delay: Duration,
    /// Standard deviation of the per-packet delay.
    pub jitter: Duration,
    /// Independent (Bernoulli) loss probability; must be 0 when `burst` is set.
    pub loss: f64,
    /// Burst loss; replaces `loss` when set.
    pub burst: Option<GilbertElliott>,
    /// Probability that a packet skips the delay line and overtakes packets in flight.
    pub reorder: f64,
    /// Probability that a packet is delivered twice.
    pub duplicate: f64,
    /// Bandwidth cap (bits per second of payload), none when `None`.
    pub bandwidth_bps: Option<f64>,
    /// PRNG seed: the same seed and the same inputs give exactly the same losses, delays and order.
    pub seed: u64,
}

/// Longest delay or jitter a link may have; bounds every time computation far from overflow.
pub const MAX_LINK_DELAY: Duration = Duration::from_secs(3600);
/// Slowest bandwidth cap (bits per second); bounds a packet's serialization time.
pub const MIN_BANDWIDTH_BPS: f64 = 1.0;

/// Longest backlog the bandwidth cap queues before dropping packets (a drop-tail router buffer).
pub const MAX_QUEUE_DELAY: Duration = Duration::from_millis(200);

impl Default for LinkConfig {
    /// A perfect link: no delay, no loss.
    fn default() -> Self {
        LinkConfig {
            delay: Duration::ZERO,
            jitter: Duration::ZERO,
            loss: 0.0,
            burst: None,
            reorder: 0.0,
            duplicate: 0.0,
            bandwidth_bps: None,
            seed: 0,
        }
    }
}

impl LinkConfig {
    /// True when the link changes nothing, so callers can skip emulation entirely.
    pub fn is_transparent(&self) -> bool {
        LinkConfig { seed: self.seed, ..LinkConfig::default() } == *self
    }

    /// How long a packet sent now may stay on the link, jitter included (six standard deviations past the
    /// mean delay: one packet in half a billion is later). A sender that stops sooner takes its last packets
    /// with it, a connection's close among them. Bandwidth queueing is not counted.
    pub fn longest_flight(&self) -> Duration {
        self.delay.saturating_add(self.jitter.saturating_mul(6))
    }

    /// Checks that probabilities are probabilities and the options do not contradict each other.
    pub fn validate(&self) -> Result<(), LinkConfigError> {
        let mut probabilities = vec![("loss", self.loss), ("reorder", self.reorder), ("duplicate", self.duplicate)];
        if let Some(b) = &self.burst {
            probabilities.extend([
                ("burst.p_good_to_bad", b.p_good_to_bad),
                ("burst.p_bad_to_good", b.p_bad_to_good),
                ("burst.loss_good", b.loss_good),
                ("burst.loss_bad", b.loss_bad),
            ]);
        }
        if let Some((name, value)) = probabilities.into_iter().find(|(_, p)| !(0.0..=1.0).contains(p)) {
            return Err(LinkConfigError::NotAProbability { name, value });
        }
        if self.burst.is_some() && self.loss > 0.0 {
            return Err(LinkConfigError::LossAndBurst);
        }
        if let Some((name, value)) =
            [("delay", self.delay), ("jitter", self.jitter)].into_iter().find(|(_, d)| *d > MAX_LINK_DELAY)
        {
            return Err(LinkConfigError::TooLong { name, value });
        }
        match self.bandwidth_bps {
            Some(bps) if !(bps.is_finite() && bps >= MIN_BANDWIDTH_BPS) => Err(LinkConfigError::Bandwidth { bps }),
            _ => Ok(()),
        }
    }
}

/// A [`LinkConfig`] that contradicts itself.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LinkConfigError {
    /// A probability outside [0, 1].
    #[error("{name} = {value} is not a probability in [0, 1]")]
    NotAProbability {
        /// Which setting.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// Both loss models at once.
    #[error("set either --loss or --burst, not both: the burst model replaces independent loss")]
    LossAndBurst,
    /// A delay longer than [`MAX_LINK_DELAY`].
    #[error("{name} {value:?} is longer than the {MAX_LINK_DELAY:?} a link may delay")]
    TooLong {
        /// Which setting.
        name: &'static str,
        /// Its value.
        value: Duration,
    },
    /// A bandwidth below [`MIN_BANDWIDTH_BPS`].
    #[error("bandwidth {bps} bit/s must be at least {MIN_BANDWIDTH_BPS} bit/s")]
    Bandwidth {
        /// The rate given.
        bps: f64,
    },
}

/// A command-line value that does not parse.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LinkParseError {
    /// Not a duration like `50ms`.
    #[error("{input:?} is not a duration; write e.g. 50ms, 1.5s, 250us or 0")]
    Duration {
        /// The text given.
        input: String,
    },
    /// Not a probability like `2%`.
    #[error("{input:?} is not a probability; write e.g. 2% or 0.02 (between 0 and 1)")]
    Probability {
        /// The text given.
        input: String,
    },
    /// Not a rate like `1mbit`.
    #[error("{input:?} is not a bandwidth; write e.g. 1mbit, 500kbit, 2gbit or 64000bit (bits per second)")]
    Bandwidth {
        /// The text given.
        input: String,
    },
    /// Not a burst model like `1%,25%`.
    #[error("{input:?} is not a burst model; write P_GB,P_BG (e.g. 1%,25%) or P_GB,P_BG,LOSS_GOOD,LOSS_BAD")]
    Burst {
        /// The text given.
        input: String,
    },
}

/// Splits `"12.5ms"` into `(12.5, "ms")`.
fn number_and_unit(s: &str) -> Option<(f64, &str)> {
    let s = s.trim();
    let split = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let value: f64 = s[..split].parse().ok()?;
    value.is_finite().then_some((value, s[split..].trim()))
}

/// Parses `50ms`, `1.5s`, `250us` (or `250µs`), `100ns`, or a bare `0`.
pub fn parse_duration(s: &str) -> Result<Duration, LinkParseError> {
    let error = || LinkParseError::Duration { input: s.to_owned() };
    let (value, unit) = number_and_unit(s).ok_or_else(error)?;
    let seconds_per_unit = match unit {
        "s" => 1.0,
        "ms" => 1e-3,
        "us" | "µs" => 1e-6,
        "ns" => 1e-9,
        "" if value == 0.0 => 0.0,
        _ => return Err(error()),
    };
    Duration::try_from_secs_f64(value * seconds_per_unit).map_err(|_| error())
}

/// Parses `2%` or `0.02` into a probability in [0, 1].
pub fn parse_probability(s: &str) -> Result<f64, LinkParseError> {
    let error = || LinkParseError::Probability { input: s.to_owned() };
    let (value, unit) = number_and_unit(s).ok_or_else(error)?;
    let p = match unit {
        "%" => value / 100.0,
        "" => value,
        _ => return Err(error()),
    };
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(error())
    }
}

/// Parses `1mbit`, `500kbit`, `2gbit` or `64000bit` (bits per second, as `tc` writes them) into bits/s.
pub fn parse_bandwidth(s: &str) -> Result<f64, LinkParseError> {
    let error = || LinkParseError::Bandwidth { input: s.to_owned() };
    let (value, unit) = number_and_unit(s).ok_or_else(error)?;
    let bits_per_unit = match unit.trim_end_matches("/s") {
        "bit" => 1.0,
        "kbit" => 1e3,
        "mbit" => 1e6,
        "gbit" => 1e9,
        _ => return Err(error()),
    };
    let bps = value * bits_per_unit;
    if bps > 0.0 {
        Ok(bps)
    } else {
        Err(error())
    }
}

/// Parses a burst model, see [`GilbertElliott::from_str`].
pub fn parse_burst(s: &str) -> Result<GilbertElliott, LinkParseError> {
    s.parse()
}

/// The link options `kinloop-server` and `kinloop-client` share: `#[command(flatten)] link: LinkArgs`.
/// Each side impairs only what it sends, so `--delay 25ms` on both sides adds 50 ms to the round trip.
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct LinkArgs {
    /// Mean one-way delay added to every packet this side sends (e.g. 25ms).
    #[arg(long, value_name = "DURATION", value_parser = parse_duration, default_value = "0ms")]
    pub delay: Duration,
    /// Standard deviation of that delay (e.g. 5ms); never reorders packets.
    #[arg(long, value_name = "DURATION", value_parser = parse_duration, default_value = "0ms")]
    pub jitter: Duration,
    /// Independent loss probability of sent packets (e.g. 2%).
    #[arg(long, value_name = "PROBABILITY", value_parser = parse_probability, default_value = "0")]
    pub loss: f64,
    /// Burst loss instead of --loss: P_GB,P_BG or P_GB,P_BG,LOSS_GOOD,LOSS_BAD (e.g. 1%,25%: bursts of 4 on average).
    #[arg(long, value_name = "P_GB,P_BG", value_parser = parse_burst)]
    pub burst: Option<GilbertElliott>,
    /// Probability that a packet skips the delay and overtakes those in flight (e.g. 1%).
    #[arg(long, value_name = "PROBABILITY", value_parser = parse_probability, default_value = "0")]
    pub reorder: f64,
    /// Probability that a packet is delivered twice (e.g. 1%).
    #[arg(long, value_name = "PROBABILITY", value_parser = parse_probability, default_value = "0")]
    pub duplicate: f64,
    /// Bandwidth cap for sent packets (e.g. 1mbit).
    #[arg(long, value_name = "RATE", value_parser = parse_bandwidth)]
    pub bandwidth: Option<f64>,
    /// Seed of the link's random choices: the same seed repeats the same losses and delays.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,
}

impl LinkArgs {
    /// The link these options describe.
    pub fn config(&self) -> LinkConfig {
        LinkConfig {
            delay: self.delay,
            jitter: self.jitter,
            loss: self.loss,
            burst: self.burst,
            reorder: self.reorder,
            duplicate: self.duplicate,
            bandwidth_bps: self.bandwidth,
            seed: self.seed,
        }
    }

    /// The link to emulate, or `None` when the options change nothing (then use the plain socket).
    pub fn emulated_link(&self) -> Result<Option<LinkConfig>, LinkConfigError> {
        let config = self.config();
        config.validate()?;
        Ok((!config.is_transparent()).then_some(config))
    }
}
