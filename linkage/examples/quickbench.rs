//! Prints the median time per call of every benchmark case (one run, so medians compare within it).
//! `quickbench scaling` times `ve_step/chainN_loopsL` for N ∈ {20, 50, 100} and L ∈ {1, 5, 10} instead.

use kinloop_linkage::algorithms::constraint_directions::{constraint_directions, DEFAULT_THRESHOLD};
use kinloop_linkage::algorithms::op_space::op_space_inertia;
use kinloop_linkage::bench::*;
use kinloop_linkage::{algorithms::integrator::Integrator, math::space::Planar};
use std::hint::black_box;
use std::time::Duration;

fn main() {
    let budget = Duration::from_millis(400);
    if std::env::args().nth(1).as_deref() == Some("scaling") {
        println!("ve_step/chainN_loopsL median, µs");
        println!("{:>6} {:>8} {:>8} {:>8}", "N \\ L", 1, 5, 10);
        for n in [20, 50, 100] {
            let row: Vec<String> = [1, 5, 10]
                .iter()
                .map(|l| {
                    let mut case = Case::new(&format!("chain{n}_loops{l}")).unwrap();
                    let t = measure(budget, || case.ve_step(Integrator::SemiImplicitEuler));
                    format!("{:>8.2}", t.median_ns / 1000.0)
                })
                .collect();
            println!("{n:>6} {}", row.join(" "));
        }
        return;
    }
    for scene in ["paper-testbed", "chain20_loops1", "chain20_loops5", "chain50_loops1", "chain50_loops5"] {
        let mut case = Case::new(scene).unwrap();
        let t = measure(budget, || case.ve_step(Integrator::SemiImplicitEuler));
        println!("ve_step/{scene}: {:.0} ns (p10 {:.0} p90 {:.0})", t.median_ns, t.p10_ns, t.p90_ns);
    }
    let mut case = Case::new("paper-testbed").unwrap();
    let t = measure(budget, || case.ve_step(Integrator::Rk4));
    println!("ve_step_rk4/testbed: {:.0} ns", t.median_ns);
    case.prepare_op_space();
    let t = measure(budget, || {
        case.op_space();
    });
    println!("op_space/testbed: {:.0} ns", t.median_ns);
    // Its two halves: Λ⁻¹ alone, and the SVD (Jacobi) with the count alone.
    let t = measure(budget, || {
        let _ = op_space_inertia(&case.model, &mut case.data, 0);
    });
    println!("  Λ⁻¹ only: {:.0} ns", t.median_ns);
    let (inverse_inertia, length_scale) = (case.data.op.inverse_inertia, case.model.length_scale);
    let t = measure(budget, || {
        black_box(constraint_directions::<Planar>(black_box(&inverse_inertia), length_scale, DEFAULT_THRESHOLD));
    });
    println!("  SVD + count only: {:.0} ns", t.median_ns);
    let mut lm = case.local_model();
    let f = paper_wrench();
    let t = measure(budget, || {
        lm.step(1e-3, &f);
    });
    println!("local_model/testbed: {:.1} ns", t.median_ns);
}
