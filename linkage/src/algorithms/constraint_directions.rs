//! Constraint directions and the number of constraints the linkage imposes on an operational point, from
//! the singular value decomposition of Λ⁻¹ (eq 10, 12).
//!
//! **Unit consistency.** Λ⁻¹ mixes units (m/(N s²) against rad/(N m s²)), so its singular values cannot be
//! compared as they are: written in millimetres, the rotational block shrinks by 10⁶ relative to the
//! translational one. We decompose the *scaled* matrix `Λ̃⁻¹ = T Λ⁻¹ T` with `T = diag(1, …, L, …)`
//! (1 on linear axes, L on angular axes), L the scene's characteristic length (`Model::length_scale`, by
//! default the links' mass-weighted radius of gyration). In scaled coordinates a twist is `(v, L ω)` and a
//! wrench `(f, τ / L)`, both in one unit; changing the unit of length multiplies the whole of `Λ̃⁻¹` by one
//! factor, so relative singular values, directions and the count are unchanged.
//!
//! **Count rule.** A direction is constrained when its singular value is at most
//! `threshold · σ_max` ([`DEFAULT_THRESHOLD`] = 0.02: the OP is at least 50 times harder to accelerate
//! along it than along its easiest direction), or when σ_max itself vanishes (an immobile OP).
//!
//! **Immobile OPs.** "Vanishes" is exact: `op_space` hands over Λ⁻¹ = 0 for an OP the loops pin, deciding
//! it against the OP's open-loop Λ⁻¹ (`op_space::IMMOBILE_TOLERANCE`, a fraction of the scaled traces, so
//! unit-invariant like the count). The round-off such an OP's Λ⁻¹ otherwise keeps (~1e-31 of the open
//! value at a slider-crank's dead centre) has no scale of its own to be told apart by here.

use crate::math::eigen::symmetric_eigen_from;
use crate::math::space::{Space, VecOps};

/// Default relative threshold on singular values below which a direction counts as constrained.
pub const DEFAULT_THRESHOLD: f64 = 0.02;

/// Singular values, directions and constraint count at one OP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstraintDirections<S: Space> {
    /// Singular values of the scaled `Λ̃⁻¹`, decreasing (units 1/kg).
    pub singular_values: S::OpVec,
    /// Unit singular directions as columns, in scaled coordinates `(v, L ω)`; the last `count` columns are
    /// the constrained directions.
    pub directions: S::OpMat,
    /// Number of constrained directions.
    pub count: usize,
    /// The length scale L used.
    pub length_scale: f64,
}

impl<S: Space> ConstraintDirections<S> {
    /// Scales an operational vector to the unit-consistent coordinates: `(v, L ω)`.
    pub fn to_scaled(&self, x: &S::OpVec) -> S::OpVec {
        scale_op::<S>(x, self.length_scale)
    }
    /// Back from scaled coordinates for a twist-like vector: `(v, ω̃ / L)`.
    pub fn twist_from_scaled(&self, x: &S::OpVec) -> S::OpVec {
        scale_op::<S>(x, 1.0 / self.length_scale)
    }
    /// Back from scaled coordinates for a wrench-like vector: `(f, L τ̃)`.
    pub fn wrench_from_scaled(&self, x: &S::OpVec) -> S::OpVec {
        scale_op::<S>(x, self.length_scale)
    }
    /// Column `i` of the directions.
    pub fn direction(&self, i: usize) -> S::OpVec {
        let mut v = S::OpVec::zero();
        for r in 0..S::DIM {
            v[r] = self.directions[(r, i)];
        }
        v
    }
}

/// Multiplies the angular part of an operational vector by `factor`.
pub fn scale_op<S: Space>(x: &S::OpVec, factor: f64) -> S::OpVec {
    let lin = <S::Point as VecOps>::LEN;
    let mut out = *x;
    for i in lin..S::DIM {
        out[i] *= factor;
    }
    out
}

/// SVD of the unit-consistent `Λ̃⁻¹ = T Λ⁻¹ T` and the number of constrained directions (see the module
/// documentation for the rule).
pub fn constraint_directions<S: Space>(
    inverse_inertia: &S::OpMat,
    length_scale: f64,
    threshold: f64,
) -> ConstraintDirections<S> {
    constraint_directions_from(inverse_inertia, length_scale, threshold, None)
}

/// As [`constraint_directions`], continuing from the `previous` directions at a nearby state (a VE
/// server's last snapshot for this OP): see [`symmetric_eigen_from`] for what the warm start buys and costs.
pub fn constraint_directions_from<S: Space>(
    inverse_inertia: &S::OpMat,
    length_scale: f64,
    threshold: f64,
    previous: Option<&S::OpMat>,
) -> ConstraintDirections<S> {
    let lin = <S::Point as VecOps>::LEN;
    let mut scaled = *inverse_inertia;
    for c in 0..S::DIM {
        for r in 0..S::DIM {
            let f = (if r >= lin { length_scale } else { 1.0 }) * (if c >= lin { length_scale } else { 1.0 });
            scaled[(r, c)] *= f;
        }
    }
    let (values, vectors) = symmetric_eigen_from::<S>(&scaled, previous);
    let sigma_max = values[0];
    let count = if sigma_max.is_nan() || sigma_max <= 0.0 {
        S::DIM
    } else {
        (0..S::DIM).filter(|&i| values[i] <= threshold * sigma_max).count()
    };
    // Eigenvalues of a PSD matrix: clamp round-off negatives to zero so they read as singular values.
    let mut singular_values = values;
    for x in singular_values.as_mut_slice() {
        *x = x.max(0.0);
    }
    ConstraintDirections { singular_values, directions: vectors, count, length_scale }
}
