//! A simulated hand that behaves like one: a grasp modelled as a mass-spring-damper attached to an intended
//! motion. The hand's mass moves with the handle (the rig adds it to the device's plant); the arm pulls the
//! hand toward where it intends to be through a spring and a damper, and moves its own mass along that
//! intention (the feedforward a person learns for their own arm):
//! ```text
//! F_h = K (x_d ⊖ x) + B (ẋ_d − ẋ) + M ẍ_d
//! ```
//! So it pushes where the linkage yields and yields where the linkage pushes back — unlike a constant force,
//! which never yields and was "a worst case approximation of the user for stability" in the paper.
//!
//! **Presets** (per linear axis; per angular axis for the wrist):
//! - `soft`: a relaxed grasp, the arm-and-hand impedance one participant showed on a HapticMaster —
//!   M 0.554 kg, B 6.45 N s/m, K 135 N/m (Sci. Rep. 5:18004, 2015, Fig 3).
//! - `firm`: a tight, co-contracted grasp. Stiffness and damping rise with grip force (Hasser & Cutkosky,
//!   2002; Fu & Çavuşoğlu, IEEE TSMC-B 2012, for stylus devices at 1-3 N of grip); taken here at about five
//!   times the relaxed values and within the ranges commonly simulated for a firm grasp (0.5-2 kg,
//!   10-30 N s/m, 500-2000 N/m): M 0.8 kg, B 25 N s/m, K 700 N/m.
//! - The wrist, on a device's angular axes: a relaxed 1e-3 kg m², 0.02 N m s/rad, 0.3 N m/rad and a firm
//!   2e-3 kg m², 0.08 N m s/rad, 2 N m/rad (values of the order Kuchenbecker, Park & Niemeyer report for
//!   the wrist holding a stylus, IEEE Haptics Symposium 2003).
//!
//! **Events**: `release` lets go at [`RELEASE_AT_S`] (the hand's wrench and mass leave the handle at once:
//! the device is left alone with whatever the controllers command), `poke` steps the intended position by
//! [`POKE_STEP_M`] along x for [`POKE_DURATION_S`] at [`POKE_AT_S`] (an abrupt jab).
//!
//! **Intended motion**: by default a tour of the operational point's reach, as the server surveyed it
//! (`Welcome::op::tour`), mapped into the device's space: waypoints that the linkage can reach, visited in
//! order and back on minimum-jerk segments (Flash & Hogan 1985) at a relaxed pace of at most
//! [`TOUR_SPEED_M_S`]; or a scripted `path` (see [`PathSpec`]); or holding still where it grasped.
//!
//! **Touring by feel.** A person exploring a linkage with a relaxed arm does not pull a handle that will not
//! come: where the linkage resists more than a light push (a heavy stretch of its reach, a dead point where
//! the OP jams, a branch it took that the waypoints did not), they stop and go back. So the soft hand's
//! intention runs on its own clock, which moves on at full pace while the arm's spring pulls the handle with
//! less than [`TOUR_PUSH_EASE_N`], slows as the pull grows, and stops at [`TOUR_PUSH_STALL_N`], for as long
//! as going on would pull harder; a step that eases the pull is never held back. Stopped for
//! [`TOUR_STALL_S`], the hand turns back along its tour. The pace drops at once to what the pull allows and
//! grows back no faster than from a stop to full pace in a fifth of a second, so a turn is not a jump of the
//! hand's velocity. By the clock a soft hand's intention can run on centimetres past a linkage that turned
//! back at a cusp of its coupler curve, pulling the handle harder than a Touch can push back, for seconds.
//! (Exploratory touch is done with forces of the order of a newton: Lederman & Klatzky, 1987; Smith, Gosselin
//! & Houde, 2002, measured 0.5-2 N stroking a surface.) The firm grasps (firm, release, poke) are the user
//! who pushes: their tours keep to the time since the grasp whatever the handle does
//! ([`HandKind::tours_by_feel`]), as do scripted paths, holds, the poke's jab and the release.

use std::time::Duration;

use kinloop_linkage::math::space::OpPose;
use kinloop_linkage::math::space::{unwrap_rotation_near, Space, VecOps};
use kinloop_protocol::Welcome;

use super::path::{minimum_jerk, PathSpec};
use super::{SimulatedUser, UserError};
use crate::device::DeviceState;

/// When a `release` hand lets go, after its grasp (s).
pub const RELEASE_AT_S: f64 = 2.0;
/// When a `poke` hand jabs, after its grasp (s).
pub const POKE_AT_S: f64 = 1.5;
/// How far a poke steps the intended position, device space (m).
pub const POKE_STEP_M: f64 = 0.01;
/// How long the poke's step lasts (s).
pub const POKE_DURATION_S: f64 = 0.2;
/// Fastest pace of a tour between waypoints, device space (m/s).
pub const TOUR_SPEED_M_S: f64 = 0.04;
/// Shortest tour segment (s).
const TOUR_SEGMENT_MIN_S: f64 = 0.6;
/// The arm's pull (linear spring force toward the intention) up to which a tour moves on at full pace (N).
pub const TOUR_PUSH_EASE_N: f64 = 1.5;
/// The pull at which a tour stops moving on (N).
pub const TOUR_PUSH_STALL_N: f64 = 3.0;
/// How long a stopped tour waits before it turns back (s).
pub const TOUR_STALL_S: f64 = 1.0;

/// The hand's impedance: mass, damping and stiffness per linear axis, and the wrist's per angular axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandImpedance {
    /// kg.
    pub mass: f64,
    /// N s/m.
    pub damping: f64,
    /// N/m.
    pub stiffness: f64,
    /// kg m².
    pub inertia: f64,
    /// N m s/rad.
    pub angular_damping: f64,
    /// N m/rad.
    pub angular_stiffness: f64,
}

impl HandImpedance {
    /// A relaxed grasp (see the module documentation for the source).
    pub fn soft() -> Self {
        HandImpedance {
            mass: 0.554,
            damping: 6.45,
            stiffness: 135.0,
            inertia: 1e-3,
            angular_damping: 0.02,
            angular_stiffness: 0.3,
        }
    }

    /// A firm grasp (see the module documentation).
    pub fn firm() -> Self {
        HandImpedance {
            mass: 0.8,
            damping: 25.0,
            stiffness: 700.0,
            inertia: 2e-3,
            angular_damping: 0.08,
            angular_stiffness: 2.0,
        }
    }
}

/// Which hand (the `--user` names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HandKind {
    /// A relaxed grasp.
    Soft,
    /// A firm grasp.
    Firm,
    /// A firm grasp that lets go at [`RELEASE_AT_S`].
    Release,
    /// A firm grasp that jabs at [`POKE_AT_S`].
    Poke,
}

impl HandKind {
    /// Every kind, in order.
    pub const ALL: [HandKind; 4] = [HandKind::Soft, HandKind::Firm, HandKind::Release, HandKind::Poke];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            HandKind::Soft => "soft",
            HandKind::Firm => "firm",
            HandKind::Release => "release",
            HandKind::Poke => "poke",
        }
    }

    /// Parses a name.
    pub fn parse(s: &str) -> Option<Self> {
        HandKind::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Whether a tour by this hand yields where the handle will not come (module documentation, touring by
    /// feel): the relaxed hand does; a firm grasp pushes on along its tour whatever the handle does.
    pub fn tours_by_feel(self) -> bool {
        self == HandKind::Soft
    }

    /// The impedance of this kind.
    pub fn impedance(self) -> HandImpedance {
        match self {
            HandKind::Soft => HandImpedance::soft(),
            _ => HandImpedance::firm(),
        }
    }
}

/// What the hand intends to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Intent {
    /// Tour the operational point's reach (its waypoints are given at build time).
    Tour,
    /// A scripted path from the grasp point.
    Path(PathSpec),
    /// Hold still where it grasped.
    Hold,
}

/// A hand as named on the command line: `KIND[:PATH]`, e.g. `soft`, `firm:circle:0.01,2`.
#[derive(Clone, Debug, PartialEq)]
pub struct HandSpec {
    /// Which hand.
    pub kind: HandKind,
    /// What it intends.
    pub intent: Intent,
}

impl HandSpec {
    /// A hand of `kind` touring the reach.
    pub fn touring(kind: HandKind) -> Self {
        HandSpec { kind, intent: Intent::Tour }
    }
}

/// The waypoints of an intended tour, as displacements from the grasp pose in the device's space (linear,
/// rotation vector).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UserContext<S: Space> {
    /// Displacements, in order.
    pub tour: Vec<S::OpVec>,
}

impl<S: Space> UserContext<S> {
    /// The welcome's tour (VE displacements from the OP's pose at the join) in the device's space: linear
    /// parts times the position scale, rotations one to one.
    pub fn from_welcome(welcome: &Welcome) -> Self {
        let k = S::DIM;
        let lin = <S::Point as VecOps>::LEN;
        let scale = welcome.mapping.position_scale;
        let tour = welcome
            .op
            .tour
            .chunks_exact(k)
            .map(|w| {
                let mut v = S::OpVec::from_slice(w);
                for i in 0..lin {
                    v[i] *= scale;
                }
                v
            })
            .collect();
        UserContext { tour }
    }
}

/// The order in which a hand tours `waypoints` (displacements from its grasp): forth from the one nearest the
/// grasp around the list, then back, so it follows the reach rather than cutting across it from the grasp
/// to the list's first point. Simulated hands and the fake DHD library's hand (through
/// `kinloop experiment renderability-dhd`) tour in this order.
pub fn tour_order<S: Space>(waypoints: &[S::OpVec]) -> Vec<S::OpVec> {
    if waypoints.is_empty() {
        return Vec::new();
    }
    let distance = |a: &S::OpVec, b: &S::OpVec| S::op_lin(&(*a - *b)).norm();
    let nearest = (0..waypoints.len())
        .min_by(|&i, &j| {
            distance(&waypoints[i], &S::OpVec::zero()).total_cmp(&distance(&waypoints[j], &S::OpVec::zero()))
        })
        .unwrap_or(0);
    // Forth from the nearest point around the list, then back.
    let mut order: Vec<S::OpVec> = (0..waypoints.len()).map(|k| waypoints[(nearest + k) % waypoints.len()]).collect();
    // Angles continuous along the way: each displacement's rotation is a logarithm, within ±π of the
    // grasp, and an OP that turns a whole circle over its reach (the testbed's link 2) would otherwise
    // have the wrist interpolate the long way round between two neighbours (a twist far beyond a
    // device's torque). Back retraces the same angles.
    let mut previous = S::OpVec::zero();
    for w in &mut order {
        unwrap_rotation_near::<S>(w, &previous);
        previous = *w;
    }
    let back: Vec<S::OpVec> = order.iter().rev().skip(1).copied().collect();
    order.extend(back);
    order
}

/// The intended motion as a function of time: minimum-jerk segments between displacements.
#[derive(Clone, Debug)]
struct Plan<S: Space> {
    /// (start time, displacement) of each knot; the motion goes from knot i to knot i + 1.
    knots: Vec<(f64, S::OpVec)>,
    /// Repeat from the start after the last knot (a tour back and forth).
    period_s: Option<f64>,
}

impl<S: Space> Plan<S> {
    fn hold() -> Self {
        Plan { knots: vec![(0.0, S::OpVec::zero())], period_s: None }
    }

    /// From the grasp to the nearest waypoint, then through the tour and back, repeated.
    fn tour(waypoints: &[S::OpVec]) -> Self {
        if waypoints.is_empty() {
            return Self::hold();
        }
        let distance = |a: &S::OpVec, b: &S::OpVec| S::op_lin(&(*a - *b)).norm();
        let order = tour_order::<S>(waypoints);
        let mut knots = vec![(0.0, S::OpVec::zero())];
        let mut t = 0.0;
        let mut last = S::OpVec::zero();
        for w in order {
            t += (distance(&w, &last) / TOUR_SPEED_M_S).max(TOUR_SEGMENT_MIN_S);
            knots.push((t, w));
            last = w;
        }
        // The repeat starts at the first waypoint (knot 1), not at the grasp.
        let start = knots.get(1).map_or(0.0, |k| k.0);
        Plan { period_s: Some(t - start).filter(|p| *p > 0.0), knots }
    }

    /// The displacement at `t_s` after the grasp.
    fn at(&self, t_s: f64) -> S::OpVec {
        let mut t = t_s.max(0.0);
        let last = self.knots[self.knots.len() - 1];
        if t >= last.0 {
            match self.period_s {
                Some(period) => {
                    let start = self.knots[1].0;
                    t = start + (t - start) % period;
                }
                None => return last.1,
            }
        }
        let i = self.knots.iter().rposition(|k| k.0 <= t).unwrap_or(0).min(self.knots.len() - 2);
        let (t0, a) = self.knots[i];
        let (t1, b) = self.knots[i + 1];
        a + (b - a) * minimum_jerk((t - t0) / (t1 - t0).max(1e-9))
    }
}

/// A scripted path as a plan (its offsets are in the device's x-y plane).
#[derive(Clone, Debug)]
struct PathPlan(PathSpec);

enum Motion<S: Space> {
    Knots(Plan<S>),
    Path(PathPlan),
}

impl<S: Space> Motion<S> {
    /// A tour, which may run on the touring clock; other motions keep to the time since the grasp.
    fn tours(&self) -> bool {
        matches!(self, Motion::Knots(plan) if plan.period_s.is_some())
    }

    fn at(&self, t_s: f64) -> S::OpVec {
        match self {
            Motion::Knots(plan) => plan.at(t_s),
            Motion::Path(PathPlan(spec)) => {
                let offset = spec.offset(t_s.max(0.0));
                let mut v = S::OpVec::zero();
                v[0] = offset[0];
                v[1] = offset[1];
                v
            }
        }
    }
}

/// The hand (see the module documentation).
pub struct Hand<S: Space> {
    kind: HandKind,
    motion: Motion<S>,
    stiffness: S::OpVec,
    damping: S::OpVec,
    mass: S::OpVec,
    grasp: Option<(Duration, OpPose<S>)>,
    clock: TourClock,
}

/// Where a touring hand's intention is along its plan (module documentation, touring by feel).
#[derive(Clone, Copy, Debug)]
struct TourClock {
    /// Plan time (s).
    plan_s: f64,
    /// Time since the grasp at the last call (s).
    last_s: f64,
    /// Along the plan (+1) or back (−1).
    direction: f64,
    /// Plan seconds per second, negative going back: follows the pace the pull allows at a bounded rate.
    pace: f64,
    /// How long the pull has held the plan still (s).
    stalled_s: f64,
}

/// How fast the tour's pace may grow (per second): a start or a turn takes a fifth of a second, as a person's
/// would, and a pull that dithers about a threshold does not make the hand's feedforward jitter with it.
const TOUR_PACE_RATE_PER_S: f64 = 5.0;

impl TourClock {
    fn new() -> Self {
        TourClock { plan_s: 0.0, last_s: 0.0, direction: 1.0, pace: 0.0, stalled_s: 0.0 }
    }

    /// Moves the plan on to `t_s` after the grasp, as fast as the arm's `pull` (N) at a plan time allows,
    /// and returns its pace (plan seconds per second, negative going back). A turn back ends at the grasp,
    /// and the tour goes forth again from there.
    fn advance(&mut self, t_s: f64, pull: impl Fn(f64) -> f64) -> f64 {
        let dt = (t_s - self.last_s).max(0.0);
        self.last_s = t_s;
        let here = pull(self.plan_s);
        let on = pull(self.plan_s + self.direction * DIFFERENCE_S);
        let allowed = if on <= here {
            1.0
        } else {
            ((TOUR_PUSH_STALL_N - here) / (TOUR_PUSH_STALL_N - TOUR_PUSH_EASE_N)).clamp(0.0, 1.0)
        };
        if allowed > 0.0 {
            self.stalled_s = 0.0;
        } else {
            self.stalled_s += dt;
            if self.stalled_s >= TOUR_STALL_S {
                self.direction = -self.direction;
                self.stalled_s = 0.0;
            }
        }
        let (before, wanted) = (self.pace, self.direction * allowed);
        self.pace = if wanted * before >= 0.0 && wanted.abs() <= before.abs() {
            // Slowing down is at once: a hand meeting resistance gives way as it feels it.
            wanted
        } else {
            let step = TOUR_PACE_RATE_PER_S * dt;
            before + (wanted - before).clamp(-step, step)
        };
        self.plan_s += self.pace * dt;
        if self.plan_s <= 0.0 && self.pace < 0.0 {
            // Back at the grasp, where the plan stands still: set out again.
            (self.plan_s, self.pace, self.direction) = (0.0, 0.0, 1.0);
        }
        self.pace
    }
}

/// The finite-difference step of the intended motion's velocity and acceleration (s).
const DIFFERENCE_S: f64 = 1e-3;

impl<S: Space> Hand<S> {
    /// A hand as `spec` says, touring `context`'s waypoints when it tours.
    pub fn new(spec: &HandSpec, context: &UserContext<S>) -> Result<Self, UserError> {
        let impedance = spec.kind.impedance();
        let linear = <S::Point as VecOps>::LEN;
        let mut stiffness = S::OpVec::zero();
        let mut damping = S::OpVec::zero();
        let mut mass = S::OpVec::zero();
        for i in 0..S::DIM {
            let angular = i >= linear;
            stiffness[i] = if angular { impedance.angular_stiffness } else { impedance.stiffness };
            damping[i] = if angular { impedance.angular_damping } else { impedance.damping };
            mass[i] = if angular { impedance.inertia } else { impedance.mass };
        }
        if context.tour.iter().any(|w| !w.is_finite()) {
            return Err(UserError::Path("the tour has a non-finite waypoint".into()));
        }
        let motion = match &spec.intent {
            Intent::Tour => Motion::Knots(Plan::tour(&context.tour)),
            Intent::Path(path) => Motion::Path(PathPlan(path.clone())),
            Intent::Hold => Motion::Knots(Plan::hold()),
        };
        Ok(Hand { kind: spec.kind, motion, stiffness, damping, mass, grasp: None, clock: TourClock::new() })
    }

    /// Seconds since the grasp (0 before it).
    fn since_grasp(&self, now: Duration) -> f64 {
        self.grasp.map_or(0.0, |(t0, _)| now.saturating_sub(t0).as_secs_f64())
    }

    fn released(&self, t_s: f64) -> bool {
        self.kind == HandKind::Release && t_s >= RELEASE_AT_S
    }

    /// The intended displacement at plan time `plan_s`, with the poke's step at `t_s` after the grasp.
    fn intended(&self, plan_s: f64, t_s: f64) -> S::OpVec {
        let mut d = self.motion.at(plan_s);
        if self.kind == HandKind::Poke && (POKE_AT_S..POKE_AT_S + POKE_DURATION_S).contains(&t_s) {
            d[0] += POKE_STEP_M;
        }
        d
    }

    /// How far the handle is from the intention `displacement` from the grasp (the arm's spring stretch).
    fn stretch(grasp: &OpPose<S>, displacement: &S::OpVec, device: &DeviceState<S>) -> S::OpVec {
        let mut target = *grasp;
        target.integrate(displacement, 1.0);
        target.difference(&device.pose)
    }

    /// The arm's spring force toward `displacement` from the grasp, linear axes (N).
    fn pull(&self, grasp: &OpPose<S>, displacement: &S::OpVec, device: &DeviceState<S>) -> f64 {
        let error = Self::stretch(grasp, displacement, device);
        let linear = <S::Point as VecOps>::LEN;
        (0..linear).map(|i| (self.stiffness[i] * error[i]).powi(2)).sum::<f64>().sqrt()
    }
}

impl<S: Space> SimulatedUser<S> for Hand<S> {
    fn wrench(&mut self, now: Duration, device: &DeviceState<S>) -> S::OpVec {
        let (_, grasp) = *self.grasp.get_or_insert((now, device.pose));
        let t = self.since_grasp(now);
        if self.released(t) {
            return S::OpVec::zero();
        }
        // The plan's time and pace: the clock of a tour by feel, or the time since the grasp.
        let (plan_s, pace) = if self.motion.tours() && self.kind.tours_by_feel() {
            let mut clock = self.clock;
            let pace = clock.advance(t, |s| self.pull(&grasp, &self.motion.at(s), device));
            self.clock = clock;
            (clock.plan_s, pace)
        } else {
            (t, 1.0)
        };
        let h = DIFFERENCE_S;
        let (before, here, after) =
            (self.intended(plan_s - h, t), self.intended(plan_s, t), self.intended(plan_s + h, t));
        // The poke is a step: no feedforward spike on its edges.
        let at_edge = |edge: f64| (t - edge).abs() < 2.0 * h;
        let (velocity, acceleration) =
            if self.kind == HandKind::Poke && (at_edge(POKE_AT_S) || at_edge(POKE_AT_S + POKE_DURATION_S)) {
                (S::OpVec::zero(), S::OpVec::zero())
            } else {
                // The intention x(p(t)): ẋ = x' ṗ and ẍ = x'' ṗ², leaving out x' p̈ (the pace's changes, a
                // step when it slows, would jolt the hand's wrench through its mass).
                ((after - before) * (0.5 * pace / h), (after - here * 2.0 + before) * (pace * pace / (h * h)))
            };
        let error = Self::stretch(&grasp, &here, device);
        let mut w = S::OpVec::zero();
        for i in 0..S::DIM {
            w[i] = self.stiffness[i] * error[i]
                + self.damping[i] * (velocity[i] - device.twist[i])
                + self.mass[i] * acceleration[i];
        }
        w
    }

    fn attached_mass(&self, now: Duration) -> S::OpVec {
        if self.released(self.since_grasp(now)) {
            S::OpVec::zero()
        } else {
            self.mass
        }
    }

    fn holds(&self, now: Duration) -> bool {
        !self.released(self.since_grasp(now))
    }
}
