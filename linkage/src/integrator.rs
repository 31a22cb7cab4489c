//! Time integration of the constrained dynamics, selectable at run time, with optional projection of q and
//! q̇ back onto the constraint manifold.

use nalgebra::DVector;

use crate::data::Data;
use crate::dense::sub_scaled;
use crate::dynamics::{check_state, drop_implicit_mass, dynamics_terms, Forces};
use crate::error::DynamicsError;
use crate::kinematics::forward_kinematics;
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

/// One Newton projection onto the constraint manifold in the mass metric: h and W are evaluated at the new q,
/// the mass factor is the last solve's (any positive-definite metric gives a valid projection):
/// `q ← q - D⁻¹ Wᵀ S⁺ h(q)`, `q̇ ← q̇ - D⁻¹ Wᵀ S⁺ W q̇` with `S = W D⁻¹ Wᵀ`. The position residual after one
/// iteration is quadratic in the drift (1e-8 m per step at 1 kHz → ~1e-15 m), and the velocity satisfies the
/// constraint of the configuration it belongs to (using the W of the step's start instead makes an O(dt)
/// velocity error every step). The correction of q (~1e-8) is too small to matter for W.
/// Leaves h, Wᵀ and the closure factors at the new q (before its correction).
/// Both corrections are `U⁻ᵀ Z S⁺ r`, so they go through the two triangular solves together.
pub fn project<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &mut DVector<f64>, qd: &mut DVector<f64>) {
    forward_kinematics(model, data, q);
    closure_residual_and_jacobian(model, data);
    kkt::factor_closures(model, data);
    let kkt = &mut data.kkt;
    let mut r_q = std::mem::replace(&mut kkt.tmp_m, DVector::zeros(0));
    let mut r_v = std::mem::replace(&mut kkt.tmp_m3, DVector::zeros(0));
    r_q.as_mut_slice().copy_from_slice(data.closure_residual.as_slice());
    kkt::columns_dot(&data.closure_jacobian_t, &kkt.z_rows, qd.as_slice(), r_v.as_mut_slice());
    kkt::schur_solve(data, &mut r_q);
    kkt::schur_solve(data, &mut r_v);
    let kkt = &mut data.kkt;
    kkt.tmp_n2.as_mut_slice().fill(0.0);
    let (t_q, t_v) = kkt.tmp_n2.as_mut_slice().split_at_mut(model.nq());
    // x - U⁻ᵀ Z s computed as x + U⁻ᵀ (-Z s).
    kkt::sub_columns_times(&kkt.z, &kkt.z_rows, r_q.as_slice(), t_q);
    kkt::sub_columns_times(&kkt.z, &kkt.z_rows, r_v.as_slice(), t_v);
    ltl::solve_ut_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), kkt.tmp_n2.as_mut_slice());
    let (t_q, t_v) = kkt.tmp_n2.as_slice().split_at(model.nq());
    for (x, t) in q.iter_mut().zip(t_q) {
        *x += t;
    }
    for (x, t) in qd.iter_mut().zip(t_v) {
        *x += t;
    }
    kkt.tmp_m = r_q;
    kkt.tmp_m3 = r_v;
}
