//! The fake device's plant: a point mass per axis with viscous friction, stiff walls at the workspace
//! bounds and the output force capped at the device's peak, held by a hand ([`super::hand`]) whose mass
//! moves with the handle. Integrated with semi-implicit Euler in steps of at most 100 µs, in the device
//! frame and SI units.

use crate::hand::{Grip, Intent};

/// Longest integration step (s).
const MAX_STEP: f64 = 1e-4;
/// Stiffness of the workspace walls (N/m).
const WALL_STIFFNESS: f64 = 4000.0;

/// The hand on the handle.
#[derive(Clone, Debug)]
pub enum Hand {
    /// Nobody holds the handle.
    Absent,
    /// A hand with this grip, intending this motion.
    Holding(Grip, Intent),
}

/// The mechanism and the hand.
pub struct Plant {
    mass: f64,
    friction: f64,
    half_extent: [f64; 3],
    max_force: f64,
    hand: Hand,
    /// Where the hand grasped the handle, and when it starts moving (plant time, s).
    grasp: [f64; 3],
    moving_from: Option<f64>,
    position: [f64; 3],
    velocity: [f64; 3],
    time: f64,
}

impl Plant {
    /// A plant sized as the system type's device: Falcon (60) a 10 cm cube and 9 N; others an omega.3-like
    /// 16 cm by 11 cm and 12 N. The handle starts where the hand's intention does (its first waypoint), or
    /// at the workspace centre.
    pub fn for_system(system: i32, hand: Hand) -> Plant {
        let (mass, friction, half_extent, max_force) =
            if system == 60 { (0.2, 0.6, [0.05, 0.05, 0.05], 9.0) } else { (0.3, 0.5, [0.055, 0.08, 0.08], 12.0) };
        let start = match &hand {
            Hand::Holding(_, intent) => intent.first().unwrap_or([0.0; 3]),
            Hand::Absent => [0.0; 3],
        };
        Plant {
            mass,
            friction,
            half_extent,
            max_force,
            hand,
            grasp: start,
            moving_from: None,
            position: start,
            velocity: [0.0; 3],
            time: 0.0,
        }
    }

    /// The peak force the motors give (N).
    pub fn max_force(&self) -> f64 {
        self.max_force
    }

    /// Handle position (m).
    pub fn position(&self) -> [f64; 3] {
        self.position
    }

    /// Handle velocity (m/s).
    pub fn velocity(&self) -> [f64; 3] {
        self.velocity
    }

    /// The hand starts its intended motion now, if not yet.
    pub fn start_moving(&mut self) {
        self.moving_from.get_or_insert(self.time);
    }

    /// Seconds since the hand started moving (0 before).
    pub fn moving_for(&self) -> f64 {
        self.moving_from.map_or(0.0, |from| self.time - from)
    }

    /// Advances `dt` seconds under the motors' force `applied` (N).
    pub fn advance(&mut self, dt: f64, applied: [f64; 3]) {
        let steps = (dt / MAX_STEP).ceil().clamp(1.0, 1e6) as usize;
        let h = dt / steps as f64;
        for _ in 0..steps {
            self.time += h;
            let (hand_mass, hand_force) = self.hand_force();
            for (axis, hand) in hand_force.into_iter().enumerate() {
                let x = self.position[axis];
                let v = self.velocity[axis];
                let bound = self.half_extent[axis];
                let wall = if x > bound {
                    -WALL_STIFFNESS * (x - bound)
                } else if x < -bound {
                    WALL_STIFFNESS * (-bound - x)
                } else {
                    0.0
                };
                let force = applied[axis] + hand + wall - self.friction * v;
                self.velocity[axis] = v + h * force / (self.mass + hand_mass);
                self.position[axis] = x + h * self.velocity[axis];
            }
        }
    }

    /// The hand's mass and the force it applies now.
    fn hand_force(&self) -> (f64, [f64; 3]) {
        let Hand::Holding(grip, intent) = &self.hand else { return (0.0, [0.0; 3]) };
        let (xd, vd, ad) = match self.moving_from {
            Some(from) => intent.at(self.grasp, self.time - from),
            None => (intent.at(self.grasp, 0.0).0, [0.0; 3], [0.0; 3]),
        };
        let force = [0, 1, 2].map(|i| {
            grip.stiffness * (xd[i] - self.position[i]) + grip.damping * (vd[i] - self.velocity[i]) + grip.mass * ad[i]
        });
        (grip.mass, force)
    }
}
