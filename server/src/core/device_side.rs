//! Thresholds stated on the device's side, in the VE's units for one user.
//!
//! The physics is unit-invariant; a threshold is only if it is stated in the scene's own scales. The VE's
//! per-user thresholds (the guards' distances, speeds and default wrench limits, the passivity controller's
//! allowance, the lead's guessing budget) are physical figures about what a hand at a device may do or
//! feel: metres, newtons, joules at the handle. [`VeConfig`](super::VeConfig) states them so, in SI at the
//! device, and this module converts them through the user's mapping (`protocol::Mapping`: device metres per
//! VE length unit `c_p`, device newtons per VE force unit `c_f`, torques and energies by `c_f c_p`, angles
//! one to one) into the units the scene is written in. A scene rewritten from metres into millimetres gets
//! `c_p` a thousand times smaller and every length threshold a thousand times larger in its numbers: the same
//! physical threshold, so the same behaviour. A user without a device is mapped one to one.
//!
//! The lead's guessing budget is a miss at the handle rather than an energy: a guess that misses the hand by
//! `δ` device metres leaves the coupling's linear spring `K` (VE units) stretched `δ / c_p`, holding
//! `½ K (δ / c_p)²`. The budget then follows the coupling the design gave this user, as the miss a hand feels
//! does; a fixed energy at the device let a soft coupling (small `c_f c_p`) guess many millimetres wrong.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::Mapping;

use super::config::{GuardLimits, VeConfig};

/// One user's thresholds, in the VE's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UserThresholds {
    /// The guards, their lengths, speeds, forces and torques in the VE's units (their names keep the SI
    /// units they have on the device's side).
    pub guards: GuardLimits,
    /// `VeConfig::passivity_allowance_j` in the VE's units of energy.
    pub passivity_allowance: f64,
    /// The energy the coupling's linear spring holds stretched by `VeConfig::coupling_lead_guess_miss_m` at the
    /// device, in the VE's units of energy (what `Coupling::steer_lead` bounds a guess by).
    pub lead_guess_energy: f64,
}

/// How many VE units one device unit is, per kind of quantity.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DeviceToVe {
    /// VE length units per device metre: `1 / c_p`.
    length: f64,
    /// VE force units per device newton: `1 / c_f`.
    force: f64,
    /// VE torque (and energy) units per device newton-metre (joule): `1 / (c_f c_p)`.
    energy: f64,
}

impl DeviceToVe {
    fn of(mapping: &Mapping) -> Self {
        let inverse = |scale: f64| 1.0 / Mapping::scale_or_one(scale);
        DeviceToVe {
            length: inverse(mapping.position_scale),
            force: inverse(mapping.force_scale),
            energy: inverse(mapping.torque_scale()),
        }
    }
}

/// The thresholds of `config` for a user mapped by `mapping` whose coupling's spring is `stiffness` (VE
/// units, per axis; the guess's budget takes its stiffest linear axis).
pub fn user_thresholds<S: Space>(config: &VeConfig, mapping: &Mapping, stiffness: &S::OpVec) -> UserThresholds {
    let to_ve = DeviceToVe::of(mapping);
    let linear_stiffness = S::op_lin(stiffness).as_slice().iter().fold(0.0f64, |k, x| k.max(*x));
    let g = &config.guards;
    UserThresholds {
        guards: GuardLimits {
            max_model_offset_m: g.max_model_offset_m * to_ve.length,
            max_model_speed_m_per_s: g.max_model_speed_m_per_s * to_ve.length,
            default_max_force_n: g.default_max_force_n * to_ve.force,
            default_max_torque_nm: g.default_max_torque_nm * to_ve.energy,
            ..*g
        },
        passivity_allowance: config.passivity_allowance_j * to_ve.energy,
        lead_guess_energy: spring_energy(linear_stiffness, config.coupling_lead_guess_miss_m * to_ve.length),
    }
}

/// `½ k x²`, zero for a stiffness that is not positive and finite (no spring holds nothing).
fn spring_energy(stiffness: f64, stretch: f64) -> f64 {
    if stiffness > 0.0 && stiffness.is_finite() {
        0.5 * stiffness * stretch * stretch
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::Vector3;

    /// A planar coupling spring of `linear` on x and y, 1 on θ.
    fn spring(linear: f64) -> Vector3<f64> {
        Vector3::new(linear, linear, 1.0)
    }

    /// A device mapped at `c_p = 0.002` (a scene in millimetres, half size on the device) and `c_f = 0.5`:
    /// a device metre is 500 VE units, a device newton 2, a joule 1000; angular speeds are not scaled.
    #[test]
    fn device_figures_become_ve_figures_through_the_mapping() {
        let config = VeConfig::default();
        let mapping = Mapping { position_scale: 0.002, force_scale: 0.5, ..Mapping::identity() };
        let t = user_thresholds::<Planar>(&config, &mapping, &spring(3000.0));
        let g = &config.guards;
        assert_eq!(t.guards.max_model_offset_m, g.max_model_offset_m * 500.0);
        assert_eq!(t.guards.max_model_speed_m_per_s, g.max_model_speed_m_per_s * 500.0);
        assert_eq!(t.guards.max_model_angular_speed_rad_per_s, g.max_model_angular_speed_rad_per_s);
        assert_eq!(t.guards.default_max_force_n, g.default_max_force_n * 2.0);
        assert!((t.guards.default_max_torque_nm - g.default_max_torque_nm * 1000.0).abs() < 1e-9);
        assert!((t.passivity_allowance - config.passivity_allowance_j * 1000.0).abs() < 1e-12);
        // The guess's miss is 500 times longer in VE units, held by a 3000-unit spring.
        let miss = config.coupling_lead_guess_miss_m * 500.0;
        assert!((t.lead_guess_energy - 0.5 * 3000.0 * miss * miss).abs() < 1e-12 * t.lead_guess_energy);
        // One to one, nothing changes.
        let same = user_thresholds::<Planar>(&config, &Mapping::identity(), &spring(3000.0));
        assert_eq!(same.guards, config.guards);
        assert_eq!(same.passivity_allowance, config.passivity_allowance_j);
    }

    /// The guess's budget is the energy of the coupling's spring at the miss: a millimetre at the device on a
    /// scene in metres mapped at `c_p = 2` is half a millimetre in the VE; a spring that is not there (zero,
    /// negative or non-finite) holds nothing, so no guess.
    #[test]
    fn the_guess_budget_is_the_spring_energy_at_the_miss() {
        let config = VeConfig { coupling_lead_guess_miss_m: 1e-3, ..VeConfig::default() };
        let mapping = Mapping { position_scale: 2.0, force_scale: 0.1, ..Mapping::identity() };
        let t = user_thresholds::<Planar>(&config, &mapping, &spring(8000.0));
        assert!((t.lead_guess_energy - 0.5 * 8000.0 * 0.25e-6).abs() < 1e-15);
        for k in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let t = user_thresholds::<Planar>(&config, &mapping, &Vector3::new(k, k, 1.0));
            assert_eq!(t.lead_guess_energy, 0.0, "{k}");
        }
    }
}
