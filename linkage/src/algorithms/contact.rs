//! Contacts between the linkage's geometry and the scene's obstacles, and their penalty forces
//! (the paper's `F_i`, with `k_contact`, `b_contact`). A scene without obstacles builds no contact terms.

use nalgebra::DVector;

use crate::algorithms::dynamics::Forces;
use crate::algorithms::jacobian::apply_wrench;
use crate::algorithms::penalty::penalty_force;
use crate::math::space::{Space, VecOps};
use crate::model::data::Kinematics;
use crate::model::{Model, Obstacle, Shape};

/// A contact (or near-contact) between one body's geometry and one obstacle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact<S: Space> {
    /// Body index.
    pub body: usize,
    /// Obstacle index.
    pub obstacle: usize,
    /// Deepest point of the body's geometry, world frame.
    pub point: S::Point,
    /// Unit normal pointing from the obstacle into free space.
    pub normal: S::Point,
    /// Signed distance along the normal (negative when penetrating), m.
    pub gap: f64,
}

/// Capacity that [`detect_contacts`] may need: two contacts per (shape, obstacle) pair.
pub fn contact_capacity<S: Space>(model: &Model<S>) -> usize {
    2 * model.obstacles.len() * model.bodies.iter().map(|b| b.geometry.len()).sum::<usize>()
}

/// Finds every (shape, obstacle) pair closer than `margin` and appends it to `out` (cleared first).
/// Allocation-free when `out` has [`contact_capacity`] room.
pub fn detect_contacts<S: Space>(model: &Model<S>, kin: &Kinematics<S>, margin: f64, out: &mut Vec<Contact<S>>) {
    out.clear();
    if model.obstacles.is_empty() {
        return;
    }
    for (body, b) in model.bodies.iter().enumerate() {
        let to_world = |p: &S::Point| kin.body_pos[body] + S::rotate(&kin.body_rot[body], p);
        for shape in &b.geometry {
            let (from, to, radius) = match shape {
                Shape::Capsule { from, to, radius } => (to_world(from), to_world(to), *radius),
                Shape::Ball { center, radius } => (to_world(center), to_world(center), *radius),
            };
            for (obstacle, o) in model.obstacles.iter().enumerate() {
                match o {
                    Obstacle::HalfSpace { normal, offset, .. } => {
                        let ends = if from == to { 1 } else { 2 };
                        for end in [from, to].iter().take(ends) {
                            let gap = normal.dot(end) - offset - radius;
                            if gap < margin {
                                out.push(Contact {
                                    body,
                                    obstacle,
                                    point: *end - *normal * radius,
                                    normal: *normal,
                                    gap,
                                });
                            }
                        }
                    }
                    Obstacle::Ball { center, radius: obstacle_radius, .. } => {
                        let axis = to - from;
                        let len2 = axis.dot(&axis);
                        let t = if len2 > 0.0 { ((*center - from).dot(&axis) / len2).clamp(0.0, 1.0) } else { 0.0 };
                        let nearest = from + axis * t;
                        let offset = nearest - *center;
                        let dist = offset.norm();
                        let gap = dist - obstacle_radius - radius;
                        if gap < margin && dist > 0.0 {
                            let normal = offset * (1.0 / dist);
                            out.push(Contact { body, obstacle, point: nearest - normal * radius, normal, gap });
                        }
                    }
                }
            }
        }
    }
}

/// Penalty contact forces `f = max(0, -k gap - b ġap)` along each contact normal, as a [`Forces`] source.
#[derive(Clone, Debug)]
pub struct PenaltyContacts<S: Space> {
    /// Contacts found at the last evaluation.
    pub contacts: Vec<Contact<S>>,
    /// Normal stiffness, N/m.
    pub stiffness: f64,
    /// Normal damping, N s/m.
    pub damping: f64,
}

impl<S: Space> PenaltyContacts<S> {
    /// With the model's contact parameters and room for every possible contact.
    pub fn new(model: &Model<S>) -> Self {
        PenaltyContacts {
            contacts: Vec::with_capacity(contact_capacity(model)),
            stiffness: model.contact.stiffness,
            damping: model.contact.damping,
        }
    }

    /// The contacts of a scene with obstacles (`None` without): what the VE and `kinloop simulate` apply.
    pub fn of_obstacles(model: &Model<S>) -> Option<Self> {
        (!model.obstacles.is_empty()).then(|| PenaltyContacts::new(model))
    }

    /// The normal force of a contact at the given kinematic state (≥ 0).
    pub fn normal_force(&self, kin: &Kinematics<S>, c: &Contact<S>) -> f64 {
        if c.gap >= 0.0 {
            return 0.0;
        }
        let gap_rate = c.normal.dot(&kin.point_velocity(Some(c.body), &c.point));
        penalty_force(self.stiffness, self.damping, c.gap, gap_rate)
    }
}

impl<S: Space> Forces<S> for PenaltyContacts<S> {
    fn add_forces(&mut self, model: &Model<S>, kin: &Kinematics<S>, tau: &mut DVector<f64>) {
        detect_contacts(model, kin, 0.0, &mut self.contacts);
        for c in &self.contacts {
            let f = self.normal_force(kin, c);
            if f > 0.0 {
                let wrench = S::op(c.normal * f, S::Angular::zero());
                apply_wrench(model, kin, c.body, &c.point, &wrench, tau);
            }
        }
    }
}
