//! A momentum observer of the hand wrench for devices without a force sensor (De Luca's generalized-momentum
//! observer, per axis): `r = K (M v − ∫ (F_cmd + r) dt − M v₀)` converges to the external wrench as a
//! first-order filter of bandwidth K. It sees everything that is not the command — the hand, but also the
//! device's own friction and damping — so it is an estimate, used only where the paper's second manipulation
//! needs the hand wrench and no sensor gives it.

use kinloop_linkage::math::space::{Space, VecOps};

/// The observer state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HandObserver<S: Space> {
    bandwidth: f64,
    mass: S::OpVec,
    integral: S::OpVec,
    initial_momentum: S::OpVec,
    estimate: S::OpVec,
    started: bool,
}

impl<S: Space> HandObserver<S> {
    pub fn new(bandwidth: f64, mass: S::OpVec) -> Self {
        HandObserver {
            bandwidth,
            mass,
            integral: S::OpVec::zero(),
            initial_momentum: S::OpVec::zero(),
            estimate: S::OpVec::zero(),
            started: false,
        }
    }

    /// Advances by `dt_s` given the device twist now and the command applied over the last period.
    pub fn update(&mut self, dt_s: f64, twist: &S::OpVec, applied_command: &S::OpVec) -> S::OpVec {
        if self.bandwidth <= 0.0 {
            return S::OpVec::zero();
        }
        let mut momentum = *twist;
        for i in 0..S::DIM {
            momentum[i] *= self.mass[i];
        }
        if !self.started {
            self.started = true;
            self.initial_momentum = momentum;
            return self.estimate;
        }
        self.integral += (*applied_command + self.estimate) * dt_s;
        self.estimate = (momentum - self.integral - self.initial_momentum) * self.bandwidth;
        if !self.estimate.is_finite() {
            self.reset();
        }
        self.estimate
    }

    pub fn reset(&mut self) {
        self.started = false;
        self.integral = S::OpVec::zero();
        self.estimate = S::OpVec::zero();
    }
}
