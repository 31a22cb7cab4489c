//! The safety envelope around every command the core sends:
//! - **limits**: the force and the torque are each scaled down, direction kept, until within the device's
//!   peaks; components the device cannot actuate (a peak of 0) are zeroed first, so an unactuated axis never
//!   shrinks the rest;
//! - **gate**: an output level in [0, 1] that ramps up over `ramp_in` while the core is healthy and down over
//!   `fade_out` while the newest snapshot is stale; the gain applied is the smoothstep of that level, so the
//!   force starts and stops without a step in value or slope, and a stale link reaches exactly zero within
//!   `fade_out`;
//! - **non-finite values** are never commanded: the caller sends zero, counts and flags it (see `HapticCore`);
//!   nor are absurd ones: a device reading or a local-model state outside the protocol's ranges
//!   ([`usable_state`]) is treated as non-finite.

use kinloop_linkage::math::space::OpPose;
pub use kinloop_linkage::math::space::PartScales;
use kinloop_linkage::math::space::{clip_wrench_parts, Space, VecOps};
use kinloop_protocol::codec::limits::{MAX_POSITION, MAX_SPEED};

use super::config::SafetyConfig;
use crate::device::DeviceSpec;

/// Peak force and torque of a device.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrenchLimits {
    /// N; 0 when the device renders no force.
    pub max_force_n: f64,
    /// N m; 0 when the device renders no torque.
    pub max_torque_nm: f64,
}

impl WrenchLimits {
    /// The limits of `spec` (non-finite or negative peaks read as 0: refuse to render rather than guess).
    pub fn of(spec: &DeviceSpec) -> Self {
        let sane = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        WrenchLimits { max_force_n: sane(spec.max_force_n), max_torque_nm: sane(spec.max_torque_nm) }
    }

    /// No torque is rendered: the grasp is a pin, its angle the linkage's business, not the hand's.
    pub fn pins_the_grasp(&self) -> bool {
        self.max_torque_nm == 0.0
    }
}

/// Zeroes the linear or angular part of `w` when the device cannot actuate it.
pub fn mask_unactuated<S: Space>(w: &S::OpVec, limits: &WrenchLimits) -> S::OpVec {
    let linear = <S::Point as VecOps>::LEN;
    let mut out = *w;
    for i in 0..S::DIM {
        let peak = if i < linear { limits.max_force_n } else { limits.max_torque_nm };
        if peak == 0.0 {
            out[i] = 0.0;
        }
    }
    out
}

/// `max(|f| / f_max, |τ| / τ_max)` over the actuated parts: 1 means exactly at a limit.
pub fn force_ratio<S: Space>(w: &S::OpVec, limits: &WrenchLimits) -> f64 {
    let ratio = |norm: f64, peak: f64| if peak > 0.0 { norm / peak } else { 0.0 };
    ratio(S::op_lin(w).norm(), limits.max_force_n).max(ratio(S::op_ang(w).norm(), limits.max_torque_nm))
}

/// The wrench within `limits` and the scales applied to its force and to its torque (1 where nothing was
/// cut). Force and torque are limited apart, each keeping its direction: a device's peaks are rated apart,
/// and scaling the whole wrench down when only the torque is over gives up the force that holds the joints
/// (the testbed's firm wrist asking 0.65 N m of `sim:paper`'s 0.2 N m cut the joint-constraint force to a
/// sixth, and the device broke through the closed loop by 4 cm). Unactuated parts are zeroed and do not
/// count as a cut. A non-finite wrench gives zero and scales 0.
pub fn limit_wrench_parts<S: Space>(w: &S::OpVec, limits: &WrenchLimits) -> (S::OpVec, PartScales) {
    if !w.is_finite() {
        return (S::OpVec::zero(), PartScales { force: 0.0, torque: 0.0 });
    }
    let actuated = mask_unactuated::<S>(w, limits);
    // A hair under each limit, so rounding never leaves a part a few ulps above it.
    let under = 1.0 - 1e-12;
    clip_wrench_parts::<S>(&actuated, limits.max_force_n * under, limits.max_torque_nm * under)
}

/// [`limit_wrench_parts`]'s wrench and the smaller of its scales.
pub fn limit_wrench<S: Space>(w: &S::OpVec, limits: &WrenchLimits) -> (S::OpVec, f64) {
    let (limited, scales) = limit_wrench_parts::<S>(w, limits);
    (limited, scales.min())
}

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
}

impl OutputGate {
    /// A closed gate (level 0).
    pub fn new(config: &SafetyConfig) -> Self {
        OutputGate { level: 0.0, ramp_in_s: config.ramp_in.as_secs_f64(), fade_out_s: config.fade_out.as_secs_f64() }
    }

    /// Moves the level for `dt_s` toward open (`healthy`) or closed; returns the gain to apply.
    pub fn update(&mut self, dt_s: f64, healthy: bool) -> f64 {
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

/// A pose and twist a device can read or a local model can hold: finite, the position within 1 km and the
/// twist within 1 km/s or rad/s (the protocol's ranges, beyond which the server refuses the uplink that
/// carries them). A corrupt device reading, or a local model driven off by terms at the edge of their own
/// ranges (b̂ = 1e6 rad/s² spun one to 1,500 rad/s in 2 ms), fails it.
pub fn usable_state<S: Space>(pose: &OpPose<S>, twist: &S::OpVec) -> bool {
    within(pose.position.as_slice(), MAX_POSITION)
        && S::rot_is_finite(&pose.rotation)
        && within(twist.as_slice(), MAX_SPEED)
}
