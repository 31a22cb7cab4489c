//! Forward dynamics of a linkage with loops (eq 1-4), assembled from the algorithms of this crate in the
//! order of the paper's section II: kinematics, D, B, G, loop closure with Baumgarte, KKT.

use nalgebra::{DMatrix, DVector};

use crate::algorithms::bias::bias_forces;
use crate::algorithms::gravity::gravity_forces;
use crate::algorithms::jacobian::apply_wrench;
use crate::algorithms::joint_forces::joint_forces;
use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
use crate::algorithms::kkt;
use crate::algorithms::loop_closure::{loop_closure, stabilize};
use crate::algorithms::mass_matrix::mass_matrix;
use crate::error::DynamicsError;
use crate::math::space::Space;
use crate::model::data::{Data, Kinematics};
use crate::model::Model;

/// Generalized forces applied from outside the linkage (users, couplings, contacts). The integrators call
/// it at every stage, with the stage's kinematics, so state-dependent forces are integrated consistently.
pub trait Forces<S: Space> {
    /// Adds this source's generalized forces `Σ Jᵀ F` at the state whose kinematics are in `kin` to `tau`.
    fn add_forces(&mut self, model: &Model<S>, kin: &Kinematics<S>, tau: &mut DVector<f64>);

    /// Linearly-implicit treatment of stiff couplings (semi-implicit Euler only). A spring-damper with
    /// operational stiffness K and damping B at Jacobian J, integrated with step h, adds `J ᵀ(hB + h²K) J` to
    /// `implicit_mass` and `-h Jᵀ K J q̇` to `tau`, making the step stable for any gains. `implicit_mass` is
    /// zero on entry. Returns true exactly when it added something. The default adds nothing.
    fn add_implicit(
        &mut self,
        _model: &Model<S>,
        _kin: &Kinematics<S>,
        _dt: f64,
        _qd: &DVector<f64>,
        _implicit_mass: &mut DMatrix<f64>,
        _tau: &mut DVector<f64>,
    ) -> bool {
        false
    }
}

/// No external forces.
impl<S: Space> Forces<S> for () {
    fn add_forces(&mut self, _: &Model<S>, _: &Kinematics<S>, _: &mut DVector<f64>) {}
}

/// A constant wrench (force, then torque; world axes) at an operational point — the paper's user.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpWrench<S: Space> {
    /// Operational point index.
    pub op: usize,
    /// The wrench.
    pub wrench: S::OpVec,
}

impl<S: Space> Forces<S> for OpWrench<S> {
    fn add_forces(&mut self, model: &Model<S>, kin: &Kinematics<S>, tau: &mut DVector<f64>) {
        let op = &model.ops[self.op];
        let p = kin.body_pos[op.body] + S::rotate(&kin.body_rot[op.body], &op.point);
        apply_wrench(model, kin, op.body, &p, &self.wrench, tau);
    }
}

/// Checks a state's length and finiteness.
pub fn check_state<S: Space>(model: &Model<S>, q: &DVector<f64>, qd: &DVector<f64>) -> Result<(), DynamicsError> {
    for (what, v, n) in [("q", q, model.nq()), ("q̇", qd, model.nv())] {
        if v.len() != n {
            return Err(DynamicsError::WrongLength { what, got: v.len(), expected: n });
        }
        if let Some(index) = v.as_slice().iter().position(|x| !x.is_finite()) {
            return Err(DynamicsError::NonFiniteInput { what, index });
        }
    }
    Ok(())
}

/// Computes every term of eq 1-3 at `(q, q̇)`: kinematics (with the bodies' inertias, from which
/// `kkt::factorize` factors D without forming it), B, G, joint forces, h, W, w, w_stab, and the
/// external forces into `data.applied`. Does not solve. When the terms already belong to exactly this
/// state (see `TermsMemo`), only the external forces are evaluated again.
pub fn dynamics_terms<S: Space, F: Forces<S> + ?Sized>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    forces: &mut F,
) {
    if !data.terms_at.holds(q, qd) {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, qd);
        if data.keep_mass_matrix {
            mass_matrix(model, data);
        }
        bias_forces(model, data);
        gravity_forces(model, data, q);
        joint_forces(model, data, q, qd);
        loop_closure(model, data);
        stabilize(model, data, qd);
        data.terms_at.record(q, qd);
    }
    crate::math::dense::zero(data.applied.as_mut_slice());
    forces.add_forces(model, &data.kin, &mut data.applied);
}

/// Forward dynamics (eq 4): fills `data.qdd` and `data.lambda` (and every intermediate term).
pub fn forward_dynamics<S: Space, F: Forces<S> + ?Sized>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    forces: &mut F,
) -> Result<(), DynamicsError> {
    dynamics_terms(model, data, q, qd, forces);
    drop_implicit_mass(data);
    kkt::factorize(model, data)?;
    kkt::solve(model, data)
}

/// Stops using the linearly-implicit mass, keeping the invariant that `implicit_mass` is zero whenever
/// `use_implicit_mass` is false (the integrators only clear it when the flag says it was used, and
/// `Forces::add_implicit` adds to it).
pub fn drop_implicit_mass<S: Space>(data: &mut Data<S>) {
    if data.use_implicit_mass {
        // (A slice's fill: nalgebra's `fill` steps an iterator per entry.)
        data.implicit_mass.as_mut_slice().fill(0.0);
        data.use_implicit_mass = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{paper_testbed, random_state};
    use nalgebra::Vector3;

    /// `(q̈, λ)` of the last solve.
    fn solved<S: Space>(model: &Model<S>, data: &Data<S>) -> DVector<f64> {
        let mut out = data.qdd.clone().resize_vertically(model.nv() + model.nc(), 0.0);
        out.rows_mut(model.nv(), model.nc()).copy_from(&data.lambda);
        out
    }

    /// `(q̈, λ)` from a fresh workspace.
    fn fresh<S: Space, F: Forces<S>>(model: &Model<S>, q: &DVector<f64>, qd: &DVector<f64>, f: &mut F) -> DVector<f64> {
        let mut data = Data::new(model);
        forward_dynamics(model, &mut data, q, qd, f).unwrap();
        solved(model, &data)
    }

    /// With D kept formed (`Data::keep_mass_matrix`, the server's setting) the KKT solve factors D itself; the
    /// accelerations and multipliers agree with the path that factors D from articulated inertias, to
    /// round-off, on every test scene.
    #[test]
    fn keeping_the_mass_matrix_gives_the_same_solve() {
        crate::testing::for_each_model!(name, model => {
            let (q, qd) = random_state(model, 11);
            let mut plain = Data::new(model);
            let mut kept = Data::new(model);
            kept.keep_mass_matrix = true;
            forward_dynamics(model, &mut plain, &q, &qd, &mut ()).unwrap();
            forward_dynamics(model, &mut kept, &q, &qd, &mut ()).unwrap();
            assert!(kept.mass_matrix_fresh && !plain.mass_matrix_fresh, "{name}");
            let (a, b) = (solved(model, &plain), solved(model, &kept));
            assert!((&a - &b).amax() <= 1e-9 * (1.0 + a.amax()), "{name}: {a} vs {b}");
        });
    }

    /// Re-evaluating at the state the terms belong to recomputes only the forces, and gives bit for bit what
    /// a fresh workspace gives; a change of q, of q̇, or kinematics evaluated elsewhere in between, is seen.
    #[test]
    fn terms_are_reused_exactly_when_the_state_is_the_same() {
        let model = paper_testbed();
        let mut data = Data::new(&model);
        let (q, qd) = random_state(&model, 3);
        let (q2, qd2) = random_state(&model, 4);
        let mut push = OpWrench { op: 0, wrench: Vector3::new(-0.5, 0.2, 0.01) };
        let mut pull = OpWrench { op: 0, wrench: Vector3::new(1.0, -0.3, 0.0) };
        forward_dynamics(&model, &mut data, &q, &qd, &mut push).unwrap();
        assert_eq!(solved(&model, &data), fresh(&model, &q, &qd, &mut push));
        // Same state, other forces: reused terms, new forces.
        assert!(data.terms_at.holds(&q, &qd));
        forward_dynamics(&model, &mut data, &q, &qd, &mut pull).unwrap();
        assert_eq!(solved(&model, &data), fresh(&model, &q, &qd, &mut pull));
        assert_ne!(solved(&model, &data), fresh(&model, &q, &qd, &mut push), "the forces must have been re-evaluated");
        // Another q̇, then another q.
        forward_dynamics(&model, &mut data, &q, &qd2, &mut pull).unwrap();
        assert_eq!(solved(&model, &data), fresh(&model, &q, &qd2, &mut pull));
        forward_dynamics(&model, &mut data, &q2, &qd2, &mut pull).unwrap();
        assert_eq!(solved(&model, &data), fresh(&model, &q2, &qd2, &mut pull));
        // Kinematics evaluated at another state in between (as the projection does): recomputed.
        forward_kinematics(&model, &mut data, &q);
        assert!(!data.terms_at.holds(&q2, &qd2));
        forward_dynamics(&model, &mut data, &q2, &qd2, &mut pull).unwrap();
        assert_eq!(solved(&model, &data), fresh(&model, &q2, &qd2, &mut pull));
        forward_velocity(&model, &mut data, &qd);
        assert!(!data.terms_at.holds(&q2, &qd2));
    }

    /// A fixed generalized force.
    struct Tau(DVector<f64>);

    impl<S: Space> Forces<S> for Tau {
        fn add_forces(&mut self, _: &Model<S>, _: &Kinematics<S>, tau: &mut DVector<f64>) {
            *tau += &self.0;
        }
    }

    /// The response to a generalized force alone is what that force adds to a full solve at the same state
    /// (eq 4 is linear in the applied forces): checked against two full solves, on every test scene (the
    /// fixed-size path up to 8 joints and the general one beyond).
    #[test]
    fn the_constrained_response_is_what_a_force_adds_to_the_solve() {
        crate::testing::for_each_model!(name, model => {
            let (q, qd) = random_state(model, 5);
            let n = model.nv();
            let tau = DVector::from_fn(n, |i, _| ((i * 7 + 3) % 5) as f64 - 2.0);
            let mut data = Data::new(model);
            forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
            let without = data.qdd.clone();
            forward_dynamics(model, &mut data, &q, &qd, &mut Tau(tau.clone())).unwrap();
            let expected = &data.qdd - &without;
            let mut x = tau.as_slice().to_vec();
            let mut scratch = vec![f64::NAN; 2 * model.nc()];
            kkt::constrained_response(model, &data, &mut x, &mut scratch);
            let got = DVector::from_vec(x);
            assert!(expected.amax() > 1e-3, "{name}: the force must move the linkage");
            assert!((&got - &expected).amax() <= 1e-9 * (1.0 + expected.amax()), "{name}: {got} vs {expected}");
        });
    }
}
