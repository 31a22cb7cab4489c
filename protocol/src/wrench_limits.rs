//! The largest force and torque a device renders or reports, and the clipping both ends do against them:
//! the client before it commands its device, the server before it applies a user's hand wrench.
//!
//! Force and torque are limited apart, each keeping its direction: a device's peaks are rated apart, and
//! scaling the whole wrench down when only the torque is over gives up the force that holds the joints.
//! Components the device cannot actuate (a peak of 0) are zeroed first, so an unactuated axis never shrinks
//! the rest.

use kinloop_linkage::math::space::{clip_wrench_parts, PartScales, Space, VecOps};

/// Peak force and torque of a device.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrenchLimits {
    /// N; 0 when the device renders no force.
    pub max_force_n: f64,
    /// N m; 0 when the device renders no torque.
    pub max_torque_nm: f64,
}

impl WrenchLimits {
    /// A device's rated peaks (non-finite or negative peaks read as 0: refuse to render rather than guess).
    pub fn rated(max_force_n: f64, max_torque_nm: f64) -> Self {
        let sane = |x: f64| if x.is_finite() && x > 0.0 { x } else { 0.0 };
        WrenchLimits { max_force_n: sane(max_force_n), max_torque_nm: sane(max_torque_nm) }
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
/// cut; see the module documentation). Unactuated parts are zeroed and do not count as a cut. A non-finite
/// wrench gives zero and scales 0.
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
