//! The join's load handed over: a linkage that waited at rest (`VeConfig::rest_unheld`) is held by the VE
//! while its first holder's coupling fades in, and handed to that coupling gradually, so it neither falls
//! away under a half-faded coupling nor lurches into the spring as the fade ends.
//!
//! **The hold.** The VE applies `σ L` at the OP of the *carrier*, where `L` is the static load there
//! (`kinloop_linkage::algorithms::reach::static_op_load`: the OP wrench that cancels gravity's and the
//! springs' acceleration in the OP's free directions, taken at the state the carrier took the hold in) and
//! `σ ∈ [0, 1]` the share still held. Each tick:
//! - `σ ← min(σ, 1 − s)`, with `s` the share of `L` that the carrier's force channel carries along `L` as
//!   the VE applies it (the user's hand wrench as heard and any load held for the user, faded; in
//!   unit-consistent coordinates `(f, τ / ℓ)`, ℓ the scene's length scale): what the user's hand has taken
//!   over is not held twice. The PD's share does not count: a PD stretched toward a local model that has
//!   not yet felt the load is not a hand that carries it, and giving the hold up to it hands the load to a
//!   spring whose user answers a round trip later;
//! - once the carrier's coupling is fully in and has heard its user (an uplink, not only the grasp at the
//!   join), `σ` falls by `dt / (fade_time + ANSWER_ROUND_TRIPS · T)`, `T` how long the handover waited for
//!   that first uplink (the round trip as this join lived it). The user's hand can answer a release only a
//!   round trip after it (the snapshot's b̂ carries the hold, so the local model feels the load as the hold
//!   lets go), so the part of `L` that neither the hold nor the hand as heard carries, which the PD is left
//!   with, stays below `T / (fade_time + ANSWER_ROUND_TRIPS · T)` of it, under `1 / ANSWER_ROUND_TRIPS`
//!   at any delay; without delay the load passes over one more fade, slowly enough that the OP sinks into
//!   the spring without passing its rest. Before the first uplink the grasp's PD holds the join's pose,
//!   where the user's local model starts, and `σ` does not fall: the load passed to it then would sink the
//!   OP by `L / K_g` (centimetres at the device for a heavy link on a light OP) a round trip before the
//!   user's hand could take it up.
//!
//! `σ` never rises during a handover, so the hold only ever lets go.
//!
//! **It holds, it does not drive.** `σ L` is a constant force: where the linkage cannot rest under it (a
//! toggle at its dead centre buckles under the load its slider is held with) the hold pushes the linkage
//! along and does work that no potential energy pays for, which the coupling hands to the device and the hand.
//! So the handover books the hold's work beyond the potential energy the linkage gained since the hold began
//! (`∫ σ L · ẋ_op dt − max(0, V − V₀)`, `V` gravity's and the springs' energy), and once that exceeds what the
//! coupling's spring would store holding the load, `½ Σ L_a² / K_a` (the energy the handover exists to keep out
//! of the spring), lets go of it over the round trip the user's hand needs to answer, by `dt / (dt + T)` a
//! tick (besides the fall above): at once without delay, and under delay slowly enough that the hand, a round
//! trip away, can take the load up as it falls rather than the spring at once; a slower release (over the
//! fade and `ANSWER_ROUND_TRIPS` round trips) leaves a buckling linkage driven for seconds. A hold that lifts
//! the linkage with the hand books nothing (the potential energy takes its work), nor one that resists a fall.
//!
//! **Who carries it (the rule).** A handover begins only when a coupling starts to fade in while nobody held
//! the linkage (every weight zero, the linkage resting): `σ = 1`. The carrier is the active coupling furthest
//! into its fade (the largest weight; the earliest joined on a tie). If another coupling overtakes it (the
//! carrier leaves or falls silent), the hold moves there with the same `σ` and a fresh `L` at that OP. A
//! linkage already held by someone is not supported when a second user joins (the holder's coupling carries
//! it); when every coupling has faded out the linkage rests again, and the next join hands it over afresh.
//!
//! **Books.** The hold is a force of the VE's own, like gravity: it is in neither the hand's nor the
//! controller's books of the passivity observer (`Coupling::controller_part` leaves it out), the step's
//! energy guard counts its work with every applied force, and the snapshot probe applies it
//! (`Evaluation::ProbeHands`), so b̂ carries the linkage as the VE does while it is held (a local model
//! without it would render a fall the VE does not make). It is not a hand, so no user's b̂ loses it.

use kinloop_linkage::algorithms::constraint_directions::scale_op;
use kinloop_linkage::math::space::{Space, VecOps};

use super::coupling::Coupling;

/// How many round trips, beyond the fade, the hold takes to let go once its carrier is heard: the part of
/// the load the hand has not yet answered stays under the inverse of this (see the module documentation).
pub const ANSWER_ROUND_TRIPS: f64 = 4.0;

/// The handover in flight (see the module documentation).
#[derive(Clone, Copy, Debug)]
pub struct Handover<S: Space> {
    /// σ: the share of `load` the VE still holds (0 when no handover is in flight).
    pub share: f64,
    /// L at the carrier's OP.
    pub load: S::OpVec,
    /// Index of the carrier among the couplings (valid for the tick it was chosen in).
    pub carrier: Option<usize>,
    /// How long the handover waited for its carrier's first uplink (s): the round trip as this join lived
    /// it (the welcome's way down, the first uplink's way up, and the playout's wait).
    pub waited_s: f64,
    /// The hold's work since it began or moved (signed).
    pub hold_work: f64,
    /// The hold's work beyond the potential energy the linkage gained since it began or moved:
    /// `hold_work − max(0, V − V₀)`.
    pub unpaid_work: f64,
    /// What [`Handover::unpaid_work`] may reach: `½ Σ L_a² / K_a` at the carrier.
    pub work_allowed: f64,
    /// The linkage's potential energy `V₀` when the hold began or moved.
    pub start_potential: f64,
    /// The hold's unpaid work has passed what it may do: it is letting go.
    pub driving: bool,
}

impl<S: Space> Default for Handover<S> {
    fn default() -> Self {
        Handover {
            share: 0.0,
            load: S::OpVec::zero(),
            carrier: None,
            waited_s: 0.0,
            hold_work: 0.0,
            unpaid_work: 0.0,
            work_allowed: 0.0,
            start_potential: 0.0,
            driving: false,
        }
    }
}

/// What one tick's update needs to know about the couplings, gathered before their weights change.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Before {
    /// Every coupling's weight was zero: nobody held the linkage.
    pub unheld: bool,
    /// `s`: the share of the hold's load the carrier's last applied wrench carried (0 without a carrier).
    pub carried: f64,
    /// The hold's power at the carrier's OP as the last tick applied it, `σ L · ẋ_op` (0 without a hold).
    pub hold_power: f64,
    /// The linkage's potential energy now (gravity, springs); read only while a hold is in flight.
    pub potential: f64,
}

/// The share of `load` that `wrench` carries along it, in unit-consistent coordinates `(f, τ / ℓ)`: the
/// projection `⟨F, L⟩ / ⟨L, L⟩`; zero for a zero or non-finite load or wrench.
pub fn carried_share<S: Space>(wrench: &S::OpVec, load: &S::OpVec, length_scale: f64) -> f64 {
    let ell = if length_scale.is_finite() && length_scale > 0.0 { length_scale } else { 1.0 };
    let (f, l) = (scale_op::<S>(wrench, 1.0 / ell), scale_op::<S>(load, 1.0 / ell));
    let (along, norm) = (f.dot(&l), l.dot(&l));
    let share = along / norm;
    if norm > 0.0 && share.is_finite() {
        share
    } else {
        0.0
    }
}

/// `s` for the coming tick, from the couplings as the last tick left them: the carrier's force channel
/// (`Coupling::hand_part`).
/// `potential` gives the linkage's potential energy, read only while a hold is in flight.
pub fn before_tick<S: Space>(
    handover: &Handover<S>,
    couplings: &[Coupling<S>],
    length_scale: f64,
    potential: impl FnOnce() -> f64,
) -> Before {
    let unheld = couplings.iter().all(|c| c.weight <= 0.0);
    match handover.carrier.and_then(|i| couplings.get(i)) {
        Some(c) if handover.share > 0.0 => Before {
            unheld,
            carried: carried_share::<S>(&c.hand_part(), &handover.load, length_scale),
            hold_power: c.hold.dot(&c.op_twist),
            potential: potential(),
        },
        _ => Before { unheld, carried: 0.0, hold_power: 0.0, potential: 0.0 },
    }
}

/// `½ Σ L_a² / K_a` over the axes with a spring: what the coupling's spring stores holding `load`.
fn spring_energy_holding<S: Space>(load: &S::OpVec, stiffness: &S::OpVec) -> f64 {
    (0..S::DIM).filter(|&a| stiffness[a] > 0.0).map(|a| 0.5 * load[a] * load[a] / stiffness[a]).sum()
}

/// The active coupling furthest into its fade (largest weight, earliest on a tie), if any.
pub fn furthest_in<S: Space>(couplings: &[Coupling<S>]) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, c) in couplings.iter().enumerate().filter(|(_, c)| c.is_active()) {
        if best.is_none_or(|(_, w)| c.weight > w) {
            best = Some((i, c.weight));
        }
    }
    best.map(|(i, _)| i)
}

impl<S: Space> Handover<S> {
    /// Coupling `index` was removed: the carrier's index follows it (a removed carrier leaves none, and the
    /// next update moves the hold).
    pub fn removed(&mut self, index: usize) {
        self.carrier = match self.carrier {
            Some(c) if c > index => Some(c - 1),
            Some(c) if c == index => None,
            other => other,
        };
    }

    /// One tick's update of σ and the carrier, after the couplings' weights for the tick are set; `load_at`
    /// gives `L` at a coupling's OP (called when a handover begins or the hold moves). `dt` is the tick and
    /// `fade_s` the fade time (s). Writes each coupling's `hold` (σ L at the carrier, zero elsewhere).
    pub fn update(
        &mut self,
        before: Before,
        couplings: &mut [Coupling<S>],
        [dt, fade_s]: [f64; 2],
        mut load_at: impl FnMut(usize) -> S::OpVec,
    ) {
        let carrier = furthest_in(couplings);
        match carrier {
            None => *self = Handover::default(),
            Some(i) if before.unheld => {
                let load = load_at(i);
                let work_allowed = spring_energy_holding::<S>(&load, &couplings[i].stiffness);
                *self = Handover {
                    share: 1.0,
                    load,
                    carrier: Some(i),
                    work_allowed,
                    start_potential: before.potential,
                    ..Handover::default()
                };
            }
            Some(i) if self.share > 0.0 => {
                if self.carrier == Some(i) {
                    self.share = self.share.min(1.0 - before.carried);
                    self.hold_work += before.hold_power * dt;
                    self.unpaid_work = self.hold_work - (before.potential - self.start_potential).max(0.0);
                } else {
                    self.load = load_at(i);
                    self.carrier = Some(i);
                    self.work_allowed = spring_energy_holding::<S>(&self.load, &couplings[i].stiffness);
                    (self.hold_work, self.unpaid_work, self.start_potential) = (0.0, 0.0, before.potential);
                }
                // Driving the linkage rather than holding it: it lets go from now on (the module documentation).
                self.driving |= self.unpaid_work > self.work_allowed;
                let heard = couplings[i].heard_time_s > 0.0;
                if !heard {
                    self.waited_s += dt;
                }
                if heard && couplings[i].weight >= 1.0 {
                    self.share -= dt / (fade_s + ANSWER_ROUND_TRIPS * self.waited_s);
                }
                if self.driving {
                    // Over the round trip the user's hand needs to answer its fall, not the coupling's fade:
                    // while it holds, the hold makes the work, and without delay it goes at once.
                    self.share -= dt / (dt + self.waited_s);
                }
                if self.share <= 0.0 || self.share.is_nan() {
                    *self = Handover::default();
                }
            }
            Some(_) => *self = Handover::default(),
        }
        for (i, c) in couplings.iter_mut().enumerate() {
            c.hold = if Some(i) == self.carrier { self.load * self.share } else { S::OpVec::zero() };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::{Vector2, Vector3};

    /// A 1 ms tick and a 0.2 s fade: `dt / fade_time` = 0.005.
    const TICK: [f64; 2] = [1e-3, 0.2];

    /// A pushing coupling at `weight` that has heard its user (an uplink at client time 1 s).
    fn coupling(weight: f64) -> Coupling<Planar> {
        let mut c = Coupling::<Planar>::new(1, Vector2::zeros(), 3, Vector3::repeat(1.0), Vector3::repeat(0.1));
        c.pushes = true;
        c.weight = weight;
        c.heard_time_s = 1.0;
        c
    }

    /// The share is a projection in `(f, τ / ℓ)`: a wrench equal to the load carries it all, a perpendicular
    /// one none, and the answer does not change with the units (lengths ×1000: torques ×1000, ℓ ×1000).
    #[test]
    fn the_carried_share_is_the_unit_consistent_projection() {
        let load = Vector3::new(0.0, 2.0, 0.03);
        assert!((carried_share::<Planar>(&load, &load, 0.1) - 1.0).abs() < 1e-15);
        assert!((carried_share::<Planar>(&(load * 0.25), &load, 0.1) - 0.25).abs() < 1e-15);
        let across = Vector3::new(5.0, 0.0, 0.0);
        assert_eq!(carried_share::<Planar>(&across, &load, 0.1), 0.0);
        let wrench = Vector3::new(0.4, 1.1, -0.01);
        let si = carried_share::<Planar>(&wrench, &load, 0.1);
        let mm = carried_share::<Planar>(&Vector3::new(0.4, 1.1, -10.0), &Vector3::new(0.0, 2.0, 30.0), 100.0);
        assert!((si - mm).abs() < 1e-12, "{si} vs {mm}");
        // By hand: ⟨(0.4, 1.1, −0.1), (0, 2, 0.3)⟩ / ⟨(0, 2, 0.3), (0, 2, 0.3)⟩.
        assert!((si - (2.2 - 0.03) / 4.09).abs() < 1e-12);
        for bad in [Vector3::zeros(), Vector3::new(f64::NAN, 0.0, 0.0)] {
            assert_eq!(carried_share::<Planar>(&wrench, &bad, 0.1), 0.0);
        }
    }

    /// A handover begins at a join onto a resting linkage, holds all of L through the fade when the coupling
    /// carries none of it, gives up what the coupling takes over, falls by `dt / fade_time` once the coupling
    /// is in (heard without waiting), and never rises; nobody holding ends it, and a linkage already held gets none.
    #[test]
    fn the_hold_begins_at_rest_gives_up_what_is_carried_and_falls_once_the_coupling_is_in() {
        let load = Vector3::new(0.0, 3.0, 0.0);
        let mut couplings = vec![coupling(0.0)];
        let mut h = Handover::<Planar>::default();
        let unheld = Before { unheld: true, carried: 0.0, ..Before::default() };
        couplings[0].weight = 0.01;
        h.update(unheld, &mut couplings, TICK, |_| load);
        assert_eq!((h.share, h.carrier), (1.0, Some(0)));
        assert_eq!(couplings[0].hold, load);
        // Mid-fade the coupling carries 30 %: the hold gives it up; then it carries less: σ does not rise.
        couplings[0].weight = 0.5;
        h.update(Before { unheld: false, carried: 0.3, ..Before::default() }, &mut couplings, TICK, |_| unreachable!());
        assert!((h.share - 0.7).abs() < 1e-15);
        h.update(Before { unheld: false, carried: 0.1, ..Before::default() }, &mut couplings, TICK, |_| unreachable!());
        assert!((h.share - 0.7).abs() < 1e-15);
        // Fully in: it falls by the fade's step each tick, to zero, and stays there.
        couplings[0].weight = 1.0;
        h.update(Before { unheld: false, carried: 0.0, ..Before::default() }, &mut couplings, TICK, |_| unreachable!());
        assert!((h.share - 0.695).abs() < 1e-12);
        for _ in 0..200 {
            h.update(
                Before { unheld: false, carried: 0.0, ..Before::default() },
                &mut couplings,
                TICK,
                |_| unreachable!(),
            );
        }
        assert_eq!((h.share, h.carrier, couplings[0].hold), (0.0, None, Vector3::zeros()));
        // A second user joining a held linkage: no hold.
        couplings.push(coupling(0.01));
        h.update(Before { unheld: false, carried: 0.0, ..Before::default() }, &mut couplings, TICK, |_| unreachable!());
        assert_eq!((h.share, couplings[1].hold), (0.0, Vector3::zeros()));
        // Nobody holds: no hold.
        couplings.iter_mut().for_each(|c| c.weight = 0.0);
        h.update(unheld, &mut couplings, TICK, |_| unreachable!());
        assert_eq!(h.carrier, None);
    }

    /// The hold is carried by the coupling furthest into its fade, and moves (same σ, a fresh L) when another
    /// overtakes it.
    #[test]
    fn the_hold_moves_to_the_coupling_furthest_in() {
        let mut couplings = vec![coupling(0.2), coupling(0.2)];
        let mut h = Handover::<Planar>::default();
        let load_at = |i: usize| Vector3::new(0.0, 1.0 + i as f64, 0.0);
        h.update(Before { unheld: true, carried: 0.0, ..Before::default() }, &mut couplings, TICK, load_at);
        assert_eq!(h.carrier, Some(0), "the earliest on a tie");
        h.update(Before { unheld: false, carried: 0.4, ..Before::default() }, &mut couplings, TICK, load_at);
        couplings[0].weight = 0.1;
        couplings[1].weight = 0.3;
        h.update(Before { unheld: false, carried: 0.9, ..Before::default() }, &mut couplings, TICK, load_at);
        assert_eq!(h.carrier, Some(1));
        assert!((h.share - 0.6).abs() < 1e-15, "the old carrier's share is not applied to the new load");
        assert_eq!(couplings[0].hold, Vector3::zeros());
        assert!((couplings[1].hold - Vector3::new(0.0, 1.2, 0.0)).norm() < 1e-15);
    }

    /// A carrier not yet heard (the grasp at the join, before the first uplink) keeps the whole hold, fully
    /// faded in or not; once heard, σ falls over the fade plus `ANSWER_ROUND_TRIPS` times the wait, so what the
    /// hand has not answered a round trip after a release stays under `1 / ANSWER_ROUND_TRIPS` of L.
    #[test]
    fn the_hold_waits_for_its_user_and_lets_go_over_the_round_trips_it_waited() {
        let load = Vector3::new(0.0, 3.0, 0.0);
        let mut couplings = vec![coupling(0.01)];
        couplings[0].heard_time_s = 0.0;
        let mut h = Handover::<Planar>::default();
        h.update(Before { unheld: true, carried: 0.0, ..Before::default() }, &mut couplings, TICK, |_| load);
        couplings[0].weight = 1.0;
        // 600 ticks unheard (a 0.6 s round trip): nothing let go.
        for _ in 0..600 {
            h.update(
                Before { unheld: false, carried: 0.0, ..Before::default() },
                &mut couplings,
                TICK,
                |_| unreachable!(),
            );
        }
        assert_eq!(h.share, 1.0);
        assert!((h.waited_s - 0.6).abs() < 1e-9, "{}", h.waited_s);
        couplings[0].heard_time_s = 1.0;
        let tau = 0.2 + ANSWER_ROUND_TRIPS * 0.6;
        let ticks = 600;
        for _ in 0..ticks {
            h.update(
                Before { unheld: false, carried: 0.0, ..Before::default() },
                &mut couplings,
                TICK,
                |_| unreachable!(),
            );
        }
        // Over one round trip σ gave up T / τ of L, under 1 / ANSWER_ROUND_TRIPS.
        let given_up = 1.0 - h.share;
        assert!((given_up - 0.6 / tau).abs() < 1e-9, "{given_up} against {}", 0.6 / tau);
        assert!(given_up < 1.0 / ANSWER_ROUND_TRIPS);
        // The PD's stretch is not a hand: only the force channel's share counts, and it ends the hold.
        couplings[0].hand_wrench = load;
        let before = before_tick(&h, &couplings, 1.0, || 0.0);
        assert!((before.carried - 1.0).abs() < 1e-15);
        h.update(before, &mut couplings, TICK, |_| unreachable!());
        assert_eq!((h.share, h.carrier), (0.0, None));
    }

    /// A hold whose work no potential energy takes (a toggle buckling under it) lets go once that work passes
    /// what the spring would store holding the load (`½ L² / K` = 4.5 here); one that lifts the linkage with
    /// the potential energy taking its work, resists a fall, or swings it to and fro stays.
    #[test]
    fn a_hold_that_drives_the_linkage_lets_go_and_one_that_holds_it_stays() {
        let load = Vector3::new(0.0, 3.0, 0.0);
        // Ticks of the hold's `power(k)` and the potential energy `potential(k)` at the end of tick k, the user
        // heard after a wait of `waited_s`.
        let run_waited = |power: &dyn Fn(usize) -> f64, potential: &dyn Fn(usize) -> f64, ticks: usize, waited_s| {
            let mut couplings = vec![coupling(0.01)];
            let mut h = Handover::<Planar>::default();
            h.update(Before { unheld: true, ..Before::default() }, &mut couplings, TICK, |_| load);
            assert_eq!(h.work_allowed, 4.5);
            h.waited_s = waited_s;
            couplings[0].weight = 0.5;
            for k in 0..ticks {
                let before = Before { unheld: false, carried: 0.0, hold_power: power(k), potential: potential(k) };
                h.update(before, &mut couplings, TICK, |_| unreachable!());
            }
            (h, couplings[0].hold)
        };
        let run = |power: &dyn Fn(usize) -> f64, potential: &dyn Fn(usize) -> f64, ticks| {
            run_waited(power, potential, ticks, 0.0)
        };
        let (pushing, level) = (|_| 3.0, |_| 0.0);
        // 3 units of power for 1 ms a tick: 4.5 is reached on the 1,500th tick and passed after it.
        let (h, hold) = run(&pushing, &level, 1499);
        assert_eq!((h.share, hold), (1.0, load), "{h:?}");
        assert!((h.unpaid_work - 4.497).abs() < 1e-9, "{h:?}");
        assert!(!h.driving);
        // Past it, the hold lets go: at once for a user heard without waiting, ...
        let (h, hold) = run(&pushing, &level, 1502);
        assert_eq!((h.share, h.carrier, hold), (0.0, None, Vector3::zeros()), "driving: let go");
        // ... over the round trip the hand needs to answer for one whose first uplink took 0.5 s.
        let (h, _) = run_waited(&pushing, &level, 1600, 0.5);
        assert!(h.driving && h.share < 0.81 && h.share > 0.79, "{h:?}");
        let (h, hold) = run_waited(&pushing, &level, 2100, 0.5);
        assert_eq!((h.share, h.carrier, hold), (0.0, None, Vector3::zeros()));
        // Lifting: the potential energy rises by the hold's work.
        let (h, hold) = run(&pushing, &|k| 3e-3 * (k + 1) as f64, 3000);
        assert_eq!((h.share, hold), (1.0, load));
        assert!(h.unpaid_work.abs() < 1e-9, "{h:?}");
        // Resisting a fall: the hold takes energy out.
        let (h, hold) = run(&|_| -3.0, &|k| -3e-3 * (k + 1) as f64, 3000);
        assert_eq!((h.share, hold), (1.0, load));
        assert!(h.unpaid_work < -8.9, "{h:?}");
        // To and fro along the load, 0.3 units out and back every 200 ticks: nothing is booked for good.
        let (h, hold) = run(&|k| if k % 200 < 100 { 3.0 } else { -3.0 }, &level, 3000);
        assert_eq!((h.share, hold), (1.0, load));
        assert!(h.unpaid_work.abs() < 1e-9, "{h:?}");
    }
}
