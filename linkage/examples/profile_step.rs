use kinloop_linkage::bench::*;
use kinloop_linkage::Integrator;
fn main() {
    let scene = std::env::args().nth(1).unwrap_or("paper-testbed".into());
    let mut case = Case::new(&scene).unwrap();
    for _ in 0..200_000 {
        case.ve_step(Integrator::SemiImplicitEuler);
    }
}
