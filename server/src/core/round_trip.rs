//! Each user's network round trip, measured by the VE without synchronised clocks.
//!
//! Every uplink names the newest snapshot its client had applied (`Uplink::last_snapshot_seq`) and how long
//! the client had held it when the uplink left (`Uplink::last_snapshot_age_s`). The VE keeps the time it built
//! each recent snapshot, so an uplink arriving at `t` gives a sample `t − built − age`: the downlink's delay
//! plus the uplink's, with everything the client did in between taken out. A driver that takes uplinks in
//! at its next tick says how long each waited for it (`UplinkSample::waited_s`), so the sample is dated at
//! the uplink's arrival: the network's trip, not the VE's tick quantum (as in virtual time, where uplinks are
//! handed over as they arrive).
//!
//! The estimate is a high percentile of the recent samples ([`WINDOW`] of them, the longest
//! [`IGNORED_PER_WINDOW`] set aside): what it is used for (`sharing::others_weight`) must hold through the
//! jitter, not its mean, but a lone late sample (a stall of the host's scheduling, say) must not rule the
//! weight for the next seconds; and the sharing rule takes the longest of every pushing user's estimates, so
//! one user's spike would rule the whole room. A step to a longer trip is followed as soon as more samples
//! than are set aside have shown it (within [`IGNORED_PER_WINDOW`] + 1 samples of its arrival), a shorter one
//! once the window has passed.
//!
//! A client cannot make the estimate shorter than the truth by more than it shortens its own stated age,
//! and an age longer than the time since the snapshot was built (a sample below zero) is ignored; a client
//! that overstates its round trip only makes the VE more careful.

/// Every this many snapshots one build time is kept and one answer sampled (a quarter of the stores and the
/// memory: the VE tick writes this ring every round for every user).
pub const STRIDE: u64 = 4;
/// Snapshot build times kept per user: 4 s of 1 kHz snapshots at [`STRIDE`], beyond any round trip the VE
/// shares.
pub const BUILT_KEPT: usize = 1024;
/// Recent samples kept per user for the estimate: 256 ms of a 1 kHz snapshot stream at [`STRIDE`].
pub const WINDOW: usize = 64;
/// The longest samples of a full window set aside as spikes (1/16 of it: the estimate is the window's 94th
/// percentile); a window still filling sets aside the same share of what it holds.
pub const IGNORED_PER_WINDOW: usize = 4;
/// Samples longer than this (s) are ignored: not a round trip but a client that stopped applying snapshots.
pub const MAX_SAMPLE_S: f64 = 10.0;
/// How fast the shortest round trip may rise, seconds per second: a route that got slower is followed in
/// minutes, a jitter spike not at all.
pub const SHORTEST_CREEP: f64 = 1e-3;

/// One user's round-trip estimate (see the module documentation).
#[derive(Clone, Debug)]
pub struct RoundTrip {
    /// `(seq, server time)` of the snapshots built whose seq is a multiple of [`STRIDE`], indexed by
    /// `seq / STRIDE % BUILT_KEPT`.
    built: Box<[(u64, f64)]>,
    /// The last [`WINDOW`] samples (s), sample n (counted from 0) at `n % WINDOW`.
    samples: [f64; WINDOW],
    /// Samples heard so far (the window holds the last `min(heard, WINDOW)`).
    heard: usize,
    estimate_s: Option<f64>,
    /// The shortest sample, crept up by [`SHORTEST_CREEP`] per second since (see [`RoundTrip::shortest_s`]).
    shortest_s: Option<f64>,
    /// Server time of the last sample (s).
    last_sample_at_s: f64,
}

impl RoundTrip {
    /// No snapshot built yet; the storage is allocated once, here.
    pub fn new() -> Self {
        RoundTrip {
            built: vec![(0, 0.0); BUILT_KEPT].into_boxed_slice(),
            samples: [0.0; WINDOW],
            heard: 0,
            estimate_s: None,
            shortest_s: None,
            last_sample_at_s: 0.0,
        }
    }

    /// Snapshot `seq` was built at `at_s` (server clock).
    pub fn built(&mut self, seq: u64, at_s: f64) {
        if seq.is_multiple_of(STRIDE) {
            self.built[slot(seq)] = (seq, at_s);
        }
    }

    /// An uplink arrived at `arrival_s` (server clock) saying its client had held snapshot `seq` for `age_s`.
    /// Returns the sample it gave, if any (seq 0 is "none yet"; a snapshot not kept, off the stride or no longer,
    /// gives none).
    pub fn heard(&mut self, arrival_s: f64, seq: u64, age_s: f64) -> Option<f64> {
        if seq == 0 || !seq.is_multiple_of(STRIDE) {
            return None;
        }
        let (kept, built_s) = self.built[slot(seq)];
        if kept != seq || !age_s.is_finite() {
            return None;
        }
        let sample = arrival_s - built_s - age_s;
        if !(0.0..=MAX_SAMPLE_S).contains(&sample) {
            return None;
        }
        self.samples[self.heard % WINDOW] = sample;
        self.heard += 1;
        self.estimate_s = Some(high_percentile(&self.samples[..self.heard.min(WINDOW)]));
        self.shortest_s = Some(match self.shortest_s {
            Some(shortest) => (shortest + SHORTEST_CREEP * (arrival_s - self.last_sample_at_s).max(0.0)).min(sample),
            None => sample,
        });
        self.last_sample_at_s = arrival_s;
        Some(sample)
    }

    /// The shortest round trip heard (s), allowed to creep up slowly: the network's own delay without its
    /// jitter, of which half is the best guess at the fastest one-way trip (the VE leads a coupling by it, see
    /// `coupling`). [`RoundTrip::estimate_s`] covers the jitter instead.
    pub fn shortest_s(&self) -> Option<f64> {
        self.shortest_s
    }

    /// The round trip (s), once an uplink has answered a snapshot.
    pub fn estimate_s(&self) -> Option<f64> {
        self.estimate_s
    }
}

/// The longest of `kept` once its longest share set aside ([`IGNORED_PER_WINDOW`] per [`WINDOW`]), on a
/// copy (the VE tick calls it for every user's sample: no allocation).
fn high_percentile(kept: &[f64]) -> f64 {
    let mut sorted = [0.0; WINDOW];
    let sorted = &mut sorted[..kept.len()];
    sorted.copy_from_slice(kept);
    let ignored = kept.len() * IGNORED_PER_WINDOW / WINDOW;
    let rank = kept.len() - 1 - ignored;
    *sorted.select_nth_unstable_by(rank, f64::total_cmp).1
}

fn slot(seq: u64) -> usize {
    ((seq / STRIDE) % BUILT_KEPT as u64) as usize
}

impl Default for RoundTrip {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_round_trip_is_the_time_since_the_build_less_the_clients_hold() {
        let mut rt = RoundTrip::new();
        assert_eq!(rt.estimate_s(), None);
        // Snapshots every ms; a 40 ms downlink, the client holds each 0.7 ms, a 60 ms uplink.
        for seq in 1..=2000u64 {
            let built = seq as f64 * 1e-3;
            rt.built(seq, built);
            if seq > 100 {
                let answered = seq - 100;
                let arrival = answered as f64 * 1e-3 + 0.040 + 0.0007 + 0.060;
                match rt.heard(arrival, answered, 0.0007) {
                    Some(sample) => assert!((sample - 0.100).abs() < 1e-9, "{sample}"),
                    None => assert!(!answered.is_multiple_of(STRIDE), "seq {answered} is kept"),
                }
            }
        }
        assert!((rt.estimate_s().unwrap() - 0.100).abs() < 1e-9);
        assert!((rt.shortest_s().unwrap() - 0.100).abs() < 1e-9);
    }

    #[test]
    fn the_shortest_trip_ignores_spikes_and_creeps_up_to_a_slower_route() {
        let mut rt = RoundTrip::new();
        // A 100 ms route, every tenth sample 150 ms later, for 10 s.
        for k in 1..=2500u64 {
            let seq = k * STRIDE;
            let built = k as f64 * 4e-3;
            rt.built(seq, built);
            let trip = if k % 10 == 0 { 0.250 } else { 0.100 };
            rt.heard(built + trip, seq, 0.0);
        }
        // (Less the creep since the last short sample: the spike arrived 154 ms after it, 0.15 ms of creep.)
        assert!((rt.shortest_s().unwrap() - 0.100).abs() < 2e-4, "{:?}", rt.shortest_s());
        assert!(rt.estimate_s().unwrap() > 0.2, "the estimate covers the spikes");
        // The route slows to 200 ms: 1 ms a second of creep, so after 10 s the shortest is 110 ms.
        for k in 2501..=5000u64 {
            let seq = k * STRIDE;
            let built = k as f64 * 4e-3;
            rt.built(seq, built);
            rt.heard(built + 0.200, seq, 0.0);
        }
        let shortest = rt.shortest_s().unwrap();
        assert!((shortest - 0.110).abs() < 1e-3, "{shortest}");
    }

    /// Feeds `rt` snapshot `k · STRIDE` built at `k · 4 ms` for each `k` in `ks`, each answered after the trip
    /// `trip(k)`; returns the estimate after each.
    fn feed(rt: &mut RoundTrip, ks: std::ops::Range<u64>, trip: impl Fn(u64) -> f64) -> Vec<f64> {
        ks.map(|k| {
            let (seq, built) = (k * STRIDE, k as f64 * 4e-3);
            rt.built(seq, built);
            rt.heard(built + trip(k), seq, 0.0).expect("a kept snapshot gives a sample");
            rt.estimate_s().expect("measured")
        })
        .collect()
    }

    #[test]
    fn lone_spikes_do_not_move_the_estimate() {
        // A 0.3 ms trip with a 6 ms stall every 100th sample (the host's scheduling, say), and once two in a row.
        let mut rt = RoundTrip::new();
        let estimates = feed(&mut rt, 1..2000, |k| if k % 100 == 0 || k == 1501 { 6e-3 } else { 0.3e-3 });
        let after_the_first_window = &estimates[WINDOW..];
        let worst = after_the_first_window.iter().fold(0.0f64, |a, &b| a.max(b));
        assert!((worst - 0.3e-3).abs() < 1e-12, "a spike moved the estimate to {worst}");
        // Four stalls within one window, the most it sets aside, still leave it at the trip.
        let estimates = feed(&mut rt, 2000..2100, |k| if k % 16 == 0 { 6e-3 } else { 0.3e-3 });
        assert!(estimates.iter().all(|&e| (e - 0.3e-3).abs() < 1e-12), "{estimates:?}");
    }

    #[test]
    fn a_longer_trip_is_followed_within_a_few_samples_and_a_shorter_one_after_a_window() {
        let mut rt = RoundTrip::new();
        feed(&mut rt, 1..500, |_| 0.3e-3);
        // The route jumps from 0.3 ms to 50 ms: the estimate covers it from the fifth long sample on.
        let estimates = feed(&mut rt, 500..600, |_| 0.050);
        let followed_after = estimates.iter().position(|&e| e > 0.050 - 1e-9).expect("followed");
        assert_eq!(followed_after + 1, IGNORED_PER_WINDOW + 1, "{:?}", &estimates[..8]);
        assert!(estimates[followed_after..].iter().all(|&e| e > 0.050 - 1e-9));
        // Back to 1 ms: the 50 ms samples rule until only the set-aside share of them is left in the window.
        let estimates = feed(&mut rt, 600..800, |_| 1e-3);
        let released_after = estimates.iter().position(|&e| e < 0.049).expect("released");
        assert_eq!(released_after + 1, WINDOW - IGNORED_PER_WINDOW, "{:?}", &estimates[..8]);
        assert!((estimates.last().unwrap() - 1e-3).abs() < 1e-12);
    }

    #[test]
    fn the_first_samples_are_taken_whole() {
        // A window still filling sets aside its share only: under 16 samples, none, so a first long sample
        // (a client still starting) is the estimate until the short ones outnumber it.
        let mut rt = RoundTrip::new();
        let estimates = feed(&mut rt, 1..40, |k| if k == 1 { 0.010 } else { 1e-3 });
        let near = |e: f64, trip: f64| (e - trip).abs() < 1e-9;
        assert!(near(estimates[0], 0.010), "{}", estimates[0]);
        assert!(near(estimates[14], 0.010), "15 samples set none aside: {}", estimates[14]);
        assert!(near(estimates[15], 1e-3), "16 set the longest aside: {}", estimates[15]);
    }

    #[test]
    fn impossible_and_unknown_answers_are_ignored() {
        let mut rt = RoundTrip::new();
        let seq = 7 * STRIDE;
        rt.built(seq, 1.0);
        rt.built(seq + 1, 1.001);
        // A snapshot never built, one off the stride, "none yet", an age longer than the time since the build,
        // a non-finite age, and a client that stopped applying snapshots long ago.
        assert_eq!(rt.heard(1.1, seq + STRIDE, 0.0), None);
        assert_eq!(rt.heard(1.1, seq + 1, 0.0), None);
        assert_eq!(rt.heard(1.1, 0, 0.0), None);
        assert_eq!(rt.heard(1.1, seq, 0.5), None);
        assert_eq!(rt.heard(1.1, seq, f64::NAN), None);
        assert_eq!(rt.heard(1.0 + MAX_SAMPLE_S + 1.0, seq, 0.0), None);
        assert_eq!(rt.estimate_s(), None);
        // A snapshot overwritten in the ring is not mistaken for the one asked about.
        rt.built(seq + STRIDE * BUILT_KEPT as u64, 5.0);
        assert_eq!(rt.heard(5.1, seq, 0.0), None);
        assert!(rt.heard(5.1, seq + STRIDE * BUILT_KEPT as u64, 0.0).is_some());
    }
}
