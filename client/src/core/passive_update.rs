//! The local model's update toward the VE made passive toward the hand : an energy tank.
//!
//! The pull toward the VE (`HapticCore::pull_model`) moves the local model's state by corrections the hand did not cause. A
//! correction that stretches the device-model coupling, or speeds the model up, stores energy there that
//! then flows into the hand: energy the network made. A VE that runs away from the model (a restore, a
//! server out of step, another user's pull the model cannot explain) would drag a still hand after it with
//! as much force as the springs give.
//!
//! Here every correction is priced by what it changes in the energy the coupling and the model hold
//! ([`energy_change`] of `½ eᵀ K_pc e + ½ k_j eᵀ T P̃ T e + ½ ẋᵀ Λ̂ ẋ`: the position channels' and the
//! joint-constraint controller's springs, and the model's kinetic energy, heavy along the constrained
//! directions), and paid from a tank
//! ([`EnergyTank`]) that only the controllers' own dissipation fills: the energy their dampers took out of
//! the coupling, plus what earlier corrections gave back. A correction that would cost more than the tank
//! holds is applied in part (the energy change is convex in the fraction applied, so the fraction
//! `level / cost` costs at most the level); the rest waits for the next tick's discrepancy. So over any
//! interval the updates put into the coupling at most what its dampers dissipated in it plus the tank's
//! capacity: seen from the hand, the device-model coupling with its updates is passive whatever the delay
//! (the two-layer idea of Franken et al. 2011: a transparency layer whose actions a passivity layer's tank
//! pays for). The tank is bounded ([`TANK_CAPACITY_J`]) so a long quiet stretch cannot save up a kick.
//!
//! What the tank does not cover: the VE follows the model's pose, so a correction also moves the VE, and
//! the energy that gives the linkage is made on the server's side of the network. The pull's own loop
//! through the delay (a correction `ẋ = −x(t − T) / τ` is stable only for `T < π τ / 2`) is held by the pull's time constant of at least two round trips (`CoreConfig::free_blend_round_trips`),
//! not by the tank; the `latency` experiment's model-update rows show both.

use kinloop_linkage::math::space::{Space, VecOps};

use super::controllers::{hadamard, project_as_stiffness};

/// Most energy the tank holds (J at the device; in the VE's units it is this divided by the mapping's torque
/// scale `c_f c_p`, so that it is the same physical budget whatever units the scene is written in). The
/// coupling of the built-in scenes holds a few millijoules at their tour speeds; the tank can pay for a few
/// such corrections at once but never store up more than a hand would notice as a kick.
pub const TANK_CAPACITY_J: f64 = 0.01;

/// The springs and the model motion whose stored energy a correction changes.
pub(crate) struct CouplingSprings<'a, S: Space> {
    /// Position channels' stiffness `K_pc`, per axis.
    pub position_stiffness: &'a S::OpVec,
    /// Joint-constraint stiffness `k_j` as rendered (softened by the linearization trust), along the
    /// constrained directions.
    pub joint_stiffness: f64,
    /// Constrained-direction projector and its length scale.
    pub projector: &'a S::OpMat,
    pub length_scale: f64,
    /// The model's OP inertia `Λ̂` (physical units): its kinetic energy is `½ ẋᵀ Λ̂ ẋ`.
    pub inertia: &'a S::OpMat,
}

/// What moving the model by `moved` and changing its twist by `sped` changes in the coupling's energy, with
/// the device-model error `error` and the model twist `twist` before (the error becomes `error − moved`):
/// `mᵀK(½m − e) + k_j mᵀTP̃T(½m − e) + sᵀΛ̂(ẋ + ½s)`, the difference of the two energies in closed form.
pub(crate) fn energy_change<S: Space>(
    springs: &CouplingSprings<S>,
    error: &S::OpVec,
    twist: &S::OpVec,
    moved: &S::OpVec,
    sped: &S::OpVec,
) -> f64 {
    let stretch = *moved * 0.5 - *error;
    let position = stretch.dot(&hadamard::<S>(springs.position_stiffness, moved));
    let joints = springs.joint_stiffness
        * stretch.dot(&project_as_stiffness::<S>(springs.projector, springs.length_scale, moved));
    let kinetic = sped.dot(&(*springs.inertia * (*twist + *sped * 0.5)));
    position + joints + kinetic
}

/// Energy the device-model coupling and the local model hold with device-model error `error`
/// (`x_d ⊖ x_m`) and model twist `twist`: `½ eᵀ K_pc e + ½ k_j eᵀ T P̃ T e + ½ ẋᵀ Λ̂ ẋ`.
#[cfg(test)]
pub(crate) fn coupling_energy<S: Space>(springs: &CouplingSprings<S>, error: &S::OpVec, twist: &S::OpVec) -> f64 {
    let position = error.dot(&hadamard::<S>(springs.position_stiffness, error));
    let joints =
        springs.joint_stiffness * error.dot(&project_as_stiffness::<S>(springs.projector, springs.length_scale, error));
    let kinetic = twist.dot(&(*springs.inertia * *twist));
    0.5 * (position + joints + kinetic)
}

/// The energy the model's updates may still put into the coupling.
#[derive(Clone, Copy, Debug)]
pub(crate) struct EnergyTank {
    /// Energy held, VE units.
    level_j: f64,
    /// [`TANK_CAPACITY_J`] in VE units.
    capacity: f64,
}

impl EnergyTank {
    /// A full tank of `capacity_j` joules at the device for a device whose energy is `device_per_ve` times
    /// the VE's (the mapping's torque scale `c_f c_p`): the same physical budget in any scene units. Full,
    /// so that a session's first corrections find the model where the VE put it.
    pub fn new(capacity_j: f64, device_per_ve: f64) -> Self {
        let per = kinloop_protocol::Mapping::scale_or_one(device_per_ve);
        let capacity = capacity_j / per;
        EnergyTank { level_j: capacity, capacity }
    }

    #[cfg(test)]
    fn level_j(&self) -> f64 {
        self.level_j
    }

    /// Adds energy the controllers dissipated (a non-finite or negative amount adds nothing).
    pub fn fill(&mut self, joules: f64) {
        if joules > 0.0 && joules.is_finite() {
            self.level_j = (self.level_j + joules).min(self.capacity);
        }
    }

    /// The fraction of a correction to apply, given what the whole correction would change in the stored
    /// energy (`cost_j`; negative when it takes energy out, which goes back into the tank), and books it.
    pub fn admit(&mut self, cost_j: f64) -> f64 {
        if !cost_j.is_finite() {
            return 0.0;
        }
        if cost_j <= self.level_j {
            self.level_j = (self.level_j - cost_j).min(self.capacity);
            return 1.0;
        }
        // Convex in the fraction α with no cost at α = 0: α = level / cost costs at most the level.
        let fraction = self.level_j / cost_j;
        self.level_j = 0.0;
        fraction
    }
}

/// The energy the controllers' dampers dissipate in a tick of `dt_s`: with error rate `error_rate`
/// (`ẋ_d − ẋ_m`) and the dampers' wrench on the device `damping_wrench` (`−B ė`, the model receiving the
/// opposite), the power they take out of the coupling is `−ėᵀ w`; times the share of the wrench the device
/// actually rendered.
pub(crate) fn damper_dissipation<S: Space>(
    error_rate: &S::OpVec,
    damping_wrench: &S::OpVec,
    rendered_share: f64,
    dt_s: f64,
) -> f64 {
    (-error_rate.dot(damping_wrench)).max(0.0) * rendered_share.clamp(0.0, 1.0) * dt_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::{Matrix3, Vector3};

    fn springs<'a>(k: &'a Vector3<f64>, p: &'a Matrix3<f64>, m: &'a Matrix3<f64>) -> CouplingSprings<'a, Planar> {
        CouplingSprings { position_stiffness: k, joint_stiffness: 400.0, projector: p, length_scale: 0.1, inertia: m }
    }

    #[test]
    fn the_coupling_energy_is_the_springs_and_the_free_motion_in_closed_form() {
        let k = Vector3::new(100.0, 200.0, 0.5);
        // x constrained, y and rotation free.
        let p = Matrix3::from_diagonal(&Vector3::new(1.0, 0.0, 0.0));
        let m = Matrix3::from_diagonal(&Vector3::new(0.0, 2.0, 0.01));
        let (e, v) = (Vector3::new(0.01, -0.02, 0.1), Vector3::new(0.3, 0.1, 2.0));
        let expected =
            0.5 * (100.0 * 1e-4 + 200.0 * 4e-4 + 0.5 * 0.01) + 0.5 * 400.0 * 1e-4 + 0.5 * (2.0 * 0.01 + 0.01 * 4.0);
        let got = coupling_energy(&springs(&k, &p, &m), &e, &v);
        assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
    }

    #[test]
    fn the_energy_change_in_closed_form_is_the_difference_of_the_energies() {
        let k = Vector3::new(300.0, 120.0, 1.5);
        let p = Matrix3::new(0.5, 0.5, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0);
        let m = Matrix3::new(1.5, 0.2, 0.01, 0.2, 0.9, -0.02, 0.01, -0.02, 0.03);
        let s = springs(&k, &p, &m);
        let (e, v) = (Vector3::new(0.003, -0.002, 0.04), Vector3::new(0.05, -0.1, 0.7));
        let (moved, sped) = (Vector3::new(-0.001, 0.004, -0.02), Vector3::new(0.02, 0.03, -0.4));
        let difference = coupling_energy(&s, &(e - moved), &(v + sped)) - coupling_energy(&s, &e, &v);
        let closed = energy_change(&s, &e, &v, &moved, &sped);
        assert!((closed - difference).abs() < 1e-12 * difference.abs().max(1e-3), "{closed} vs {difference}");
    }

    #[test]
    fn the_tank_pays_corrections_only_from_what_was_dissipated() {
        let mut tank = EnergyTank::new(TANK_CAPACITY_J, 1.0);
        // A costly correction empties the tank and is applied in part.
        let fraction = tank.admit(4.0 * TANK_CAPACITY_J);
        assert!((fraction - 0.25).abs() < 1e-12);
        assert_eq!(tank.level_j(), 0.0);
        // Empty: nothing more goes in until the dampers dissipate some.
        assert_eq!(tank.admit(1e-6), 0.0);
        tank.fill(2e-3);
        assert_eq!(tank.admit(1e-3), 1.0);
        assert!((tank.level_j() - 1e-3).abs() < 1e-15);
        // A correction that takes energy out refills it, up to the capacity.
        assert_eq!(tank.admit(-1.0), 1.0);
        assert_eq!(tank.level_j(), TANK_CAPACITY_J);
        // Nothing fills it but dissipation, and no reading spends it wildly.
        tank.fill(f64::NAN);
        tank.fill(-1.0);
        tank.fill(1.0);
        assert_eq!(tank.level_j(), TANK_CAPACITY_J);
        assert_eq!(tank.admit(f64::INFINITY), 0.0);
        assert_eq!(tank.admit(f64::NAN), 0.0);
        assert_eq!(tank.level_j(), TANK_CAPACITY_J);
    }

    #[test]
    fn a_partial_correction_costs_at_most_the_tank_level() {
        // The energy change is convex in the fraction applied: check it on a correction that stretches the
        // springs and speeds up the model.
        let k = Vector3::new(300.0, 300.0, 1.0);
        let p = Matrix3::from_diagonal(&Vector3::new(0.0, 1.0, 0.0));
        let m = Matrix3::from_diagonal(&Vector3::new(1.5, 0.0, 0.02));
        let s = springs(&k, &p, &m);
        let (e, v) = (Vector3::new(0.002, -0.001, 0.01), Vector3::new(0.05, 0.0, 0.3));
        let (moved, sped) = (Vector3::new(-0.02, 0.004, -0.1), Vector3::new(0.2, 0.0, 1.0));
        let before = coupling_energy(&s, &e, &v);
        let cost = coupling_energy(&s, &(e - moved), &(v + sped)) - before;
        let mut tank = EnergyTank::new(TANK_CAPACITY_J, 1.0);
        tank.admit(TANK_CAPACITY_J - 1e-3);
        assert!(cost > tank.level_j());
        let level = tank.level_j();
        let a = tank.admit(cost);
        let partial = coupling_energy(&s, &(e - moved * a), &(v + sped * a)) - before;
        assert!(partial <= level + 1e-15, "{partial} > {level}");
    }
}
