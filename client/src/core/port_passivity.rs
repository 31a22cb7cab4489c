//! The client's check of the two-port as a whole: the linkage never holds more through its coupling than the
//! hand has put into the client's end, net; what the local model would give the hand beyond that, it gives up.
//!
//! **Why.** The VE's controller (`server/src/core/passivity.rs`) holds what its coupling gives the linkage
//! within what the hand put into the client's end, gross: the VE's half of the time-domain passivity network
//! (Ryu, Artigas & Preusche 2010). Nothing held what the client's end gives back. So the energy a hand puts
//! in could be spent twice: a soft hand that winds a crank against its load under 300 ms and then yields is
//! pushed back by the local model's copy of the load, while the VE, a round trip behind, follows each push and
//! only part of each yield and keeps the energy; swing by swing the linkage gains what no one put in
//! (docs/robustness.md, "Energy growth at 300 ms"). The network's other half of the scheme, the client's
//! emission held within the VE's gross receipts, does not fit a client whose end is a second copy of the
//! linkage: every swing between the local model and the device counts as emitted at the model's port and
//! never as received at the VE's, so it brakes the model with no delay at all (the paper's manipulation lost
//! its second binding of the loop). The client's end checks the whole instead, with both ends' books.
//!
//! **The account.** `A = (R_c − E_c) − (E_VE − R_VE) + E_allow + D`: what the hand put into the client's end
//! net (the local model's port books, received minus emitted), minus what the VE's coupling gave the linkage
//! net (the server's books as its snapshots report them, already checked by `EnergyReports`: emitted into the
//! linkage minus received from it), plus an allowance ([`PORT_ALLOWANCE_J`] at the device, in the VE's units
//! through the mapping's `c_f c_p`), plus what this controller has dissipated (`D`). All sums over the axes:
//! passivity is the port's. The VE's books are a downlink late, which only makes the bound stricter later.
//!
//! **The controller.** While `A < 0`, the model's kinetic energy `½ ẋᵀ Λ̂ ẋ` is taken out up to the deficit
//! (its twist scaled down), and what is taken out is booked in `D`, so the account comes back to zero: the
//! variable damper of the time-domain passivity controller (Hannaford & Ryu 2002), which dissipates each step's
//! excess and no more. A yield the VE has not followed then meets a model that stops rather than one that
//! pushes back, until the VE's coupling gives back what the linkage releases.
//!
//! **A user alone.** With others on the linkage, this user's coupling passes on energy between their hands and
//! the linkage, a round trip late by their own links, that this end's books do not see; braking one model
//! against them made energy (four hands on the testbed's link2 with no delay, one letting go and one poking:
//! 32 mJ beyond the hands' work). The check applies while the user holds the linkage alone; shared linkages
//! keep the VE's controller and the exchange's weighting (`VeConfig::exchange_delay_s`).

use kinloop_linkage::math::space::{Space, VecOps};
use kinloop_protocol::passivity::PortBooks;

/// Energy the linkage may hold through its coupling beyond what the hand put in, before the client's end gives
/// up its own (J at the device): the VE's own allowance (`VeConfig::passivity_allowance_j`'s default).
pub const PORT_ALLOWANCE_J: f64 = 2.0e-3;

/// The controller's state (VE units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PortPassivity {
    /// `E_allow` in the VE's units.
    allowance: f64,
    /// What the controller has dissipated so far (`D`).
    dissipated: f64,
}

impl PortPassivity {
    /// A controller allowing `allowance_j` (J at the device; `device_per_ve` is the mapping's `c_f c_p`).
    pub fn new(allowance_j: f64, device_per_ve: f64) -> Self {
        PortPassivity {
            allowance: allowance_j / kinloop_protocol::Mapping::scale_or_one(device_per_ve),
            dissipated: 0.0,
        }
    }

    /// The account `A` (VE units): what this end received net (`own`, received minus emitted) and what the VE's
    /// end received net (`remote`: what its coupling took from the linkage minus what it gave it), plus the
    /// allowance and what this controller dissipated.
    pub fn account(&self, remote: &PortBooks, own: &PortBooks) -> f64 {
        own.net_received_j() + remote.net_received_j() + self.allowance + self.dissipated
    }

    /// The model twist after the controller: `twist` as it is while the account is in credit; else scaled so
    /// that its kinetic energy `½ ẋᵀ Λ̂ ẋ` (`inertia` = Λ̂) falls by the deficit, or to zero when it holds less.
    /// What it takes out is booked.
    pub fn brake<S: Space>(
        &mut self,
        remote: &PortBooks,
        own: &PortBooks,
        inertia: &S::OpMat,
        twist: &S::OpVec,
    ) -> S::OpVec {
        let deficit = -self.account(remote, own);
        if deficit.is_nan() || deficit <= 0.0 {
            return *twist;
        }
        let kinetic = 0.5 * twist.dot(&(*inertia * *twist));
        if !(kinetic > 0.0 && kinetic.is_finite()) {
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
        let mut pc = PortPassivity::new(allowance, 1.0);
        assert_eq!(pc.brake::<Planar>(&remote, &books(0.0, 1.0), &inertia, &twist), twist, "in credit");
        let deficit = 0.05;
        let own = books(0.0, 1.0 + allowance + deficit);
        let braked = pc.brake::<Planar>(&remote, &own, &inertia, &twist);
        let before = kinetic(&inertia, &twist);
        assert!((before - kinetic(&inertia, &braked) - deficit).abs() < 1e-12, "{before} -> {braked:?}");
        assert!(pc.account(&remote, &own).abs() < 1e-12);
        assert_eq!(pc.brake::<Planar>(&remote, &own, &inertia, &braked), braked, "paid");
    }

    /// A deficit beyond the model's kinetic energy stops the model, and only what it held is booked: the rest
    /// stays owed until the VE's end receives more.
    #[test]
    fn a_deficit_beyond_the_models_energy_stops_it_and_stays_owed() {
        let inertia = Matrix3::identity();
        let twist = Vector3::new(0.1, 0.0, 0.0);
        let (remote, own) = (books(0.0, 0.0), books(0.0, 1.0));
        let mut pc = PortPassivity::new(0.0, 1.0);
        assert_eq!(pc.brake::<Planar>(&remote, &own, &inertia, &twist), Vector3::zeros());
        assert!((pc.account(&remote, &own) - (kinetic(&inertia, &twist) - 1.0)).abs() < 1e-12);
        // The VE's end receives what is owed: the account is in credit again and the model moves on.
        let paid = books(1.0, 0.0);
        assert_eq!(pc.brake::<Planar>(&paid, &own, &inertia, &twist), twist);
    }

    /// Energy that swings between the local model and the device (received and emitted alike at the model's
    /// port, none of it through the VE) leaves the account as it was: only energy the VE's coupling gave the
    /// linkage beyond the hand's net work is held against the client's end.
    #[test]
    fn a_swing_between_model_and_device_costs_nothing_and_the_linkages_gain_does() {
        let inertia = Matrix3::identity();
        let twist = Vector3::new(0.2, 0.1, 0.0);
        let mut pc = PortPassivity::new(0.0, 1.0);
        let swinging = books(5.0, 5.0);
        assert_eq!(pc.brake::<Planar>(&PortBooks::default(), &swinging, &inertia, &twist), twist);
        // The VE's coupling gave the linkage 0.01 J the hand never put in: the model gives up as much.
        let gave = books(0.0, 0.01);
        let braked = pc.brake::<Planar>(&gave, &swinging, &inertia, &twist);
        assert!((kinetic(&inertia, &twist) - kinetic(&inertia, &braked) - 0.01).abs() < 1e-12, "{braked:?}");
    }
}
