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
    /// Steps whose start took out of the kinetic energy what earlier steps made (`VeConfig::energy_guard`).
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
}
