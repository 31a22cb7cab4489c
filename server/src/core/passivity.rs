//! Time-domain passivity observer and controller on each coupling (Hannaford & Ryu 2002; Ryu, Kwon &
//! Hannaford 2004 for the per-axis use on a multi-DOF port).
//!
//! **The port.** Seen from the VE, a user's graphics-controller PD (section IV, Fig 3) is a one-port at the
//! user's OP whose other side is the network delay and the client's local model. The force channel F_h is
//! not part of it: that energy is the human's to give, and the VE applies it beside the PD (see
//! `coupling`). On each operational axis `a` the observer books the energy this port has *absorbed* from the
//! VE,
//! ```text
//! E_a(n) = − Σ_{k ≤ n} F_c,a(k) · ẋ_op,a(k+1) · h,
//! ```
//! with `F_c` the PD wrench the step effectively applied (fade and implicit correction included) and
//! `ẋ_op(k+1) = J q̇⁺` the OP velocity that step produced (the work semi-implicit Euler actually does). A
//! spring-damper tied to a consistent reference keeps `E_a ≥ 0` (it gives back at most what it stored);
//! with a delayed reference it can go negative: the coupling generates energy. Booking each axis on its
//! own is stricter than booking their sum (the port is passive when every axis is) and keeps a deficit in
//! one axis (the testbed's stiff angular axis) from being paid for by the others.
//!
//! **The controller scales the PD, it does not add a damper.** The textbook controller for this causality
//! is a damper `α ẋ_op` sized to dissipate the deficit. It fails here: the VE's OP is tied to the local
//! model's by a stiff PD (K_g up to 10⁴), so a damper at the OP only makes the OP lag, the PD pulls harder
//! by the damper's force, and the deficit never shrinks while the damper keeps braking the motion the force
//! channel drives (measured on the paper's session at 0 ms delay with α capped at 10 N·s/m: the damper
//! dissipated 0.39 J against 0.06 J of work by the hand, and the device saturated). What generates the
//! energy is the PD's *reference*, so the controller bounds the PD's output instead. For the coming tick,
//! each axis gets a scale `β_a ∈ [0, 1]` from its account
//! ```text
//! A_a = E_a + max(0, Σ_b E_b),        β_a = clamp(1 + A_a / E_allow, 0, 1),
//! ```
//! full strength while the axis is in credit, fading linearly to zero as its deficit reaches the allowance
//! `E_allow`. An axis in deficit may draw on the surplus the port as a whole has absorbed (energy moves
//! between axes through the linkage; the port is passive when the total is), and while its account is above
//! `−E_allow` a tick in which its PD is about to absorb energy (`w F_pd,a ẋ_op,a ≤ 0`, predicted from the
//! last evaluation) is not scaled, so the account can recover. Below `−E_allow` the scale is zero whatever
//! the prediction: with a stiff PD the OP can reverse within a tick and a prediction of "absorbing" be wrong,
//! and an axis must not keep generating on wrong predictions. The port as a whole thus generates at most
//! `k E_allow` (k axes) plus one tick's worth per axis over a session: passive with an initial storage of
//! `k E_allow`, which the passivity inequality allows. The scale is continuous in the account, so the PD
//! never switches on or off as a step.

//!
//! **Across the network (two-port).** The coupling is one end of the two-port between the user's device and the
//! VE (`kinloop_linkage::passivity`); the client's local model is the other, and its uplinks carry its books.
//! Energy the user has put into the local model may legitimately come out here: each axis's account is
//! credited with what the client received on it, less what the force channel has already delivered to the VE
//! on it (that energy reached the VE beside the PD), never below zero. The credit trusts the client only as far
//! as the server can check it: it is the smaller of the client's report (refused and counted when it is
//! non-finite, negative, shrinking or faster than the device can push, see `EnergyReports`) and the server's
//! own booking of the same flow from the uplinks it received (the model wrench times the model twist, held
//! over each gap) plus the allowance. A client that overstates what it received buys nothing; one that
//! understates only makes its own coupling stricter.

use kinloop_linkage::passivity::{output_scale, EnergyReports, PortBooks, MAX_AXES};
use kinloop_linkage::{Space, VecOps};

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
    /// The PD scale β for the coming tick, per axis, from the power `predicted_power` (per axis, W) the
    /// unscaled PD would deliver to the VE at the last evaluated state; `allowance_j` is `E_allow` (≥ 0; zero
    /// is the strict limit: off while in deficit). Counts an activation when an axis is scaled down.
    pub fn pd_scale<S: Space>(&mut self, predicted_power: &S::OpVec, allowance_j: f64) -> S::OpVec {
        let surplus = self.absorbed_j.max(0.0);
        let mut scale = S::OpVec::zero();
        let mut scaled = false;
        for axis in 0..S::DIM {
            let account = self.absorbed_axis_j[axis] + surplus + self.client_credit(axis, allowance_j);
            let beta = output_scale(account, predicted_power[axis] <= 0.0, allowance_j);
            scaled |= beta < 1.0;
            scale[axis] = beta;
        }
        if scaled {
            self.activations += 1;
        }
        scale
    }

    /// What the client put in on `axis` and the force channel has not yet delivered (J, ≥ 0): the smaller of
    /// its report and the server's own booking plus `allowance_j`.
    pub fn client_credit(&self, axis: usize, allowance_j: f64) -> f64 {
        let trusted = self.client.accepted.received_j[axis].min(self.client_seen.received_j[axis] + allowance_j);
        (trusted - self.force_channel.emitted_j[axis]).max(0.0)
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
    use kinloop_linkage::Planar;
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

    #[test]
    fn each_axis_is_booked_on_its_own_and_may_draw_on_the_ports_surplus() {
        // x absorbs 3 J, θ generates 1 J: the port as a whole absorbed 2 J, which pays for θ's deficit.
        let mut observer = PassivityObserver::default();
        observer.observe::<Planar>(
            &V::from_slice(&[-3.0, 0.0, 2.0]),
            &on_x(0.0),
            &V::from_slice(&[1.0, 5.0, 0.5]),
            1.0,
        );
        assert_eq!(observer.absorbed_axis_j[..3], [3.0, 0.0, -1.0]);
        assert_eq!(observer.absorbed_j, 2.0);
        let delivering = V::from_slice(&[1.0, 1.0, 1.0]);
        assert_eq!(observer.pd_scale::<Planar>(&delivering, 2.0), delivering, "in credit overall: full strength");
        assert_eq!(observer.activations, 0);
        // θ generates 2.5 J more: the port is 0.5 J in deficit, θ 3.5 J: with a 4 J allowance θ's PD is at
        // 1 − 3.5/4 while it delivers energy, at full strength while it absorbs, and x and y are untouched.
        observer.observe::<Planar>(&V::from_slice(&[0.0, 0.0, 5.0]), &on_x(0.0), &V::from_slice(&[0.0, 0.0, 0.5]), 1.0);
        assert_eq!(observer.absorbed_j, -0.5);
        assert_eq!(observer.pd_scale::<Planar>(&delivering, 4.0), V::from_slice(&[1.0, 1.0, 0.125]));
        assert_eq!(observer.pd_scale::<Planar>(&V::from_slice(&[1.0, 1.0, -1.0]), 4.0), delivering);
        assert_eq!(observer.activations, 1);
        // Beyond the allowance the axis is off, whatever the prediction says.
        assert_eq!(
            observer.pd_scale::<Planar>(&V::from_slice(&[1.0, 1.0, -1.0]), 3.0),
            V::from_slice(&[1.0, 1.0, 0.0])
        );
        assert_eq!(observer.pd_scale::<Planar>(&delivering, 0.0), V::from_slice(&[1.0, 1.0, 0.0]), "strict limit");
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
        for n in 0..(seconds / h) as usize {
            let reference = u * n as f64 * h;
            let pd = k * (reference - x) + b * (u - v);
            let beta = match allowance_j {
                Some(allowance) => observer.pd_scale::<Planar>(&on_x(pd * v), allowance)[0],
                None => 1.0,
            };
            let force = beta * pd;
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
            let beta = observer.pd_scale::<Planar>(&on_x(pd * v), 0.0)[0];
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
