//! Forward dynamics of a linkage with loops (eq 1-4), assembled from the algorithms of this crate in the
//! order of the paper's section II: kinematics, D, B, G, loop closure with Baumgarte, KKT.

use nalgebra::{DMatrix, DVector};

use crate::bias::bias_forces;
use crate::data::{Data, Kinematics};
use crate::error::DynamicsError;
use crate::gravity::gravity_forces;
use crate::jacobian::apply_wrench;
use crate::joint_forces::joint_forces;
use crate::kinematics::{forward_kinematics, forward_velocity};
use crate::kkt;
use crate::loop_closure::{loop_closure, stabilize};
use crate::mass_matrix::mass_matrix;
use crate::model::Model;
use crate::space::Space;

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
    let n = model.nq();
    for (what, v) in [("q", q), ("q̇", qd)] {
        if v.len() != n {
            return Err(DynamicsError::WrongLength { what, got: v.len(), expected: n });
        }
        if let Some(index) = v.as_slice().iter().position(|x| !x.is_finite()) {
            return Err(DynamicsError::NonFiniteInput { what, index });
        }
    }
    Ok(())
}

/// Computes every term of eq 1-3 at `(q, q̇)`: kinematics, D, B, G, joint forces, h, W, w, w_stab, and the
/// external forces into `data.applied`. Does not solve.
pub fn dynamics_terms<S: Space, F: Forces<S> + ?Sized>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &DVector<f64>,
    qd: &DVector<f64>,
    forces: &mut F,
) {
    forward_kinematics(model, data, q);
    forward_velocity(model, data, qd);
    mass_matrix(model, data);
    bias_forces(model, data);
    gravity_forces(model, data, q);
    joint_forces(model, data, q, qd);
    loop_closure(model, data);
    stabilize(model, data, qd);
    data.applied.fill(0.0);
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
        data.implicit_mass.fill(0.0);
        data.use_implicit_mass = false;
    }
}
