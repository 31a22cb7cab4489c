//! How the integrator sees the users' couplings and the penalty contacts: [`VeForces`] adds their wrenches
//! to eq 4's right side and the linearly implicit part of each coupling to its left (see `coupling`).
//!
//! **Users on one OP.** The couplings are visited in an order that groups users by OP ([`VeForces::order`]),
//! and neighbours at the same body and point (several users on a scene's one OP, the common case) form a
//! *run*: its first coupling evaluates the OP's pose, twist and Jacobian, the others copy them, and the run
//! enters eq 4 once, as `Jᵀ Σ F` and `Jᵀ (Σ C) J`, the same sums as per user but with one pass over the
//! supporting joints, whatever order the users joined in.

use kinloop_linkage::contact::PenaltyContacts;
use kinloop_linkage::data::Kinematics;
use kinloop_linkage::jacobian::{apply_wrench, support};
use kinloop_linkage::{Forces, Model, Space, VecOps};
use nalgebra::{DMatrix, DVector};

use super::coupling::Coupling;

/// Where the integrator's evaluations are recorded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Evaluation {
    /// A step: each evaluation's wrench is accumulated into `step_wrench` with these stage weights.
    Step(&'static [f64]),
    /// An extra evaluation (snapshots): nothing is accumulated.
    Probe,
    /// The snapshot evaluation: as `Probe`, but each coupling applies only its hand wrench (force
    /// channel), not its graphics-controller PD. Those are a numerical tie between the
    /// VE and one user's local model, not a physical force: folded into another user's frozen bias they act
    /// as a stiff spring seen one snapshot late and without its stiffness, which made sessions with two
    /// users on one OP go unstable.
    ProbeHands,
}

/// Stage weights of an integrator's evaluations.
pub fn stage_weights(integrator: kinloop_linkage::Integrator) -> &'static [f64] {
    match integrator {
        kinloop_linkage::Integrator::Rk4 => &[1.0 / 6.0, 2.0 / 6.0, 2.0 / 6.0, 1.0 / 6.0],
        _ => &[1.0],
    }
}

/// `(&items[first], &mut items[other])` for two different indices.
fn first_and_other<T>(items: &mut [T], first: usize, other: usize) -> (&T, &mut T) {
    if first < other {
        let (low, high) = items.split_at_mut(other);
        (&low[first], &mut high[0])
    } else {
        let (low, high) = items.split_at_mut(first);
        (&high[0], &mut low[other])
    }
}

/// Every external force of the VE: the users' couplings and, when the scene has obstacles, the penalty
/// contacts. One value per integrator call.
pub struct VeForces<'a, S: Space> {
    /// The couplings, one per user.
    pub couplings: &'a mut [Coupling<S>],
    /// Every index of `couplings` once, users of one OP next to each other (any order is correct; this one
    /// makes each OP one run).
    pub order: &'a [usize],
    /// Penalty contacts, when the scene has obstacles.
    pub contacts: Option<&'a mut PenaltyContacts<S>>,
    /// What to record.
    pub evaluation: Evaluation,
    /// Evaluations so far.
    pub stage: usize,
}

impl<S: Space> Forces<S> for VeForces<'_, S> {
    fn add_forces(&mut self, model: &Model<S>, kin: &Kinematics<S>, tau: &mut DVector<f64>) {
        let stage_weight = match self.evaluation {
            Evaluation::Step(weights) => weights.get(self.stage).copied(),
            Evaluation::Probe | Evaluation::ProbeHands => None,
        };
        let hands_only = self.evaluation == Evaluation::ProbeHands;
        // The current run (see the module documentation): its first coupling and the sum of its wrenches,
        // applied once the run ends.
        let mut run: Option<(usize, S::OpVec)> = None;
        let apply_run = |couplings: &[Coupling<S>], (first, sum): (usize, S::OpVec), tau: &mut DVector<f64>| {
            let first = &couplings[first];
            apply_wrench(model, kin, first.body, &first.op_pose.position, &sum, tau);
        };
        for &i in self.order {
            match run.as_mut().filter(|(first, _)| self.couplings[i].at_same_point(&self.couplings[*first])) {
                Some((first, _)) => {
                    let (first, c) = first_and_other(self.couplings, *first, i);
                    c.evaluate_as(first, !hands_only);
                }
                None => {
                    if let Some(ended) = run.take() {
                        apply_run(self.couplings, ended, tau);
                    }
                    self.couplings[i].evaluate(model, kin, !hands_only);
                    run = Some((i, S::OpVec::zero()));
                }
            }
            let c = &mut self.couplings[i];
            if let (true, Some((_, sum))) = (c.is_active(), run.as_mut()) {
                *sum += if hands_only { c.hand_part() } else { c.wrench };
            }
            if let Some(weight) = stage_weight {
                c.step_wrench += c.wrench * weight;
            }
        }
        if let Some(ended) = run {
            apply_run(self.couplings, ended, tau);
        }
        self.stage += 1;
        if let Some(contacts) = self.contacts.as_deref_mut() {
            contacts.add_forces(model, kin, tau);
        }
    }

    fn add_implicit(
        &mut self,
        model: &Model<S>,
        _kin: &Kinematics<S>,
        dt: f64,
        _qd: &DVector<f64>,
        implicit_mass: &mut DMatrix<f64>,
        tau: &mut DVector<f64>,
    ) -> bool {
        let mut added = false;
        let n = implicit_mass.nrows();
        let (mass, tau) = (implicit_mass.as_mut_slice(), tau.as_mut_slice());
        let couplings = &*self.couplings;
        let mut active = self.order.iter().map(|&i| &couplings[i]).filter(|c| c.is_active()).peekable();
        while let Some(c) = active.next() {
            // The run of active couplings at this OP (module documentation): Σ C and Σ spring, one pass.
            let mut coefficient = c.implicit_coefficient(dt);
            let mut spring = c.implicit_spring(dt);
            while let Some(next) = active.next_if(|next| next.at_same_point(c)) {
                coefficient += next.implicit_coefficient(dt);
                spring += next.implicit_spring(dt);
            }
            // Jᵀ is n×k column-major: entry (i, a) at a n + i.
            let jt = c.jacobian_t.as_slice();
            for i in support(model, Some(c.body)) {
                for a in 0..S::DIM {
                    tau[i] -= jt[a * n + i] * spring[a];
                }
                // Jᵀ C J is symmetric: each pair once (the support runs from the body toward the root, so the
                // joints before i are the ones below it), mirrored.
                for j in support(model, Some(c.body)) {
                    let mut m = 0.0;
                    for a in 0..S::DIM {
                        m += jt[a * n + i] * coefficient[a] * jt[a * n + j];
                    }
                    mass[j * n + i] += m;
                    if j == i {
                        break;
                    }
                    mass[i * n + j] += m;
                }
            }
            added = true;
        }
        added
    }
}
