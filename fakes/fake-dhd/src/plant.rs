//! The fake device's plant: a point mass per axis with viscous friction, stiff walls at the workspace
//! bounds and the output force capped at the device's peak, held by a hand that pulls the handle by a
//! spring-damper towards a point touring a circle in the y-z plane. Integrated with semi-implicit Euler in
//! steps of at most 100 µs, in the device frame and SI units.

/// Longest integration step (s).
const MAX_STEP: f64 = 1e-4;
/// Radius (m) and period (s) of the circle the hand's target tours.
const TOUR_RADIUS: f64 = 0.015;
const TOUR_PERIOD: f64 = 4.0;
/// Stiffness of the workspace walls (N/m).
const WALL_STIFFNESS: f64 = 4000.0;

/// The hand on the handle.
#[derive(Clone, Copy, Debug)]
pub enum Hand {
    /// Nobody holds the handle.
    Absent,
    /// A hand: stiffness (N/m) and damping (N s/m) of its grip towards its target.
    Holding { stiffness: f64, damping: f64 },
}

impl Hand {
    /// A hand with this grip.
    pub fn holding(stiffness: f64, damping: f64) -> Hand {
        Hand::Holding { stiffness, damping }
    }
}

/// The mechanism and the hand.
pub struct Plant {
    mass: f64,
    friction: f64,
    half_extent: [f64; 3],
    max_force: f64,
    hand: Hand,
    position: [f64; 3],
    velocity: [f64; 3],
    time: f64,
}

impl Plant {
    /// A plant sized as the system type's device: Falcon (60) a 10 cm cube and 9 N; others an omega.3-like
    /// 16 cm by 11 cm and 12 N.
    pub fn for_system(system: i32, hand: Hand) -> Plant {
        let (mass, friction, half_extent, max_force) =
            if system == 60 { (0.2, 0.6, [0.05, 0.05, 0.05], 9.0) } else { (0.3, 0.5, [0.055, 0.08, 0.08], 12.0) };
        Plant { mass, friction, half_extent, max_force, hand, position: [0.0; 3], velocity: [0.0; 3], time: 0.0 }
    }

    /// The peak force the motors give (N).
    pub fn max_force(&self) -> f64 {
        self.max_force
    }

    /// Whether a hand holds the handle.
    pub fn held(&self) -> bool {
        matches!(self.hand, Hand::Holding { .. })
    }

    /// Handle position (m).
    pub fn position(&self) -> [f64; 3] {
        self.position
    }

    /// Handle velocity (m/s).
    pub fn velocity(&self) -> [f64; 3] {
        self.velocity
    }

    /// Where the hand pulls at time `t` (s).
    fn target(t: f64) -> [f64; 3] {
        let phase = 2.0 * std::f64::consts::PI * t / TOUR_PERIOD;
        [0.0, TOUR_RADIUS * phase.sin(), TOUR_RADIUS * (1.0 - phase.cos())]
    }

    /// Advances `dt` seconds to time `now` under the motors' force `applied` (N).
    pub fn advance(&mut self, now: f64, dt: f64, applied: [f64; 3]) {
        let steps = (dt / MAX_STEP).ceil().clamp(1.0, 1e6) as usize;
        let h = dt / steps as f64;
        for _ in 0..steps {
            self.time += h;
            let target = Self::target(self.time.min(now));
            for axis in 0..3 {
                let x = self.position[axis];
                let v = self.velocity[axis];
                let hand = match self.hand {
                    Hand::Absent => 0.0,
                    Hand::Holding { stiffness, damping } => stiffness * (target[axis] - x) - damping * v,
                };
                let bound = self.half_extent[axis];
                let wall = if x > bound {
                    -WALL_STIFFNESS * (x - bound)
                } else if x < -bound {
                    WALL_STIFFNESS * (-bound - x)
                } else {
                    0.0
                };
                let force = applied[axis] + hand + wall - self.friction * v;
                self.velocity[axis] = v + h * force / self.mass;
                self.position[axis] = x + h * self.velocity[axis];
            }
        }
    }
}
