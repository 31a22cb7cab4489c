//! The inverse operational-space inertia Λ⁻¹ at an operational point, with the loops closed (eq 9) and
//! with them cut open.
//!
//! Eq 9 reads `Λ⁻¹ = J D⁻¹ Jᵀ - J D⁻¹ Wᵀ (W D⁻¹ Wᵀ)⁻¹ W D⁻¹ Jᵀ`, which needs the inverse of
//! `S = W D⁻¹ Wᵀ`: singular for redundant closures. We compute the same quantity as `J P Jᵀ` with
//! `P = D⁻¹ - D⁻¹ Wᵀ S⁺ W D⁻¹` (the top-left block of the KKT inverse) using the factors of the KKT solve:
//! with `Y = U⁻¹ Jᵀ`, `Z = U⁻¹ Wᵀ` and the rank-revealing factor `S_rr = R Rᵀ` over the independent rows,
//! `Λ⁻¹ = Yᵀ Y - Gᵀ G` where `G = R⁻¹ (Zᵀ Y)_r`. The first term is the open-chain `Λ⁻¹`.
//! Y is nonzero only on the joints that support the OP's body (see `ltl`), so an OP near the base is cheap.

use crate::data::Data;
use crate::dense::{dot, mul_add};
use crate::error::DynamicsError;
use crate::jacobian::{frame_bias_acceleration, frame_jacobian_t};
use crate::ltl;
use crate::model::Model;
use crate::space::{MatOps, Space};

/// Computes `data.op` for operational point `op`: Jᵀ, J̇q̇, Λ⁻¹ (closed) and Λ⁻¹ (open). Needs
/// `forward_kinematics`, `forward_velocity` (for J̇q̇), `mass_matrix`, `loop_closure` and `kkt::factorize`
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
    let n = model.nq();
    let k = S::DIM;
    let ws = &mut data.op;
    frame_jacobian_t(model, &data.kin, body, p, &mut ws.jacobian_t);
    ws.jdot_qdot = frame_bias_acceleration(&data.kin, body, p);
    ws.y.as_mut_slice().copy_from_slice(ws.jacobian_t.as_slice());
    // Jᵀ, and so Y, is nonzero only on the joints that move `body`: rows 0..=body.
    let rows = body + 1;
    let kkt = &data.kkt;
    ltl::solve_u_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), ws.y.as_mut_slice(), rows);
    let y = ws.y.as_slice();
    let mut open = S::OpMat::zero();
    for c in 0..k {
        for r in 0..=c {
            let v = dot(&y[r * n..r * n + rows], &y[c * n..c * n + rows]);
            open[(r, c)] = v;
            open[(c, r)] = v;
        }
    }
    ws.inverse_inertia_open = open;
    let mut closed = open;
    let rank = kkt.schur_rank;
    if model.nc() > 0 && rank > 0 {
        // G = R⁻¹ (Zᵀ Y) restricted to the pivoted independent rows, one column of Y at a time.
        let l = kkt.schur_factor.as_slice();
        let m = model.nc();
        let z = kkt.z.as_slice();
        let g = ws.g.as_mut_slice();
        for (yc, gc) in y.chunks_exact(n).zip(g.chunks_exact_mut(m)) {
            let yc = &yc[..rows];
            for i in 0..rank {
                let zi = kkt.schur_perm[i];
                let mut s = dot(&z[zi * n..zi * n + kkt.z_rows[zi]], yc);
                for (j, gj) in gc[..i].iter().enumerate() {
                    s = mul_add(-l[j * m + i], *gj, s);
                }
                gc[i] = s * kkt.schur_inv_diag[i];
            }
        }
        for c in 0..k {
            for r in 0..=c {
                let s = dot(&g[r * m..r * m + rank], &g[c * m..c * m + rank]);
                closed[(r, c)] -= s;
                if r != c {
                    closed[(c, r)] -= s;
                }
            }
        }
    }
    if !closed.is_finite() {
        return Err(DynamicsError::NonFiniteResult { what: "inverse operational-space inertia" });
    }
    ws.inverse_inertia = closed;
    Ok(())
}
