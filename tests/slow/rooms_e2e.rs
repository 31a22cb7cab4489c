//! Rooms in the programs themselves: `kinloop-server --rooms` with one real-time thread and two rooms, one
//! made to take 2 ms a tick (`debug_cost_ms`, a test knob), and two `kinloop-client`s in the other. The slow
//! room overruns the thread's share, so the executor moves it off the real-time thread: the calm room's
//! users do not miss (its per-room `--json` deadline misses stay under a tenth of its ticks, where sharing
//! the thread with a 2 ms tick at 1 kHz would miss nearly every one), the calm room never restores, a client
//! asking the slow room is refused with a reason it prints, and one asking for a room that does not exist
//! learns which rooms do. And `kinloop load` in a process of its own drives two rooms of two users each
//! from one shared clock thread: every user renders, and one asking for a room that does not exist is
//! reported while the others carry on. Sixteen rooms of two users from one load process lose few uplinks.

use crate::common;

use std::time::Duration;

use common::child::{json_object, listening, ChildProcess, Program, Role};

const NAME: &str = "a_two_millisecond_room_does_not_make_the_other_rooms_users_miss";

const ROOMS: &str = "
[[room]]
name = \"calm\"
scene = \"fourbar-crank-rocker\"

[[room]]
name = \"slow\"
scene = \"paper-testbed\"
debug_cost_ms = 2.0
";

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| (*a).to_owned()).collect()
}

/// `kinloop-server --rooms` with `rooms` (the file's text) and one real-time thread, in `dir`; the server,
/// its address and its certificate's fingerprint.
fn serve_rooms(test: &str, rooms: &str, dir: &std::path::Path) -> (ChildProcess, std::net::SocketAddr, String) {
    std::fs::write(dir.join("rooms.toml"), rooms).unwrap();
    let args = strings(&["--rooms", "rooms.toml", "--rt-threads", "1", "--listen", "127.0.0.1:0", "--json"]);
    let mut server = ChildProcess::spawn(test, &Role::Program { program: Program::Server, args }, dir, "server");
    let (addr, fingerprint) =
        server.wait_for_stdout("the server prints its address", Duration::from_secs(30), listening);
    (server, addr, fingerprint)
}

#[test]
fn a_two_millisecond_room_does_not_make_the_other_rooms_users_miss() {
    common::child::serve_if_child();
    let _bounded = common::bounded(NAME, Duration::from_secs(120));
    let dir = common::temp_dir();
    let (mut server, addr, fingerprint) = serve_rooms(NAME, ROOMS, dir.path());
    let client = |room: &str, op: &str, seconds: &str, tag: &str| {
        let mut args = vec!["--server".to_owned(), addr.to_string(), "--fingerprint".to_owned(), fingerprint.clone()];
        args.extend(strings(&["--room", room, "--op", op, "--duration", seconds, "--user", "firm", "--json"]));
        ChildProcess::spawn(NAME, &Role::Program { program: Program::Client, args }, dir.path(), tag)
    };
    // The slow room is measured first (its cost passes the share within a few dozen ticks, and until then
    // it shares the one real-time thread with the calm room, whose joins that load may refuse).
    std::thread::sleep(Duration::from_secs(2));
    let mut calm = [client("calm", "coupler", "8", "calm-1"), client("calm", "crank-tip", "8", "calm-2")];
    for (room, tag, expected) in
        [("slow", "slow", "over its real-time budget"), ("nowhere", "nowhere", "rooms: calm, slow")]
    {
        let mut refused = client(room, "link2", "3", tag);
        let status = refused.exit_status(Duration::from_secs(30));
        assert!(!status.success(), "{room}: the client was admitted");
        let said = refused.log();
        assert!(said.contains(expected), "{room}: the client did not print why ({expected}):\n{said}");
    }
    for c in &mut calm {
        let status = c.exit_status(Duration::from_secs(45));
        assert!(status.success(), "a calm client exited with {status}:\n{}", c.log_tail());
    }
    server.interrupt();
    let status = server.exit_status(Duration::from_secs(20));
    assert!(status.success(), "the server exited with {status}:\n{}", server.log_tail());
    let json = json_object(&server.stdout());
    let rooms = json["rooms"].as_array().expect("rooms");
    let room = |name: &str| rooms.iter().find(|r| r["name"] == name).unwrap_or_else(|| panic!("{name}: {json}"));
    let (calm, slow) = (room("calm"), room("slow"));
    println!("calm: {}\nslow: cost {} µs, quarantined {}", calm["stats"]["ve"], slow["cost_us"], slow["quarantined"]);
    assert_eq!(slow["quarantined"], true, "the overrunning room stayed on the real-time thread: {slow}");
    assert!(slow["cost_us"].as_f64().unwrap() >= 1500.0, "the knob's 2 ms was not measured: {slow}");
    assert!(slow["quarantines"].as_u64() >= Some(1), "{slow}");
    assert_eq!(calm["quarantines"].as_u64(), Some(0), "the calm room was sent to the quarantine: {calm}");
    let ve = &calm["stats"]["ve"];
    let ticks = ve["step_time"]["samples"].as_f64().expect("samples");
    let misses = ve["deadline_misses"].as_f64().expect("deadline_misses");
    assert!(ticks > 5000.0, "{ve}");
    // Sharing the thread with the 2 ms room would miss nearly every tick. On a 2-core host the calm room's
    // thread competes with the quarantine's quarter core, the two clients' 1 kHz loops and QUIC, so host
    // stalls still make it miss a few ticks in a hundred: a tenth keeps the two cases an order of magnitude
    // apart without timing the host.
    assert!(misses <= 0.1 * ticks, "the calm room missed {misses} of {ticks} ticks: {ve}");
    assert_eq!(ve["core"]["state_restores"].as_u64(), Some(0), "{ve}");
    assert_eq!(ve["core"]["users_joined"].as_u64(), Some(2), "{ve}");
    assert!(ve["core"]["max_closure_error"].as_f64().unwrap() <= 1e-6, "{ve}");
}

const LOAD: &str = "four_users_in_two_rooms_render_from_one_load_process";

const TWO_ROOMS: &str = "
[[room]]
name = \"bench-a\"
scene = \"fourbar-crank-rocker\"

[[room]]
name = \"bench-b\"
scene = \"paper-testbed\"
";

#[test]
fn four_users_in_two_rooms_render_from_one_load_process() {
    common::child::serve_if_child();
    let _bounded = common::bounded(LOAD, Duration::from_secs(120));
    let dir = common::temp_dir();
    let (mut server, addr, fingerprint) = serve_rooms(LOAD, TWO_ROOMS, dir.path());
    // Users 1 and 4 join bench-a, 2 and 5 bench-b, 3 a room that does not exist.
    let mut args = vec!["--server".to_owned(), addr.to_string(), "--fingerprint".to_owned(), fingerprint];
    args.extend(strings(&["--users", "5", "--rooms", "bench-a,bench-b,nowhere", "--duration", "6", "--json"]));
    let mut load = ChildProcess::spawn(LOAD, &Role::Program { program: Program::Load, args }, dir.path(), "load");
    let status = load.exit_status(Duration::from_secs(60));
    assert!(status.success(), "kinloop load exited with {status}:\n{}", load.log_tail());
    let outcome = json_object(&load.stdout());
    println!("load: {outcome}");
    assert_eq!(outcome["rendered"], 4, "{outcome}");
    assert_eq!(outcome["refused"], 1, "{outcome}");
    let users = outcome["per_user"].as_array().expect("per_user");
    let nowhere = &users[2];
    assert_eq!(nowhere["room"], "nowhere");
    let why = nowhere["error"].as_str().expect("the refused user says why");
    assert!(why.contains("rooms: bench-a, bench-b"), "the refusal does not list the rooms: {why}");
    for (i, room) in [(0, "bench-a"), (1, "bench-b"), (3, "bench-a"), (4, "bench-b")] {
        let user = &users[i];
        assert_eq!(user["room"], room, "{user}");
        assert_eq!(user["rendered"], true, "{user}");
        let ticks = user["ticks"].as_f64().unwrap();
        assert!(ticks >= 5000.0, "user {} ran {ticks} ticks of 6000: {user}", i + 1);
        // Snapshots at the VE's 1 kHz reach every user of the load process, with room for a busy machine.
        assert!(user["snapshots_received"].as_f64().unwrap() >= 0.5 * ticks, "{user}");
        let rms = user["device_lm_rms_mm"].as_f64().unwrap();
        assert!(rms > 0.0 && rms < 20.0, "the hand's device-OP distance {rms} mm: {user}");
        assert!(user["max_force_ratio"].as_f64().unwrap() <= 1.0, "{user}");
        assert!(user["uplinks_sent"].as_f64().unwrap() > 0.5 * ticks, "{user}");
    }
    // The two users of a room hold different operational points where the scene has several.
    assert_ne!(users[0]["op"], users[3]["op"], "{outcome}");
    server.interrupt();
    let status = server.exit_status(Duration::from_secs(20));
    assert!(status.success(), "the server exited with {status}:\n{}", server.log_tail());
    let json = json_object(&server.stdout());
    for room in json["rooms"].as_array().expect("rooms") {
        let core = &room["stats"]["ve"]["core"];
        assert_eq!(core["users_joined"].as_u64(), Some(2), "{room}");
        assert_eq!(core["state_restores"].as_u64(), Some(0), "{room}");
        assert!(core["max_closure_error"].as_f64().unwrap() <= 1e-6, "{room}");
    }
}

const SIXTEEN: &str = "sixteen_rooms_of_two_users_from_one_load_process_lose_few_uplinks";

/// The bound on the share of a user's uplinks the server never sees. With a runtime thread and an uplink
/// thread per user in the load process, and the OS's default socket buffers, the server's one UDP socket
/// overflowed whenever its runtime was held up for a few milliseconds, and half the uplinks of 32 users were
/// lost on a busy 2-core machine (docs/benchmarks.md, "Rooms per server").
const UPLINK_LOSS_BOUND: f64 = 0.05;

#[test]
fn sixteen_rooms_of_two_users_from_one_load_process_lose_few_uplinks() {
    common::child::serve_if_child();
    let _bounded = common::bounded(SIXTEEN, Duration::from_secs(150));
    let dir = common::temp_dir();
    let rooms: String =
        (1..=16).map(|i| format!("[[room]]\nname = \"r{i}\"\nscene = \"paper-testbed\"\nmax_users = 2\n\n")).collect();
    let (mut server, addr, fingerprint) = serve_rooms(SIXTEEN, &rooms, dir.path());
    let names: Vec<String> = (1..=16).map(|i| format!("r{i}")).collect();
    let mut args = vec!["--server".to_owned(), addr.to_string(), "--fingerprint".to_owned(), fingerprint];
    args.extend(strings(&["--users", "32", "--rooms", &names.join(","), "--duration", "6", "--realtime", "--json"]));
    let mut load = ChildProcess::spawn(SIXTEEN, &Role::Program { program: Program::Load, args }, dir.path(), "load");
    let status = load.exit_status(Duration::from_secs(90));
    assert!(status.success(), "kinloop load exited with {status}:\n{}", load.log_tail());
    let outcome = json_object(&load.stdout());
    assert_eq!(outcome["rendered"], 32, "{outcome}");
    server.interrupt();
    let status = server.exit_status(Duration::from_secs(20));
    assert!(status.success(), "the server exited with {status}:\n{}", server.log_tail());
    let json = json_object(&server.stdout());
    let mut seen = 0;
    for room in json["rooms"].as_array().expect("rooms") {
        let core = &room["stats"]["ve"]["core"];
        assert_eq!(core["state_restores"].as_u64(), Some(0), "{room}");
        assert!(core["max_closure_error"].as_f64().unwrap() <= 1e-6, "{room}");
        for user in room["stats"]["per_user"].as_array().expect("per_user") {
            seen += 1;
            let loss = user["uplink_loss"].as_f64().expect("uplink_loss");
            println!("{} {}: uplink loss {:.4}", room["name"], user["name"], loss);
            assert!(loss < UPLINK_LOSS_BOUND, "{}: the server missed {loss} of a user's uplinks: {user}", room["name"]);
        }
    }
    assert_eq!(seen, 32, "{json}");
    for user in outcome["per_user"].as_array().expect("per_user") {
        let ticks = user["ticks"].as_f64().unwrap();
        assert!(user["uplink_loss"].as_f64().unwrap() < UPLINK_LOSS_BOUND, "left the load process: {user}");
        assert!(user["snapshots_received"].as_f64().unwrap() >= 0.5 * ticks, "{user}");
    }
}
