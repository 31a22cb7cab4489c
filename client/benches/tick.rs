//! `client/tick_testbed`: one haptic tick of the core on the paper's testbed (goal ≤ 0.5 µs).

use criterion::{criterion_group, criterion_main, Criterion};

fn tick(c: &mut Criterion) {
    c.bench_function("client/tick_testbed", |b| {
        b.iter_custom(|iters| {
            let ns = kinloop_client::bench::client_tick_testbed(iters).expect("testbed builds");
            std::time::Duration::from_nanos((ns * iters as f64) as u64)
        })
    });
}

criterion_group!(benches, tick);
criterion_main!(benches);
