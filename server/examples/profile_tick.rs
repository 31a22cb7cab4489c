//! Runs `server/ve_tick_users_N` in a loop for profilers: `profile_tick [USERS] [TICKS]` (defaults 1, 20000).
//! For instruction counts, which a noisy machine does not disturb:
//! `valgrind --tool=callgrind profile_tick 1 20000`, then `callgrind_annotate --inclusive=yes` and read the
//! entries under `ve_tick_users::{{closure}}` (the tick). Toggling collection on `*ve_tick_users*` does not
//! work: the tick closure matches the pattern too and toggles collection off again.

fn main() {
    let mut args = std::env::args().skip(1);
    let users = args.next().map_or(1, |s| s.parse().expect("USERS is a count"));
    let ticks = args.next().map_or(20_000, |s| s.parse().expect("TICKS is a count"));
    let ns = kinloop_server::bench::ve_tick_users(users, ticks).expect("the testbed loads");
    println!("{users} users: {ns:.0} ns per tick");
}
