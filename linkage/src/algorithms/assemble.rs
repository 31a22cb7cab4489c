//! Assembly: the closed configuration nearest a given q, by Gauss-Newton steps `Δq = -W⁺ h` (minimum-norm
//! corrections through the SVD pseudo-inverse, so redundant closures are fine). Used by
//! `kinloop inspect --assemble` and for scenes whose q0 does not quite close; not a hot path.

use nalgebra::DVector;
use thiserror::Error;

use crate::algorithms::kinematics::{forward_kinematics, forward_velocity};
use crate::algorithms::loop_closure::loop_closure;
use crate::math::space::Space;
use crate::model::data::Data;
use crate::model::Model;

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

/// Newton steps from `q_start` until `‖h‖ ≤ tolerance` (default use: `1e-12 · length_scale`).
pub fn assemble<S: Space>(model: &Model<S>, q_start: &DVector<f64>, tolerance: f64) -> Result<Assembly, AssembleError> {
    if q_start.len() != model.nq() || q_start.iter().any(|x| !x.is_finite()) {
        return Err(AssembleError::BadStart(format!("expected {} finite numbers", model.nq())));
    }
    let mut data = Data::new(model);
    let mut q = q_start.clone();
    let zero = DVector::zeros(model.nq());
    let eval = |data: &mut Data<S>, q: &DVector<f64>| {
        forward_kinematics(model, data, q);
        forward_velocity(model, data, &zero);
        loop_closure(model, data);
        data.closure_residual.norm()
    };
    let initial_residual = eval(&mut data, &q);
    let mut residual = initial_residual;
    for iterations in 0..100 {
        if residual <= tolerance || !model.has_loops() {
            return Ok(Assembly { q, initial_residual, residual, iterations });
        }
        let w = data.closure_jacobian();
        let svd = w.svd(true, true);
        let step = svd
            .solve(&data.closure_residual, 1e-12 * svd.singular_values.max())
            .map_err(|e| AssembleError::BadStart(e.to_string()))?;
        // Halve the step until the residual decreases (robust far from the manifold).
        let mut scale = 1.0;
        loop {
            let trial = &q - &step * scale;
            let r = eval(&mut data, &trial);
            if r < residual || scale < 1e-6 {
                q = trial;
                residual = r;
                break;
            }
            scale *= 0.5;
        }
        if scale < 1e-6 {
            return Err(AssembleError::NotConverged { residual, iterations });
        }
    }
    if residual <= tolerance {
        Ok(Assembly { q, initial_residual, residual, iterations: 100 })
    } else {
        Err(AssembleError::NotConverged { residual, iterations: 100 })
    }
}
