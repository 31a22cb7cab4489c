//! How the integrator sees the users' couplings and the penalty contacts: [`VeForces`] adds their wrenches
//! to eq 4's right side and the linearly implicit part of each coupling to its left (see `coupling`).
//!
//! **Users on one OP.** The couplings are visited in an order that groups users by OP ([`VeForces::order`]),
//! and neighbours at the same body and point (several users on a scene's one OP, the common case) form a
//! *run*: its first coupling evaluates the OP's pose, twist and Jacobian, the others copy them, and the run
//! enters eq 4 once, as `Jᵀ Σ F` and `Jᵀ (Σ C) J`, the same sums as per user but with one pass over the
//! supporting joints, whatever order the users joined in.

use kinloop_linkage::algorithms::contact::PenaltyContacts;
use kinloop_linkage::algorithms::jacobian::{apply_wrench, support};
use kinloop_linkage::model::data::Kinematics;
use kinloop_linkage::{algorithms::dynamics::Forces, math::space::Space, math::space::VecOps, model::Model};
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
    /// channel) and the VE's hold at its OP (`handover`), not its graphics-controller PD. Those are a numerical tie between the
    /// VE and one user's local model, not a physical force: folded into another user's frozen bias they act
    /// as a stiff spring seen one snapshot late and without its stiffness, which made sessions with two
    /// users on one OP go unstable.
    ProbeHands,
}

/// Stage weights of an integrator's evaluations.
pub fn stage_weights(integrator: kinloop_linkage::algorithms::integrator::Integrator) -> &'static [f64] {
    match integrator {
        kinloop_linkage::algorithms::integrator::Integrator::Rk4 => &[1.0 / 6.0, 2.0 / 6.0, 2.0 / 6.0, 1.0 / 6.0],
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
                *sum += if hands_only { c.hand_part() + c.hold } else { c.wrench };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::coupling::tests::testbed_in_motion;
    use kinloop_linkage::math::space::OpPose;
    use kinloop_linkage::math::space::Planar;
    use nalgebra::Vector3;

    /// Users on one OP evaluated as runs (module documentation) add exactly the per-user sums, in any order:
    /// with couplings on links 2, 2, 2, 4, 2 (one of them not pushing), visited in join order (a run of three,
    /// then two runs of one) or grouped by OP with the last one first (a run of four led by the last index,
    /// then link 4), `τ` and the implicit terms equal `Σ Jᵀ F` and `Σ Jᵀ diag(c) J` formed densely from
    /// Jacobians evaluated afresh for each coupling, and every coupling holds its own OP's pose, twist and
    /// Jacobian.
    #[test]
    fn users_on_one_op_add_the_per_user_sums() {
        let (model, data, qd) = testbed_in_motion(8);
        let n = model.nv();
        let point = nalgebra::Vector2::new(0.01, -0.002);
        let joined: Vec<Coupling<Planar>> =
            [(1, 0.7, true), (1, 1.0, false), (1, 0.5, true), (3, 0.4, true), (1, 0.9, true)]
                .into_iter()
                .enumerate()
                .map(|(i, (body, weight, pushes))| {
                    let k = 300.0 * (i + 1) as f64;
                    let stiffness = Vector3::new(k, 0.8 * k, 0.02 * k);
                    let mut c = Coupling::new(body, point, n, stiffness, stiffness * 0.05);
                    c.pushes = pushes;
                    c.weight = weight;
                    c.hand_wrench = Vector3::new(0.3 - 0.1 * i as f64, 0.2 * i as f64, 0.001);
                    c.target_pose =
                        OpPose { position: nalgebra::Point2::new(0.02, 0.03 * i as f64).coords, ..OpPose::identity() };
                    c
                })
                .collect();
        let dt = 1e-3;
        for order in [[0, 1, 2, 3, 4], [4, 0, 1, 2, 3]] {
            let mut couplings = joined.clone();
            let mut forces = VeForces {
                couplings: &mut couplings,
                order: &order,
                contacts: None,
                evaluation: Evaluation::Step(&[1.0]),
                stage: 0,
            };
            let mut tau = DVector::zeros(n);
            forces.add_forces(&model, &data.kin, &mut tau);
            let (mut mass, mut tau_implicit) = (DMatrix::zeros(n, n), DVector::zeros(n));
            assert!(forces.add_implicit(&model, &data.kin, dt, &qd, &mut mass, &mut tau_implicit));

            let (mut expected_tau, mut expected_mass, mut expected_implicit) =
                (DVector::zeros(n), DMatrix::zeros(n, n), DVector::zeros(n));
            for c in &couplings {
                let mut fresh = c.clone();
                fresh.jacobian_t.fill(f64::NAN);
                fresh.evaluate(&model, &data.kin, true);
                assert_eq!((c.op_pose, c.op_twist, c.wrench), (fresh.op_pose, fresh.op_twist, fresh.wrench));
                if !c.is_active() {
                    continue;
                }
                assert_eq!(c.jacobian_t, fresh.jacobian_t);
                let jt = &fresh.jacobian_t;
                expected_tau += jt * DVector::from_column_slice(fresh.wrench.as_slice());
                let coefficient = DVector::from_column_slice(fresh.implicit_coefficient(dt).as_slice());
                expected_mass += jt * DMatrix::from_diagonal(&coefficient) * jt.transpose();
                expected_implicit -= jt * DVector::from_column_slice(fresh.implicit_spring(dt).as_slice());
            }
            let close = |a: &DMatrix<f64>, b: &DMatrix<f64>| (a - b).amax() <= 1e-13 * b.amax();
            assert!(
                close(
                    &DMatrix::from_column_slice(n, 1, tau.as_slice()),
                    &DMatrix::from_column_slice(n, 1, expected_tau.as_slice())
                ),
                "{tau} vs {expected_tau}"
            );
            assert!(close(&mass, &expected_mass), "{mass} vs {expected_mass}");
            assert_eq!(mass, mass.transpose());
            let (got, want) = (&tau_implicit, &expected_implicit);
            assert!((got - want).amax() <= 1e-13 * want.amax(), "{got} vs {want}");
        }
    }

    /// The implicit terms of two couplings (on links 2 and 4, so their supports overlap and differ) against
    /// the dense products `Σ Jᵀ diag(c) J` and `−Σ Jᵀ (h wβK ⊙ ẋ)` formed with nalgebra from each Jacobian:
    /// the symmetric fill adds the same matrix, exactly symmetric.
    #[test]
    fn implicit_terms_are_the_dense_products() {
        let (model, data, qd) = testbed_in_motion(5);
        let n = model.nv();
        let mut couplings: Vec<Coupling<Planar>> = [(1, 200.0, 0.7), (3, 3000.0, 0.3)]
            .into_iter()
            .map(|(body, k, weight)| {
                let stiffness = Vector3::new(k, 1.3 * k, 0.01 * k);
                let mut c = Coupling::new(body, nalgebra::Vector2::new(0.01, -0.002), n, stiffness, stiffness * 0.05);
                c.pushes = true;
                c.weight = weight;
                c.pd_scale = Vector3::new(1.0, 0.5, 0.9);
                c.evaluate(&model, &data.kin, true);
                c
            })
            .collect();
        let dt = 1e-3;
        let (mut expected_mass, mut expected_tau) = (DMatrix::zeros(n, n), DVector::zeros(n));
        for c in &couplings {
            let coefficient = c.implicit_coefficient(dt);
            let spring = Vector3::from_fn(|a, _| dt * c.pd_weight(a) * c.stiffness[a] * c.op_twist[a]);
            let jt = &c.jacobian_t;
            expected_mass +=
                jt * DMatrix::from_diagonal(&DVector::from_column_slice(coefficient.as_slice())) * jt.transpose();
            expected_tau -= jt * DVector::from_column_slice(spring.as_slice());
        }
        let mut forces = VeForces {
            couplings: &mut couplings,
            order: &[0, 1],
            contacts: None,
            evaluation: Evaluation::ProbeHands,
            stage: 0,
        };
        let (mut mass, mut tau) = (DMatrix::zeros(n, n), DVector::zeros(n));
        assert!(forces.add_implicit(&model, &data.kin, dt, &qd, &mut mass, &mut tau));
        assert_eq!(mass, mass.transpose());
        let scale = expected_mass.amax();
        assert!((&mass - &expected_mass).amax() <= 1e-13 * scale, "{mass} vs {expected_mass}");
        assert!((&tau - &expected_tau).amax() <= 1e-13 * expected_tau.amax(), "{tau} vs {expected_tau}");
        // Link 4's coupling reaches every joint, link 2's only the first two.
        assert!(mass[(3, 3)] > 0.0 && (mass[(1, 1)] - expected_mass[(1, 1)]).abs() <= 1e-13 * scale);
    }
}
