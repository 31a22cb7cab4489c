//! Time integration of the constrained dynamics, selectable at run time, with optional projection of q and
//! q̇ back onto the constraint manifold.

use nalgebra::DVector;

use crate::algorithms::configuration;
use crate::algorithms::dynamics::{check_state, drop_implicit_mass, dynamics_terms, Forces};
use crate::algorithms::energy_guard::EnergyGuard;
use crate::algorithms::implicit_joint_forces::add_implicit_joint_terms;
use crate::algorithms::kinematics::forward_poses;
use crate::algorithms::kkt;
use crate::algorithms::loop_closure::{closure_residual, closure_residual_and_jacobian};
use crate::algorithms::ltl;
use crate::error::DynamicsError;
use crate::math::dense::{self, by_size, dot, sub_scaled};
use crate::math::kkt_small;
use crate::math::quaternion;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::{JointKind, Model};

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
    step_guarded(model, data, q, qd, forces, cfg, None)
}

/// [`step`] with the step's energy account ([`EnergyGuard`]): semi-implicit Euler steps take out of the
/// kinetic energy what earlier steps made; other schemes leave the guard reset. On error the state is left as
/// it was before any correction.
pub fn step_guarded<S: Space, F: Forces<S> + ?Sized>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
    forces: &mut F,
    cfg: &StepConfig,
    mut guard: Option<&mut EnergyGuard>,
) -> Result<StepReport, DynamicsError> {
    check_state(model, q, qd)?;
    if cfg.integrator != Integrator::SemiImplicitEuler {
        if let Some(g) = guard.take() {
            g.reset();
        }
    }
    let dt = cfg.dt;
    // Kept to restore the state should the step end non-finite (RK4 keeps it anyway for its stages).
    dense::copy(data.integ.q_start.as_mut_slice(), q.as_slice());
    dense::copy(data.integ.qd_start.as_mut_slice(), qd.as_slice());
    let report;
    match cfg.integrator {
        Integrator::SemiImplicitEuler | Integrator::ExplicitEuler => {
            dynamics_terms(model, data, q, qd, forces);
            if let Some(g) = guard.as_deref_mut() {
                if g.open_step(model, data, q, qd) {
                    // q̇ was scaled: B, the dampers and the stabilization depend on it.
                    dynamics_terms(model, data, q, qd, forces);
                }
            }
            report = StepReport { closure_error: data.closure_residual.norm() };
            // The matrix is zero unless the last step used it: clear it only then (n² writes otherwise wasted).
            drop_implicit_mass(data);
            if cfg.implicit_forces && cfg.integrator == Integrator::SemiImplicitEuler {
                // The couplings' terms and then the joints' own stiff terms (`implicit_joint_forces`).
                let couplings =
                    forces.add_implicit(model, &data.kin, dt, qd, &mut data.implicit_mass, &mut data.applied);
                let joints = add_implicit_joint_terms(model, dt, q, qd, &mut data.implicit_mass, &mut data.applied);
                data.use_implicit_mass = couplings || joints;
            }
            kkt::factorize(model, data)?;
            kkt::solve(model, data)?;
            if cfg.integrator == Integrator::SemiImplicitEuler {
                add_scaled(qd, dt, &data.qdd);
                advance(model, q, dt, qd);
                if let Some(g) = guard {
                    g.close_step(model, data, dt, qd);
                }
            } else {
                advance(model, q, dt, qd);
                add_scaled(qd, dt, &data.qdd);
            }
        }
        Integrator::Rk4 => {
            drop_implicit_mass(data);
            let mut closure_error = 0.0;
            for stage in 0..4 {
                // Stage state: start + c·dt·k_{stage-1}, c = 0, ½, ½, 1.
                let c = [0.0, 0.5, 0.5, 1.0][stage];
                let (mut q_stage, mut qd_stage) = take_stage(data);
                q_stage.copy_from(&data.integ.q_start);
                qd_stage.copy_from(&data.integ.qd_start);
                if stage > 0 {
                    advance(model, &mut q_stage, c * dt, &data.integ.k_q[stage - 1]);
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
                if model.has_balls() && stage > 0 {
                    let mut theta = std::mem::replace(&mut data.integ.dq, DVector::zeros(0));
                    theta.copy_from(&data.integ.k_q[stage - 1]);
                    ball_rates(model, &theta, c * dt, &mut data.integ.k_q[stage]);
                    data.integ.dq = theta;
                }
                data.integ.k_qd[stage].copy_from(&data.qdd);
                put_stage(data, q_stage, qd_stage);
                solved?;
            }
            let ws = &mut data.integ;
            if model.has_balls() {
                // RKMK: the weighted stage rates, all in the tangent space at the step's start, applied once.
                for i in 0..model.nv() {
                    ws.dq[i] = ws.k_q[0][i] + 2.0 * ws.k_q[1][i] + 2.0 * ws.k_q[2][i] + ws.k_q[3][i];
                }
                q.copy_from(&ws.q_start);
                configuration::integrate(model, q, &ws.dq, dt / 6.0);
            } else {
                for i in 0..model.nv() {
                    q[i] = ws.q_start[i]
                        + dt / 6.0 * (ws.k_q[0][i] + 2.0 * ws.k_q[1][i] + 2.0 * ws.k_q[2][i] + ws.k_q[3][i]);
                }
            }
            for i in 0..model.nv() {
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
        q.copy_from(&data.integ.q_start);
        qd.copy_from(&data.integ.qd_start);
        return Err(DynamicsError::NonFiniteResult { what: "state after the step" });
    }
    Ok(report)
}

/// `q ← q ⊕ h v` (see `configuration::integrate`; a plain `axpy` without ball joints).
fn advance<S: Space>(model: &Model<S>, q: &mut DVector<f64>, h: f64, v: &DVector<f64>) {
    if model.has_balls() {
        configuration::integrate(model, q, v, h);
    } else {
        add_scaled(q, h, v);
    }
}

/// RK4 on the ball joints' spheres as Runge-Kutta-Munthe-Kaas: a stage at `q_start ⊕ θ`, `θ = c dt k`,
/// turns at the body rate ω = q̇; what it contributes to the step is the rate of θ, `J_r⁻¹(θ) ω`
/// (`math::quaternion`), which keeps the scheme fourth order (plain ω would leave an `O(dt²)` commutator per
/// step). `theta` holds the previous stage's rates, scaled here by `c dt`; `rates` holds ω and is converted
/// in place on the ball joints' entries.
fn ball_rates<S: Space>(model: &Model<S>, theta: &DVector<f64>, c_dt: f64, rates: &mut DVector<f64>) {
    for (i, joint) in model.joints.iter().enumerate() {
        if matches!(joint.kind, JointKind::Ball { slot: 0 }) {
            let t = nalgebra::Vector3::new(theta[i], theta[i + 1], theta[i + 2]) * c_dt;
            let w = nalgebra::Vector3::new(rates[i], rates[i + 1], rates[i + 2]);
            let r = quaternion::right_jacobian_inv_mul(&t, &w);
            rates.as_mut_slice()[i..i + 3].copy_from_slice(r.as_slice());
        }
    }
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

/// Largest closure residual the projection may leave, relative to the scene's length scale
/// `Model::length_scale` (so that the choice does not depend on the unit of length: the testbed, L = 0.046 m,
/// gets 1e-10 m). The chord iterations of [`project`] stop below it; beyond [`CHORD_ITERATIONS`] the full
/// Newton step finishes the job.
pub const CHORD_TOLERANCE: f64 = 2e-9;

/// Chord iterations [`project`] takes at most before it refactors at the new configuration.
pub const CHORD_ITERATIONS: usize = 3;

/// One projection onto the constraint manifold in the mass metric: h and W are evaluated once, at the new
/// q, and the correction uses the factors of the step's last KKT solve (`Z = U⁻¹ W_sᵀ`, `S = W_s D⁻¹ W_sᵀ`
/// at the solve's state s, a stale Jacobian as in the chord form of Newton's method):
/// `δq = -D⁻¹ W_sᵀ S⁺ r_q`, `δq̇ = -D⁻¹ W_sᵀ S⁺ r_v`, starting from `r_q = h(q)`, `r_v = W(q) q̇`.
///
/// **The residual is predicted, not re-evaluated.** After a correction δ the residual is, to first order,
/// `r ← r + W(q) δ` (m dot products; the second-order term is `O(|δ|²)` times the linkage's curvature, far
/// below the tolerance; `predicted_residual_is_the_evaluated_one` checks it on the benchmark chains). While the
/// predicted `|r_q|` exceeds [`CHORD_TOLERANCE`] times the length scale, the chord is applied again, each time
/// shrinking the residual by the factor `|I - W(q) D⁻¹ W_sᵀ S⁺|`, of the order of W's relative change
/// since s: O(dt |q̇|), ~1e-3 at 1 kHz. The iterations thus solve the linearized constraint
/// `W(q) δ = -h(q)` like the exact Newton step, which leaves the same second-order term. If they have not
/// converged after [`CHORD_ITERATIONS`], or stop contracting (very fast motion), Z and S are refactored at the
/// new q and one exact correction takes the remaining predicted residual to zero. **Redundant closures**
/// (`closure_rank < nc`: the spherical four-bar's revolute cut) always take the exact step: there the
/// pivoting keeps only some rows, and with the rows and factors of the solve's state the drift of the dropped
/// rows would not be corrected and the closure error would grow step by step.
///
/// Why this is enough: any positive-definite metric gives a valid projection, and every step corrects what
/// the last one left. The velocity is made to satisfy the constraint of the configuration it
/// belongs to (the W of the step's start in place of W(q) would leave an O(dt) velocity error every step).
/// What this saves: a refactorization costs the triangular solve of Wᵀ, the Schur complement and its
/// pivoted factorization; a bound instead of the prediction (`|Δq|∞ · |h|`) would refactor far more often
/// than the prediction and the iterations do.
///
/// **What the prediction leaves out is measured.** The second-order term is `O(|δ|²)` times the linkage's
/// curvature, and `|δ|` is not bounded by the residual: it grows as `|δ| ≈ |h| / σ_min(W)` where W is near
/// a loss of rank (a Delta, a six-bar near a singular configuration) and with the drift of a linkage spun at
/// tens of rad/s. So after each pass h is evaluated once at the corrected q (the body poses and h, no
/// Jacobian), and when it exceeds the pass's prediction by more than the tolerance (the second-order term
/// mattered), h and W are evaluated afresh there and the projection repeats, up to
/// [`MAX_PROJECTION_PASSES`] passes: Newton's method from the corrected q, whose remainder is of the order of
/// the square of the one it corrects. In ordinary motion, the paper's manipulation included, one pass and
/// the one evaluation. What the prediction itself carries (a row the pivoting dropped, which no correction
/// along the kept rows reaches) does not start another pass. **Redundant closures** (`closure_rank < nc`)
/// take a further pass only from a residual above [`SECOND_ORDER_RESIDUAL`]: there the pivoting chooses
/// the kept rows afresh at the corrected q, and at a fold (the Bennett linkage's, where a row vanishes) a
/// pass on another choice of rows trades one row's residual for another's rather than removing a remainder.
///
/// Needs [`kkt::factorize`] at a nearby state (the step's dynamics). Leaves the body poses and h at the q it
/// returns, and Wᵀ at the q the last pass began from. Both corrections are `U⁻ᵀ Z S⁺ r`, so they go through
/// the triangular solve together.
pub fn project<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
) -> Projection {
    let tolerance = CHORD_TOLERANCE * model.length_scale;
    let mut projection = project_once(model, data, q, qd);
    loop {
        forward_poses(model, data, q);
        closure_residual(model, data);
        projection.residual = data.closure_residual.norm();
        // NaN (a state gone bad) compares false: no further pass; the step reports the non-finite state.
        let missed = if model.closure_rank == model.nc() {
            projection.residual - projection.predicted_residual > tolerance
        } else {
            projection.initial_residual > SECOND_ORDER_RESIDUAL * model.length_scale
        };
        if !missed || projection.passes >= MAX_PROJECTION_PASSES {
            return projection;
        }
        let again = project_once(model, data, q, qd);
        projection = Projection {
            chord_iterations: projection.chord_iterations + again.chord_iterations,
            refactored: projection.refactored || again.refactored,
            passes: projection.passes + 1,
            ..again
        };
    }
}

/// A redundant closure's further pass (see [`project`]): when the residual a pass starts from exceeds this
/// fraction of the length scale L, whose correction's remainder, about `r²/L`, may exceed the tolerance.
pub const SECOND_ORDER_RESIDUAL: f64 = 4.47e-5; // √CHORD_TOLERANCE

/// Passes [`project`] takes at most (each evaluates h and W at the q the one before left, see there). In
/// Newton's quadratic regime the remainder squares each pass: from a step that begins just short of torn
/// open (a residual of 1 % of the length scale) three passes reach the tolerance; the others are for passes
/// that overshoot where W is near a loss of rank, until the corrected q is back in that regime.
pub const MAX_PROJECTION_PASSES: usize = 6;

/// One pass of [`project`]: h and W evaluated at q, the chord corrections, and the exact one if needed.
fn project_once<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
) -> Projection {
    forward_poses(model, data, q);
    closure_residual_and_jacobian(model, data);
    let n = model.nv();
    let kkt = &mut data.kkt;
    // (`factor_closures` needs tmp_m, `schur_solve` tmp_m2.)
    let mut r_q = std::mem::replace(&mut kkt.tmp_m3, DVector::zeros(0));
    let mut r_v = std::mem::replace(&mut kkt.tmp_m4, DVector::zeros(0));
    dense::copy(r_q.as_mut_slice(), data.closure_residual.as_slice());
    // W(q) q̇ over whole columns: W(q)'s support is W_s's, but an entry may vanish at one state only.
    let wt = data.closure_jacobian_t.as_slice();
    for (r, col) in r_v.as_mut_slice().iter_mut().zip(wt.chunks_exact(n)) {
        *r = dot(col, qd.as_slice());
    }
    let tolerance = CHORD_TOLERANCE * model.length_scale;
    let initial_residual = r_q.norm();
    // NaN (a state gone bad) compares false and takes the exact step.
    let mut converged = false;
    let mut chord_iterations = 0;
    if model.closure_rank == model.nc() {
        let mut before = initial_residual;
        while chord_iterations < CHORD_ITERATIONS {
            correct(model, data, &mut r_q, &mut r_v, q, qd);
            chord_iterations += 1;
            let after = r_q.norm();
            converged = after <= tolerance;
            // Not contracting by at least half (or NaN): W(q) is too far from the factors' W_s for the chord.
            let contracting = after <= 0.5 * before;
            if converged || !contracting {
                break;
            }
            before = after;
        }
    }
    if !converged {
        kkt::factor_closures(model, data);
        correct(model, data, &mut r_q, &mut r_v, q, qd);
    }
    let projection = Projection {
        chord_iterations,
        refactored: !converged,
        predicted_residual: r_q.norm(),
        initial_residual,
        residual: f64::NAN,
        passes: 1,
    };
    data.kkt.tmp_m3 = r_q;
    data.kkt.tmp_m4 = r_v;
    projection
}

/// What a [`project`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection {
    /// Corrections made with the factors of the step's solve.
    pub chord_iterations: usize,
    /// Whether Z and S were refactored at the new configuration for a final, exact correction.
    pub refactored: bool,
    /// `|h|` after the corrections as predicted to first order (`h + W δ`), m or rad (of the last pass).
    pub predicted_residual: f64,
    /// `|h|` evaluated at the q the last pass began from.
    pub initial_residual: f64,
    /// `|h|` evaluated at the q the projection returns.
    pub residual: f64,
    /// Passes taken, each evaluating h and W at the q the one before left (see [`project`]).
    pub passes: usize,
}

/// Applies one correction with the current factors to `q` and `q̇` and updates the predicted residuals:
/// `δ = -U⁻ᵀ Z S⁺ r`, `r ← r + W(q) δ` for both pairs, W(q) from `closure_jacobian_t`.
pub(crate) fn correct<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    r_q: &mut DVector<f64>,
    r_v: &mut DVector<f64>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
) {
    if model.has_balls() {
        // The correction is a displacement in velocity coordinates: gather it, then turn q by it.
        let mut dq = std::mem::replace(&mut data.integ.dq, DVector::zeros(0));
        dense::zero(dq.as_mut_slice());
        correct_small_or_general(model, data, r_q, r_v, &mut dq, qd);
        configuration::integrate(model, q, &dq, 1.0);
        data.integ.dq = dq;
    } else {
        correct_small_or_general(model, data, r_q, r_v, q, qd);
    }
}

fn correct_small_or_general<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    r_q: &mut DVector<f64>,
    r_v: &mut DVector<f64>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
) {
    by_size!(model.nv(), N => {
        let mut s = std::mem::replace(&mut data.kkt.tmp_m, DVector::zeros(0));
        let (r, x) = ([r_q.as_mut_slice(), r_v.as_mut_slice()], [q.as_mut_slice(), qd.as_mut_slice()]);
        kkt_small::correct::<N>(&data.kkt, data.closure_jacobian_t.as_slice(), r, x, s.as_mut_slice());
        data.kkt.tmp_m = s;
    }, _ => correct_general(model, data, r_q, r_v, q, qd))
}

/// [`correct`] for any n (models of at most 8 joints take `kkt_small`, with the same results).
pub(crate) fn correct_general<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    r_q: &mut DVector<f64>,
    r_v: &mut DVector<f64>,
    q: &mut DVector<f64>,
    qd: &mut DVector<f64>,
) {
    let n = model.nv();
    let kkt = &mut data.kkt;
    dense::zero(kkt.tmp_n2.as_mut_slice());
    // t = -Z S⁺ r per right-hand side (S⁺ on a copy: r is updated below), then U⁻ᵀ t for both together.
    let mut s = std::mem::replace(&mut kkt.tmp_m, DVector::zeros(0));
    for (r, side) in [(&*r_q, 0), (&*r_v, 1)] {
        dense::copy(s.as_mut_slice(), r.as_slice());
        kkt::schur_solve(data, &mut s);
        let kkt = &mut data.kkt;
        let t = &mut kkt.tmp_n2.as_mut_slice()[side * n..(side + 1) * n];
        kkt::sub_columns_times(&kkt.z, &kkt.z_rows, s.as_slice(), t);
    }
    let kkt = &mut data.kkt;
    kkt.tmp_m = s;
    ltl::solve_ut_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), kkt.tmp_n2.as_mut_slice());
    let (t_q, t_v) = kkt.tmp_n2.as_slice().split_at(n);
    let wt = data.closure_jacobian_t.as_slice();
    for (x, r, t) in [(q, r_q, t_q), (qd, r_v, t_v)] {
        for (x, t) in x.as_mut_slice().iter_mut().zip(t) {
            *x += t;
        }
        for (r, col) in r.as_mut_slice().iter_mut().zip(wt.chunks_exact(n)) {
            *r += dot(col, t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::dynamics::forward_dynamics;
    use crate::algorithms::kkt::{solve_general, z_and_schur_general};
    use crate::testing::{for_each_model, paper_testbed, random_state};

    /// `(‖h(q)‖, ‖W(q) q̇‖)` evaluated afresh.
    fn residuals(model: &Model<crate::math::space::Planar>, q: &DVector<f64>, qd: &DVector<f64>) -> (f64, f64) {
        let mut data = Data::new(model);
        forward_poses(model, &mut data, q);
        closure_residual_and_jacobian(model, &mut data);
        let n = model.nv();
        let w_qd = data.closure_jacobian_t.as_slice().chunks_exact(n).map(|c| dot(c, qd.as_slice()).powi(2));
        (data.closure_residual.norm(), w_qd.sum::<f64>().sqrt())
    }

    /// The testbed at q0 with joint rates of `speed` times a fixed pattern (made consistent with the loop),
    /// after one semi-implicit Euler step of 1 ms without projection: a drift of order dt² q̇². The workspace
    /// holds the factors of the step's solve.
    fn drifted(
        model: &Model<crate::math::space::Planar>,
        speed: f64,
    ) -> (Data<crate::math::space::Planar>, DVector<f64>, DVector<f64>) {
        let mut data = Data::new(model);
        let mut q = model.q0.clone();
        // A velocity on the manifold: project a raw one at q0 (the exact Newton step, factors at q0).
        let mut qd = DVector::from_fn(model.nv(), |i, _| speed * [1.0, -0.4, 0.7, 0.2][i]);
        forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
        project(model, &mut data, &mut q.clone(), &mut qd);
        forward_dynamics(model, &mut data, &q, &qd, &mut ()).unwrap();
        qd.axpy(1e-3, &data.qdd, 1.0);
        q.axpy(1e-3, &qd, 1.0);
        (data, q, qd)
    }

    /// The projection, with the factors of a solve one step back, takes the position and velocity residuals
    /// of a step down by at least the factor its documentation promises, from slow to fast (single-pass)
    /// motion of the testbed (the faster, the more W moves in a step and the less the stale factors help),
    /// and never leaves more than its tolerance, evaluated afresh.
    #[test]
    fn chord_projection_contracts_the_residuals_of_a_step() {
        let model = paper_testbed();
        for speed in [0.5, 5.0, 15.0] {
            let (mut data, mut q, mut qd) = drifted(&model, speed);
            let dt = 1e-3;
            let (h_before, v_before) = residuals(&model, &q, &qd);
            let q_before = q.clone();
            let projection = project(&model, &mut data, &mut q, &mut qd);
            let (h_after, _) = residuals(&model, &q, &qd);
            assert!(projection.chord_iterations >= 1, "speed {speed}: {projection:?}");
            // The velocity is made consistent with the configuration the step reached (whose constraint the
            // step violated); the position correction then moves W by O(|Δq|), a floor far below this.
            let (_, v_after) = residuals(&model, &q_before, &qd);
            // W moves by about dt·|q̇| relative in a step: the stale factors leave that fraction.
            let factor = (5.0 * dt * speed).max(1e-3);
            assert!(h_before > 1e-10, "speed {speed}: the step should drift ({h_before:.2e})");
            assert!(h_after <= factor * h_before + 1e-15, "speed {speed}: h {h_before:.2e} -> {h_after:.2e}");
            let tolerance = CHORD_TOLERANCE * model.length_scale;
            assert!(h_after <= tolerance, "speed {speed}: h {h_before:.2e} -> {h_after:.2e}");
            assert!(v_after <= factor * v_before + 1e-13, "speed {speed}: W q̇ {v_before:.2e} -> {v_after:.2e}");
        }
    }

    /// A step whose result is not finite (here a step of 1e300 s from joint rates of 1e10 rad/s, which
    /// overflows) returns the error and leaves q and q̇ as they were, with every integrator: the caller can
    /// carry on from its last state.
    #[test]
    fn a_step_that_ends_non_finite_leaves_the_state_as_it_was() {
        let model = paper_testbed();
        let mut data = Data::new(&model);
        let mut push =
            crate::algorithms::dynamics::OpWrench { op: 0, wrench: nalgebra::Vector3::new(-0.5, 0.0, -0.0025) };
        for integrator in [Integrator::SemiImplicitEuler, Integrator::ExplicitEuler, Integrator::Rk4] {
            let (mut q, mut qd) = crate::testing::random_state(&model, 5);
            qd *= 1e10;
            let before = (q.clone(), qd.clone());
            let cfg = StepConfig { integrator, ..StepConfig::euler(1e300) };
            // The Euler steps overflow at the end, RK4 within its stages (D of a non-finite q is not factored).
            assert!(step(&model, &mut data, &mut q, &mut qd, &mut push, &cfg).is_err(), "{integrator:?}");
            assert_eq!((q, qd), before, "{integrator:?}");
            // And the workspace still serves a sound step.
            let mut state = before.clone();
            step(&model, &mut data, &mut state.0, &mut state.1, &mut push, &StepConfig::euler(1e-3)).unwrap();
        }
    }

    /// Spun at tens of rad/s, the testbed drifts so far in a step that one pass of the projection leaves
    /// more than the tolerance (its correction's second-order remainder); a further pass is taken exactly
    /// when the first one's residual, evaluated afresh, missed its prediction by more than the tolerance, and
    /// the passes close the loop to the tolerance. In ordinary motion one pass is taken.
    #[test]
    fn violent_motion_takes_further_passes_and_leaves_the_tolerance() {
        let model = paper_testbed();
        let tolerance = CHORD_TOLERANCE * model.length_scale;
        for speed in [0.5, 5.0, 15.0] {
            let (mut data, mut q, mut qd) = drifted(&model, speed);
            assert_eq!(project(&model, &mut data, &mut q, &mut qd).passes, 1, "speed {speed}");
        }
        let mut one_pass_left_too_much = false;
        for speed in [30.0, 75.0, 200.0] {
            let (data, q, qd) = drifted(&model, speed);
            let (mut once, mut q_once, mut qd_once) = (data.clone(), q.clone(), qd.clone());
            let first = project_once(&model, &mut once, &mut q_once, &mut qd_once);
            let h_once = residuals(&model, &q_once, &qd_once).0;
            one_pass_left_too_much |= h_once > tolerance;
            let missed = h_once - first.predicted_residual > tolerance;
            let (mut data, mut q, mut qd) = (data, q, qd);
            let projection = project(&model, &mut data, &mut q, &mut qd);
            let (h_after, _) = residuals(&model, &q, &qd);
            // A further pass exactly when the first one's evaluated residual missed its prediction.
            assert_eq!(projection.passes >= 2, missed, "speed {speed}: {h_once:.2e} after {first:?}, {projection:?}");
            assert!(h_after <= tolerance, "speed {speed}: left {h_after:.2e} m after {projection:?}");
            assert!(
                (projection.residual - h_after).abs() <= 1e-15,
                "speed {speed}: {projection:?} against {h_after:.2e}"
            );
        }
        assert!(one_pass_left_too_much, "the fastest case should need the further passes");
    }

    /// On every test scene of at most 8 joints with loops (redundant ones included), the fixed-size kernels
    /// give the general forms' Z, S, q̈, λ and chord corrections bit for bit, at random states; one of the
    /// scenes has more than 8 joints and takes the general form either way.
    #[test]
    fn fixed_size_kernels_give_the_general_forms_bits() {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut compared = 0;
        for_each_model!(name, model => {
            if model.nv() <= 8 && model.nc() > 0 {
                for seed in 0..5 {
                    let (q, qd) = random_state(model, seed);
                    let mut small = Data::new(model);
                    dynamics_terms(model, &mut small, &q, &qd, &mut ());
                    kkt::factorize(model, &mut small).unwrap();
                    let mut general = small.clone();
                    general.kkt.z.fill(f64::NAN);
                    general.kkt.schur.fill(f64::NAN);
                    z_and_schur_general(model, &mut general);
                    let case = format!("{name}, seed {seed}");
                    assert_eq!(bits(small.kkt.z.as_slice()), bits(general.kkt.z.as_slice()), "{case}: Z");
                    assert_eq!(bits(small.kkt.schur.as_slice()), bits(general.kkt.schur.as_slice()), "{case}: S");
                    kkt::solve(model, &mut small).unwrap();
                    solve_general(model, &mut general);
                    assert_eq!(bits(small.qdd.as_slice()), bits(general.qdd.as_slice()), "{case}: q̈");
                    assert_eq!(bits(small.lambda.as_slice()), bits(general.lambda.as_slice()), "{case}: λ");
                    // A chord correction at a configuration off the manifold, with the factors above.
                    let off = q.map(|x| x + 1e-4);
                    forward_poses(model, &mut small, &off);
                    closure_residual_and_jacobian(model, &mut small);
                    let mut general = small.clone();
                    let r_q = small.closure_residual.clone();
                    let r_v = DVector::from_fn(model.nc(), |i, _| 1e-3 * (i as f64 + 1.0));
                    let mut a = (r_q.clone(), r_v.clone(), off.clone(), qd.clone());
                    let mut b = (r_q, r_v, off.clone(), qd.clone());
                    correct(model, &mut small, &mut a.0, &mut a.1, &mut a.2, &mut a.3);
                    correct_general(model, &mut general, &mut b.0, &mut b.1, &mut b.2, &mut b.3);
                    for (what, x, y) in [("r_q", &a.0, &b.0), ("r_v", &a.1, &b.1), ("q", &a.2, &b.2), ("q̇", &a.3, &b.3)] {
                        assert_eq!(bits(x.as_slice()), bits(y.as_slice()), "{case}: corrected {what}");
                    }
                    assert_ne!(a.2, off, "{case}: the correction should move q");
                    compared += 1;
                }
            }
        });
        assert!(compared >= 5 * 6, "only {compared} cases compared");
    }

    /// Energy a step made is out of the velocity as soon as the step settles, and the next step's open finds
    /// nothing more to book: a step whose end velocity is doubled (three times its kinetic energy made, no
    /// force working) is brought back to the energy it had plus the credit the account held (what the first
    /// step's projection lost), and stepping on opens with nothing to take out.
    #[test]
    fn a_settled_step_hands_on_none_of_the_energy_it_made() {
        use crate::algorithms::gravity::{field_energy, kinetic_energy};
        use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
        let model = paper_testbed();
        let (mut q, mut qd) = random_state(&model, 3);
        let mut data = Data::new(&model);
        let mut guard = EnergyGuard::default();
        let config = StepConfig::euler(1e-3);
        let energy = |data: &mut Data<crate::math::space::Planar>, q: &DVector<f64>, qd: &DVector<f64>| {
            forward_kinematics(&model, data, q);
            forward_velocity(&model, data, qd);
            kinetic_energy(&model, data) + field_energy(&model, data, q)
        };
        step_guarded(&model, &mut data, &mut q, &mut qd, &mut (), &config, Some(&mut guard)).expect("steps");
        let settled = energy(&mut data, &q, &qd);
        assert!(!guard.settle(&model, &data, &q, &mut qd), "a plain step made energy: {}", guard.reservoir());
        let credit = -guard.reservoir();
        assert!(credit >= 0.0);
        // The next step makes three times the kinetic energy, with no force working.
        let kinetic = kinetic_energy(&model, &data);
        qd *= 2.0;
        energy(&mut data, &q, &qd);
        assert!(guard.settle(&model, &data, &q, &mut qd), "the doubled velocity is scaled back");
        let after = energy(&mut data, &q, &qd);
        assert!(credit < 3.0 * kinetic, "the credit {credit} covers what the step made");
        let tolerance = 1e-9 * settled.abs().max(kinetic);
        assert!((after - (settled + credit)).abs() <= tolerance, "{after} against {settled} + {credit}");
        assert!((guard.removed - (3.0 * kinetic - credit)).abs() <= tolerance, "removed {}", guard.removed);
        // The next step opens at the settled state: nothing left to book or take out.
        let removed = guard.removed;
        step_guarded(&model, &mut data, &mut q, &mut qd, &mut (), &config, Some(&mut guard)).expect("steps");
        assert_eq!(guard.removed, removed);
    }
}
