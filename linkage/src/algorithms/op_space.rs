//! The inverse operational-space inertia Λ⁻¹ at an operational point, with the loops closed (eq 9) and
//! with them cut open.
//!
//! Eq 9 reads `Λ⁻¹ = J D⁻¹ Jᵀ - J D⁻¹ Wᵀ (W D⁻¹ Wᵀ)⁻¹ W D⁻¹ Jᵀ`, which needs the inverse of
//! `S = W D⁻¹ Wᵀ`: singular for redundant closures. We compute the same quantity as `J P Jᵀ` with
//! `P = D⁻¹ - D⁻¹ Wᵀ S⁺ W D⁻¹` (the top-left block of the KKT inverse) using the factors of the KKT solve:
//! with `Y = U⁻¹ Jᵀ`, `Z = U⁻¹ Wᵀ` and the rank-revealing factor `S_rr = R Rᵀ` over the independent rows,
//! `Q = Z_r R⁻ᵀ` has orthonormal columns spanning the kept closures' directions and
//! `Λ⁻¹ = Yᵀ (I - Q Qᵀ) Y`. `Yᵀ Y` is the open-chain `Λ⁻¹`.
//!
//! **Gram form.** We build Q (from Z and the factor, no new factorization), compute `Ỹ = Y - Q (Qᵀ Y)` and
//! take `Λ⁻¹ = Ỹᵀ Ỹ`, not the shorter `Yᵀ Y - Gᵀ G` with `G = Qᵀ Y = R⁻¹ (Zᵀ Y)_r`: near a configuration
//! where the closures lose rank, a kept row can have a relative pivot near
//! [`crate::algorithms::kkt::RANK_TOLERANCE`], R a condition number up to 1e5, and the difference of two
//! large Gram matrices lost its small eigenvalues to round-off: random linkages built at such a
//! configuration gave an eigenvalue of -1.7e-6 (not positive semi-definite, so not an inverse inertia).
//! A Gram matrix is positive semi-definite whatever the round-off, and its small eigenvalues come from
//! the small columns of Ỹ rather than from a cancellation.
//! Y is nonzero only on the joints that support the OP's body (see `ltl`), so an OP near the base is cheap.
//!
//! **Immobile points.** Where the loops pin the OP (a slider-crank's slider at a dead centre), Λ⁻¹ is zero,
//! but Ỹ keeps the round-off of the projection: Λ⁻¹ ~ 1e-31 of the open-loop one, a matrix of noise whose
//! largest direction would read as free. An OP that keeps at most [`IMMOBILE_TOLERANCE`] of its open-loop
//! mobility (scaled traces, see there) gets Λ⁻¹ = 0 and Ỹ = 0, so that `constraint_directions` counts
//! every direction and the couplings through Ỹ vanish, as they do exactly.

use crate::algorithms::jacobian::{frame_bias_acceleration, frame_jacobian_t};
use crate::algorithms::ltl;
use crate::error::DynamicsError;
use crate::math::dense::{self, by_size, dot, dot_fixed, mul_add};
use crate::math::space::{MatOps, Space, VecOps};
use crate::model::data::Data;
use crate::model::Model;

/// The fraction of its open-loop mobility below which an OP counts as immobile: Λ⁻¹ is set to zero when
/// `tr(T Λ⁻¹ T) ≤ IMMOBILE_TOLERANCE · tr(T Λ⁻¹_open T)`, `T = diag(1 linear, L angular)` as in
/// `constraint_directions` (so the rule, like the count, does not depend on units).
///
/// **Why 1e-10.** What round-off leaves of a pinned OP is tiny: Ỹ's columns keep about ε_mach of Y's, so the
/// ratio is of the order of ε_mach². It grows where the kept closures are
/// nearly dependent: the projection's basis Q loses orthogonality as ε_mach·cond(R)², and with
/// `kkt::RANK_TOLERANCE` = 1e-10 on the Schur pivots, cond(R) reaches 1e5, so up to ~1e-6 of Y survives,
/// a ratio of ~1e-12. 1e-10 stays a hundred times above that. A genuinely mobile OP falls below it only
/// within about 1e-5 rad of a dead centre (the ratio grows as the square of the distance: 2.3e-12 at 1e-6
/// rad on the slider-crank), where moving it takes 1e10 times its open-loop force, which no haptic device
/// renders; or with a mass ratio of 1e10 between its body and what the loops tie it to.
pub const IMMOBILE_TOLERANCE: f64 = 1e-10;

/// Computes `data.op` for operational point `op`: Jᵀ, J̇q̇, Y, Ỹ and Λ⁻¹ with the loops closed (the open one
/// on demand: [`open_inverse_inertia`], which the snapshots do not need). Needs
/// `forward_kinematics`, `forward_velocity` (for J̇q̇), `loop_closure` and `kkt::factorize`
/// at the same configuration, with no implicit mass in the factor.
pub fn op_space_inertia<S: Space>(model: &Model<S>, data: &mut Data<S>, op: usize) -> Result<(), DynamicsError> {
    let point = model.ops.get(op).ok_or(DynamicsError::UnknownOp { index: op, count: model.ops.len() })?;
    let p = data.kin.body_pos[point.body] + S::rotate(&data.kin.body_rot[point.body], &point.point);
    frame_point_inertia(model, data, point.body, &p)
}

/// As [`op_space_inertia`], for an arbitrary point at world position `p` fixed to `body`.
pub fn frame_point_inertia<S: Space>(
    model: &Model<S>,
    data: &mut Data<S>,
    body: usize,
    p: &S::Point,
) -> Result<(), DynamicsError> {
    let n = model.nv();
    let ws = &mut data.op;
    // Jᵀ is built in Y, which the solve then overwrites, and copied to `jacobian_t` beside the solve: the other
    // way round the solve waited for a copy that reloads the Jacobian's just-written entries.
    frame_jacobian_t(model, &data.kin, body, p, &mut ws.y);
    ws.jdot_qdot = frame_bias_acceleration(&data.kin, body, p);
    copy_op_columns::<S>(ws.jacobian_t.as_mut_slice(), ws.y.as_slice(), n);
    // Jᵀ, and so Y, is nonzero only on the joints that move `body`: rows 0..=body.
    let rows = body + 1;
    let kkt = &data.kkt;
    ltl::solve_u_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), ws.y.as_mut_slice(), rows);
    let y = ws.y.as_slice();
    let y_closed = ws.y_closed.as_mut_slice();
    copy_op_columns::<S>(y_closed, y, n);
    let rank = kkt.schur_rank;
    let closed = if model.nc() > 0 && rank > 0 {
        let basis = Closures {
            z: kkt.z.as_slice(),
            l: kkt.schur_factor.as_slice(),
            inv_diag: kkt.schur_inv_diag.as_slice(),
            perm: &kkt.schur_perm[..rank],
            m: model.nc(),
        };
        let q = ws.closure_basis.as_mut_slice();
        let angular = model.length_scale * model.length_scale;
        let removed = by_size!(n, N => project_out::<S, N>(N, &basis, q, y_closed, angular),
            _ => project_out::<S, 0>(n, &basis, q, y_closed, angular));
        let closed = gram::<S>(y_closed, n, n);
        let kept = scaled_trace::<S>(&closed, angular);
        // `kept + removed` is the open-loop trace: projecting out a unit vector takes g² off the squared norm.
        if kept <= IMMOBILE_TOLERANCE * (kept + removed) {
            dense::zero(y_closed);
            S::OpMat::zero()
        } else {
            closed
        }
    } else {
        gram::<S>(y, n, rows)
    };
    if !closed.is_finite() {
        return Err(DynamicsError::NonFiniteResult { what: "inverse operational-space inertia" });
    }
    ws.inverse_inertia = closed;
    Ok(())
}

/// Λ⁻¹ with the loops cut open, `J D⁻¹ Jᵀ = Yᵀ Y`, from the Y of the last [`op_space_inertia`] or
/// [`frame_point_inertia`].
pub fn open_inverse_inertia<S: Space>(model: &Model<S>, data: &Data<S>) -> S::OpMat {
    let n = model.nv();
    gram::<S>(data.op.y.as_slice(), n, n)
}

/// `dst ← src` for n×k column-major workspaces (Jᵀ, Y, Ỹ): with n a constant up to 8 the copy is inline,
/// where a length known only at run time calls `memcpy` (see `dense::copy`).
#[inline(always)]
fn copy_op_columns<S: Space>(dst: &mut [f64], src: &[f64], n: usize) {
    by_size!(n, N => dst[..S::DIM * N].copy_from_slice(&src[..S::DIM * N]), _ => dst.copy_from_slice(src))
}

/// `Yᵀ Y` for the n×k column-major `y` whose rows from `rows` on are zero. Up to 8 joints over whole
/// columns with n a constant (the same sums: the rows past `rows` add exact zeros).
fn gram<S: Space>(y: &[f64], n: usize, rows: usize) -> S::OpMat {
    // (The slice to its exact length lets the compiler drop the bounds checks of the column products.)
    by_size!(n, N => { let y = &y[..S::DIM * N]; gram_of::<S>(|r, c| dot_fixed::<N>(&y[r * N..], &y[c * N..])) },
        _ => gram_of::<S>(|r, c| dot(&y[r * n..r * n + rows], &y[c * n..c * n + rows])))
}

/// The symmetric k×k matrix of the column products `dot(r, c)`.
#[inline(always)]
fn gram_of<S: Space>(dot: impl Fn(usize, usize) -> f64) -> S::OpMat {
    let mut g = S::OpMat::zero();
    for c in 0..S::DIM {
        for r in 0..=c {
            let v = dot(r, c);
            g[(r, c)] = v;
            g[(c, r)] = v;
        }
    }
    g
}

/// The kept closures' directions in the metric of D: Z's columns, the pivoted factor `S_rr = L Lᵀ` and its
/// reciprocal diagonal (the KKT workspace's).
struct Closures<'a> {
    z: &'a [f64],
    l: &'a [f64],
    inv_diag: &'a [f64],
    perm: &'a [usize],
    m: usize,
}

/// Builds the orthonormal basis `Q = Z_r L⁻ᵀ` (n×rank, into `q`: column i is Z's column `perm[i]` minus
/// its components along the columns before it, scaled, as in Gram-Schmidt but with the coefficients taken
/// from the factor) and projects it out of every column of `y`: `y ← y - Q (Qᵀ y)`. Returns what was
/// projected out, `Σ_c w_c Σ_i (q_iᵀ y_c)²` with `w_c` = 1 on linear and `angular` (L²) on angular columns:
/// the scaled trace of `Λ⁻¹_open - Λ⁻¹`, the reference for [`IMMOBILE_TOLERANCE`] at the cost of one
/// multiply-add per product already formed. Called with the constant `N = n` for small linkages, so that
/// the loops over rows unroll, and with `N = 0` otherwise.
#[inline(always)]
fn project_out<S: Space, const N: usize>(
    n: usize,
    c: &Closures<'_>,
    q: &mut [f64],
    y: &mut [f64],
    angular: f64,
) -> f64 {
    let n = if N > 0 { N } else { n };
    let rank = c.perm.len();
    for (i, &zi) in c.perm.iter().enumerate() {
        let (done, rest) = q.split_at_mut(i * n);
        let qi = &mut rest[..n];
        qi.copy_from_slice(&c.z[zi * n..(zi + 1) * n]);
        for (j, qj) in done.chunks_exact(n).enumerate() {
            // L[i][j], column-major m×m.
            let lij = c.l[j * c.m + i];
            for (x, v) in qi.iter_mut().zip(qj) {
                *x = mul_add(-lij, *v, *x);
            }
        }
        let inv = c.inv_diag[i];
        for x in qi.iter_mut() {
            *x *= inv;
        }
    }
    let q = &q[..rank * n];
    let (linear, rotational) = y.split_at_mut(<S::Point as VecOps>::LEN * n);
    let removed_linear = project_columns(n, q, linear);
    mul_add(angular, project_columns(n, q, rotational), removed_linear)
}

/// `y ← y - Q (Qᵀ y)` for the columns of `y`, returning `Σ (q_iᵀ y_c)²` (see [`project_out`]).
#[inline(always)]
fn project_columns(n: usize, q: &[f64], y: &mut [f64]) -> f64 {
    let mut removed = 0.0;
    for yc in y.chunks_exact_mut(n) {
        for qi in q.chunks_exact(n) {
            let g = dot(qi, yc);
            removed = mul_add(g, g, removed);
            for (x, v) in yc.iter_mut().zip(qi) {
                *x = mul_add(-g, *v, *x);
            }
        }
    }
    removed
}

/// `tr(T A T)` with `T = diag(1 linear, L angular)`: `angular` is L².
fn scaled_trace<S: Space>(a: &S::OpMat, angular: f64) -> f64 {
    (0..S::DIM).map(|i| if i < <S::Point as VecOps>::LEN { a[(i, i)] } else { angular * a[(i, i)] }).sum()
}
