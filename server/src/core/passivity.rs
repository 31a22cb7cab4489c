//! Time-domain passivity observer and controller on each coupling (Hannaford & Ryu 2002, in the
//! energy-bookkeeping form Ryu and Artigas use for delayed teleoperation).
//!
//! **What is observed.** Seen from the VE, a user's coupling (the graphics-controller PD, the network delay
//! and the client's local model behind it) is a one-port at the user's OP. The human's force channel F_h
//! is not part of it: that energy is the human's to give. The observer integrates the energy this port has
//! *absorbed* from the VE,
//! ```text
//! E_obs(n) = − Σ_{k ≤ n} F_c(k) · ẋ_op(k+1) · h,
//! ```
//! where `F_c` is the wrench the step applied minus `w F_h` (the PD and the controller's own damper) and
//! `ẋ_op(k+1) = J q̇⁺` the OP velocity that step produced (the work semi-implicit Euler actually does). A
//! spring-damper tied to a consistent reference keeps `E_obs ≥ 0`: it can give back what it stored, never
//! more. With a delayed reference it can turn negative: the coupling is generating energy.
//!
//! **What is controlled.** While `E_obs < 0`, the next tick adds a damper `α` at the OP sized to dissipate
//! the whole deficit in one tick at the current velocity, `α = −E_obs / (h ‖ẋ_op‖²_L)` with the
//! unit-consistent norm `‖(v, ω)‖²_L = |v|² + L²|ω|²` (so α is `α` on linear axes and `α L²` on angular
//! ones), capped by `passivity_max_damping`. Under implicit coupling the damper is integrated implicitly,
//! so any α is stable; what a tick could not dissipate stays in `E_obs` and is dissipated next.

use kinloop_linkage::{Space, VecOps};

/// Energy account of one coupling.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PassivityObserver {
    /// Energy the coupling has absorbed from the VE so far (J); negative means it generated energy.
    pub absorbed_j: f64,
    /// Energy the controller's damper dissipated (J).
    pub dissipated_j: f64,
    /// Ticks in which the controller added damping.
    pub activations: u64,
}

impl PassivityObserver {
    /// The damper for the coming tick: zero while the port is passive or the OP is at rest.
    pub fn damping<S: Space>(&mut self, op_twist: &S::OpVec, dt: f64, length_scale: f64, max: f64) -> S::OpVec {
        let mut alpha = S::OpVec::zero();
        if self.absorbed_j >= 0.0 {
            return alpha;
        }
        let l2 = length_scale * length_scale;
        let speed2 = S::op_lin(op_twist).dot(&S::op_lin(op_twist)) + l2 * S::op_ang(op_twist).dot(&S::op_ang(op_twist));
        if speed2 <= f64::MIN_POSITIVE {
            return alpha;
        }
        let a = (-self.absorbed_j / (dt * speed2)).min(max);
        let lin = <S::Point as VecOps>::LEN;
        for axis in 0..S::DIM {
            alpha[axis] = if axis < lin { a } else { a * l2 };
        }
        self.activations += 1;
        alpha
    }

    /// Books one step: the controller-side wrench `controller_wrench` (PD plus damper) moved the OP at
    /// `op_velocity_after` for `dt`; `damper_wrench` is the damper's share.
    pub fn observe<S: Space>(
        &mut self,
        controller_wrench: &S::OpVec,
        damper_wrench: &S::OpVec,
        op_velocity_after: &S::OpVec,
        dt: f64,
    ) {
        let absorbed = -controller_wrench.dot(op_velocity_after) * dt;
        let dissipated = -damper_wrench.dot(op_velocity_after) * dt;
        if absorbed.is_finite() && dissipated.is_finite() {
            self.absorbed_j += absorbed;
            self.dissipated_j += dissipated;
        }
    }
}
