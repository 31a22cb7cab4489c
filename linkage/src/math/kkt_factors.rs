//! The storage of the KKT solve's factors (eq 4): D's factor U, `Z = U⁻¹ Wᵀ`, the Schur complement
//! `S = Zᵀ Z` and its pivoted Cholesky factor. Plain matrices, written by `kkt` and `kkt_small`, read by
//! `op_space` and `integrator`.

use nalgebra::{DMatrix, DVector};

/// Factors and intermediate products of the KKT solve (eq 4) and of Λ⁻¹ (eq 9).
#[derive(Clone, Debug)]
pub struct KktWorkspace {
    /// U with D = U Uᵀ, U upper triangular with the tree's sparsity (Featherstone's LTL in transposed
    /// storage), n×n. Only the upper triangle is written.
    pub factor: DMatrix<f64>,
    /// Reciprocals of U's diagonal (for the triangular solves), n.
    pub factor_inv_diag: DVector<f64>,
    /// Z = U⁻¹ Wᵀ, n×m.
    pub z: DMatrix<f64>,
    /// Support of each column c of Wᵀ and Z: rows `z_rows[c]..n` of the column are zero.
    /// The fixed-size kernels (`kkt_small`, n ≤ 8) never narrow it: they leave the
    /// initial `n` (full support), which is always a valid, merely less sparse, bound.
    pub z_rows: Vec<usize>,
    /// The Schur complement S = W D⁻¹ Wᵀ = Zᵀ Z, m×m.
    pub schur: DMatrix<f64>,
    /// Pivoted Cholesky factor of S (lower, in pivoted order), m×m.
    pub schur_factor: DMatrix<f64>,
    /// Reciprocals of the diagonal of `schur_factor` (the first `schur_rank` entries are valid), m.
    pub schur_inv_diag: DVector<f64>,
    /// Pivot order: `schur_perm[k]` is the closure row eliminated at step k.
    pub schur_perm: Vec<usize>,
    /// Numerical rank of S: rows `schur_perm[rank..]` are dependent and get λ = 0.
    pub schur_rank: usize,
    /// Scratch of length n.
    pub tmp_n: DVector<f64>,
    /// Scratch of length m.
    pub tmp_m: DVector<f64>,
    /// Scratch of length m.
    pub tmp_m2: DVector<f64>,
    /// Scratch of length m.
    pub tmp_m3: DVector<f64>,
    /// Scratch of length m.
    pub tmp_m4: DVector<f64>,
    /// Scratch of n×2 (two right-hand sides solved together).
    pub tmp_n2: DMatrix<f64>,
}

impl KktWorkspace {
    /// Zeroed storage for n joints and m closure rows.
    pub fn new(n: usize, m: usize) -> Self {
        KktWorkspace {
            factor: DMatrix::zeros(n, n),
            factor_inv_diag: DVector::zeros(n),
            z: DMatrix::zeros(n, m),
            z_rows: vec![n; m],
            schur: DMatrix::zeros(m, m),
            schur_factor: DMatrix::zeros(m, m),
            schur_inv_diag: DVector::zeros(m),
            schur_perm: (0..m).collect(),
            schur_rank: 0,
            tmp_n: DVector::zeros(n),
            tmp_m: DVector::zeros(m),
            tmp_m2: DVector::zeros(m),
            tmp_m3: DVector::zeros(m),
            tmp_m4: DVector::zeros(m),
            tmp_n2: DMatrix::zeros(n, 2),
        }
    }
}
