//! The Agones adapter against a fake SDK sidecar (`kinloop-fake-agones`: the SDK's gRPC service on a loopback
//! port, recording each call): what a real sidecar would see of `kinloop-server --agones`: Ready only once
//! the server listens, health pings at the configured period and none while the VE is stalled, the `rooms`
//! Counter and `users` List following the rooms (the admin command's and the allocations' too) and the joins
//! and leaves, an allocation becoming a room a client joins, Shutdown after the drain; a sidecar
//! that fails calls or goes away is retried and the server carries on; without one the program stops with one
//! line. Every SDK call the server makes is covered here.

use std::net::SocketAddr;
use std::process::Command;
use std::time::{Duration, Instant};

use kinloop_fake_agones::{Call, FakeSidecar, Journal};
use kinloop_linkage::model::builtin;
use kinloop_protocol::quic::{client_endpoint, connect, recv_control, ConnectedSession, EndpointOptions, Trust};
use kinloop_protocol::{
    AdminAnswer, AdminCommand, AdminRequest, Control, DeviceCaps, Hello, Join, LocalModelForm, Role, PROTOCOL_VERSION,
};
use kinloop_server::fleet::agones::{self, AgonesAdapter, AgonesConfig, ROOMS_COUNTER, USERS_LIST};
use kinloop_server::fleet::allocation::{REFUSED_ANNOTATION, ROOM_ANNOTATION, SCENE_ANNOTATION};
use kinloop_server::fleet::{self, user_label};
use kinloop_server::{Access, Server, ServerConfig, ServerHandle};

const HEALTH_PERIOD: Duration = Duration::from_millis(100);
/// Scheduling slack on a busy host when asking whether a ping came "within one period".
const SLACK: Duration = Duration::from_millis(60);

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn settings(sidecar: &FakeSidecar) -> AgonesConfig {
    AgonesConfig { port: Some(sidecar.port()), health_period: HEALTH_PERIOD, connect_within: Duration::from_secs(5) }
}

/// The adapter for `sidecar`, following the events of the feed it returns.
async fn adapter_for(sidecar: &FakeSidecar) -> (AgonesAdapter, fleet::FleetFeed) {
    let settings = settings(sidecar);
    let sdk = agones::connect(&settings).await.expect("the fake sidecar answers");
    let (feed, events) = fleet::channel();
    (AgonesAdapter::spawn(sdk, &settings, events), feed)
}

/// The admin command's token of the servers here.
const ADMIN_TOKEN: &str = "admin-secret";

/// A server for the paper's testbed (its one room "default") that tells `feed` and takes admin commands.
fn start_server(feed: fleet::FleetFeed) -> ServerHandle {
    let scene = builtin::scene("paper-testbed").unwrap().unwrap();
    let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
    config.realtime = false;
    config.rt_threads = 1;
    config.drain = Duration::from_secs(2);
    config.fleet = Some(feed);
    config.admin = Some(Access::parse(&format!("{ADMIN_TOKEN}\n"), "admin tokens").unwrap());
    Server::start(config).expect("the server starts")
}

/// A fake sidecar, the adapter and a server (its default room counted).
struct Fleet {
    sidecar: FakeSidecar,
    journal: Journal,
    adapter: AgonesAdapter,
    server: ServerHandle,
}

impl Fleet {
    async fn start() -> Fleet {
        let sidecar = FakeSidecar::start().await.expect("fake sidecar");
        let journal = sidecar.journal().clone();
        let (adapter, feed) = adapter_for(&sidecar).await;
        let server = start_server(feed);
        until("the default room counted", || journal.counter(ROOMS_COUNTER) == 1).await;
        Fleet { sidecar, journal, adapter, server }
    }

    /// Drains the server, lets the adapter call Shutdown, stops the sidecar.
    async fn finish(self) {
        self.server.shutdown().await.expect("drained");
        self.adapter.finished(Duration::from_secs(10)).await;
        let _ = self.sidecar.stop().await;
    }
}

/// Sends `server` an admin command and asserts it was done.
async fn admin(server: &ServerHandle, command: AdminCommand) {
    let options = EndpointOptions { client_bind: loopback(), ..EndpointOptions::default() };
    let client = client_endpoint(&Trust::Fingerprint(server.fingerprint().to_string()), &options).unwrap();
    let request = AdminRequest { version: PROTOCOL_VERSION, token: ADMIN_TOKEN.into(), command };
    let answer = kinloop_protocol::quic::admin(&client, server.local_addr(), "localhost", &request).await;
    assert!(matches!(answer, Ok(AdminAnswer::Done { .. })), "{answer:?}");
}

fn remove(name: &str) -> AdminCommand {
    AdminCommand::RemoveRoom { name: name.into() }
}

/// Joins the default room.
async fn join(server: &ServerHandle, name: &str) -> ConnectedSession {
    join_room(server, name, "").await
}

async fn join_room(server: &ServerHandle, name: &str, room: &str) -> ConnectedSession {
    let options = EndpointOptions { client_bind: loopback(), ..EndpointOptions::default() };
    let client = client_endpoint(&Trust::Fingerprint(server.fingerprint().to_string()), &options).unwrap();
    let hello = Hello {
        version: PROTOCOL_VERSION,
        token: String::new(),
        client_name: name.into(),
        role: Role::Manipulator,
        room: room.into(),
    };
    let join = Join {
        op: "link2".into(),
        device: DeviceCaps { max_force_n: 20.0, continuous_force_n: 10.0, ..DeviceCaps::generous("sim", 3) },
        form: LocalModelForm::OpSpace,
        mapping: Default::default(),
    };
    connect(&client, server.local_addr(), "localhost", &hello, |_| Ok(join)).await.expect("welcome")
}

/// Polls `what` until it holds (at most 10 s).
async fn until(what: &str, mut holds: impl FnMut() -> bool) {
    let start = Instant::now();
    while !holds() {
        assert!(start.elapsed() < Duration::from_secs(10), "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

fn pings(journal: &Journal) -> Vec<Instant> {
    journal.calls().iter().filter(|c| c.call == Call::Health).map(|c| c.at).collect()
}

fn count(journal: &Journal, call: &Call) -> usize {
    journal.calls().iter().filter(|c| c.call == *call).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_sidecar_sees_ready_health_counts_and_shutdown_after_the_drain() {
    let sidecar = FakeSidecar::start().await.expect("fake sidecar");
    let journal = sidecar.journal().clone();
    let (adapter, feed) = adapter_for(&sidecar).await;
    // Nothing but the SDK's connection check before the server listens, then Ready.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let calls = journal.calls();
    assert!(!calls.is_empty() && calls.iter().all(|c| c.call == Call::GetGameServer), "{calls:?}");
    let server = start_server(feed);
    until("Ready", || count(&journal, &Call::Ready) == 1).await;
    until("the room counted", || journal.counter(ROOMS_COUNTER) == 1).await;

    // Health at the configured period while the VE ticks.
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let ticking = pings(&journal);
    let gaps: Vec<Duration> = ticking.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = gaps.clone();
    sorted.sort();
    let median = sorted[sorted.len() / 2];
    assert!(ticking.len() >= 5, "{} pings in a second at a {HEALTH_PERIOD:?} period", ticking.len());
    assert!(median >= HEALTH_PERIOD / 2 && median <= HEALTH_PERIOD * 2, "median gap {median:?}");

    // A stalled VE stops the pings within one health period; they resume when it ticks again.
    let stall = Duration::from_millis(1500);
    let stalled_at = Instant::now();
    server.stall_ve(stall);
    tokio::time::sleep(stall + 5 * HEALTH_PERIOD).await;
    let all = pings(&journal);
    let during: Vec<_> =
        all.iter().filter(|t| **t > stalled_at + HEALTH_PERIOD + SLACK && **t < stalled_at + stall).collect();
    let last_before = all.iter().filter(|t| **t <= stalled_at + stall).max().copied().unwrap();
    println!(
        "agones: health period {HEALTH_PERIOD:?}: median gap {median:?}; the last ping {:?} after the VE stalled; \
         {} pings during the stall's rest",
        last_before.saturating_duration_since(stalled_at),
        during.len()
    );
    assert!(during.is_empty(), "pings while the VE was stalled: {} of them", during.len());
    assert!(all.iter().any(|t| *t > stalled_at + stall), "pings resume once the VE ticks again");

    // Users as a List: joins and leaves.
    let a = join(&server, "alice").await;
    let b = join(&server, "bob").await;
    let (a_label, b_label) =
        (user_label("default", "alice", a.welcome.user_id), user_label("default", "bob", b.welcome.user_id));
    until("both users listed", || journal.list(USERS_LIST).len() == 2).await;
    assert_eq!(journal.list(USERS_LIST), vec![a_label.clone(), b_label.clone()]);
    a.connection.close(0u32.into(), b"bye");
    until("alice's leave listed", || journal.list(USERS_LIST) == vec![b_label.clone()]).await;

    // The drain: bob is told to move (and does); then the room closes and Shutdown is the last call.
    let mut control = b.recv;
    let leaver = tokio::spawn(async move {
        loop {
            match recv_control(&mut control).await {
                Ok(Control::Leave { .. }) | Err(_) => break,
                Ok(_) => {}
            }
        }
        b.connection.close(0u32.into(), b"moving");
    });
    server.shutdown().await.expect("drained");
    leaver.await.unwrap();
    adapter.finished(Duration::from_secs(10)).await;
    let calls = journal.calls();
    assert_eq!(calls.last().map(|c| &c.call), Some(&Call::Shutdown), "{:?}", &calls[calls.len().saturating_sub(5)..]);
    assert_eq!(count(&journal, &Call::Shutdown), 1);
    assert_eq!(journal.counter(ROOMS_COUNTER), 0, "the room closed");
    assert!(journal.list(USERS_LIST).is_empty(), "every user left");
    let ups = calls.iter().filter(|c| matches!(&c.call, Call::Counter { diff: 1, .. })).count();
    assert_eq!(ups, 1, "one room opened");
    let _ = sidecar.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sidecar_that_fails_or_goes_away_is_retried_and_the_server_carries_on() {
    let sidecar = FakeSidecar::start().await.expect("fake sidecar");
    let journal = sidecar.journal().clone();
    let (adapter, feed) = adapter_for(&sidecar).await;
    journal.fail_next(3);
    let server = start_server(feed);
    // The GameServer watch fails to open (and is reopened), two Readys fail, then one lands.
    until("Ready retried", || count(&journal, &Call::Ready) == 3).await;
    until("the room counted", || journal.counter(ROOMS_COUNTER) == 1).await;
    until("the watch reopened", || count(&journal, &Call::WatchGameServer) == 2).await;

    // The sidecar goes away; the server serves on; it comes back on the same port and hears from the server
    // again: health pings and the List.
    let port = sidecar.port();
    let journal = sidecar.stop().await;
    let gone_at = Instant::now();
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let session = join(&server, "carol").await;
    until("the server admits a client with its sidecar gone", || server.stats().users == 1).await;
    let back_at = Instant::now();
    let back = FakeSidecar::start_on(SocketAddr::from(([127, 0, 0, 1], port)), journal.clone()).await.expect("restart");
    until("health pings after the sidecar came back", || pings(&journal).iter().any(|t| *t > back_at)).await;
    let label = user_label("default", "carol", session.welcome.user_id);
    until("the join listed once the sidecar came back", || journal.list(USERS_LIST).contains(&label)).await;
    assert!(pings(&journal).iter().all(|t| *t < gone_at || *t > back_at), "no pings reached a stopped sidecar");
    session.connection.close(0u32.into(), b"bye");
    server.shutdown().await.expect("drained");
    adapter.finished(Duration::from_secs(15)).await;
    assert_eq!(journal.calls().last().map(|c| c.call.clone()), Some(Call::Shutdown));
    let _ = back.stop().await;
}

/// Rooms opened and closed by the admin command are counted like the rooms the server starts with; a server
/// whose last room closes while it serves on is Ready again, and one that drains is not (it shuts down).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn admin_rooms_are_counted_a_server_with_none_left_is_ready_again_and_one_that_drains_shuts_down() {
    let Fleet { sidecar, journal, adapter, server } = Fleet::start().await;
    let create = |name: &str| AdminCommand::CreateRoom {
        name: name.into(),
        scene: "fourbar-crank-rocker".into(),
        token_file: String::new(),
        max_users: 4,
    };

    admin(&server, create("second")).await;
    until("the admin's room counted", || journal.counter(ROOMS_COUNTER) == 2).await;
    admin(&server, remove("default")).await;
    until("the default room uncounted", || journal.counter(ROOMS_COUNTER) == 1).await;
    assert_eq!(count(&journal, &Call::Ready), 1, "a room left: not Ready again");
    admin(&server, remove("second")).await;
    until("Ready again", || count(&journal, &Call::Ready) == 2).await;
    assert_eq!(journal.counter(ROOMS_COUNTER), 0);

    admin(&server, create("third")).await;
    until("the third room counted", || journal.counter(ROOMS_COUNTER) == 1).await;
    server.shutdown().await.expect("drained");
    adapter.finished(Duration::from_secs(10)).await;
    assert_eq!(journal.counter(ROOMS_COUNTER), 0, "the drain closed the third room");
    assert_eq!(count(&journal, &Call::Ready), 2, "a draining server is not Ready again");
    assert_eq!(journal.calls().last().map(|c| c.call.clone()), Some(Call::Shutdown));
    let _ = sidecar.stop().await;
}

/// A lobby's allocation (the `rooms` count raised, the room and scene in the GameServer's annotations, the
/// GameServer streamed to the server's watch) becomes a room a client joins by name, counted once; its
/// users are listed as `ROOM/NAME#ID`; closing it lowers the count. Updates that repeat the allocation (the
/// sidecar streams every counter change) create nothing more.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_allocation_creates_its_room_a_client_joins_it_and_closing_it_lowers_the_count() {
    let fleet = Fleet::start().await;
    let (journal, server) = (fleet.journal.clone(), &fleet.server);
    assert!(count(&journal, &Call::WatchGameServer) >= 1, "the GameServer is watched once the server is Ready");

    journal.allocate(ROOMS_COUNTER, &[(ROOM_ANNOTATION, "lab-3"), (SCENE_ANNOTATION, "paper-testbed")]);
    let rooms = || server.room_stats().into_iter().map(|r| r.name).collect::<Vec<_>>();
    until("the allocated room open", || rooms().contains(&"lab-3".to_string())).await;
    let alice = join_room(server, "alice", "lab-3").await;
    let label = user_label("lab-3", "alice", alice.welcome.user_id);
    until("alice listed in her room", || journal.list(USERS_LIST) == vec![label.clone()]).await;
    assert_eq!(journal.counter(ROOMS_COUNTER), 2, "the allocation counted the room; the server did not again");
    let ups = journal.calls().iter().filter(|c| matches!(&c.call, Call::Counter { diff: 1, .. })).count();
    assert_eq!(ups, 1, "the server raised the count for its default room only");
    assert_eq!(rooms(), vec!["default".to_string(), "lab-3".to_string()], "one room for one allocation");

    admin(server, remove("lab-3")).await;
    until("the closed room uncounted", || journal.counter(ROOMS_COUNTER) == 1).await;
    until("alice unlisted", || journal.list(USERS_LIST).is_empty()).await;
    drop(alice);
    fleet.finish().await;
    assert_eq!(journal.counter(ROOMS_COUNTER), 0);
}

/// An allocation for a scene the server cannot load is refused with the reason (on the GameServer, for the
/// lobby) and the `rooms` count the allocation raised is lowered again; a server left with no room is Ready
/// again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_allocation_for_a_scene_the_server_cannot_load_is_refused_and_the_count_restored() {
    let fleet = Fleet::start().await;
    let (journal, server) = (fleet.journal.clone(), &fleet.server);
    admin(server, remove("default")).await;
    until("Ready with no room", || count(&journal, &Call::Ready) == 2).await;

    journal.allocate(ROOMS_COUNTER, &[(ROOM_ANNOTATION, "lab-4"), (SCENE_ANNOTATION, "no-such-scene")]);
    assert_eq!(journal.state(), "Allocated");
    until("Ready again after the refusal", || count(&journal, &Call::Ready) == 3).await;
    assert_eq!(journal.counter(ROOMS_COUNTER), 0, "the refused allocation's room uncounted");
    assert!(server.room_stats().is_empty(), "no room opened");
    let downs = journal.calls().iter().filter(|c| matches!(&c.call, Call::Counter { diff: -1, .. })).count();
    assert_eq!(downs, 2, "the default room's close and the refusal");

    // The reason, for the lobby, on the GameServer.
    let reason = journal.annotations().get(REFUSED_ANNOTATION).cloned().unwrap_or_default();
    assert!(reason.contains("lab-4") && reason.contains("no-such-scene"), "{reason:?}");
    fleet.finish().await;
}

/// `kinloop-server --agones` with no sidecar stops within a few seconds, exit code 1, saying why in one line.
#[test]
fn without_a_sidecar_the_program_stops_within_seconds_with_one_line() {
    let dead_port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let dir = tempfile::tempdir().unwrap();
    let started = Instant::now();
    let output = Command::new(env!("CARGO_BIN_EXE_kinloop-server"))
        .args(["--scene", "paper-testbed", "--listen", "127.0.0.1:0", "--agones"])
        .env("AGONES_SDK_GRPC_PORT", dead_port.to_string())
        .env("RUST_LOG", "error")
        .current_dir(dir.path())
        .output()
        .expect("the server runs");
    let took = started.elapsed();
    let stderr = String::from_utf8_lossy(&output.stderr);
    println!("agones: no sidecar: exit {:?} after {took:?}: {stderr}", output.status.code());
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(took < Duration::from_secs(6), "took {took:?}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line: {stderr}");
    assert!(lines[0].starts_with("error:") && lines[0].contains("Agones SDK sidecar"), "{stderr}");
    assert!(lines[0].contains(&dead_port.to_string()), "names the port: {stderr}");
}
