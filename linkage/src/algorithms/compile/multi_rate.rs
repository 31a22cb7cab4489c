//! Ball and universal joints, which turn a body at more than one rate, compiled into the model's one-rate
//! entries (the recursions of kinematics, D, B and the factor stay one column of W per entry):
//! - a **ball** joint is three entries sharing one unit quaternion in q (nq = 4, nv = 3), each turning about
//!   one body axis through the joint's centre; the first two carry massless internal bodies with the pose of
//!   the third, the scene's body. No angle sequence, so no gimbal singularity (see `kinematics`,
//!   `configuration`);
//! - a **universal** joint is two revolute entries about its two axes, the first carrying a massless
//!   cross-piece (nq = nv = 2), as the scene would write it with an explicit cross-piece of zero mass.

use nalgebra::DVector;

use crate::math::space::{Space, VecOps};
use crate::model::{Body, Joint, JointKind};

/// The compiled tree as it grows: entries (joints and the bodies they carry, in topological order), the
/// configuration and velocity at q0, and for each entry the index of the scene's joint it comes from.
pub(super) struct Entries<S: Space> {
    pub bodies: Vec<Body<S>>,
    pub joints: Vec<Joint<S>>,
    pub q0: Vec<f64>,
    pub qd0: Vec<f64>,
    pub file_joint: Vec<usize>,
}

impl<S: Space> Entries<S> {
    pub fn with_capacity(n: usize) -> Self {
        Entries {
            bodies: Vec::with_capacity(n),
            joints: Vec::with_capacity(n),
            q0: Vec::with_capacity(n),
            qd0: Vec::with_capacity(n),
            file_joint: Vec::with_capacity(n),
        }
    }

    /// Appends scene joint `ji` (validated: `joint` has its placement, parent, damping; `axes` are the
    /// universal joint's) carrying `body`; returns the index of the entry that carries `body`.
    pub fn push(
        &mut self,
        ji: usize,
        joint: Joint<S>,
        (q, qd): (f64, f64),
        body: Body<S>,
        axes: Option<[S::Point; 2]>,
    ) -> usize {
        let mut joint = joint;
        joint.q_index = self.q0.len();
        match (joint.kind, axes) {
            (JointKind::Ball { .. }, _) => {
                self.q0.extend_from_slice(&[1.0, 0.0, 0.0, 0.0]);
                for slot in 0..3 {
                    let mut axis = S::Point::zero();
                    axis.as_mut_slice()[slot] = 1.0;
                    let entry = Joint { kind: JointKind::Ball { slot }, axis, ..self.follower(&joint, slot) };
                    let carried = if slot == 2 { body.clone() } else { internal(&joint.name, &format!("rate {slot}")) };
                    self.add(ji, entry, 0.0, carried);
                }
            }
            (_, Some([first, second])) => {
                self.q0.push(0.0);
                self.add(ji, Joint { axis: first, ..joint.clone() }, 0.0, internal(&joint.name, "cross-piece"));
                let mut entry = Joint { axis: second, ..self.follower(&joint, 1) };
                entry.q_index = self.q0.len();
                self.q0.push(0.0);
                self.add(ji, entry, 0.0, body);
            }
            _ => {
                self.q0.push(q);
                self.add(ji, joint, qd, body);
            }
        }
        self.joints.len() - 1
    }

    /// Entry `k` > 0 of a multi-rate joint: hangs from the entry before with an identity placement.
    fn follower(&self, joint: &Joint<S>, k: usize) -> Joint<S> {
        if k == 0 {
            return joint.clone();
        }
        Joint {
            parent: self.joints.len() - 1,
            placement_rot: S::rot_identity(),
            placement_pos: S::Point::zero(),
            ..joint.clone()
        }
    }

    fn add(&mut self, ji: usize, joint: Joint<S>, qd: f64, body: Body<S>) {
        self.joints.push(joint);
        self.bodies.push(body);
        self.qd0.push(qd);
        self.file_joint.push(ji);
    }

    /// The initial configuration and velocity.
    pub fn initial_state(&self) -> (DVector<f64>, DVector<f64>) {
        (DVector::from_column_slice(&self.q0), DVector::from_column_slice(&self.qd0))
    }
}

/// A massless internal body named after its joint (no geometry: nothing to draw or touch).
fn internal<S: Space>(joint: &str, role: &str) -> Body<S> {
    Body {
        name: format!("{joint} ({role})"),
        mass: 0.0,
        com: S::Point::zero(),
        inertia: S::rot_inertia_zero(),
        geometry: Vec::new(),
    }
}
