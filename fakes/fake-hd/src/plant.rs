//! The fake Touch's plant, in the vendor's units: millimetres, millimetres per second, newtons. One point
//! mass per axis (the stylus tip's apparent mass) with viscous friction and stiff walls at the usable
//! workspace, held by a hand: a spring-damper grasp (its own mass moving with the stylus) pulling towards
//! where the hand means the stylus to be. The hand goes through waypoints and back, each leg a half cosine
//! (rest to rest) at a relaxed average pace. Integrated with semi-implicit Euler in steps of at most 100 µs.

/// Apparent mass at the stylus tip (kg): the Touch's, as kinloop's `sim:touch` preset gives it.
const TIP_MASS_KG: f64 = 0.045;
/// Mechanism friction (N per mm/s).
const FRICTION_N_PER_MM_S: f64 = 0.0005;
/// Wall stiffness at the usable workspace's bounds (N/mm).
const WALL_N_PER_MM: f64 = 2.0;
/// Longest integration step (s).
const MAX_STEP_S: f64 = 1e-4;
/// The hand's average pace between waypoints (mm/s), and the shortest leg (s).
const PACE_MM_S: f64 = 40.0;
const SHORTEST_LEG_S: f64 = 0.5;

/// A grasp: the hand's mass (kg), damping (N per mm/s) and stiffness (N/mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grasp {
    /// kg.
    pub mass: f64,
    /// N s/mm.
    pub damping: f64,
    /// N/mm.
    pub stiffness: f64,
}

impl Grasp {
    /// A relaxed grasp: M 0.554 kg, B 6.45 N s/m, K 135 N/m (`shared/haptics-facts.md`), per millimetre.
    pub const SOFT: Grasp = Grasp { mass: 0.554, damping: 0.00645, stiffness: 0.135 };
    /// A firm grasp: M 0.8 kg, B 25 N s/m, K 700 N/m, per millimetre.
    pub const FIRM: Grasp = Grasp { mass: 0.8, damping: 0.025, stiffness: 0.7 };
}

/// The stylus, and the hand on it (none: nobody holds it).
pub struct Plant {
    half_extent: [f64; 3],
    hand: Option<(Grasp, Vec<[f64; 3]>)>,
    position: [f64; 3],
    velocity: [f64; 3],
    /// Seconds the hand has been moving (None: it waits for a session).
    moving: Option<f64>,
}

impl Plant {
    /// A stylus at the first waypoint (or the centre) of a workspace `half_extent` (mm) wide.
    pub fn new(half_extent: [f64; 3], hand: Option<(Grasp, Vec<[f64; 3]>)>) -> Plant {
        let start = hand.as_ref().and_then(|(_, w)| w.first().copied()).unwrap_or([0.0; 3]);
        Plant { half_extent, hand, position: start, velocity: [0.0; 3], moving: None }
    }

    /// Position (mm).
    pub fn position(&self) -> [f64; 3] {
        self.position
    }

    /// Velocity (mm/s).
    pub fn velocity(&self) -> [f64; 3] {
        self.velocity
    }

    /// The hand sets off, if it has not.
    pub fn start_moving(&mut self) {
        self.moving.get_or_insert(0.0);
    }

    /// Where the hand means the stylus to be after `t` seconds of motion (mm).
    fn intended(&self, waypoints: &[[f64; 3]], t: f64) -> [f64; 3] {
        if waypoints.len() < 2 {
            return waypoints.first().copied().unwrap_or([0.0; 3]);
        }
        // There and back: legs 0..n-1 forwards, then the same legs backwards.
        let legs: Vec<([f64; 3], [f64; 3])> = waypoints
            .windows(2)
            .map(|w| (w[0], w[1]))
            .chain(waypoints.windows(2).rev().map(|w| (w[1], w[0])))
            .collect();
        let duration = |(a, b): &([f64; 3], [f64; 3])| {
            let d = (0..3).map(|i| (b[i] - a[i]).powi(2)).sum::<f64>().sqrt();
            (d / PACE_MM_S).max(SHORTEST_LEG_S)
        };
        let period: f64 = legs.iter().map(duration).sum();
        let mut left = t % period;
        for leg in &legs {
            let span = duration(leg);
            if left <= span {
                let s = 0.5 - 0.5 * (std::f64::consts::PI * left / span).cos();
                return [0, 1, 2].map(|i| leg.0[i] + s * (leg.1[i] - leg.0[i]));
            }
            left -= span;
        }
        waypoints[0]
    }

    /// Advances `dt` seconds under the motors' force `force` (N).
    pub fn advance(&mut self, dt: f64, force: [f64; 3]) {
        let steps = (dt / MAX_STEP_S).ceil().clamp(1.0, 1e6) as usize;
        let h = dt / steps as f64;
        for _ in 0..steps {
            let (mass, hand) = match &self.hand {
                Some((grasp, waypoints)) => {
                    let target = self.intended(waypoints, self.moving.unwrap_or(0.0));
                    let pull = [0, 1, 2]
                        .map(|i| grasp.stiffness * (target[i] - self.position[i]) - grasp.damping * self.velocity[i]);
                    (TIP_MASS_KG + grasp.mass, pull)
                }
                None => (TIP_MASS_KG, [0.0; 3]),
            };
            if let Some(t) = self.moving.as_mut() {
                *t += h;
            }
            for axis in 0..3 {
                let (x, bound) = (self.position[axis], self.half_extent[axis]);
                let wall = WALL_N_PER_MM * ((-bound - x).max(0.0) - (x - bound).max(0.0));
                let total = force[axis] + hand[axis] + wall - FRICTION_N_PER_MM_S * self.velocity[axis];
                // N / kg = m/s² = 1000 mm/s².
                self.velocity[axis] += h * 1000.0 * total / mass;
                self.position[axis] += h * self.velocity[axis];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_stylus_follows_the_hand_and_a_push_moves_a_free_one() {
        let mut free = Plant::new([80.0, 60.0, 35.0], None);
        // 1 N on 45 g against friction c for 10 ms, in closed form: with k = 1000 c / m (1/s),
        // x = (F/c) (t − (1 − e^(−k t)) / k) mm; the semi-implicit steps add about v h / 2.
        free.advance(0.01, [1.0, 0.0, 0.0]);
        let (f, t, k) = (1.0, 0.01, 1000.0 * FRICTION_N_PER_MM_S / TIP_MASS_KG);
        let closed = f / FRICTION_N_PER_MM_S * (t - (1.0 - (-k * t).exp()) / k);
        assert!((free.position()[0] - closed).abs() < 0.02 * closed, "{:?} against {closed}", free.position());
        let tour = vec![[0.0, 0.0, 0.0], [20.0, 0.0, 0.0]];
        let mut held = Plant::new([80.0, 60.0, 35.0], Some((Grasp::FIRM, tour)));
        held.start_moving();
        // The first leg (20 mm) takes 0.5 s; after it the hand has brought the stylus near 20 mm.
        held.advance(0.5, [0.0; 3]);
        assert!(held.position()[0] > 12.0 && held.position()[0] < 24.0, "{:?}", held.position());
    }
}
