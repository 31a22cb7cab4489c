//! Assembly: the closed configuration nearest a given q, by Gauss-Newton steps `Δq = -W⁺ h` (minimum-norm
//! corrections through the SVD pseudo-inverse, so redundant closures are fine). Used by
//! `kinloop inspect --assemble` and for scenes whose q0 does not quite close; not a hot path.
//!
//! **In the scene's scales.** h mixes lengths (coincident points, points on planes) with unit-free rows
//! (perpendicular axes, equal angles), and q mixes angles with prismatic lengths. Both are read in the
//! scene's length scale L (`Model::length_scale`): length rows and prismatic coordinates divided by L, so the
//! step, its line search and the stopping test are the same whatever unit of length the scene is written in
//! (a residual in millimetres would otherwise outweigh the rotation rows a thousand times over).

use nalgebra::{DMatrix, DVector};
use thiserror::Error;

use crate::algorithms::configuration;
use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
use crate::algorithms::loop_closure::loop_closure;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::{ClosurePrimitive, JointKind, Model};

/// Result of an assembly.
#[derive(Clone, Debug, PartialEq)]
pub struct Assembly {
    /// The closed configuration.
    pub q: DVector<f64>,
    /// ‖h‖ at the start.
    pub initial_residual: f64,
    /// ‖h‖ at the end.
    pub residual: f64,
    /// Newton iterations taken.
    pub iterations: usize,
}

/// Why assembly failed.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum AssembleError {
    /// The residual stopped decreasing (the loop cannot close near this q).
    #[error("assembly did not converge: residual {residual:.3e} after {iterations} iterations (the loops may not close near this configuration)")]
    NotConverged {
        /// Residual reached.
        residual: f64,
        /// Iterations taken.
        iterations: usize,
    },
    /// q has the wrong length or is not finite.
    #[error("invalid starting configuration: {0}")]
    BadStart(String),
}

/// Newton steps from `q_start` until the residual, its length rows read in length scales, is at most
/// `tolerance / length_scale` (default use: `tolerance = 1e-12 · length_scale`). The residuals reported are
/// `‖h‖` in the scene's units.
pub fn assemble<S: Space>(model: &Model<S>, q_start: &DVector<f64>, tolerance: f64) -> Result<Assembly, AssembleError> {
    configuration::check(model, q_start.as_slice()).map_err(AssembleError::BadStart)?;
    let scales = ClosureScales::of(model);
    let mut data = Data::new(model);
    let mut q = q_start.clone();
    let zero = DVector::zeros(model.nv());
    // (‖h‖ read in length scales, ‖h‖ in the scene's units)
    let eval = |data: &mut Data<S>, q: &DVector<f64>| {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, &zero);
        loop_closure(model, data);
        (scales.residual(&data.closure_residual), data.closure_residual.norm())
    };
    let tolerance = tolerance / scales.length;
    let (mut scaled, initial_residual) = eval(&mut data, &q);
    let mut residual = initial_residual;
    for iterations in 0..100 {
        if scaled <= tolerance || !model.has_loops() {
            return Ok(Assembly { q, initial_residual, residual, iterations });
        }
        let step = scales
            .newton_step(&data.closure_jacobian(), &data.closure_residual)
            .map_err(|e| AssembleError::BadStart(e.to_string()))?;
        // Halve the step until the residual decreases (robust far from the manifold).
        let mut scale = 1.0;
        loop {
            let mut trial = q.clone();
            configuration::integrate(model, &mut trial, &step, -scale);
            let (r, plain) = eval(&mut data, &trial);
            if r < scaled || scale < 1e-6 {
                q = trial;
                (scaled, residual) = (r, plain);
                break;
            }
            scale *= 0.5;
        }
        if scale < 1e-6 {
            return Err(AssembleError::NotConverged { residual, iterations });
        }
    }
    if scaled <= tolerance {
        Ok(Assembly { q, initial_residual, residual, iterations: 100 })
    } else {
        Err(AssembleError::NotConverged { residual, iterations: 100 })
    }
}

/// How closure rows and coordinates are read in the scene's length scale L: a length row (coincident points,
/// a point on a plane) divided by L, a unit-free one (perpendicular directions, equal angles) as it is; a
/// prismatic coordinate divided by L, a revolute one as it is. Serves every Gauss-Newton projection onto the
/// loops (assembly, the reach survey), so that each takes the same steps in any unit of length.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosureScales {
    /// The length scale L (1 when the model's is not a positive number).
    pub length: f64,
    /// Per closure row: `1 / L` or 1.
    rows: DVector<f64>,
    /// Per coordinate: `L` for a prismatic one (a step in length scales is L times longer in the scene's
    /// units), 1 for a revolute one.
    columns: DVector<f64>,
}

impl ClosureScales {
    /// The scales of `model`.
    pub fn of<S: Space>(model: &Model<S>) -> Self {
        let length = if model.length_scale > 0.0 && model.length_scale.is_finite() { model.length_scale } else { 1.0 };
        let mut rows = DVector::from_element(model.closure_rows, 1.0);
        for cut in &model.cuts {
            let mut row = cut.row;
            for prim in &cut.primitives {
                let is_length = matches!(prim, ClosurePrimitive::Coincident { .. } | ClosurePrimitive::OnPlane { .. });
                for r in row..(row + prim.rows()).min(model.closure_rows) {
                    rows[r] = if is_length { 1.0 / length } else { 1.0 };
                }
                row += prim.rows();
            }
        }
        let columns = DVector::from_iterator(
            model.nv(),
            model.joints.iter().map(|j| if j.kind == JointKind::Prismatic { length } else { 1.0 }),
        );
        ClosureScales { length, rows, columns }
    }

    /// `‖h‖` with its length rows in length scales.
    pub fn residual(&self, h: &DVector<f64>) -> f64 {
        h.iter().zip(self.rows.iter()).map(|(x, r)| (x * r) * (x * r)).sum::<f64>().sqrt()
    }

    /// `W` read in length scales: rows times the row scales, columns times the coordinate scales.
    pub fn jacobian(&self, w: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(w.nrows(), w.ncols(), |r, c| w[(r, c)] * self.rows[r] * self.columns[c])
    }

    /// The minimum-norm Gauss-Newton correction `Δq` (to subtract from q) that zeroes `h` to first order, the
    /// norm taken in length scales: `columns ⊙ W̃⁺ (rows ⊙ h)`.
    pub fn newton_step(&self, w: &DMatrix<f64>, h: &DVector<f64>) -> Result<DVector<f64>, &'static str> {
        let scaled = self.jacobian(w);
        // The SVD panics on a NaN; a non-finite Jacobian (a configuration blown up) has no step.
        if scaled.iter().any(|x| !x.is_finite()) {
            return Err("the closure Jacobian is not finite");
        }
        let svd = scaled.svd(true, true);
        let step = svd.solve(&h.component_mul(&self.rows), 1e-12 * svd.singular_values.max())?;
        Ok(step.component_mul(&self.columns))
    }
}
