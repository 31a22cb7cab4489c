//! The client's own gains, designed from its device and from what the server's survey found at the
//! operational point (`Welcome::op`) under the mapping the server chose (`Welcome::mapping`). The server
//! designs the graphics controller (the VE side); the client designs the loops it closes itself, each at its
//! own rate and with margin. Gains are in device units (what the hand feels); the core converts them to the
//! VE units its controllers compute in.
//!
//! Per group of axes (linear; angular when the device actuates torque), with T the haptic period, m and b
//! the device's own mass and viscous damping:
//! 1. **Device damping**: `B = min(B_max, 2 ζ √(K_max m))`, ζ = [`DEVICE_DAMPING_RATIO`]: enough to damp the
//!    device's mass on the stiffest spring it renders, never more than the device renders stably.
//! 2. **Device stiffness**: `K = min(K_max, η · 2 (b + B) / T)`. A sampled spring-damper on a device is
//!    stable while `K T / 2 < b + B` (Colgate & Schenkel, J. Robotic Systems 14(1), 1997, with the virtual
//!    damping on the side of stability as Gil et al. found, IEEE TCST 2004); η = [`PASSIVITY_MARGIN`]
//!    halves the bound. `K_max` is the device's own rating, which already embeds what its electronics and
//!    friction allow; on desktop devices it binds first.
//! 3. **Split** between the joint-constraint controller (paper Fig 4, `k_j`, `b_j`, along the constrained
//!    directions) and the position channels (`K_pc`, `B_pc`, every direction): [`JOINT_SHARE`] of the
//!    stiffness and [`JOINT_DAMPING_SHARE`] of the damping to the joints, the rest to the channels, so that
//!    along a constrained direction the device feels at most `K` and `B`. The damping goes mostly to the
//!    channels because they alone hold the device to the local model in the free directions, while the
//!    joints never act without them: a third of `K` with two thirds of `B` damps the device's mass at
//!    ζ ≈ 0.8, where a third of each leaves it at 0.4 (less with a firm hand's mass), which let a
//!    five-bar robot's effector under a firm hand make more energy over its tour than the criterion allows.
//!    The
//!    joint-constraint controller acts through the unit-consistent coordinates `(v, L ω)`, so on the angular
//!    axes the device feels `k_j (c_p L)²`; with torque actuation `k_j` and `b_j` also stay within the
//!    angular budget's share.
//! 4. **The local model**: the position channels' reaction drives the local model, a mass as light as the
//!    OP's lightest direction over its reach (`m_op = 1 / max λ(Λ⁻¹)`), integrated once a period. A spring
//!    on a mass integrated at step T is stable for `K T² / m < 4` and a damper for `B T / m < 2`; the channels
//!    keep a quarter and a half of these (in VE units, `K_pc c_p / c_f ≤ m_op / T²`,
//!    `B_pc c_p / c_f ≤ m_op / T`), so no OP is too light for its device's channels.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::{Mapping, OpSummary};

use super::config::ControllerGains;
use crate::device::DeviceSpec;

/// Damping ratio of the device's mass on its stiffest spring.
pub const DEVICE_DAMPING_RATIO: f64 = 0.7;
/// Fraction of the sampled-spring stability bound used.
pub const PASSIVITY_MARGIN: f64 = 0.5;
/// Share of the stiffness budget given to the joint-constraint controller.
pub const JOINT_SHARE: f64 = 2.0 / 3.0;
/// Share of the damping budget given to the joint-constraint controller (the rest damps the position
/// channels, which act in every direction).
pub const JOINT_DAMPING_SHARE: f64 = 1.0 / 3.0;
/// Fraction of the local model's stability bounds (`K T² / m ≤ 1`, `B T / m ≤ 1`) the position channels use.
pub const LOCAL_MODEL_MARGIN: f64 = 0.25;

/// One group's budget: (stiffness, damping) in device units.
fn budget(max_stiffness: f64, max_damping: f64, mass: f64, own_damping: f64, period_s: f64) -> (f64, f64) {
    if max_stiffness.is_nan() || max_stiffness <= 0.0 {
        return (0.0, 0.0);
    }
    let damping = max_damping.min(2.0 * DEVICE_DAMPING_RATIO * (max_stiffness * mass).sqrt()).max(0.0);
    let stiffness = max_stiffness.min(PASSIVITY_MARGIN * 2.0 * (own_damping + damping) / period_s);
    (stiffness, damping)
}

/// The designed gains (device units) for `device` at the OP `op` under `mapping`, length scale
/// `length_scale`, haptic period `period_s` (see the module documentation).
pub fn designed_gains<S: Space>(
    device: &DeviceSpec,
    mapping: &Mapping,
    op: &OpSummary,
    length_scale: f64,
    period_s: f64,
) -> ControllerGains {
    let lin = <S::Point as VecOps>::LEN;
    let first = |v: &[f64], at: usize| v.get(at).copied().unwrap_or(0.0);
    let (k_lin, b_lin) =
        budget(device.max_stiffness, device.max_damping, first(&device.mass, 0), first(&device.damping, 0), period_s);
    let torque = device.max_torque_nm > 0.0;
    let (k_ang, b_ang) = if torque {
        budget(
            device.max_angular_stiffness,
            device.max_angular_damping,
            first(&device.mass, lin),
            first(&device.damping, lin),
            period_s,
        )
    } else {
        (0.0, 0.0)
    };
    let (c_p, c_f, c_t) = (mapping.position_scale, mapping.force_scale, mapping.torque_scale());
    // The joints' share, within the angular budget too where the device renders torque (step 3).
    let lever = (c_p * length_scale).powi(2);
    let mut joint_stiffness = JOINT_SHARE * k_lin;
    let mut joint_damping = JOINT_DAMPING_SHARE * b_lin;
    if torque && lever > 0.0 {
        joint_stiffness = joint_stiffness.min(JOINT_SHARE * k_ang / lever);
        joint_damping = joint_damping.min(JOINT_DAMPING_SHARE * b_ang / lever);
    }
    // Step 4: the local model's lightest mass and inertia (VE units) bound the channels.
    let lightest = |inverse: f64| if inverse > 0.0 { 1.0 / inverse } else { f64::INFINITY };
    let (m_op, i_op) = (lightest(op.inverse_mass_max), lightest(op.inverse_rotational_inertia_max));
    let t = period_s;
    let channel_lin = ((1.0 - JOINT_SHARE) * k_lin).min(LOCAL_MODEL_MARGIN * c_f / c_p * m_op / (t * t));
    let channel_lin_damping = ((1.0 - JOINT_DAMPING_SHARE) * b_lin).min(LOCAL_MODEL_MARGIN * c_f / c_p * m_op / t);
    let channel_ang = ((1.0 - JOINT_SHARE) * k_ang).min(LOCAL_MODEL_MARGIN * c_t * i_op / (t * t));
    let channel_ang_damping = ((1.0 - JOINT_DAMPING_SHARE) * b_ang).min(LOCAL_MODEL_MARGIN * c_t * i_op / t);
    let per_axis = |l: f64, a: f64| (0..S::DIM).map(|i| if i < lin { l } else { a }).collect();
    ControllerGains {
        joint_stiffness,
        joint_damping,
        position_stiffness: per_axis(channel_lin, channel_ang),
        position_damping: per_axis(channel_lin_damping, channel_ang_damping),
    }
}
