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
//! closure row with the largest remaining pivot in the scene's own scale (`Model::closure_row_weights`: a
//! length row's divided by L², so the choice does not depend on units, and a row vanishing at the current
//! state, like a Bennett linkage's at its fold, is not kept in place of one that holds the loop), treats a
//! row as dependent when its remaining pivot falls below [`RANK_TOLERANCE`] of its own diagonal `S_ii`, and
//! stops when no independent row is left or when it has kept
//! `Model::closure_rank` rows — the *generic* rank of W, found once at compile time by SVD on the manifold.
//! The cap matters: off the manifold (drift, or an RK4 stage state) structurally redundant rows are no
//! longer exactly dependent; their spurious singular value is proportional to the drift, and keeping such a
//! row would produce enormous multipliers and lock the mechanism. The rows left over get λ = 0; pivoting
//! still chooses which rows to keep at every solve, so the choice follows the motion. q̈ is unique whatever
//! W's rank, so this gives the exact accelerations; λ is the basic solution on the kept rows.

use nalgebra::{DMatrix, DVector};

use crate::algorithms::articulated;
use crate::algorithms::ltl;
use crate::algorithms::mass_matrix;
use crate::error::DynamicsError;
use crate::math::dense::{self, by_size, dot, dot_fixed, mul_add, sub_scaled};
use crate::math::kkt_small;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::Model;

/// A closure row is dependent when its remaining pivot is below this fraction of its own `S_ii`
/// (relative pivot 1e-10 ↔ about 1e-5 rad between constraint normals).
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Factors D (plus `implicit_mass` when in use) and, when the model has loops, forms Z, S and the pivoted
/// factor of S. Needs `forward_kinematics` and `loop_closure`. D alone is factored from the bodies'
/// articulated inertias without being formed (`articulated`), unless it is formed already
/// (`Data::keep_mass_matrix`); with `implicit_mass`, D is formed if need be and the sum factored by `ltl`.
pub fn factorize<S: Space>(model: &Model<S>, data: &mut Data<S>) -> Result<(), DynamicsError> {
    if data.use_implicit_mass || data.mass_matrix_fresh {
        mass_matrix::ensure(model, data);
        let kkt = &mut data.kkt;
        let (d, extra) = (&data.mass_matrix, data.use_implicit_mass.then_some(&data.implicit_mass));
        ltl::factor_sum(model, d, extra, &mut kkt.factor, kkt.factor_inv_diag.as_mut_slice())?;
    } else {
        articulated::factor(model, data)?;
    }
    factor_closures(model, data);
    Ok(())
}

/// With the mass factor U in place, forms `Z = U⁻¹ Wᵀ`, `S = Zᵀ Z` and the pivoted factor of S from the
/// current `closure_jacobian_t`. Each column of Wᵀ is nonzero only on the joints supporting the closure's
/// bodies, and so is its column of Z (see `ltl`): the solves and the products stop at that support.
pub fn factor_closures<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let m = model.nc();
    if m == 0 {
        return;
    }
    let n = model.nv();
    by_size!(n, N => kkt_small::z_and_schur::<N>(&mut data.kkt, data.closure_jacobian_t.as_slice(), m),
        _ => z_and_schur_general(model, data));
    let kkt = &mut data.kkt;
    kkt.schur_rank = dense::pivoted_cholesky(
        &kkt.schur,
        &mut kkt.schur_factor,
        &mut kkt.schur_perm,
        &mut kkt.tmp_m,
        kkt.schur_inv_diag.as_mut_slice(),
        RANK_TOLERANCE,
        model.closure_rank,
        Some(&model.closure_row_weights),
    );
}

/// `Z = U⁻¹ Wᵀ` and `S = Zᵀ Z` for any n (models of at most 8 joints take `kkt_small`, with the same
/// results), with the supports `z_rows`.
pub(crate) fn z_and_schur_general<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let (n, m) = (model.nv(), model.nc());
    let kkt = &mut data.kkt;
    dense::copy(kkt.z.as_mut_slice(), data.closure_jacobian_t.as_slice());
    let z = kkt.z.as_mut_slice();
    for (rows, col) in kkt.z_rows.iter_mut().zip(z.chunks_exact(n)) {
        *rows = col.iter().rposition(|x| *x != 0.0).map_or(0, |r| r + 1);
    }
    // Consecutive columns with the same support (the rows of one primitive) are solved together.
    let mut c = 0;
    while c < m {
        let rows = kkt.z_rows[c];
        let mut end = c + 1;
        while end < m && end - c < 4 && kkt.z_rows[end] == rows {
            end += 1;
        }
        ltl::solve_u_columns(model, &kkt.factor, kkt.factor_inv_diag.as_slice(), &mut z[c * n..end * n], rows);
        c = end;
    }
    let s = kkt.schur.as_mut_slice();
    for j in 0..m {
        let zj = &z[j * n..j * n + kkt.z_rows[j]];
        for i in 0..=j {
            let zi = &z[i * n..i * n + kkt.z_rows[i]];
            // Up to 8 joints, over whole columns: the same sum (the rows past a support add exact zeros).
            let v = by_size!(n, N => dot_fixed::<N>(&z[i * n..], &z[j * n..]), _ => dot(zi, zj));
            s[j * m + i] = v;
            s[i * m + j] = v;
        }
    }
}

/// `out[c] = a[:, c] · x` for the columns of `a` (Wᵀ or Z, n×m), each over its support `rows[c]`
/// (`KktWorkspace::z_rows`).
///
/// Up to 8 joints the columns are taken whole, with n a constant: the same sums (the rows past a support
/// add exact zeros) without the loop bookkeeping, which outweighs four multiplications.
pub fn columns_dot(a: &DMatrix<f64>, rows: &[usize], x: &[f64], out: &mut [f64]) {
    let n = a.nrows();
    let columns = a.as_slice().chunks_exact(n);
    by_size!(n, N => {
        for (o, col) in out.iter_mut().zip(columns) {
            *o = dot_fixed::<N>(col, x);
        }
    }, _ => {
        for ((o, col), rows) in out.iter_mut().zip(columns).zip(rows) {
            *o = dot(&col[..*rows], &x[..*rows]);
        }
    })
}

/// `x ← x - a r` for `a` as in [`columns_dot`] (whole columns up to 8 joints, likewise).
pub fn sub_columns_times(a: &DMatrix<f64>, rows: &[usize], r: &[f64], x: &mut [f64]) {
    let n = a.nrows();
    let columns = a.as_slice().chunks_exact(n);
    by_size!(n, N => {
        let x: &mut [f64; N] = (&mut x[..N]).try_into().expect("n entries");
        for (col, rc) in columns.zip(r) {
            for (x, c) in x.iter_mut().zip(col) {
                *x = mul_add(-rc, *c, *x);
            }
        }
    }, _ => {
        for ((col, rows), rc) in columns.zip(rows).zip(r) {
            sub_scaled(&mut x[..*rows], *rc, &col[..*rows]);
        }
    })
}

/// Solves `S x = r` in place on the independent rows of the pivoted factor; dependent rows get `x = 0`.
pub fn schur_solve<S: Space>(data: &mut Data<S>, r: &mut DVector<f64>) {
    let kkt = &mut data.kkt;
    let inv = kkt.schur_inv_diag.as_slice();
    dense::pivoted_solve(&kkt.schur_factor, inv, &kkt.schur_perm, kkt.schur_rank, r, &mut kkt.tmp_m2);
}

/// Solves eq 4 for `data.qdd` and `data.lambda` with the right-hand side
/// `τ = applied + joint_force - bias - gravity` and `-w_stab`. Needs [`factorize`] and `stabilize`.
/// With `y = U⁻¹ τ`: `λ = S⁺ (Zᵀ y + w_stab)` (= `S⁺ (W q̈_free + w_stab)`) and `q̈ = U⁻ᵀ (y - Z λ)`
/// (= `q̈_free - D⁻¹ Wᵀ λ`): one solve with U and one with Uᵀ.
pub fn solve<S: Space>(model: &Model<S>, data: &mut Data<S>) -> Result<(), DynamicsError> {
    by_size!(model.nv(), N => {
        let column = |v: &DVector<f64>| -> [f64; N] { v.as_slice()[..N].try_into().expect("n entries") };
        let (a, f, b, g) = (column(&data.applied), column(&data.joint_force), column(&data.bias), column(&data.gravity));
        let tau = std::array::from_fn(|i| a[i] + f[i] - b[i] - g[i]);
        let lambda = data.lambda.as_mut_slice();
        let qdd = kkt_small::solve::<N>(&data.kkt, tau, data.closure_bias_stab.as_slice(), lambda);
        data.qdd.as_mut_slice()[..N].copy_from_slice(&qdd);
    }, _ => solve_general(model, data));
    if data.qdd.as_slice().iter().any(|x| !x.is_finite()) {
        return Err(DynamicsError::NonFiniteResult { what: "joint accelerations" });
    }
    Ok(())
}

/// The accelerations a generalized force `τ` alone gives the linkage with its loops closed, `q̈ = P τ` with
/// `P = D⁻¹ − D⁻¹Wᵀ S⁺ W D⁻¹` (eq 4 with no velocity, gravity, joint-force or stabilization terms): what
/// adding `τ` to the applied forces adds to a [`solve`] at the same state, eq 4 being linear in them.
/// Needs [`factorize`]. `x` holds τ (n entries) on entry and q̈ on return; `scratch` has at least 2m entries.
pub fn constrained_response<S: Space>(model: &Model<S>, data: &Data<S>, x: &mut [f64], scratch: &mut [f64]) {
    let (n, m) = (model.nv(), model.nc());
    let (zeros, lambda) = scratch[..2 * m].split_at_mut(m);
    zeros.fill(0.0);
    by_size!(n, N => {
        let tau: [f64; N] = x[..N].try_into().expect("n entries");
        x[..N].copy_from_slice(&kkt_small::solve::<N>(&data.kkt, tau, zeros, lambda));
    }, _ => {
        let (factor, inv) = (&data.kkt.factor, data.kkt.factor_inv_diag.as_slice());
        ltl::solve_u_columns(model, factor, inv, x, n);
        if m > 0 {
            let kkt = &data.kkt;
            columns_dot(&kkt.z, &kkt.z_rows, x, lambda);
            dense::pivoted_solve_slices(kkt.schur_factor.as_slice(), m, kkt.schur_inv_diag.as_slice(), &kkt.schur_perm,
                kkt.schur_rank, lambda, zeros);
            sub_columns_times(&kkt.z, &kkt.z_rows, lambda, x);
        }
        ltl::solve_ut_columns(model, factor, inv, x);
    });
}

/// [`solve`] for any n (models of at most 8 joints take `kkt_small`, with the same results).
pub(crate) fn solve_general<S: Space>(model: &Model<S>, data: &mut Data<S>) {
    let n = model.nv();
    let tau = data.applied.as_slice().iter().zip(data.joint_force.as_slice()).zip(data.bias.as_slice());
    for ((x, ((a, f), b)), g) in data.qdd.as_mut_slice().iter_mut().zip(tau).zip(data.gravity.as_slice()) {
        *x = a + f - b - g;
    }
    let (factor, inv) = (&data.kkt.factor, data.kkt.factor_inv_diag.as_slice());
    ltl::solve_u_columns(model, factor, inv, data.qdd.as_mut_slice(), n);
    if model.nc() > 0 {
        let mut rhs = std::mem::replace(&mut data.lambda, DVector::zeros(0));
        let kkt = &data.kkt;
        columns_dot(&kkt.z, &kkt.z_rows, data.qdd.as_slice(), rhs.as_mut_slice());
        rhs += &data.closure_bias_stab;
        schur_solve(data, &mut rhs);
        sub_columns_times(&data.kkt.z, &data.kkt.z_rows, rhs.as_slice(), data.qdd.as_mut_slice());
        data.lambda = rhs;
    }
    let (factor, inv) = (&data.kkt.factor, data.kkt.factor_inv_diag.as_slice());
    ltl::solve_ut_columns(model, factor, inv, data.qdd.as_mut_slice());
}
