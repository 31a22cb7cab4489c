//! `cargo bench -p kinloop-server`: one VE tick with N users on the paper's testbed.

use criterion::{criterion_group, criterion_main, Criterion};

fn ve_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("server");
    for users in [1usize, 4, 16, 64] {
        group.bench_function(format!("ve_tick_users_{users}"), |b| {
            b.iter_custom(|iters| {
                let ns = kinloop_server::bench::ve_tick_users(users, iters).expect("bench runs");
                std::time::Duration::from_nanos((ns * iters as f64) as u64)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, ve_tick);
criterion_main!(benches);
