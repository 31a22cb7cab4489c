//! Counters of a [`VeCore`](super::VeCore), cheap to copy out for stats.

/// What the VE has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct VeMetrics {
    /// VE steps taken.
    pub ticks: u64,
    /// Ticks skipped because the VE fell too far behind.
    pub skipped_ticks: u64,
    /// Ticks after which snapshots were built.
    pub snapshot_ticks: u64,
    /// Snapshots built and offered.
    pub snapshots_built: u64,
    /// Snapshots not offered (non-finite dynamics or failed wire checks).
    pub snapshots_withheld: u64,
    /// Failed steps after which the last good state was restored.
    pub state_restores: u64,
    /// Uplinks used.
    pub uplinks_accepted: u64,
    /// Uplinks refused as broken or hostile.
    pub uplinks_rejected: u64,
    /// Uplinks used with their hand wrench clipped to the device's rating.
    pub uplinks_clipped: u64,
    /// Uplinks ignored as stale or duplicate.
    pub uplinks_stale: u64,
    /// Users present now (leaving ones not counted).
    pub users: u32,
    /// Joins accepted.
    pub users_joined: u64,
    /// Users removed after leaving.
    pub users_left: u64,
    /// Joins refused.
    pub joins_refused: u64,
    /// Ticks in which some passivity controller scaled a PD down.
    pub passivity_activations: u64,
    /// Steps whose end took out of the kinetic energy what the step made (`VeConfig::energy_guard`).
    pub energy_guard_activations: u64,
    /// Energy those steps took out, in the scene's units (J in SI).
    pub energy_guard_removed: f64,
    /// Clients' energy reports refused (non-finite, negative, shrinking, or faster than the device): the
    /// coupling kept the last good one.
    pub energy_reports_refused: u64,
    /// Couplings softened mid-session because their user's round trip grew beyond what they were designed
    /// for (`design::soften`).
    pub couplings_softened: u64,
    /// Closure residual norm at the start of the last step (m).
    pub closure_error: f64,
    /// Largest closure residual seen (m).
    pub max_closure_error: f64,
    /// Events dropped because nobody drained the queue.
    pub events_dropped: u64,
    /// Offered room states the VE resumed from.
    pub resumes_accepted: u64,
    /// Offered room states refused (by the VE, or by the driver for their signature, scene or age).
    pub resumes_refused: u64,
    /// The round trips the users' sharing of one another's hands was judged by (`sharing`).
    pub sharing: SharingMetrics,
}

/// Upper edges (s) of [`SharingMetrics`]' round-trip bins; the last bin holds everything longer.
pub const TRIP_BIN_EDGES_S: [f64; 7] = [0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3, 8e-3, 16e-3];

/// What the weight of the other users' hands was judged by: the round-trip samples heard and, per snapshot
/// round with two or more pushing users, the exchange's round trip (`sharing::others_weight`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SharingMetrics {
    /// Round-trip samples heard, every user's (`round_trip::RoundTrip::heard`).
    pub samples: u64,
    /// Those samples by length, in the bins [`TRIP_BIN_EDGES_S`] bound.
    pub sample_bins: [u64; 8],
    /// Snapshot rounds with two or more pushing users.
    pub rounds: u64,
    /// Those rounds whose exchange round trip took the others' hands below whole for the users with the most
    /// others (longer than the exchange delay over their number, or unmeasured).
    pub rounds_weighted: u64,
    /// Rounds in which the longest estimate alone, without the jitter buffer's hold, was over that bound.
    pub rounds_over_by_estimate: u64,
    /// Rounds in which some pushing user's jitter buffer was holding (its hold added to the round trip).
    pub rounds_held: u64,
    /// Rounds in which some pushing user's round trip was not measured yet.
    pub rounds_unmeasured: u64,
    /// Pushing users whose own round trip (hold included) was over the bound, summed over the rounds.
    pub users_over: u64,
    /// The exchange's round trip per round (unmeasured ones aside), in the bins [`TRIP_BIN_EDGES_S`] bound.
    pub trip_bins: [u64; 8],
}

impl SharingMetrics {
    /// Counts a round-trip sample of `sample_s`.
    pub fn note_sample(&mut self, sample_s: f64) {
        self.samples += 1;
        self.sample_bins[bin(sample_s)] += 1;
    }
}

/// The bin of a round trip of `trip_s`.
pub fn bin(trip_s: f64) -> usize {
    TRIP_BIN_EDGES_S.iter().take_while(|edge| trip_s > **edge).count()
}
