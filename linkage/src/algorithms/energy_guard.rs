//! The constrained step's own energy account: a passivity observer and controller on the integrator.
//!
//! Semi-implicit Euler on eq 4 is not symplectic once D depends on q and B is evaluated explicitly: in a fast
//! swing (tens to hundreds of rad/s, where a 1 kHz step turns a joint by a tenth of a radian) the step itself
//! makes mechanical energy, an error first order in the step that no coupling or Baumgarte gain can see. A
//! linkage falling through a crank's dead centre under a user's hand then swings up instead of settling.
//!
//! The account compares each step's change of mechanical energy `E = T + V` (kinetic, and the potential whose
//! gradient is G: gravity, joint and cut springs) with the work the non-conservative generalized forces did
//! over it, `h τ_nc · q̇⁺` with `τ_nc = applied + joint_force − D_implicit q̈` (the users' couplings, contacts,
//! dampers, actuators, range walls, and the linearly-implicit terms as the step used them) and `q̇⁺` the
//! velocity that moved q. What is left over is energy the step (or the projection) made or lost. It is
//! summed in a reservoir, as Hannaford and Ryu's passivity observer sums a port's energy; when the sum is
//! positive, the kinetic energy is reduced by it at the next step's start by scaling q̇ (a uniform scale keeps
//! `W q̇ = 0`), which empties the reservoir. A caller that publishes the state between steps (the VE) settles
//! each step at its end instead ([`EnergyGuard::settle`]), so no one reads a state holding energy a step made.
//!
//! **Credit.** Energy the step lost (the projection's and the scheme's own dissipation) is credited, so
//! symplectic Euler's bounded oscillation of E is not cut at each peak (which would damp every motion), but
//! the credit is capped at the kinetic energy of the moment: a long, slow run cannot bank a budget that a
//! later runaway spends.
//!
//! The guard acts only on semi-implicit Euler (the VE's scheme); RK4's error is fourth order and its work
//! would need the stage weights.

use nalgebra::DVector;

use crate::algorithms::gravity::{field_energy, kinetic_energy};
use crate::math::dense::dot;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::Model;

/// The reservoir and the books of the step in flight. Start with [`EnergyGuard::default`]; call
/// [`EnergyGuard::reset`] whenever the state is set from outside the integrator (a restore, a linkage held
/// at rest), since the account is of the step, not of jumps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnergyGuard {
    /// Energy the steps made (positive) or lost (negative, at most the kinetic energy), not yet taken out.
    reservoir: f64,
    /// Mechanical energy at the start of the last step, after any correction; `None` before the first.
    opened_at: Option<f64>,
    /// Work of the non-conservative forces over the last step.
    work: f64,
    /// Energy taken out of the linkage since the start, in the scene's units.
    pub removed: f64,
    /// Steps after which energy was taken out (at the next open or at `settle`).
    pub activations: u64,
}

impl EnergyGuard {
    /// Forgets the account of the step in flight and the reservoir (the counters are kept).
    pub fn reset(&mut self) {
        self.reservoir = 0.0;
        self.opened_at = None;
        self.work = 0.0;
    }

    /// The energy a step made or lost and not yet taken out (positive: made).
    pub fn reservoir(&self) -> f64 {
        self.reservoir
    }

    /// At a step's start, with the kinematics of `(q, q̇)` in `data` (after `dynamics_terms`): books what the
    /// last step made, and when the reservoir is positive scales `q̇` to take it out of the kinetic energy.
    /// True when `q̇` was changed (the caller re-evaluates the terms that depend on it).
    pub fn open_step<S: Space>(
        &mut self,
        model: &Model<S>,
        data: &Data<S>,
        q: &DVector<f64>,
        qd: &mut DVector<f64>,
    ) -> bool {
        let kinetic = kinetic_energy(model, data);
        let mut energy = kinetic + field_energy(model, data, q);
        let mut scaled = false;
        if let Some(opened_at) = self.opened_at {
            self.reservoir = (self.reservoir + energy - opened_at - self.work).max(-kinetic);
            if self.reservoir > 0.0 && kinetic > 0.0 {
                let taken = self.reservoir.min(kinetic);
                let scale = ((kinetic - taken) / kinetic).sqrt();
                qd.as_mut_slice().iter_mut().for_each(|v| *v *= scale);
                self.reservoir -= taken;
                self.removed += taken;
                self.activations += 1;
                energy -= taken;
                scaled = true;
            }
        }
        self.opened_at = Some(energy);
        scaled
    }

    /// At a step's end, with the kinematics of its end state `(q, q̇)` in `data`: books the step at once, as
    /// the next step's open would, and takes out of `q̇` what the step made, so that no one reads a state
    /// holding energy the step made (the next open then finds nothing to book). True when `q̇` was changed.
    pub fn settle<S: Space>(
        &mut self,
        model: &Model<S>,
        data: &Data<S>,
        q: &DVector<f64>,
        qd: &mut DVector<f64>,
    ) -> bool {
        let scaled = self.open_step(model, data, q, qd);
        // The step's work is booked; the next open starts from this state with nothing done since.
        self.work = 0.0;
        scaled
    }

    /// After the step's solve and update: the work `h τ_nc · q̇⁺` of the forces the step applied, with `q̇⁺` the
    /// velocity that moved q.
    pub fn close_step<S: Space>(&mut self, model: &Model<S>, data: &Data<S>, dt: f64, qd_moved: &DVector<f64>) {
        let n = model.nv();
        let mut power =
            dot(data.applied.as_slice(), qd_moved.as_slice()) + dot(data.joint_force.as_slice(), qd_moved.as_slice());
        if data.use_implicit_mass {
            // The linearly-implicit terms act as the force `−D_implicit q̈` on top of `applied`.
            for i in 0..n {
                let row: f64 = (0..n).map(|j| data.implicit_mass[(i, j)] * data.qdd[j]).sum();
                power -= row * qd_moved[i];
            }
        }
        self.work = dt * power;
    }
}
