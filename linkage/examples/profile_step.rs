//! Runs one benchmark case in a loop for profilers:
//! `profile_step [SCENE] [CALLS] [step|rk4|op_space]` (defaults: paper-testbed, 200000, step).
//! Build it with line tables (`cargo build --profile profiling -p kinloop-linkage --example profile_step`);
//! `perf record -g` shows where the time goes; for instruction counts, which do not suffer from a noisy
//! machine, run under `valgrind --tool=callgrind --collect-atstart=no --toggle-collect='*run_calls*'`.

use kinloop_linkage::algorithms::integrator::Integrator;
use kinloop_linkage::bench::*;

#[inline(never)]
fn run_calls(case: &mut Case, calls: usize, what: &str) {
    for _ in 0..calls {
        match what {
            "rk4" => case.ve_step(Integrator::Rk4),
            "op_space" => {
                std::hint::black_box(case.op_space());
            }
            _ => case.ve_step(Integrator::SemiImplicitEuler),
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let scene = args.next().unwrap_or("paper-testbed".into());
    let calls = args.next().map_or(200_000, |s| s.parse().expect("CALLS is a count"));
    let what = args.next().unwrap_or("step".into());
    let mut case = Case::new(&scene).expect("a benchmark scene");
    if what == "op_space" {
        case.prepare_op_space();
    }
    run_calls(&mut case, calls, &what);
}
