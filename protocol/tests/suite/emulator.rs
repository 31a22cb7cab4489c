//! The link emulator does what its settings say, measured in virtual time over many packets.

use std::time::Duration;

use clap::Parser;
use kinloop_protocol::emulator::*;

const MS: Duration = Duration::from_millis(1);
const PACKET_BYTES: usize = 100;

#[derive(Debug, Clone, Copy)]
struct Delivery {
    seq: u64,
    sent: Duration,
    delivered: Duration,
}

impl Delivery {
    fn delay_s(&self) -> f64 {
        (self.delivered - self.sent).as_secs_f64()
    }
}

/// Sends `count` packets `spacing` apart in virtual time and collects every delivery at its exact due time.
fn run(config: LinkConfig, count: u64, spacing: Duration) -> (Vec<Delivery>, LinkStats) {
    let mut link = LinkEmulator::new(config).expect("valid config");
    let mut deliveries = Vec::new();
    let mut drain_until = |link: &mut LinkEmulator<(u64, Duration)>, now: Duration| {
        while let Some(due) = link.poll_timeout().filter(|due| *due <= now) {
            let (seq, sent) = link.poll(due).expect("due item");
            deliveries.push(Delivery { seq, sent, delivered: due });
        }
    };
    for seq in 0..count {
        let now = spacing * seq as u32;
        drain_until(&mut link, now);
        link.send_sized(now, (seq, now), PACKET_BYTES);
    }
    drain_until(&mut link, Duration::MAX);
    assert_eq!(link.in_flight(), 0);
    (deliveries, link.stats())
}

fn mean_and_std(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count() as f64;
    let mean = values.clone().sum::<f64>() / n;
    let variance = values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, variance.sqrt())
}

#[test]
fn mean_delay_and_jitter_match_the_settings() {
    let config = LinkConfig { delay: 50 * MS, jitter: 5 * MS, seed: 1, ..LinkConfig::default() };
    // Packets far apart, so the no-overtaking rule never binds and delays are the raw draws.
    let (deliveries, _) = run(config, 20_000, 100 * MS);
    let (mean, std) = mean_and_std(deliveries.iter().map(Delivery::delay_s));
    // Standard errors: 5 ms / sqrt(20000) ≈ 0.035 ms for the mean, ≈ 0.025 ms for the deviation.
    assert!((mean - 0.050).abs() < 0.0002, "mean delay {mean}");
    assert!((std - 0.005).abs() < 0.0002, "jitter {std}");
}

#[test]
fn constant_delay_is_exact() {
    let config = LinkConfig { delay: 25 * MS, ..LinkConfig::default() };
    let (deliveries, _) = run(config, 1000, MS);
    assert!(deliveries.iter().all(|d| d.delivered - d.sent == 25 * MS));
}

#[test]
fn jitter_never_reorders() {
    let config = LinkConfig { delay: 20 * MS, jitter: 5 * MS, seed: 2, ..LinkConfig::default() };
    let (deliveries, stats) = run(config, 20_000, MS);
    assert!(deliveries.windows(2).all(|w| w[0].seq < w[1].seq));
    assert_eq!(stats.reordered, 0);
}

#[test]
fn bernoulli_loss_rate_matches() {
    let config = LinkConfig { loss: 0.02, seed: 3, ..LinkConfig::default() };
    let (deliveries, stats) = run(config, 200_000, MS);
    let rate = 1.0 - deliveries.len() as f64 / 200_000.0;
    // Standard error sqrt(0.02 · 0.98 / 200000) ≈ 0.0003.
    assert!((rate - 0.02).abs() < 0.002, "loss rate {rate}");
    assert_eq!(stats.dropped as usize, 200_000 - deliveries.len());
}

#[test]
fn gilbert_elliott_burst_length_and_loss_rate_match() {
    let burst = GilbertElliott { p_good_to_bad: 0.01, p_bad_to_good: 0.25, loss_good: 0.0, loss_bad: 1.0 };
    let config = LinkConfig { burst: Some(burst), seed: 4, ..LinkConfig::default() };
    let count = 1_000_000u64;
    let (deliveries, _) = run(config, count, MS);
    let mut lost = vec![true; count as usize];
    for d in &deliveries {
        lost[d.seq as usize] = false;
    }
    let bursts: Vec<usize> = lost.split(|is_lost| !is_lost).map(<[bool]>::len).filter(|len| *len > 0).collect();
    let mean_burst = bursts.iter().sum::<usize>() as f64 / bursts.len() as f64;
    let loss_rate = lost.iter().filter(|l| **l).count() as f64 / count as f64;
    // ≈ 9600 bursts, geometric with mean 4 (std 3.5): standard error ≈ 0.035.
    assert!((mean_burst - 4.0).abs() < 0.2, "mean burst length {mean_burst}");
    assert!((loss_rate - burst.stationary_loss()).abs() < 0.003, "loss rate {loss_rate}");
}

#[test]
fn reorder_probability_matches_and_reordered_packets_overtake() {
    let config = LinkConfig { delay: 20 * MS, reorder: 0.1, seed: 5, ..LinkConfig::default() };
    let (deliveries, stats) = run(config, 100_000, MS);
    // A packet arrived early when a packet sent before it arrives after it.
    let mut earliest_later = u64::MAX;
    let mut early = 0;
    for d in deliveries.iter().rev() {
        if d.seq > earliest_later {
            early += 1;
        }
        earliest_later = earliest_later.min(d.seq);
    }
    let fraction = early as f64 / 100_000.0;
    assert!((fraction - 0.1).abs() < 0.005, "reordered fraction {fraction}");
    assert_eq!(stats.reordered, early);
}

#[test]
fn duplicate_probability_matches() {
    let config = LinkConfig { duplicate: 0.05, seed: 6, ..LinkConfig::default() };
    let (deliveries, stats) = run(config, 100_000, MS);
    let extra = deliveries.len() as f64 / 100_000.0 - 1.0;
    assert!((extra - 0.05).abs() < 0.005, "duplicate fraction {extra}");
    assert_eq!(stats.duplicated as usize, deliveries.len() - 100_000);
}

#[test]
fn bandwidth_cap_serializes_packets_and_tail_drops_a_full_queue() {
    // 1 Mbit/s and 1250-byte packets: 10 ms each on the wire.
    let config = LinkConfig { bandwidth_bps: Some(1e6), ..LinkConfig::default() };
    let mut link = LinkEmulator::new(config).unwrap();
    for seq in 0..30u64 {
        link.send(Duration::ZERO, vec![seq as u8; 1250]);
    }
    let mut deliveries = Vec::new();
    while let Some(due) = link.poll_timeout() {
        deliveries.push((due, link.poll(due).unwrap()[0]));
    }
    // Packets starting within MAX_QUEUE_DELAY (200 ms) of backlog are kept: 21 of them.
    assert_eq!(deliveries.len(), 21);
    assert_eq!(link.stats().queue_overflow, 9);
    for (i, (due, seq)) in deliveries.iter().enumerate() {
        assert_eq!(*seq as usize, i);
        assert_eq!(*due, 10 * MS * (i as u32 + 1));
    }
}

#[test]
fn same_seed_gives_the_same_link_and_another_seed_does_not() {
    let config = |seed| LinkConfig {
        delay: 10 * MS,
        jitter: 3 * MS,
        loss: 0.05,
        reorder: 0.02,
        duplicate: 0.02,
        seed,
        ..LinkConfig::default()
    };
    let timeline =
        |seed| -> Vec<(u64, Duration)> { run(config(seed), 5000, MS).0.iter().map(|d| (d.seq, d.delivered)).collect() };
    assert_eq!(timeline(42), timeline(42));
    assert_ne!(timeline(42), timeline(43));
}

#[test]
fn poll_hands_out_nothing_before_it_is_due() {
    let mut link = LinkEmulator::new(LinkConfig { delay: 5 * MS, ..LinkConfig::default() }).unwrap();
    link.send(Duration::ZERO, vec![1u8]);
    assert_eq!(link.poll_timeout(), Some(5 * MS));
    assert_eq!(link.poll(4 * MS), None);
    assert_eq!(link.poll(5 * MS), Some(vec![1u8]));
    assert_eq!(link.poll_timeout(), None);
}

#[test]
fn contradictory_settings_are_refused() {
    let burst = GilbertElliott { p_good_to_bad: 0.1, p_bad_to_good: 0.1, loss_good: 0.0, loss_bad: 1.0 };
    let both = LinkConfig { loss: 0.1, burst: Some(burst), ..LinkConfig::default() };
    assert_eq!(LinkEmulator::<Vec<u8>>::new(both).unwrap_err(), LinkConfigError::LossAndBurst);
    let not_probability = LinkConfig { duplicate: 1.5, ..LinkConfig::default() };
    assert!(matches!(not_probability.validate(), Err(LinkConfigError::NotAProbability { name: "duplicate", .. })));
    let glacial = LinkConfig { delay: MAX_LINK_DELAY + MS, ..LinkConfig::default() };
    assert!(matches!(glacial.validate(), Err(LinkConfigError::TooLong { name: "delay", .. })));
    let trickle = LinkConfig { bandwidth_bps: Some(0.5), ..LinkConfig::default() };
    assert!(matches!(trickle.validate(), Err(LinkConfigError::Bandwidth { .. })));
}

#[test]
fn command_line_values_parse_like_tc() {
    assert_eq!(parse_duration("50ms"), Ok(50 * MS));
    assert_eq!(parse_duration("1.5s"), Ok(1500 * MS));
    assert_eq!(parse_duration("250us"), Ok(Duration::from_micros(250)));
    assert_eq!(parse_duration("0"), Ok(Duration::ZERO));
    assert!(parse_duration("50").is_err());
    assert!(parse_duration("-5ms").is_err());
    assert_eq!(parse_probability("2%"), Ok(0.02));
    assert_eq!(parse_probability("0.25"), Ok(0.25));
    assert!(parse_probability("150%").is_err());
    assert_eq!(parse_bandwidth("1mbit"), Ok(1e6));
    assert_eq!(parse_bandwidth("500kbit"), Ok(5e5));
    assert!(parse_bandwidth("1mb").is_err());
    let burst = parse_burst("1%,25%").unwrap();
    assert_eq!((burst.p_good_to_bad, burst.p_bad_to_good, burst.loss_good, burst.loss_bad), (0.01, 0.25, 0.0, 1.0));
    assert!(parse_burst("1%").is_err());
}

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    link: LinkArgs,
}

#[test]
fn link_args_flatten_into_a_command_line() {
    let cli = Cli::parse_from(["kinloop-client", "--delay", "50ms", "--jitter", "5ms", "--loss", "2%", "--seed", "7"]);
    let config = cli.link.config();
    assert_eq!((config.delay, config.jitter, config.loss, config.seed), (50 * MS, 5 * MS, 0.02, 7));
    assert_eq!(cli.link.emulated_link().unwrap(), Some(config));
    let plain = Cli::parse_from(["kinloop-client"]);
    assert_eq!(plain.link.emulated_link().unwrap(), None);
}
