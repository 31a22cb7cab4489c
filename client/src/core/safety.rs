//! The safety envelope around every command the core sends:
//! - **limits**: the force and the torque are each scaled down, direction kept, until within the device's
//!   peaks ([`kinloop_protocol::wrench_limits`], shared with the server);
//! - **gate**: an output level in [0, 1] that ramps up over `ramp_in` while the core is healthy and down over
//!   `fade_out` while the newest snapshot is stale; the gain applied is the smoothstep of that level, so the
//!   force starts and stops without a step in value or slope, and a stale link reaches exactly zero within
//!   `fade_out` of running ticks; the level moves at most one nominal period a tick, so a loop that stalled
//!   (the device held its last command meanwhile) resumes the fade where it was instead of stepping the force;
//! - **non-finite values** are never commanded: the caller sends zero, counts and flags it (see `HapticCore`);
//!   nor are absurd ones: a device reading or a local-model state outside the protocol's ranges
//!   ([`usable_device_state`], [`usable_model_state`]) is treated as non-finite.

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
pub use kinloop_linkage::math::space::PartScales;
use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::codec::limits::{MAX_POSITION, MAX_SCENE_POSITION, MAX_SCENE_SPEED, MAX_SPEED};
pub use kinloop_protocol::wrench_limits::{
    force_ratio, limit_wrench, limit_wrench_parts, mask_unactuated, WrenchLimits,
};

use super::config::SafetyConfig;
use crate::device::DeviceSpec;

/// `3s² − 2s³`: 0 → 1 with zero slope at both ends.
pub fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// The output gate (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputGate {
    level: f64,
    ramp_in_s: f64,
    fade_out_s: f64,
    /// The longest step a tick may move the level by, in seconds (the haptic loop's nominal period).
    max_step_s: f64,
}

impl OutputGate {
    /// A closed gate (level 0) for a loop of nominal period `period`.
    pub fn new(config: &SafetyConfig, period: Duration) -> Self {
        OutputGate {
            level: 0.0,
            ramp_in_s: config.ramp_in.as_secs_f64(),
            fade_out_s: config.fade_out.as_secs_f64(),
            max_step_s: period.as_secs_f64(),
        }
    }

    /// Moves the level for `dt_s` (at most one nominal period) toward open (`healthy`) or closed; returns the
    /// gain to apply.
    pub fn update(&mut self, dt_s: f64, healthy: bool) -> f64 {
        let dt_s = dt_s.min(self.max_step_s);
        let step = |time: f64| if time > 0.0 { dt_s / time } else { 1.0 };
        self.level = if healthy {
            (self.level + step(self.ramp_in_s)).min(1.0)
        } else {
            (self.level - step(self.fade_out_s)).max(0.0)
        };
        self.gain()
    }

    /// The gain now.
    pub fn gain(&self) -> f64 {
        smoothstep(self.level)
    }

    /// Closes the gate at once (after a fault: the next output ramps in from zero).
    pub fn close(&mut self) {
        self.level = 0.0;
    }
}

/// Every number within `±bound` (false for NaN).
pub fn within(values: &[f64], bound: f64) -> bool {
    values.iter().all(|x| x.abs() <= bound)
}

/// A pose and twist a device can read (device units): finite, the position within 1 km and the twist within
/// 1 km/s or rad/s (the protocol's device ranges). A corrupt device reading fails it.
pub fn usable_device_state<S: Space>(pose: &OpPose<S>, twist: &S::OpVec) -> bool {
    within(pose.position.as_slice(), MAX_POSITION)
        && S::rot_is_finite(&pose.rotation)
        && within(twist.as_slice(), MAX_SPEED)
}

/// A pose and twist a local model can hold (the scene's units): finite and within the protocol's scene
/// ranges, beyond which the server refuses the uplink that carries them. A local model driven off by terms at
/// the edge of their own ranges (b̂ = 1e6 rad/s² spun one to 1,500 rad/s in 2 ms) fails it.
pub fn usable_model_state<S: Space>(pose: &OpPose<S>, twist: &S::OpVec) -> bool {
    within(pose.position.as_slice(), MAX_SCENE_POSITION)
        && S::rot_is_finite(&pose.rotation)
        && within(twist.as_slice(), MAX_SCENE_SPEED)
}

/// The damper that holds a released handle: half the device's highest stable damping on each axis (linear and
/// angular), against the handle's twist, in device units.
pub fn brake<S: Space>(device: &DeviceSpec, twist: &S::OpVec) -> S::OpVec {
    full_damping::<S>(device, twist) * 0.5
}

/// The device's highest stable damping on each axis (linear and angular) against `twist`, in device units.
pub fn full_damping<S: Space>(device: &DeviceSpec, twist: &S::OpVec) -> S::OpVec {
    let lin = <S::Point as VecOps>::LEN;
    let mut w = S::OpVec::zero();
    for a in 0..S::DIM {
        let b = if a < lin { device.max_damping } else { device.max_angular_damping };
        w[a] = -b * twist[a];
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tick that comes 20 ms late while the link is stale moves the gate as one on-time tick does: the
    /// device held its command through the stall, and the fade goes on from there without a step.
    #[test]
    fn a_late_tick_moves_the_gate_by_one_period_at_most() {
        let config = SafetyConfig::default();
        let period = Duration::from_millis(1);
        let mut gate = OutputGate::new(&config, period);
        let ramp_ticks = (config.ramp_in.as_secs_f64() / period.as_secs_f64()).ceil() as usize;
        for _ in 0..ramp_ticks + 1 {
            gate.update(period.as_secs_f64(), true);
        }
        assert_eq!(gate.gain(), 1.0, "open after the ramp");
        let mut on_time = gate;
        let after_one_period = on_time.update(period.as_secs_f64(), false);
        let after_stall = gate.update(0.020, false);
        assert_eq!(after_stall, after_one_period);
        let uncapped = smoothstep(1.0 - 0.020 / config.fade_out.as_secs_f64());
        assert!(1.0 - after_stall < (1.0 - uncapped) / 10.0, "{after_stall} against {uncapped} uncapped");
        // The fade still ends: stale ticks close it within fade_out of ticks.
        let fade_ticks = (config.fade_out.as_secs_f64() / period.as_secs_f64()).ceil() as usize;
        for _ in 0..fade_ticks {
            gate.update(0.020, false);
        }
        assert_eq!(gate.gain(), 0.0);
    }
}
