//! Drain on SIGTERM, with real processes: server A is the `kinloop-server` program (a child process) holding
//! the paper's four-bar for a client whose hand holds it still, with server B (the same room key and CA) as
//! the client's fallback. A is sent SIGTERM: it stops admitting, hands the client the room's newest signed
//! state and tells it to move, and exits 0 once the client has gone; the client moves to B, which resumes
//! the linkage where it was, without a force step, and the client's recording marks the time between the
//! two servers as session 0. See docs/resume.md.

use crate::common;

use std::time::{Duration, Instant};

use common::child::{listening, ChildProcess, Program, Role};
use common::live;
use common::records;
use common::resume::{self, Moved, MAX_FORCE_STEP_N};
use kinloop_server::driver::load_scene;
use kinloop_server::ServerConfig;

#[test]
fn a_terminated_server_drains_its_client_to_another_and_exits_zero() {
    const NAME: &str = "a_terminated_server_drains_its_client_to_another_and_exits_zero";
    let stage = resume::Stage::set(NAME);
    let dir = &stage.dir;
    let path = |name: &str| stage.path(name);
    let file = |name: &str| path(name).display().to_string();
    let args = [
        "--scene",
        "paper-testbed",
        "--listen",
        "127.0.0.1:0",
        "--cert",
        &file("a.pem"),
        "--key",
        &file("a.key"),
        "--room-key",
        &file("room.key"),
        "--record",
        &file("a.csv"),
        "--stats-every",
        "0",
        "--drain-s",
        "3",
    ]
    .map(String::from)
    .to_vec();
    let mut server_a =
        ChildProcess::spawn(NAME, &Role::Program { program: Program::Server, args }, dir.path(), "server-a");
    let a_addr = server_a.wait_for_stdout("server A listening", Duration::from_secs(15), listening).0;

    // B runs the same scene as A (the room's state names its scene), in this process.
    let rt = live::runtime();
    let (scene, label) = load_scene("paper-testbed").expect("built-in scene");
    let mut config = ServerConfig::new(scene, label, live::LOOPBACK);
    config.realtime = false;
    let server_b = live::start_server(&rt, resume::room_server(config, dir.path(), "b"));

    let client = resume::start_holder(dir.path(), a_addr, server_b.local_addr());
    let client_started = Instant::now();
    let a_user = client.welcome().user_id;
    std::thread::sleep(Duration::from_millis(2500));

    server_a.terminate();
    let termed = Instant::now();
    let t_term = termed.duration_since(client_started).as_secs_f64();
    common::wait_until("the client moves to server B", Duration::from_secs(10), || client.stats().reconnects == 1);
    let back_s = termed.elapsed().as_secs_f64();
    let status = server_a.exit_status(Duration::from_secs(10));
    let exited_s = termed.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(1500));
    let stats = client.shutdown();
    let b_stats = live::stop_server(&rt, server_b);

    let moved = Moved::measure(&path("a.csv"), &path("b.csv"), &path("client.csv"), a_user, t_term);
    let ticks = records::client_ticks(&path("client.csv"));
    let gap: Vec<_> = ticks.iter().filter(|t| t.session == 0).collect();
    let (gap_from, gap_to) = (gap.first().expect("a marked gap").t, gap.last().expect("a marked gap").t);
    println!(
        "drain: {moved}; client on B {back_s:.2} s after SIGTERM; A exited {exited_s:.2} s after it with {status}; \
         the client's record marks {:.3} s between servers ({} ticks)",
        gap_to - gap_from,
        gap.len()
    );
    assert!(status.success(), "A exits 0 after draining: {status}\n{}", server_a.log_tail());
    assert!(server_a.log().contains("SIGTERM: draining"), "{}", server_a.log_tail());
    moved.assert_goals(back_s);
    assert!(moved.fade_out_n <= MAX_FORCE_STEP_N, "force step {} N on leaving A", moved.fade_out_n);
    assert_eq!(stats.resumes, 1, "B resumed from the state A handed over");
    assert_eq!(b_stats.ve.core.resumes_accepted, 1);

    // The record: session 1 on A, a contiguous run of 0 from SIGTERM on, then session 2 on B to the end; the
    // old session's force has faded out by the end of the gap, and B's starts from zero.
    let first_gap = ticks.iter().position(|t| t.session == 0).expect("a gap");
    let last_gap = ticks.iter().rposition(|t| t.session == 0).expect("a gap");
    assert!(ticks[..first_gap].iter().all(|t| t.session == 1), "session 1 before the gap");
    assert!(ticks[first_gap..=last_gap].iter().all(|t| t.session == 0), "one gap");
    assert!(ticks[last_gap + 1..].iter().all(|t| t.session == 2), "session 2 after the gap");
    assert!(ticks.len() > last_gap + 1000, "the client rendered B's linkage after the gap");
    assert!(
        gap_from >= t_term - 0.01 && gap_from <= t_term + 0.5,
        "the gap starts at the drain: {gap_from} vs {t_term}"
    );
    assert!(ticks[last_gap].gain == 0.0, "A's session faded out within the gap");
    assert!(ticks[last_gap + 1].gain < 0.01, "B's session ramps in from zero force");
}
