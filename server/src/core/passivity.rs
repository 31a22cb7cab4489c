//! Time-domain passivity observer and controller on each coupling (Hannaford & Ryu 2002). On by default
//! (`VeConfig::passivity`).
//!
//! **The port.** Seen from the VE, a user's coupling (section IV, Fig 3: the force channel F_h beside the
//! graphics-controller PD) is a one-port at the user's OP whose other side is the network and the client's
//! local model. On each operational axis `a` the observer books the energy the PD has *absorbed* from the VE,
//! ```text
//! E_a(n) = − Σ_{k ≤ n} F_c,a(k) · ẋ_op,a(k+1) · h,        E = Σ_a E_a,
//! ```
//! with `F_c` the controller's wrench the step effectively applied (scaled PD and brake, fade and implicit
//! correction included) and `ẋ_op(k+1) = J q̇⁺` the OP velocity that step produced (the work semi-implicit
//! Euler actually does); the force channel's work is booked apart (`force_channel`). A spring-damper tied to
//! a consistent reference keeps `E ≥ 0` (it gives back at most what it stored); with a delayed reference it
//! can go negative: the coupling generates energy.
//!
//! **The account.** Energy may legitimately enter the VE through the coupling when the hand put it in at the
//! client. The controller's account is
//! ```text
//! A = E + (force channel: received − emitted) + (what the hand put into the client's end, trusted),
//! ```
//! the energy the VE has received through the coupling beyond what the hand put in is `−A`. It is one
//! account for the port, not one per axis: passivity is a property of the port's total power, and the linkage
//! moves energy from one OP axis to another (a coupler turning under delay takes on one axis what it gives on
//! another). Per-axis accounts would cut such an axis's PD off for good though the port as a whole is passive.
//! What the client's end *emitted* (its local model's work on the hand) is not debited: the local model is a
//! second copy of the linkage with its own gravity and synchronisation, and what it gives a holding hand is
//! not energy the VE's coupling created (as a linkage starts it can give a holding hand far more than the
//! VE's PD absorbs; debited, that would hold the PD off). The bound the controller keeps is
//! therefore: the VE gains through the coupling at most what the hand put in, plus `E_allow`.
//!
//! **The controller scales the PD and brakes what it takes off.** The textbook controller for this causality
//! is a damper `α ẋ_op` added to the PD, sized to dissipate the deficit. It fails here: the VE's OP is tied to
//! the local model's by a stiff PD (K_g up to 10⁴), so a damper beside the PD only makes the OP lag, the PD
//! pulls harder by the damper's force, and the deficit never shrinks while the damper keeps braking the motion
//! the force channel drives (the damper dissipates more than the hand's work and the device saturates). What
//! generates the energy is the PD's *reference*, so the controller scales the PD, and what it takes off becomes a brake on
//! the OP with the PD's own damping (`−(1 − β) B_g ⊙ ẋ_op`, see `coupling`). The brake only dissipates: a PD
//! scaled to zero leaves the VE damped rather than free (a linkage left free under gravity with the hand's
//! force still on can run away), and what the brake absorbs is booked, so the account recovers and the PD
//! comes back. For the coming tick each axis gets
//! ```text
//! β_a = clamp(1 + A / E_allow, 0, 1),
//! ```
//! full strength while the port is in credit, fading linearly to zero as its deficit reaches the allowance
//! `E_allow`. While `A > −E_allow` an axis whose PD is about to absorb energy (`w F_pd,a ẋ_op,a ≤ 0`,
//! predicted from the last evaluation) is not scaled, so the account can recover; below `−E_allow` the scale
//! is zero whatever the prediction (with a stiff PD the OP can reverse within a tick and a prediction of
//! "absorbing" be wrong). **Raising β is paid for**: a stiffer spring at the same stretch `e_a` holds
//! `½ Δβ w K_a e_a²` more energy that no one put in and that the PD gives the VE as it relaxes, so a rise is
//! limited to what the account holds above `−E_allow` (shared by the axes in order). Through the PD the port
//! thus generates about `E_allow` over a session (plus the ticks in which a prediction of "absorbing" was
//! wrong): passive with that initial storage. The scale is continuous in the account, so the PD never switches
//! on or off as a step.
//!
//! **When scaling the PD is not enough, the force channel fades too.** The hand's force reaches the VE a half
//! round trip late, so it can drive the VE where the hand's local model did not go: a linkage held at a dead
//! centre gives way to a push the local model had taken as held, and the late push then runs it off (a 4 kg
//! slider against a crank's spring, wound past its far dead centre at 300 ms one way, took more than ten times
//! from the force channel what the hand put into its end). The PD is then already off, and what the port still
//! generates is the force channel's. Beyond the PD's allowance (`A < −E_allow`) the force channel is scaled
//! as the PD is, one allowance further on (`Self::hand_scale`): it fades to zero as the deficit reaches
//! `2 E_allow`, an axis about to absorb keeping it whole until then. The brake and the hand's absorbing work
//! then bring the account back, and the hand's force with it. The port thus generates at most about
//! `2 E_allow` over a session.
//!
//! **Per axis, for stiff gains** (`VeConfig::passivity_per_axis`, off by default). The credit for what the
//! hand put in counts what it received and not what it took back, so a client whose model shakes under a
//! constant hand earns credit with every swing. With stiff gains on a turning link (the paper's K_g on a
//! jittery network) credit earned on the linear axes can pay for energy generated on the angular one. The
//! per-axis controller (each axis on its own account plus the PD's surplus, no brake, no price on a rise)
//! scales only the axis that generates and leaves it free, which steadies such a link; under delay it also
//! cuts axes that merely pass energy on, so it is off by default. Debiting what the client's end emitted
//! instead would hold the PD off as a linkage starts (see the account above).
//!
//! **Across the network (two-port).** The coupling is one end of the two-port between the user's device and the
//! VE (`kinloop_protocol::passivity`); the client's local model is the other, and its uplinks carry its books.
//! The credit for what the hand put in trusts the client only as far as the server can check it: on each axis
//! it is the smaller of the client's report (refused and counted when it is non-finite, negative, shrinking or
//! faster than the device can push, see `EnergyReports`) and the server's own booking of the same flow from
//! the uplinks it received (the model wrench times the model twist, held over each gap) plus the allowance. A
//! client that overstates what it received buys at most an allowance per axis; one that understates only
//! makes its own coupling stricter.

use kinloop_linkage::{math::space::Space, math::space::VecOps};
use kinloop_protocol::passivity::{output_scale, EnergyReports, PortBooks, MAX_AXES};

use super::guards::MAX_OP_DIM;

/// Longest gap between two uplinks over which the server holds the earlier one's power in its own booking of
/// the client's port (s): a longer silence books nothing rather than a guess.
const MAX_HELD_GAP_S: f64 = 0.1;

/// Energy account of one coupling, per operational axis, and the books of its end of the two-port.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PassivityObserver {
    /// Energy the coupling's PD has absorbed from the VE so far, all axes (J); negative: it generated energy.
    pub absorbed_j: f64,
    /// The same per operational axis, linear first (J; N·m·rad on angular axes, also J).
    pub absorbed_axis_j: [f64; MAX_OP_DIM],
    /// Ticks in which the controller scaled some axis of the PD down.
    pub activations: u64,
    /// The coupling's whole port (PD and force channel) as the snapshots report it.
    pub port: PortBooks,
    /// The force channel's part of it.
    pub force_channel: PortBooks,
    /// The client's books as it reported them (checked).
    #[serde(skip)]
    pub client: EnergyReports,
    /// The server's own booking of the client's port from the uplinks it received.
    pub client_seen: PortBooks,
    /// Client clock and per-axis power of the last uplink booked into `client_seen`.
    #[serde(skip)]
    client_last: Option<(f64, [f64; MAX_AXES])>,
}

impl PassivityObserver {
    /// The PD scale β for the coming tick, per axis. `predicted_power` is the power (per axis, W) the unscaled
    /// PD would deliver to the VE at the last evaluated state, `spring_energy` what its spring holds per unit
    /// of β (`½ w K_a e_a²`, J), `previous` the β the last tick used, `allowance_j` is `E_allow` (≥ 0; zero is
    /// the strict limit: off while in deficit). Counts an activation when an axis is scaled down.
    pub fn pd_scale<S: Space>(
        &mut self,
        predicted_power: &S::OpVec,
        spring_energy: &S::OpVec,
        previous: &S::OpVec,
        allowance_j: f64,
    ) -> S::OpVec {
        let account = self.account_j(allowance_j);
        // What raising β may still spend: a stiffer spring at the same stretch holds energy no one put in.
        let mut headroom = (account + allowance_j).max(0.0);
        let mut scale = S::OpVec::zero();
        for axis in 0..S::DIM {
            let mut beta = output_scale(account, predicted_power[axis] <= 0.0, allowance_j);
            let rise = beta - previous[axis];
            if rise > 0.0 && spring_energy[axis] > 0.0 {
                let affordable = rise.min(headroom / spring_energy[axis]);
                headroom -= affordable * spring_energy[axis];
                beta = previous[axis] + affordable;
            }
            scale[axis] = beta;
        }
        self.count_activation::<S>(&scale);
        scale
    }

    /// The force channel's scale for the coming tick, per axis: full while the port's deficit is within the
    /// PD's share of the allowance (`−E_allow`, where β reaches zero), then `output_scale` of the account one
    /// allowance further on, so the hand's force fades out as the deficit reaches `−2 E_allow`, except on an
    /// axis where it is about to absorb (`predicted_hand_power ≤ 0`), which keeps it whole until then.
    /// The force channel is scaled only once the PD is off: then the deficit still grows only because the
    /// delayed hand's force drives a VE that moves otherwise than the hand's local model did.
    pub fn hand_scale<S: Space>(&self, predicted_hand_power: &S::OpVec, allowance_j: f64) -> S::OpVec {
        let beyond_pd = self.account_j(allowance_j) + allowance_j;
        let mut scale = S::OpVec::zero();
        for axis in 0..S::DIM {
            scale[axis] = output_scale(beyond_pd, predicted_hand_power[axis] <= 0.0, allowance_j);
        }
        scale
    }

    /// The PD scale of the per-axis controller (`VeConfig::passivity_per_axis`): each axis on its own account,
    /// `A_a = E_a + max(0, E) + max(0, R_a − F_a)` with `R_a` what the hand put into the client's end on the
    /// axis (trusted as in [`Self::client_received`]) and `F_a` what the force channel delivered on it; no
    /// brake and no price on a rise (see the module documentation for where this is the better choice).
    pub fn pd_scale_per_axis<S: Space>(&mut self, predicted_power: &S::OpVec, allowance_j: f64) -> S::OpVec {
        let surplus = self.absorbed_j.max(0.0);
        let mut scale = S::OpVec::zero();
        for axis in 0..S::DIM {
            let credit = (self.trusted_received(axis, allowance_j) - self.force_channel.emitted_j[axis]).max(0.0);
            let account = self.absorbed_axis_j[axis] + surplus + credit;
            scale[axis] = output_scale(account, predicted_power[axis] <= 0.0, allowance_j);
        }
        self.count_activation::<S>(&scale);
        scale
    }

    fn count_activation<S: Space>(&mut self, scale: &S::OpVec) {
        if (0..S::DIM).any(|axis| scale[axis] < 1.0) {
            self.activations += 1;
        }
    }

    /// The account `A` (J): what the coupling's port (PD and force channel) absorbed from the VE, plus what the
    /// hand put into the client's end (trusted as far as the server can check it).
    pub fn account_j(&self, allowance_j: f64) -> f64 {
        self.absorbed_j + self.force_channel.net_received_j() + self.client_received(allowance_j)
    }

    /// What the hand put into the client's end on all axes (J, ≥ 0): per axis, the smaller of the client's
    /// report and the server's own booking plus `allowance_j`.
    pub fn client_received(&self, allowance_j: f64) -> f64 {
        (0..MAX_AXES).map(|axis| self.trusted_received(axis, allowance_j)).sum()
    }

    /// What the hand put into the client's end on `axis` (J): the smaller of the client's report and the
    /// server's own booking plus `allowance_j`.
    fn trusted_received(&self, axis: usize, allowance_j: f64) -> f64 {
        self.client.accepted.received_j[axis].min(self.client_seen.received_j[axis] + allowance_j)
    }

    /// Books one step: the PD wrench `pd_wrench` and the force channel's `hand_wrench` the step applied moved
    /// the OP at `op_velocity_after` for `dt`. Non-finite values (a failed step) are not booked.
    pub fn observe<S: Space>(
        &mut self,
        pd_wrench: &S::OpVec,
        hand_wrench: &S::OpVec,
        op_velocity_after: &S::OpVec,
        dt: f64,
    ) {
        let mut absorbed = [0.0; MAX_OP_DIM];
        let (mut pd_power, mut hand_power, mut port_power) = ([0.0; MAX_AXES], [0.0; MAX_AXES], [0.0; MAX_AXES]);
        for axis in 0..S::DIM {
            pd_power[axis] = pd_wrench[axis] * op_velocity_after[axis];
            hand_power[axis] = hand_wrench[axis] * op_velocity_after[axis];
            port_power[axis] = pd_power[axis] + hand_power[axis];
            absorbed[axis] = -pd_power[axis] * dt;
        }
        if absorbed.iter().chain(&hand_power).all(|a| a.is_finite()) {
            for (total, a) in self.absorbed_axis_j.iter_mut().zip(absorbed) {
                *total += a;
            }
            self.absorbed_j += absorbed.iter().sum::<f64>();
            self.port.book(&port_power[..S::DIM], dt);
            self.force_channel.book(&hand_power[..S::DIM], dt);
        }
    }

    /// Books an accepted uplink's part of the client's port into the server's own account of it: the model
    /// wrench `wrench` on the local model moving at `twist`, at the client's clock `time_s`. The earlier
    /// uplink's power is held over the gap (at most [`MAX_HELD_GAP_S`]).
    pub fn observe_client<S: Space>(&mut self, time_s: f64, wrench: &S::OpVec, twist: &S::OpVec) {
        let mut power_out = [0.0; MAX_AXES];
        for axis in 0..S::DIM {
            // Power into the local model is energy the client's end received.
            power_out[axis] = -wrench[axis] * twist[axis];
        }
        if let Some((last_s, last_power)) = self.client_last {
            let gap = time_s - last_s;
            if gap > 0.0 && gap <= MAX_HELD_GAP_S {
                self.client_seen.book(&last_power[..S::DIM], gap);
            }
        }
        if power_out.iter().all(|p| p.is_finite()) && time_s.is_finite() {
            self.client_last = Some((time_s, power_out));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use std::f64::consts::PI;

    type V = <Planar as Space>::OpVec;

    fn on_x(f: f64) -> V {
        V::from_slice(&[f, 0.0, 0.0])
    }

    /// `−∫₀ᵗ F₀ sin(ωs) · V₀ sin(ωs + φ) ds`, in closed form.
    fn absorbed_closed_form(f0: f64, v0: f64, omega: f64, phi: f64, t: f64) -> f64 {
        -0.5 * f0 * v0 * (t * phi.cos() - ((2.0 * omega * t + phi).sin() - phi.sin()) / (2.0 * omega))
    }

    #[test]
    fn observer_books_minus_the_integral_of_force_times_velocity() {
        let (f0, v0, omega, h) = (2.0, 0.3, 2.0 * PI * 1.5, 1e-6);
        // In phase: the port pushes along the motion (active); in antiphase: it brakes (a damper); at 90°: a
        // lossless spring or mass, which over whole periods books nothing.
        for phi in [0.0, PI, PI / 2.0, 1.0] {
            let mut observer = PassivityObserver::default();
            let steps = 2_000_000; // 2 s: three periods
            for k in 0..steps {
                // Each step's force is the one at its start, the velocity the one at its end (semi-implicit
                // Euler); the rectangle rule then converges to the integral at first order in h.
                let t = k as f64 * h;
                let force = on_x(f0 * (omega * t).sin());
                let velocity = on_x(v0 * (omega * (t + h) + phi).sin());
                observer.observe::<Planar>(&force, &on_x(0.0), &velocity, h);
            }
            let expected = absorbed_closed_form(f0, v0, omega, phi, steps as f64 * h);
            let booked = observer.absorbed_axis_j[0];
            assert!((booked - expected).abs() < 2e-5, "φ = {phi}: booked {booked} J, closed form {expected} J");
            assert_eq!(observer.absorbed_j, booked, "one axis moved: the total is that axis");
            assert_eq!(observer.absorbed_axis_j[1..], [0.0; MAX_OP_DIM - 1]);
        }
    }

    /// β for an unstretched spring (nothing to price) from `previous` β.
    fn scale_from(observer: &mut PassivityObserver, power: &V, previous: &V, allowance_j: f64) -> V {
        observer.pd_scale::<Planar>(power, &V::zeros(), previous, allowance_j)
    }

    #[test]
    fn the_port_is_booked_as_a_whole_and_only_delivering_axes_are_scaled() {
        // x absorbs 3 J, θ generates 1 J: energy the linkage moved from one axis to another. The port absorbed
        // 2 J and is passive, so nothing is scaled (one account per axis would have cut θ off).
        let mut observer = PassivityObserver::default();
        observer.observe::<Planar>(
            &V::from_slice(&[-3.0, 0.0, 2.0]),
            &on_x(0.0),
            &V::from_slice(&[1.0, 5.0, 0.5]),
            1.0,
        );
        assert_eq!(observer.absorbed_axis_j[..3], [3.0, 0.0, -1.0]);
        assert_eq!(observer.absorbed_j, 2.0);
        let full = V::from_slice(&[1.0, 1.0, 1.0]);
        assert_eq!(scale_from(&mut observer, &full, &full, 2.0), full, "in credit: full strength");
        assert_eq!(observer.activations, 0);
        // θ generates 2.5 J more: the port is 0.5 J in deficit; with a 4 J allowance every axis about to
        // deliver energy is at 1 − 0.5/4, and one about to absorb is at full strength.
        observer.observe::<Planar>(&V::from_slice(&[0.0, 0.0, 5.0]), &on_x(0.0), &V::from_slice(&[0.0, 0.0, 0.5]), 1.0);
        assert_eq!(observer.absorbed_j, -0.5);
        assert_eq!(scale_from(&mut observer, &full, &full, 4.0), V::from_slice(&[0.875, 0.875, 0.875]));
        let absorbing_on_theta = V::from_slice(&[1.0, 1.0, -1.0]);
        assert_eq!(scale_from(&mut observer, &absorbing_on_theta, &full, 4.0), V::from_slice(&[0.875, 0.875, 1.0]));
        assert_eq!(observer.activations, 2);
        // Beyond the allowance the port is off, whatever the prediction says.
        assert_eq!(scale_from(&mut observer, &absorbing_on_theta, &full, 0.4), V::zeros());
        assert_eq!(scale_from(&mut observer, &full, &full, 0.0), V::zeros(), "strict limit");
    }

    #[test]
    fn the_account_counts_the_force_channel_and_what_the_hand_put_in_at_the_client() {
        let mut observer = PassivityObserver::default();
        // The force channel delivered 1.5 J to the VE on x and took 0.5 J back: the account is 1 J short.
        observer.observe::<Planar>(&on_x(0.0), &on_x(1.5), &on_x(1.0), 1.0);
        observer.observe::<Planar>(&on_x(0.0), &on_x(0.5), &on_x(-1.0), 1.0);
        assert_eq!(observer.account_j(0.1), -1.0);
        // The client reports 2 J received on x and its uplinks show 1.2 J (a model wrench of 1.2 N on a
        // model moving along it at 1 m/s for a second, an uplink every 50 ms): the server credits 1.2 J plus the
        // allowance.
        for n in 0..=20 {
            observer.observe_client::<Planar>(0.05 * n as f64, &on_x(1.2), &on_x(1.0));
        }
        observer.client.check(1.0, &[2.0, 0.0, 0.0], &[0.0; 3], 10.0, 0.0).unwrap();
        let received = observer.client_received(0.1);
        assert!((received - 1.3).abs() < 1e-12, "{received} J, seen {:?}", observer.client_seen);
        assert!((observer.account_j(0.1) - 0.3).abs() < 1e-12);
    }

    /// The force channel keeps full strength while the deficit is the PD's to stop (down to `−E_allow`), then
    /// fades linearly to zero at `−2 E_allow` on an axis about to deliver; one about to absorb keeps it whole
    /// down to `−2 E_allow`; past that it is off whatever the prediction.
    #[test]
    fn the_force_channel_fades_only_once_the_deficit_is_beyond_the_pds_allowance() {
        let allowance = 1.0;
        let delivering = V::from_slice(&[1.0, 1.0, 1.0]);
        let absorbing_on_y = V::from_slice(&[1.0, -1.0, 1.0]);
        // The force channel emits `deficit` J on x into the VE with nothing credited for it.
        let scale_at = |deficit: f64, power: &V| {
            let mut observer = PassivityObserver::default();
            observer.observe::<Planar>(&on_x(0.0), &on_x(deficit), &on_x(1.0), 1.0);
            assert!((observer.account_j(allowance) + deficit).abs() < 1e-12);
            observer.hand_scale::<Planar>(power, allowance)
        };
        assert_eq!(scale_at(0.0, &delivering), delivering, "in credit");
        assert_eq!(scale_at(0.9, &delivering), delivering, "the PD's share of the allowance");
        for (deficit, want) in [(1.25, 0.75), (1.5, 0.5), (2.0, 0.0), (5.0, 0.0)] {
            assert!((scale_at(deficit, &delivering) - V::repeat(want)).norm() < 1e-12, "deficit {deficit} J");
        }
        assert_eq!(scale_at(1.5, &absorbing_on_y), V::from_slice(&[0.5, 1.0, 0.5]));
        assert_eq!(scale_at(2.5, &absorbing_on_y), V::zeros(), "past 2 E_allow: off");
    }

    #[test]
    fn raising_the_scale_on_a_stretched_spring_is_paid_from_the_account() {
        // The port absorbed 0.5 J; its PD was off on x and y, and each spring holds 1 J at full strength. A
        // stiffer spring at the same stretch holds energy no one put in, so the rise may spend the account down
        // to −E_allow (0.6 J here) and no further: x takes all of it, y must wait.
        let mut observer = PassivityObserver::default();
        observer.observe::<Planar>(&on_x(-0.5), &on_x(0.0), &on_x(1.0), 1.0);
        let (off, spring) = (V::from_slice(&[0.0, 0.0, 1.0]), V::from_slice(&[1.0, 1.0, 0.0]));
        let full = V::from_slice(&[1.0, 1.0, 1.0]);
        let beta = observer.pd_scale::<Planar>(&full, &spring, &off, 0.1);
        assert!((beta - V::from_slice(&[0.6, 0.0, 1.0])).norm() < 1e-12, "β = {beta:?}");
        // An unstretched spring costs nothing to stiffen; lowering β is always free.
        assert_eq!(observer.pd_scale::<Planar>(&full, &V::zeros(), &off, 0.1), full);
        let spring_on_x = V::from_slice(&[1.0, 0.0, 0.0]);
        observer.observe::<Planar>(&on_x(2.0), &on_x(0.0), &on_x(1.0), 1.0);
        assert_eq!(observer.pd_scale::<Planar>(&full, &spring_on_x, &full, 0.1), V::zeros());
    }

    #[test]
    fn non_finite_steps_are_not_booked() {
        let mut observer = PassivityObserver::default();
        observer.observe::<Planar>(&on_x(f64::NAN), &on_x(0.0), &on_x(1.0), 1e-3);
        observer.observe::<Planar>(&on_x(1.0), &on_x(0.0), &on_x(f64::INFINITY), 1e-3);
        assert_eq!(observer, PassivityObserver::default());
    }

    /// A 1 kg mass on x tied by a PD (K, B) to a reference moving at constant speed `u`, integrated by
    /// semi-implicit Euler with the PD scaled by the controller when `allowance_j` is given. The reference
    /// is an energy source: at full strength the PD drags the mass up to speed and keeps delivering whatever
    /// the motion asks. Returns the observer and the mass's final speed.
    fn dragged_mass(allowance_j: Option<f64>, seconds: f64) -> (PassivityObserver, f64) {
        let (k, b, u, m, h) = (1000.0, 100.0, 0.2, 1.0, 1e-4);
        let (mut x, mut v) = (0.0, 0.0);
        let mut observer = PassivityObserver::default();
        let mut beta = 1.0;
        for n in 0..(seconds / h) as usize {
            let reference = u * n as f64 * h;
            let pd = k * (reference - x) + b * (u - v);
            let spring = 0.5 * k * (reference - x).powi(2);
            beta = match allowance_j {
                Some(allowance) => observer.pd_scale::<Planar>(&on_x(pd * v), &on_x(spring), &on_x(beta), allowance)[0],
                None => 1.0,
            };
            // The coupling's controller part: the scaled PD and the brake that replaces the rest (`coupling`).
            let force = beta * pd - (1.0 - beta) * b * v;
            v += h * force / m;
            x += h * v;
            observer.observe::<Planar>(&on_x(force), &on_x(0.0), &on_x(v), h);
        }
        (observer, v)
    }

    #[test]
    fn an_active_port_is_booked_as_generating_and_the_controller_bounds_it() {
        // Plain: the PD delivers the mass's kinetic energy; the booking agrees with ½ m v² to the step's
        // first-order error.
        let (plain, speed) = dragged_mass(None, 2.0);
        let kinetic = 0.5 * speed * speed;
        assert!((speed - 0.2).abs() < 1e-3, "the mass follows the reference: {speed} m/s");
        assert!((-plain.absorbed_j - kinetic).abs() < 0.02 * kinetic, "{} J vs ½ m v² = {kinetic} J", plain.absorbed_j);
        assert_eq!(plain.activations, 0);
        // Controlled: the port generates at most the allowance (plus one tick's worth), however long it runs.
        let allowance = 1e-3;
        let (controlled, _) = dragged_mass(Some(allowance), 10.0);
        assert!(controlled.absorbed_j > -1.05 * allowance, "generated {} J", -controlled.absorbed_j);
        assert!(controlled.activations > 0);
    }

    #[test]
    fn a_passive_port_is_never_scaled() {
        // A mass at rest on a fixed reference, pushed 1 N away from it for 0.3 s and then let go: the PD
        // stores what the push puts into its spring and gives back no more, so the account never goes below
        // zero and the controller never acts, however small its allowance.
        let (k, b, m, h) = (1000.0, 2.0, 1.0, 1e-3);
        let (mut x, mut v) = (0.0, 0.0);
        let mut observer = PassivityObserver::default();
        let mut lowest = f64::INFINITY;
        for n in 0..5000 {
            let push = if n < 300 { 1.0 } else { 0.0 };
            let pd = -k * x - b * v;
            let beta = observer.pd_scale::<Planar>(&on_x(pd * v), &on_x(0.5 * k * x * x), &on_x(1.0), 0.0)[0];
            assert_eq!(beta, 1.0, "step {n}");
            v += h * (push + beta * pd) / m;
            x += h * v;
            observer.observe::<Planar>(&on_x(beta * pd), &on_x(0.0), &on_x(v), h);
            lowest = lowest.min(observer.absorbed_j);
        }
        assert!(lowest >= 0.0, "lowest account {lowest} J");
        assert!(observer.absorbed_j > 0.0, "the damper dissipated what the push put in");
        assert_eq!(observer.activations, 0);
    }
}
