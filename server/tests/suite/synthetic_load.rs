//! The load the server's benchmarks and `--synthetic-users` put on the VE is a client's load: synthetic users
//! whose energy books the server accepts, and snapshots whose bytes grow with the users, not their square.

use kinloop_server::bench::TickBench;

/// A round's snapshot bytes at 2, 4, 8 and 16 users on the testbed are a fixed number per user: linear in
/// the users (with the others' rows, each snapshot carried N − 1 of them and a round grew as N²).
#[test]
fn snapshot_bytes_per_round_grow_linearly_with_users() {
    let per_user: Vec<(usize, f64)> = [2usize, 4, 8, 16]
        .into_iter()
        .map(|users| {
            let mut bench = TickBench::new(users, 50).expect("the testbed takes the users");
            (users, bench.tick_encoded() as f64 / users as f64)
        })
        .collect();
    let (_, first) = per_user[0];
    assert!(first > 100.0, "a snapshot carries its local model: {per_user:?}");
    for &(users, bytes) in &per_user {
        // Varint counters may take a byte more or less; a row of another user is 48 bytes on the testbed.
        assert!((bytes - first).abs() <= 4.0, "{users} users: {bytes} bytes a user against {first}: {per_user:?}");
    }
}

/// Synthetic users keep books as a client does: after a second of pushing, every user's books have grown
/// (its hand put energy into its local model) and the server refused none of their reports.
#[test]
fn synthetic_users_books_grow_and_the_server_accepts_them() {
    let mut bench = TickBench::new(4, 0).expect("the testbed takes the users");
    for _ in 0..1000 {
        bench.tick();
    }
    let metrics = bench.core().metrics();
    assert_eq!(metrics.energy_reports_refused, 0, "{metrics:?}");
    assert!(metrics.uplinks_accepted >= 4 * 990, "{metrics:?}");
    for (i, user) in bench.users().iter().enumerate() {
        let books = user.books();
        let total: f64 = books.received_j.iter().chain(&books.emitted_j).sum();
        assert!(total > 0.0, "user {i}'s books stayed empty: {books:?}");
    }
}
