//! The client's half of the two-port's passivity: what the local model gives the device side is held within
//! what the VE's coupling has received from the linkage.
//!
//! **Why.** The network two-port between the hand and the VE (`kinloop_protocol::passivity`) is passive when
//! what leaves it at both ends is no more than what enters it at both ends. The time-domain passivity
//! network (Ryu, Artigas & Preusche 2010) splits that bound in two, one per end, each checked against the
//! other end's books a delay late: at the VE, what the coupling gives the linkage is held within what the
//! hand put into the client's end (`server/src/core/passivity.rs`); here, what the client's end gives the
//! hand is held within what the VE's end took from the linkage. Without this half, the energy a hand puts in
//! can be spent twice: a soft hand that winds a crank against its load under 300 ms and then yields is pushed
//! back by the local model's copy of the load, while the VE, a round trip behind, follows each push and only
//! part of each yield and keeps the energy; swing by swing the linkage gains what no one put in
//! (docs/robustness.md, "Energy growth at 300 ms").
//!
//! **The account.** `A = R_VE + E_allow + D − E_client`: the energy the VE's coupling port has received as
//! its snapshots report it (`R_VE`, the server's books, accepted by [`EnergyReports`]), plus an allowance
//! ([`PORT_ALLOWANCE_J`] at the device, in the VE's units through the mapping's `c_f c_p`), plus what this
//! controller has dissipated (`D`), minus what the client's end has emitted (`E_client`, the local model's
//! port books: the power its wrench takes out of its motion). All sums over the axes: passivity is the port's.
//!
//! **The controller.** While `A < 0`, the model's kinetic energy `½ ẋᵀ Λ̂ ẋ` is taken out up to the deficit
//! (its twist scaled down), and what is taken out is booked in `D`, so the account comes back to zero: the
//! variable damper of the time-domain passivity controller (Hannaford & Ryu 2002), which dissipates each step's
//! excess and no more. A yield the VE has not followed then meets a model that stops rather than one that
//! pushes back, until the VE's coupling gives back what the linkage releases.

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::passivity::PortBooks;

/// Energy the client's end may emit beyond what the VE's end received (J at the device): the VE's own
/// allowance (`VeConfig::passivity_allowance_j`'s default), so each end of the two-port may generate as much.
pub const PORT_ALLOWANCE_J: f64 = 2.0e-3;

/// The controller's state: what it has dissipated so far (VE units).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PortPassivity {
    dissipated: f64,
}

impl PortPassivity {
    /// The account `A` (VE units): what the VE's end received (`remote`) plus `allowance` plus what this
    /// controller dissipated, minus what this end emitted (`own`).
    pub fn account(&self, remote: &PortBooks, own: &PortBooks, allowance: f64) -> f64 {
        let received: f64 = remote.received_j.iter().sum();
        let emitted: f64 = own.emitted_j.iter().sum();
        received + allowance + self.dissipated - emitted
    }

    /// The model twist after the controller: `twist` as it is while the account is in credit; else scaled so
    /// that its kinetic energy `½ ẋᵀ Λ̂ ẋ` (`inertia` = Λ̂) falls by the deficit, or to zero when it holds less.
    /// What it takes out is booked.
    pub fn brake<S: Space>(
        &mut self,
        remote: &PortBooks,
        own: &PortBooks,
        allowance: f64,
        inertia: &S::OpMat,
        twist: &S::OpVec,
    ) -> S::OpVec {
        let deficit = -self.account(remote, own, allowance);
        let kinetic = 0.5 * twist.dot(&(*inertia * *twist));
        if !(deficit > 0.0 && kinetic > 0.0 && kinetic.is_finite()) {
            return *twist;
        }
        let taken = deficit.min(kinetic);
        self.dissipated += taken;
        *twist * ((kinetic - taken) / kinetic).max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::{Matrix3, Vector3};

    fn books(received: f64, emitted: f64) -> PortBooks {
        let mut b = PortBooks::default();
        b.received_j[0] = received;
        b.emitted_j[1] = emitted;
        b
    }

    fn kinetic(inertia: &Matrix3<f64>, twist: &Vector3<f64>) -> f64 {
        0.5 * twist.dot(&(inertia * twist))
    }

    /// In credit the model moves on; in deficit its kinetic energy falls by exactly the deficit, which is
    /// booked, so the next tick with the same books finds the account back at zero and leaves the model be.
    #[test]
    fn the_model_gives_up_the_deficit_from_its_kinetic_energy_and_no_more() {
        let inertia = Matrix3::from_diagonal(&Vector3::new(2.0, 0.5, 0.01));
        let twist = Vector3::new(0.3, -0.4, 2.0);
        let (remote, allowance) = (books(1.0, 0.0), 0.002);
        let mut pc = PortPassivity::default();
        assert_eq!(pc.brake::<Planar>(&remote, &books(0.0, 1.0), allowance, &inertia, &twist), twist, "in credit");
        let deficit = 0.05;
        let own = books(0.0, 1.0 + allowance + deficit);
        let braked = pc.brake::<Planar>(&remote, &own, allowance, &inertia, &twist);
        let before = kinetic(&inertia, &twist);
        assert!((before - kinetic(&inertia, &braked) - deficit).abs() < 1e-12, "{before} -> {braked:?}");
        assert!(pc.account(&remote, &own, allowance).abs() < 1e-12);
        assert_eq!(pc.brake::<Planar>(&remote, &own, allowance, &inertia, &braked), braked, "paid");
    }

    /// A deficit beyond the model's kinetic energy stops the model, and only what it held is booked: the rest
    /// stays owed until the VE's end receives more.
    #[test]
    fn a_deficit_beyond_the_models_energy_stops_it_and_stays_owed() {
        let inertia = Matrix3::identity();
        let twist = Vector3::new(0.1, 0.0, 0.0);
        let (remote, own, allowance) = (books(0.0, 0.0), books(0.0, 1.0), 0.0);
        let mut pc = PortPassivity::default();
        assert_eq!(pc.brake::<Planar>(&remote, &own, allowance, &inertia, &twist), Vector3::zeros());
        assert!((pc.account(&remote, &own, allowance) - (kinetic(&inertia, &twist) - 1.0)).abs() < 1e-12);
        // The VE's end receives what is owed: the account is in credit again and the model moves on.
        let paid = books(1.0, 0.0);
        assert_eq!(pc.brake::<Planar>(&paid, &own, allowance, &inertia, &twist), twist);
    }
}
