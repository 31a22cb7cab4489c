//! Criterion benches of the linkage hot paths (development); `kinloop bench` reports the same cases.

use criterion::{criterion_group, criterion_main, Criterion};
use kinloop_linkage::algorithms::integrator::Integrator;
use kinloop_linkage::bench::{paper_wrench, Case};

fn benches(c: &mut Criterion) {
    for scene in ["paper-testbed", "chain20_loops1", "chain20_loops5", "chain50_loops1", "chain50_loops5"] {
        let mut case = Case::new(scene).expect("benchmark scene");
        c.bench_function(&format!("ve_step/{scene}"), |b| b.iter(|| case.ve_step(Integrator::SemiImplicitEuler)));
    }
    let mut case = Case::new("paper-testbed").unwrap();
    case.prepare_op_space();
    c.bench_function("op_space/testbed", |b| b.iter(|| case.op_space()));
    let mut lm = case.local_model();
    let f = paper_wrench();
    c.bench_function("local_model/testbed", |b| b.iter(|| lm.step(1e-3, &f)));
}

criterion_group!(linkage, benches);
criterion_main!(linkage);
