//! The client's own gains, designed from its device under the mapping the server chose
//! (`Welcome::mapping`). The server
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
//! 4. **The local model** takes the position channels' reaction at the end of its step
//!    (`channel_reaction`), which is stable for any stiffness and damping on any mass, so the channels keep
//!    the device's budget however light the OP is: a hand holding the load stretches them by `F / K_pc`.
//!    Their stiffness stays within [`CHANNEL_COUPLING_RATIO`] times the graphics controller's `K_g` on each
//!    axis (both at the device), so on the OP's lightest mass, on which both are designed, the channels'
//!    frequency is at most ten times the coupling's (80 Hz at the coupling's 8 Hz floor, 200 Hz at its 20 Hz
//!    cap). A channel stiffer than that holds the local model to the device, so its reaction, which
//!    goes up as the hand's wrench, carries b̂ (a snapshot old) back to the VE: a slider leaving its dead
//!    centre under 300 ms of delay then swings its VE more than 5 cm from the device as heard.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::{CouplingGains, Mapping};

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

/// Most the position channels' stiffness may be, as a multiple of the graphics controller's K_g on the same
/// axis at the device: the channels' frequency on the OP's lightest mass within ten times the coupling's.
pub const CHANNEL_COUPLING_RATIO: f64 = 100.0;

/// One group's budget: (stiffness, damping) in device units.
fn budget(max_stiffness: f64, max_damping: f64, mass: f64, own_damping: f64, period_s: f64) -> (f64, f64) {
    if max_stiffness.is_nan() || max_stiffness <= 0.0 {
        return (0.0, 0.0);
    }
    let damping = max_damping.min(2.0 * DEVICE_DAMPING_RATIO * (max_stiffness * mass).sqrt()).max(0.0);
    let stiffness = max_stiffness.min(PASSIVITY_MARGIN * 2.0 * (own_damping + damping) / period_s);
    (stiffness, damping)
}

/// The designed gains (device units) for `device` under `mapping`, the scene's length scale
/// `length_scale`, haptic period `period_s` (see the module documentation).
pub fn designed_gains<S: Space>(
    device: &DeviceSpec,
    mapping: &Mapping,
    coupling: &CouplingGains,
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
    let c_p = mapping.position_scale;
    // The joints' share, within the angular budget too where the device renders torque (step 3).
    let lever = (c_p * length_scale).powi(2);
    let mut joint_stiffness = JOINT_SHARE * k_lin;
    let mut joint_damping = JOINT_DAMPING_SHARE * b_lin;
    if torque && lever > 0.0 {
        joint_stiffness = joint_stiffness.min(JOINT_SHARE * k_ang / lever);
        joint_damping = joint_damping.min(JOINT_DAMPING_SHARE * b_ang / lever);
    }
    // Step 4: the channels take the rest of the device's budget, whatever the OP's mass, their stiffness within
    // `CHANNEL_COUPLING_RATIO` times the graphics controller's on each axis, at the device.
    let per_axis = |l: f64, a: f64| (0..S::DIM).map(|i| if i < lin { l } else { a }).collect::<Vec<f64>>();
    let mut position_stiffness = per_axis((1.0 - JOINT_SHARE) * k_lin, (1.0 - JOINT_SHARE) * k_ang);
    let to_device = [mapping.force_scale / c_p, mapping.torque_scale()];
    for (a, k) in position_stiffness.iter_mut().enumerate() {
        let coupling_at_device = coupling.stiffness.get(a).copied().unwrap_or(0.0) * to_device[usize::from(a >= lin)];
        if coupling_at_device > 0.0 {
            *k = k.min(CHANNEL_COUPLING_RATIO * coupling_at_device);
        }
    }
    ControllerGains {
        joint_stiffness,
        joint_damping,
        position_stiffness,
        position_damping: per_axis((1.0 - JOINT_DAMPING_SHARE) * b_lin, (1.0 - JOINT_DAMPING_SHARE) * b_ang),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::DevicePreset;
    use kinloop_linkage::math::space::{Planar, SceneKind};

    fn mapping(position_scale: f64, force_scale: f64) -> Mapping {
        Mapping { position_scale, force_scale, ..Mapping::identity() }
    }

    /// A Falcon on an OP whose lightest mass at the device is a fraction of a gram (`m c_f / c_p`): the
    /// channels take a third of the device's stiffness budget and two thirds of its damping whatever the
    /// mass, as long as the coupling is no softer than a hundredth of them.
    #[test]
    fn the_channels_keep_the_devices_budget_on_a_light_op() {
        let falcon = DevicePreset::Falcon.spec(SceneKind::Planar).unwrap();
        let (k, b) = budget(falcon.max_stiffness, falcon.max_damping, falcon.mass[0], falcon.damping[0], 1e-3);
        let map = mapping(8.0, 6.5e-4);
        // K_g on a 13 kg (VE) lightest mass, 1 g at the device, at the coupling's 20 Hz cap (no delay).
        let k_g = 13.0 * (2.0 * std::f64::consts::PI * 20.0_f64).powi(2);
        let coupling = CouplingGains { stiffness: vec![k_g, k_g, 0.0], damping: vec![1.0, 1.0, 0.0] };
        let gains = designed_gains::<Planar>(&falcon, &map, &coupling, 0.1, 1e-3);
        let expected = (1.0 - JOINT_SHARE) * k;
        assert!((gains.position_stiffness[0] - expected).abs() < 1e-9 * expected, "{gains:?} against {expected}");
        let damping = (1.0 - JOINT_DAMPING_SHARE) * b;
        assert!((gains.position_damping[1] - damping).abs() < 1e-9 * damping, "{gains:?}");
    }

    /// Against a coupling a thousand times softer at the device than the device's channel budget, the
    /// channels stop at `CHANNEL_COUPLING_RATIO` times it, on the linear and on the angular axes (the
    /// angular at the torque scale `c_f c_p`).
    #[test]
    fn the_channels_stay_within_a_hundred_couplings() {
        let paper = DevicePreset::Paper.spec(SceneKind::Planar).unwrap();
        let map = mapping(0.5, 0.02);
        let free =
            designed_gains::<Planar>(&paper, &map, &CouplingGains { stiffness: vec![], damping: vec![] }, 0.1, 1e-3);
        let (k_lin, k_ang) = (free.position_stiffness[0] / 1000.0, free.position_stiffness[2] / 1000.0);
        let coupling = CouplingGains {
            stiffness: vec![k_lin * map.position_scale / map.force_scale, 0.0, k_ang / map.torque_scale()],
            damping: vec![0.0; 3],
        };
        let capped = designed_gains::<Planar>(&paper, &map, &coupling, 0.1, 1e-3);
        let ratio = |a: usize, k: f64| capped.position_stiffness[a] / k;
        assert!((ratio(0, k_lin) - CHANNEL_COUPLING_RATIO).abs() < 1e-9, "{capped:?}");
        assert!((ratio(2, k_ang) - CHANNEL_COUPLING_RATIO).abs() < 1e-9, "{capped:?}");
        // No coupling on an axis (a pinned grasp's angle, here y) leaves the budget.
        assert_eq!(capped.position_stiffness[1], free.position_stiffness[1]);
    }
}
