//! Runs `server/ve_tick_users_N` in a loop for profilers: `profile_tick [USERS] [TICKS]` (defaults 1, 20000).
//! For instruction counts, which a noisy machine does not disturb:
//! `valgrind --tool=callgrind profile_tick 1 20000`, then `callgrind_annotate --inclusive=yes` and read the
//! entries under `TickBench::tick` (the tick; divide by 1.1 × TICKS, the warm-up included).

fn main() {
    let mut args = std::env::args().skip(1);
    let users = args.next().map_or(1, |s| s.parse().expect("USERS is a count"));
    let ticks = args.next().map_or(20_000, |s| s.parse().expect("TICKS is a count"));
    let ns = kinloop_server::bench::ve_tick_users(users, ticks).expect("the testbed loads");
    println!("{users} users: {ns:.0} ns per tick");
}
