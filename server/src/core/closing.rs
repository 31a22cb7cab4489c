//! Closing the loops (eq 2: h(q) = 0) of a configuration the VE is about to start from: a state a
//! reconnecting client offers (`resume`) and the restore point a failed step falls back to (`tick`).

use kinloop_linkage::algorithms::assemble::assemble;
use kinloop_linkage::algorithms::kinematics::forward_kinematics;
use kinloop_linkage::algorithms::loop_closure::closure_residual;
use kinloop_linkage::math::space::Space;
use kinloop_linkage::model::data::Data;
use kinloop_linkage::model::Model;
use nalgebra::DVector;

use super::BROKEN_CLOSURE_PER_LENGTH;

/// Residual, in length scales, to which a configuration is re-assembled (as `Model::compile` closes q0).
const ASSEMBLY_PER_LENGTH: f64 = 1e-12;

/// A configuration with its loops closed.
pub(super) struct Closed {
    /// The configuration, assembled onto the loops.
    pub q: DVector<f64>,
    /// `|h(q)|` there, in the scene's units.
    pub residual: f64,
}

/// `q` re-assembled onto the loops (Newton on h(q)), or the residual `|h(q)|` it starts from when that is
/// above what a step may start from (`BROKEN_CLOSURE_PER_LENGTH` of the length scale) or the assembly does
/// not converge. Leaves the body poses in `data` at `q`. Allocates the assembly's own workspace: for rare
/// events (a resume, a restore), never the step.
pub(super) fn close_loops<S: Space>(model: &Model<S>, data: &mut Data<S>, q: &DVector<f64>) -> Result<Closed, f64> {
    if !model.has_loops() {
        return Ok(Closed { q: q.clone(), residual: 0.0 });
    }
    forward_kinematics(model, data, q);
    closure_residual(model, data);
    let residual = data.closure_residual.norm();
    // A residual that is not a number is no closure either.
    let within = residual.partial_cmp(&(BROKEN_CLOSURE_PER_LENGTH * model.length_scale));
    if !matches!(within, Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)) {
        return Err(residual);
    }
    match assemble(model, q, ASSEMBLY_PER_LENGTH * model.length_scale) {
        Ok(assembly) => Ok(Closed { q: assembly.q, residual: assembly.residual }),
        Err(_) => Err(residual),
    }
}

#[cfg(test)]
mod tests {
    use kinloop_linkage::math::space::Planar;
    use kinloop_linkage::model::builtin;

    use super::*;

    fn testbed() -> Model<Planar> {
        let scene = builtin::scene("paper-testbed").expect("built in").expect("parses");
        Model::<Planar>::compile(&scene, "paper-testbed").expect("compiles")
    }

    /// The residual at q, evaluated afresh (not the one `close_loops` reports).
    fn residual(model: &Model<Planar>, q: &DVector<f64>) -> f64 {
        let mut data = Data::new(model);
        forward_kinematics(model, &mut data, q);
        closure_residual(model, &mut data);
        data.closure_residual.norm()
    }

    /// A configuration open by a fraction of a percent of the length scale (as a restore point may be after
    /// violent motion) is assembled onto the loops near where it was; one open beyond what a step may start
    /// from is refused with its residual.
    #[test]
    fn slightly_open_loops_are_closed_and_torn_ones_refused() {
        let model = testbed();
        let mut data = Data::new(&model);
        let l = model.length_scale;
        let mut q = model.q0.clone();
        q[0] += 0.002;
        let open = residual(&model, &q);
        assert!(open > 1e-4 * l && open < BROKEN_CLOSURE_PER_LENGTH * l, "open by {open:.3e} of {l} m");
        let closed = close_loops(&model, &mut data, &q).expect("closes");
        let after = residual(&model, &closed.q);
        assert!(after <= 1e-10 * l, "closed to {after:.3e} m");
        assert!((closed.residual - after).abs() <= 1e-12 * l);
        assert!((&closed.q - &q).amax() < 0.01, "moved {:.3e} rad", (&closed.q - &q).amax());
        let mut torn = model.q0.clone();
        torn[0] += 0.5;
        let r = residual(&model, &torn);
        assert!(r > BROKEN_CLOSURE_PER_LENGTH * l);
        assert!(matches!(close_loops(&model, &mut data, &torn), Err(e) if (e - r).abs() <= 1e-12 * l));
    }
}
