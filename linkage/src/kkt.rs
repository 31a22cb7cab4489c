//! The KKT solve of eq 4:
//! ```text
//! [ D  Wᵀ ] [ q̈ ]   [ Σ Jᵢᵀ Fᵢ + J_hᵀ F_h - B - G ]
//! [ W  0  ] [ λ  ] = [ -w_stab                     ]
//! ```
//! by the range-space (Schur complement) method: factor `D = U Uᵀ` (tree-sparse, see `ltl`), form
//! `Z = U⁻¹ Wᵀ` and `S = W D⁻¹ Wᵀ = Zᵀ Z`, then solve `S λ = W D⁻¹ τ + w_stab` and
//! `q̈ = D⁻¹ (τ - Wᵀ λ)`.
//!
//! **Redundant closures and singular configurations.** S is singular when W loses rank (an overconstrained
//! parallelogram, a spherical four-bar closed by a 5-equation revolute cut, a four-bar at a toggle). We never
//! invert it: S is factored by a *diagonal-pivoted (rank-revealing) Cholesky* that picks, at each step, the
//! closure row with the largest remaining pivot relative to its own diagonal `S_ii` (so the choice does not
//! depend on units), and stops when that ratio falls below [`RANK_TOLERANCE`] or when it has kept
//! `Model::closure_rank` rows — the *generic* rank of W, found once at compile time by SVD on the manifold.
//! The cap matters: off the manifold (drift, or an RK4 stage state) structurally redundant rows are no
//! longer exactly dependent; their spurious singular value is proportional to the drift, and keeping such a
//! row would produce enormous multipliers and lock the mechanism. The rows left over get λ = 0; pivoting
//! still chooses which rows to keep at every solve, so the choice follows the motion. q̈ is unique whatever
//! W's rank, so this gives the exact accelerations; λ is the basic solution on the kept rows.

use nalgebra::DVector;

use crate::data::Data;
use crate::dense;
use crate::error::DynamicsError;
use crate::ltl;
use crate::model::Model;
use crate::space::Space;

/// A closure row is dependent when its remaining pivot is below this fraction of its own `S_ii`
/// (relative pivot 1e-10 ↔ about 1e-5 rad between constraint normals).
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Factors D (plus `implicit_mass` when in use) and, when the model has loops, forms Z, S and the pivoted
/// factor of S. Needs `mass_matrix` and `loop_closure`.
pub fn factorize<S: Space>(model: &Model<S>, data: &mut Data<S>) -> Result<(), DynamicsError> {
    let kkt = &mut data.kkt;
    kkt.factor.copy_from(&data.mass_matrix);
    if data.use_implicit_mass {
        kkt.factor += &data.implicit_mass;
    }
    ltl::factor(model, &mut kkt.factor)?;
    factor_closures(model, data);
    Ok(())
}

/// With the mass factor U in place, forms `Z = U⁻¹ Wᵀ`, `S = Zᵀ Z` and the pivoted factor of S from the
/// current `closure_jacobian_t`.
pub fn factor_closures<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let m = model.nc();
    if m == 0 {
        return;
    }
    let kkt = &mut data.kkt;
    kkt.z.copy_from(&data.closure_jacobian_t);
    let n = model.nq();
    for r in 0..m {
        let col = &mut kkt.z.as_mut_slice()[r * n..(r + 1) * n];
        ltl::solve_u(model, &kkt.factor, col);
    }
    kkt.z.tr_mul_to(&kkt.z, &mut kkt.schur);
    kkt.schur_rank = dense::pivoted_cholesky(
        &kkt.schur,
        &mut kkt.schur_factor,
        &mut kkt.schur_perm,
        &mut kkt.tmp_m,
        RANK_TOLERANCE,
        model.closure_rank,
    );
}

/// Solves `S x = r` in place on the independent rows of the pivoted factor; dependent rows get `x = 0`.
pub fn schur_solve<S: Space>(data: &mut Data<S>, r: &mut DVector<f64>) {
    let kkt = &mut data.kkt;
    dense::pivoted_solve(&kkt.schur_factor, &kkt.schur_perm, kkt.schur_rank, r, &mut kkt.tmp_m2);
}

/// Solves eq 4 for `data.qdd` and `data.lambda` with the right-hand side
/// `τ = applied + joint_force - bias - gravity` and `-w_stab`. Needs [`factorize`] and `stabilize`.
pub fn solve<S: Space>(model: &Model<S>, data: &mut Data<S>) -> Result<(), DynamicsError> {
    let n = model.nq();
    for i in 0..n {
        data.qdd[i] = data.applied[i] + data.joint_force[i] - data.bias[i] - data.gravity[i];
    }
    // Unconstrained accelerations D⁻¹ τ.
    ltl::solve(model, &data.kkt.factor, data.qdd.as_mut_slice());
    if model.nc() > 0 {
        // λ = S⁺ (W q̈_free + w_stab), then q̈ = q̈_free - D⁻¹ Wᵀ λ = q̈_free - U⁻ᵀ Z λ.
        let mut rhs = std::mem::replace(&mut data.lambda, DVector::zeros(0));
        rhs.copy_from(&data.closure_bias_stab);
        rhs.gemv_tr(1.0, &data.closure_jacobian_t, &data.qdd, 1.0);
        schur_solve(data, &mut rhs);
        data.lambda = rhs;
        let tmp = &mut data.kkt.tmp_n;
        tmp.gemv(1.0, &data.kkt.z, &data.lambda, 0.0);
        ltl::solve_ut(model, &data.kkt.factor, tmp.as_mut_slice());
        data.qdd -= &*tmp;
    }
    if data.qdd.iter().any(|x| !x.is_finite()) {
        return Err(DynamicsError::NonFiniteResult { what: "joint accelerations" });
    }
    Ok(())
}
