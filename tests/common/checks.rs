//! What every session must end with, whatever was done to it: no panic, no state restore in the
//! VE, the loop closed, no NaN reaching a device and no force above a device's limit.

use kinloop_client::device::DevicePreset;
use kinloop_client::driver::ClientStats;
use kinloop_linkage::math::space::SceneKind;
use kinloop_server::ServerStats;

use super::records::{linear, Tick};

/// The VE's side: never restored, loop closed to 1e-6 m.
pub fn assert_ve_unharmed(what: &str, ve: &ServerStats) {
    let core = &ve.ve.core;
    assert_eq!(core.state_restores, 0, "{what}: the VE restored its state");
    assert!(core.max_closure_error <= 1e-6, "{what}: loop closure {:.3e} m", core.max_closure_error);
    assert!(core.snapshots_withheld == 0, "{what}: {} snapshots withheld", core.snapshots_withheld);
}

/// A client's side from its counters: force commanded and within the limit, nothing non-finite.
pub fn assert_client_unharmed(what: &str, stats: &ClientStats) {
    assert!(stats.max_force_ratio <= 1.0, "{what}: force ratio {}", stats.max_force_ratio);
    assert!(stats.max_force_ratio > 0.0, "{what}: no force was ever rendered");
    assert_eq!(stats.core.unwrap_or_default().non_finite_events, 0, "{what}: non-finite output");
}

/// A client's side from its recording, independently of its counters: every command finite and within
/// the paper device's force and torque limits.
pub fn assert_commands_within_paper_device(what: &str, ticks: &[Tick]) {
    let spec = DevicePreset::Paper.spec(SceneKind::Planar).expect("paper device");
    for t in ticks {
        assert!(t.command.iter().all(|f| f.is_finite()), "{what}: non-finite command at {} s", t.t);
        assert!(linear(t.command) <= spec.max_force_n * (1.0 + 1e-6), "{what}: {:?} N at {} s", t.command, t.t);
        assert!(t.command[2].abs() <= spec.max_torque_nm * (1.0 + 1e-6), "{what}: {:?} at {} s", t.command, t.t);
    }
}

/// Fastest change of the output gain between two ticks (1/s). The client's fades are smoothsteps in time
/// (at most 1.5 / fade time), so a late tick moves the gain further but not faster; a step would move it
/// by up to 1 in one tick, 1000/s at 1 kHz.
pub fn fastest_gain_change(ticks: &[Tick]) -> f64 {
    ticks.windows(2).map(|w| (w[1].gain - w[0].gain).abs() / (w[1].t - w[0].t).max(1e-6)).fold(0.0, f64::max)
}

/// Ticks after the force first reached full gain that ran below it (a fade the user felt).
pub fn ticks_below_full_gain(ticks: &[Tick]) -> usize {
    let Some(first) = ticks.iter().position(|t| t.gain >= 1.0) else { return ticks.len() };
    ticks[first..].iter().filter(|t| t.gain < 1.0).count()
}

/// How long a clutch held the output faded (s): from the first tick at zero gain after the output first
/// reached full gain to the next tick back at full gain; None when the output never fades and recovers.
pub fn clutched_seconds(ticks: &[Tick]) -> Option<f64> {
    let first_full = ticks.iter().position(|t| t.gain >= 1.0)?;
    let faded = ticks[first_full..].iter().position(|t| t.gain == 0.0)? + first_full;
    let back = ticks[faded..].iter().position(|t| t.gain >= 1.0)? + faded;
    Some(ticks[back].t - ticks[faded].t)
}
