//! What the core tells its driver and its tests: per tick ([`TickOutput`], [`TickReport`] and the
//! [`ControllerWrenches`] in it) and over its life ([`CoreStats`]).

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::Uplink;

/// The wrench each controller asks for this tick, before the safety envelope, and what was commanded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerWrenches<S: Space> {
    /// Four-channel teleoperator, position channels (on the device).
    pub position_channel: S::OpVec,
    /// Joint-constraint controller.
    pub joint_constraint: S::OpVec,
    /// Impedance controller (free directions).
    pub impedance: S::OpVec,
    /// Contact force channel.
    pub contact: S::OpVec,
    /// Their sum.
    pub requested: S::OpVec,
    /// What the device is commanded after the output gate, the mapping and the limits (device units; the
    /// other wrenches here are in VE units).
    pub command: S::OpVec,
}

impl<S: Space> ControllerWrenches<S> {
    pub(super) fn zero() -> Self {
        let z = S::OpVec::zero();
        ControllerWrenches {
            position_channel: z,
            joint_constraint: z,
            impedance: z,
            contact: z,
            requested: z,
            command: z,
        }
    }
}

/// Everything one tick computed, for recording and tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickReport<S: Space> {
    /// The tick's time.
    pub time: Duration,
    /// False until the first snapshot: no model, zero output.
    pub active: bool,
    /// Device pose mapped into the VE (see `CoreConfig::index_at_first_snapshot`).
    pub device_pose: OpPose<S>,
    /// Device twist.
    pub device_twist: S::OpVec,
    /// Local model OP pose after this tick's step.
    pub model_pose: OpPose<S>,
    /// Local model OP twist.
    pub model_twist: S::OpVec,
    /// Hand wrench: measured, or the observer's estimate, or zero.
    pub hand_wrench: S::OpVec,
    /// The wrench that drove the local model this tick (and goes up as the uplink's `hand_wrench`).
    pub model_wrench: S::OpVec,
    /// Per-controller wrenches.
    pub wrenches: ControllerWrenches<S>,
    /// Output gate gain in [0, 1].
    pub gain: f64,
    /// Scale the device limits applied (1 = not clamped).
    pub clamp_scale: f64,
    /// Constrained directions counted by the core (with hysteresis).
    pub constraint_count: usize,
    /// The server's count in the snapshot in use.
    pub snapshot_constraint_count: u8,
    /// Seq of the snapshot in use (0 before the first).
    pub snapshot_seq: u64,
    /// How long ago the snapshot in use arrived.
    pub snapshot_age: Option<Duration>,
    /// `x_d ⊖ x_m`.
    pub tracking_error: S::OpVec,
    /// Uplink flags of this tick.
    pub flags: u32,
}

impl<S: Space> TickReport<S> {
    pub(super) fn idle(time: Duration) -> Self {
        let z = S::OpVec::zero();
        TickReport {
            time,
            active: false,
            device_pose: OpPose::identity(),
            device_twist: z,
            model_pose: OpPose::identity(),
            model_twist: z,
            hand_wrench: z,
            model_wrench: z,
            wrenches: ControllerWrenches::zero(),
            gain: 0.0,
            clamp_scale: 1.0,
            constraint_count: 0,
            snapshot_constraint_count: 0,
            snapshot_seq: 0,
            snapshot_age: None,
            tracking_error: z,
            flags: 0,
        }
    }
}

/// Counters over the core's life.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CoreStats {
    /// Ticks run.
    pub ticks: u64,
    /// Ticks with a local model (after the first snapshot).
    pub active_ticks: u64,
    /// Snapshots taken as newest.
    pub snapshots_accepted: u64,
    /// Snapshots dropped because a newer one was already there (latest wins).
    pub snapshots_superseded: u64,
    /// Snapshots refused as corrupt.
    pub snapshots_rejected: u64,
    /// Ticks whose device reading or output was non-finite or absurd (zero was commanded instead).
    pub non_finite_events: u64,
    /// Ticks whose command was clamped to the device limits.
    pub clamped_ticks: u64,
    /// Ticks with a stale snapshot.
    pub stale_ticks: u64,
    /// Largest `|f| / f_max` or `|τ| / τ_max` commanded: never above 1.
    pub max_force_ratio: f64,
    /// Uplinks built (one per active tick).
    pub uplinks_built: u64,
    /// Uplinks that left (all, or those through the deadband).
    pub uplinks_sent: u64,
    /// Sum of squared linear tracking errors |x_d − x_m|² over active ticks (m²).
    pub tracking_error_sum_sq: f64,
    /// Largest linear tracking error (m).
    pub tracking_error_max: f64,
    /// Snapshots whose energy books were refused (non-finite, negative, shrinking, or faster than the wire's
    /// largest wrench at its largest speed): the rest of the snapshot was used, the last good books kept.
    pub energy_reports_refused: u64,
    /// Ticks on which the device's presence sensor said no hand held it (output faded, `HAND_OFF` sent).
    pub hand_off_ticks: u64,
    /// Ticks whose pull toward the VE was applied only in part because it would have put more energy into
    /// the device-model coupling than its dampers had dissipated (`CoreConfig::passive_update`).
    pub updates_limited: u64,
}

impl CoreStats {
    /// RMS of the linear distance between device and local-model OP (m).
    pub fn tracking_error_rms(&self) -> f64 {
        if self.active_ticks == 0 {
            0.0
        } else {
            (self.tracking_error_sum_sq / self.active_ticks as f64).sqrt()
        }
    }

    /// Fraction of uplinks the deadband saved (0 without a deadband).
    pub fn uplink_saving(&self) -> f64 {
        if self.uplinks_built == 0 {
            0.0
        } else {
            1.0 - self.uplinks_sent as f64 / self.uplinks_built as f64
        }
    }
}

/// What a tick returns: the device command, the uplink to send (borrowed from the core's preallocated
/// message: a tick allocates nothing), and the report.
#[derive(Debug)]
pub struct TickOutput<'a, S: Space> {
    /// The wrench to command (device units).
    pub command: S::OpVec,
    /// The uplink to send this tick, if any.
    pub uplink: Option<&'a Uplink>,
    /// What the tick computed.
    pub report: &'a TickReport<S>,
}
