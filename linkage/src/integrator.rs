//! Time integration of the constrained dynamics, selectable at run time, with optional projection of q and
//! q̇ back onto the constraint manifold.

use nalgebra::DVector;

use crate::data::Data;
use crate::dense::{dot, sub_scaled};
use crate::dynamics::{check_state, drop_implicit_mass, dynamics_terms, Forces};
use crate::error::DynamicsError;
use crate::kinematics::forward_poses;
use crate::kkt;
use crate::loop_closure::closure_residual_and_jacobian;
use crate::ltl;
use crate::model::Model;
use crate::space::Space;

/// Which integration scheme.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Explicit (forward) Euler: q and q̇ both from the start of the step. Included to show where it fails.
    ExplicitEuler,
    /// Semi-implicit (symplectic) Euler: q̇ first, then q with the new q̇. One dynamics evaluation per step;
    /// supports linearly-implicit couplings.
    SemiImplicitEuler,
    /// Classical fourth-order Runge-Kutta: four evaluations per step.
    Rk4,
}

impl Integrator {
    /// All schemes, for sweeps.
    pub const ALL: [Integrator; 3] = [Integrator::ExplicitEuler, Integrator::SemiImplicitEuler, Integrator::Rk4];

    /// Short name used on command lines and in charts.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::ExplicitEuler => "explicit-euler",
            Integrator::SemiImplicitEuler => "euler",
            Integrator::Rk4 => "rk4",
        }
    }

    /// Parses `euler` (semi-implicit), `explicit-euler` or `rk4`.
    pub fn parse(s: &str) -> Option<Integrator> {
        match s {
            "euler" | "semi-implicit-euler" | "symplectic-euler" => Some(Integrator::SemiImplicitEuler),
            "explicit-euler" | "forward-euler" => Some(Integrator::ExplicitEuler),
            "rk4" => Some(Integrator::Rk4),
            _ => None,
        }
    }

    /// Dynamics evaluations per step.
    pub fn evaluations(self) -> usize {
        match self {
            Integrator::Rk4 => 4,
            _ => 1,
        }
    }
}

/// How to take a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConfig {
    /// The scheme.
    pub integrator: Integrator,
    /// Step size, s.
    pub dt: f64,
    /// Project q and q̇ onto the constraint manifold after the step.
    pub project: bool,
    /// Let the forces add linearly-implicit terms (semi-implicit Euler only).
    pub implicit_forces: bool,
}

impl StepConfig {
    /// Semi-implicit Euler with projection and implicit couplings: the VE's default.
    pub fn euler(dt: f64) -> Self {
        StepConfig { integrator: Integrator::SemiImplicitEuler, dt, project: true, implicit_forces: true }
    }
}

/// What a step observed.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct StepReport {
    /// Norm of the closure residual h at the start of the step (after the previous step's projection).
    pub closure_error: f64,
}

/// Advances `(q, q̇)` by one step of `cfg.dt` under `forces`. On error the state is left unchanged.
pub fn step<S: Space, F: Forces<S> + ?Sized>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
    forces: &mut F,
    cfg: &StepConfig,
) -> Result<StepReport, DynamicsError> {
    check_state(model, q, qd)?;
    let dt = cfg.dt;
    let report;
    match cfg.integrator {
        Integrator::SemiImplicitEuler | Integrator::ExplicitEuler => {
            dynamics_terms(model, data, q, qd, forces);
            report = StepReport { closure_error: data.closure_residual.norm() };
            // The matrix is zero unless the last step used it: clear it only then (n² writes otherwise wasted).
            drop_implicit_mass(data);
            data.use_implicit_mass = cfg.implicit_forces
                && cfg.integrator == Integrator::SemiImplicitEuler
                && forces.add_implicit(model, &data.kin, dt, qd, &mut data.implicit_mass, &mut data.applied);
            kkt::factorize(model, data)?;
            kkt::solve(model, data)?;
            if cfg.integrator == Integrator::SemiImplicitEuler {
                add_scaled(qd, dt, &data.qdd);
                add_scaled(q, dt, qd);
            } else {
                add_scaled(q, dt, qd);
                add_scaled(qd, dt, &data.qdd);
            }
        }
        Integrator::Rk4 => {
            drop_implicit_mass(data);
            let ws = &mut data.integ;
            ws.q_start.copy_from(q);
            ws.qd_start.copy_from(qd);
            let mut closure_error = 0.0;
            for stage in 0..4 {
                // Stage state: start + c·dt·k_{stage-1}, c = 0, ½, ½, 1.
                let c = [0.0, 0.5, 0.5, 1.0][stage];
                let (mut q_stage, mut qd_stage) = take_stage(data);
                q_stage.copy_from(&data.integ.q_start);
                qd_stage.copy_from(&data.integ.qd_start);
                if stage > 0 {
                    q_stage.axpy(c * dt, &data.integ.k_q[stage - 1], 1.0);
                    qd_stage.axpy(c * dt, &data.integ.k_qd[stage - 1], 1.0);
                }
                let solved = (|| {
                    dynamics_terms(model, data, &q_stage, &qd_stage, forces);
                    if stage == 0 {
                        closure_error = data.closure_residual.norm();
                    }
                    kkt::factorize(model, data)?;
                    kkt::solve(model, data)
                })();
                data.integ.k_q[stage].copy_from(&qd_stage);
                data.integ.k_qd[stage].copy_from(&data.qdd);
                put_stage(data, q_stage, qd_stage);
                solved?;
            }
            let ws = &data.integ;
            for i in 0..model.nq() {
                q[i] =
                    ws.q_start[i] + dt / 6.0 * (ws.k_q[0][i] + 2.0 * ws.k_q[1][i] + 2.0 * ws.k_q[2][i] + ws.k_q[3][i]);
                qd[i] = ws.qd_start[i]
                    + dt / 6.0 * (ws.k_qd[0][i] + 2.0 * ws.k_qd[1][i] + 2.0 * ws.k_qd[2][i] + ws.k_qd[3][i]);
            }
            report = StepReport { closure_error };
        }
    }
    if cfg.project && model.has_loops() {
        project(model, data, q, qd);
    }
    if q.as_slice().iter().chain(qd.as_slice()).any(|x| !x.is_finite()) {
        return Err(DynamicsError::NonFiniteResult { what: "state after the step" });
    }
    Ok(report)
}

/// `x ← x + h v`.
fn add_scaled(x: &mut DVector<f64>, h: f64, v: &DVector<f64>) {
    sub_scaled(x.as_mut_slice(), -h, v.as_slice());
}

fn take_stage<S: Space>(data: &mut Data<S>) -> (DVector<f64>, DVector<f64>) {
    (
        std::mem::replace(&mut data.integ.q_stage, DVector::zeros(0)),
        std::mem::replace(&mut data.integ.qd_stage, DVector::zeros(0)),
    )
}

fn put_stage<S: Space>(data: &mut Data<S>, q: DVector<f64>, qd: DVector<f64>) {
    data.integ.q_stage = q;
    data.integ.qd_stage = qd;
}

/// Largest closure residual the chord projection is predicted to leave, relative to the scene's length
/// scale `Model::length_scale` (so that the choice does not depend on the unit of length: the testbed,
/// L = 0.046 m, gets 1e-10 m); beyond it [`project`] takes the full Newton step.
pub const CHORD_TOLERANCE: f64 = 2e-9;

/// One projection onto the constraint manifold in the mass metric: h and W are evaluated at the new q,
/// the correction uses the factors of the step's last KKT solve (`Z = U⁻¹ W_sᵀ`, `S = W_s D⁻¹ W_sᵀ` at the
/// solve's state s, a stale Jacobian as in the chord form of Newton's method):
/// `q ← q - D⁻¹ W_sᵀ S⁺ h(q)`, `q̇ ← q̇ - D⁻¹ W_sᵀ S⁺ W(q) q̇`.
///
/// Why this is enough: any positive-definite metric gives a valid projection, and the residual left after
/// the correction is `(W(q) - W_s) D⁻¹ W_sᵀ S⁺ h`: W moves by O(dt q̇) in a step (~1e-3 relative at 1 kHz),
/// so 1e-8 m of drift per step leaves ~1e-11 m, and every step corrects what the last one left (the closure
/// error measured at the start of the steps stays below 8e-11 m over the paper's 3 s on the testbed). The
/// velocity satisfies the constraint of the configuration it belongs to up to the same factor (the W of the
/// step's start in place of W(q) would leave an O(dt) velocity error every step). Reusing the factors saves
/// the second triangular solve of Wᵀ, the Schur complement and its pivoted factorization; the poses at the
/// new q come from [`forward_poses`] (no inertias: the closure does not need them).
///
/// **Fast motion** refactors Z and S at the new q, the full Newton step, when the chord would leave more
/// than [`CHORD_TOLERANCE`] times the length scale: its residual is about `|Δq|∞ · |h|`, Δq the motion
/// since the factors' state (the 60 s demo, where the paper's constant push speeds the linkage up without
/// bound, reached 5e-8 m with the chord alone). **Redundant closures** (`closure_rank < nc`: the spherical
/// four-bar's revolute cut) always take the full step: there the pivoting keeps only some rows, and with the
/// rows and factors of the solve's state the drift of the dropped rows was not corrected (the spherical
/// four-bar's closure error grew by 3 % a step, to 1e-7 m within 0.1 s of swinging).
///
/// Needs [`kkt::factorize`] at a nearby state (the step's dynamics). Leaves h and Wᵀ at the new q (before
/// its correction) and the body poses there; both corrections are `U⁻ᵀ Z S⁺ r`, so they go through the
/// triangular solve together.
pub fn project<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &mut DVector<f64>, qd: &mut DVector<f64>) {
    // How far q moved from the configuration of the factors (the step's last dynamics evaluation): W moved
    // by about as much, relatively, and the chord leaves that fraction of the residual.
    let moved = q.as_slice().iter().zip(data.terms_at.q().as_slice()).fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
    forward_poses(model, data, q);
    closure_residual_and_jacobian(model, data);
    let chord_leaves = moved * data.closure_residual.norm();
    // NaN (a state gone bad) takes the full step too.
    let chord_suffices = chord_leaves <= CHORD_TOLERANCE * model.length_scale;
    if model.closure_rank < model.nc() || !chord_suffices {
        // Redundant closures, or fast motion: the full Newton step (see the documentation above).
        kkt::factor_closures(model, data);
    }
    let n = model.nq();
    let kkt = &mut data.kkt;
    let mut r_q = std::mem::replace(&mut kkt.tmp_m, DVector::zeros(0));
    let mut r_v = std::mem::replace(&mut kkt.tmp_m3, DVector::zeros(0));
    r_q.as_mut_slice().copy_from_slice(data.closure_residual.as_slice());
    // W(q) q̇ over whole columns: W(q)'s support is W_s's, but an entry may vanish at one state only.
    for (r, col) in r_v.as_mut_slice().iter_mut().zip(data.closure_jacobian_t.as_slice().chunks_exact(n)) {
        *r = dot(col, qd.as_slice());
    }
    kkt::schur_solve(data, &mut r_q);
    kkt::schur_solve(data, &mut r_v);
    let kkt = &mut data.kkt;
    kkt.tmp_n2.as_mut_slice().fill(0.0);
    let (t_q, t_v) = kkt.tmp_n2.as_mut_slice().split_at_mut(n);
    // x - U⁻ᵀ Z s computed as x + U⁻ᵀ (-Z s).
    kkt::sub_columns_times(&kkt.z, &kkt.z_rows, r_q.as_slice(), t_q);
    kkt::sub_columns_times(&kkt.z, &kkt.z_rows, r_v.as_slice(), t_v);
    ltl::solve_ut_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), kkt.tmp_n2.as_mut_slice());
    let (t_q, t_v) = kkt.tmp_n2.as_slice().split_at(n);
    for (x, t) in q.as_mut_slice().iter_mut().zip(t_q) {
        *x += t;
    }
    for (x, t) in qd.as_mut_slice().iter_mut().zip(t_v) {
        *x += t;
    }
    kkt.tmp_m = r_q;
    kkt.tmp_m3 = r_v;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::forward_dynamics;
    use crate::testing::paper_testbed;

    /// `(‖h(q)‖, ‖W(q) q̇‖)` evaluated afresh.
    fn residuals(model: &Model<crate::Planar>, q: &DVector<f64>, qd: &DVector<f64>) -> (f64, f64) {
        let mut data = Data::new(model);
        forward_poses(model, &mut data, q);
        closure_residual_and_jacobian(model, &mut data);
        let n = model.nq();
        let w_qd = data.closure_jacobian_t.as_slice().chunks_exact(n).map(|c| dot(c, qd.as_slice()).powi(2));
        (data.closure_residual.norm(), w_qd.sum::<f64>().sqrt())
    }

    /// The chord projection, with the factors of a solve one step back, takes the position and velocity
    /// residuals of a step down by at least the factor its documentation promises, from slow to fast motion
    /// of the testbed (the faster, the more W moves in a step and the less the stale factors help), and never
    /// leaves more than its tolerance (at 5 and 20 rad/s it takes the full Newton step: measured
    /// 1.6e-7 → 1.9e-13 and 2.6e-6 → 4.8e-11, where the chord alone left 6e-10 and 4e-8).
    #[test]
    fn chord_projection_contracts_the_residuals_of_a_step() {
        let model = paper_testbed();
        for speed in [0.5, 5.0, 20.0] {
            let mut data = Data::new(&model);
            let mut q = model.q0.clone();
            // A velocity on the manifold: project a raw one at q0 (the exact Newton step, factors at q0).
            let mut qd = DVector::from_fn(model.nq(), |i, _| speed * [1.0, -0.4, 0.7, 0.2][i]);
            forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
            project(&model, &mut data, &mut q.clone(), &mut qd);
            let dt = 1e-3;
            // One semi-implicit Euler step without projection: drift of order dt² q̇².
            forward_dynamics(&model, &mut data, &q, &qd, &mut ()).unwrap();
            qd.axpy(dt, &data.qdd, 1.0);
            q.axpy(dt, &qd, 1.0);
            let (h_before, v_before) = residuals(&model, &q, &qd);
            let q_before = q.clone();
            project(&model, &mut data, &mut q, &mut qd);
            let (h_after, _) = residuals(&model, &q, &qd);
            // The velocity is made consistent with the configuration the step reached (whose constraint the
            // step violated); the position correction then moves W by O(|Δq|), a floor far below this.
            let (_, v_after) = residuals(&model, &q_before, &qd);
            // W moves by about dt·|q̇| relative in a step: the stale factors leave that fraction.
            let factor = (5.0 * dt * speed).max(1e-3);
            assert!(h_before > 1e-10, "speed {speed}: the step should drift ({h_before:.2e})");
            assert!(h_after <= factor * h_before + 1e-15, "speed {speed}: h {h_before:.2e} -> {h_after:.2e}");
            // Fast enough for the chord to leave more than the tolerance, the full Newton step is taken.
            let tolerance = CHORD_TOLERANCE * model.length_scale;
            assert!(h_after <= tolerance, "speed {speed}: h {h_before:.2e} -> {h_after:.2e}");
            assert!(v_after <= factor * v_before + 1e-13, "speed {speed}: W q̇ {v_before:.2e} -> {v_after:.2e}");
        }
    }
}
