//! Rooms in-process over real QUIC on 127.0.0.1: a rooms file's mistakes are refused naming the file, the
//! room and the key; a client picks its room by name and one asking for an unknown room learns the rooms its
//! token opens; the admin command opens and closes rooms only with the admin token; a panicking room is
//! closed with a reason its users are told while the other room goes on.

use std::future::Future;
use std::time::Duration;

use kinloop_linkage::model::builtin;
use kinloop_protocol::quic::{admin, connect, recv_control, ConnectError};
use kinloop_protocol::{
    AdminAnswer, AdminCommand, AdminRequest, Control, Hello, Join, RefusalReason, Role, PROTOCOL_VERSION,
};
use kinloop_server::driver::rooms::{load_rooms_file, RoomsFileError};
use kinloop_server::{Access, Server, ServerConfig, ServerHandle};

use crate::loopback::{endpoint, join_link2, loopback};

async fn bounded<T>(test: impl Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(30), test).await.expect("the test took longer than 30 s")
}

/// Writes `files` into a fresh directory and loads `rooms.toml` from it.
fn rooms_from(
    files: &[(&str, &str)],
) -> (tempfile::TempDir, Result<Vec<kinloop_server::driver::rooms::RoomSpec>, RoomsFileError>) {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    let loaded = load_rooms_file(&dir.path().join("rooms.toml"));
    (dir, loaded)
}

fn start(rooms: &[(&str, &str)], admin_tokens: Option<&str>) -> (tempfile::TempDir, ServerHandle) {
    let (dir, specs) = rooms_from(rooms);
    let scene = builtin::scene("paper-testbed").unwrap().unwrap();
    let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
    config.realtime = false;
    config.rooms = specs.unwrap();
    config.rt_threads = 1;
    config.admin = admin_tokens.map(|t| Access::parse(t, "admin tokens").unwrap());
    (dir, Server::start(config).unwrap())
}

fn hello(token: &str, room: &str) -> Hello {
    Hello {
        version: PROTOCOL_VERSION,
        token: token.into(),
        client_name: "rooms test".into(),
        role: Role::Manipulator,
        room: room.into(),
    }
}

async fn command(server: &ServerHandle, token: &str, command: AdminCommand) -> AdminAnswer {
    let request = AdminRequest { version: PROTOCOL_VERSION, token: token.into(), command };
    admin(&endpoint(server), server.local_addr(), "localhost", &request).await.expect("an answer")
}

const TWO_ROOMS: &str = "
[[room]]
name = \"alpha\"
scene = \"paper-testbed\"
token_file = \"alpha.tokens\"

[[room]]
name = \"beta\"
scene = \"paper-testbed\"
token_file = \"beta.tokens\"
";

/// What is wrong, the files, and the room and key the refusal must name.
type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a str, &'a str);

#[test]
fn a_rooms_file_with_a_mistake_is_refused_naming_file_room_and_key() {
    let cases: [Case; 3] = [
        ("bad scene", &[("rooms.toml", "[[room]]\nname = \"a\"\nscene = \"no-such-scene\"\n")], "\"a\"", "`scene`"),
        (
            "duplicate name",
            &[("rooms.toml", "[[room]]\nname = \"a\"\nscene = \"paper-testbed\"\n[[room]]\nname = \"a\"\nscene = \"paper-testbed\"\n")],
            "\"a\"",
            "`name`",
        ),
        (
            "missing token file",
            &[("rooms.toml", "[[room]]\nname = \"b\"\nscene = \"paper-testbed\"\ntoken_file = \"gone.tokens\"\n")],
            "\"b\"",
            "`token_file`",
        ),
    ];
    for (what, files, room, key) in cases {
        let (_dir, loaded) = rooms_from(files);
        let error = loaded.expect_err(what);
        let message = error.to_string();
        assert!(matches!(error, RoomsFileError::Entry { .. }), "{what}: {message}");
        assert!(message.contains("rooms.toml") && message.contains(room) && message.contains(key), "{what}: {message}");
    }
    let (_dir, loaded) =
        rooms_from(&[("rooms.toml", "[[room]]\nname = \"a\"\nscene = \"paper-testbed\"\ncolour = 3\n")]);
    assert!(loaded.unwrap_err().to_string().contains("colour"), "an unknown key is named");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_join_their_room_and_an_unknown_room_is_answered_with_the_rooms_their_token_opens() {
    bounded(async {
        let files =
            [("rooms.toml", TWO_ROOMS), ("alpha.tokens", "a-token\nboth-token\n"), ("beta.tokens", "both-token\n")];
        let (_dir, server) = start(&files, None);
        let client = endpoint(&server);
        let session =
            connect(&client, server.local_addr(), "localhost", &hello("a-token", "alpha"), |_| Ok(join_link2()))
                .await
                .expect("alpha admits its token");
        assert_eq!(session.welcome.scene.op_name, "link2");
        let refused = |result: Result<_, ConnectError>| match result {
            Err(ConnectError::Refused(refused)) => refused.reason,
            other => panic!("expected a refusal, got {other:?}"),
        };
        let beta = hello("a-token", "beta");
        let wrong = connect(&client, server.local_addr(), "localhost", &beta, |_| Ok(join_link2()));
        assert_eq!(refused(wrong.await), RefusalReason::BadToken, "beta's tokens do not include alpha's");
        for (token, available) in
            [("both-token", vec!["alpha", "beta"]), ("a-token", vec!["alpha"]), ("nobody", vec![])]
        {
            let gamma = hello(token, "gamma");
            let unknown = connect(&client, server.local_addr(), "localhost", &gamma, |_| Ok(join_link2()));
            let reason = refused(unknown.await);
            let expected = RefusalReason::UnknownRoom {
                requested: "gamma".into(),
                available: available.iter().map(|s| s.to_string()).collect(),
            };
            assert_eq!(reason, expected, "{token}");
            assert!(reason.to_string().contains("gamma"), "{reason}");
        }
        // Statistics are published every 100 ms.
        tokio::time::sleep(Duration::from_millis(300)).await;
        let reports = server.room_stats();
        let users: Vec<(String, u32)> = reports.iter().map(|r| (r.name.clone(), r.stats.users)).collect();
        assert_eq!(users, vec![("alpha".to_string(), 1), ("beta".to_string(), 0)]);
        drop(session);
        server.shutdown_rooms().await.expect("clean shutdown");
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_admin_command_opens_and_closes_rooms_only_with_the_admin_token() {
    bounded(async {
        let files = [("rooms.toml", "[[room]]\nname = \"first\"\nscene = \"paper-testbed\"\n")];
        let (_dir, server) = start(&files, Some("admin-secret\n"));
        let create = || AdminCommand::CreateRoom {
            name: "second".into(),
            scene: "fourbar-crank-rocker".into(),
            token_file: String::new(),
            max_users: 4,
        };
        match command(&server, "not-the-secret", create()).await {
            AdminAnswer::Refused { what } => assert!(what.contains("admin token"), "{what}"),
            other => panic!("a wrong admin token was obeyed: {other:?}"),
        }
        assert_eq!(server.room_stats().len(), 1, "nothing was created");
        let AdminAnswer::Done { rooms } = command(&server, "admin-secret", create()).await else {
            panic!("the admin token was refused")
        };
        let names: Vec<&str> = rooms.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["first", "second"]);
        match command(&server, "admin-secret", create()).await {
            AdminAnswer::Refused { what } => assert!(what.contains("already open"), "{what}"),
            other => panic!("a second room of one name was opened: {other:?}"),
        }
        let client = endpoint(&server);
        let in_second = connect(&client, server.local_addr(), "localhost", &hello("x", "second"), |scene| {
            Ok(Join { op: scene.ops[0].clone(), ..join_link2() })
        })
        .await
        .expect("the new room admits users");
        let mut control = in_second.recv;
        let AdminAnswer::Done { rooms } =
            command(&server, "admin-secret", AdminCommand::RemoveRoom { name: "second".into() }).await
        else {
            panic!("the room was not removed")
        };
        assert_eq!(rooms.len(), 1);
        match recv_control(&mut control).await {
            Ok(Control::Leave { reason }) => assert!(reason.contains("admin"), "{reason}"),
            other => panic!("the removed room's user was not told: {other:?}"),
        }
        server.shutdown_rooms().await.expect("clean shutdown");
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_room_that_panics_is_closed_with_a_reason_and_the_other_room_goes_on() {
    bounded(async {
        let files = [(
            "rooms.toml",
            "[[room]]\nname = \"steady\"\nscene = \"paper-testbed\"\n[[room]]\nname = \"fragile\"\nscene = \"paper-testbed\"\ndebug_panic_after_ticks = 5000\n",
        )];
        let (_dir, server) = start(&files, None);
        let client = endpoint(&server);
        let fragile = connect(&client, server.local_addr(), "localhost", &hello("x", "fragile"), |_| Ok(join_link2()))
            .await
            .expect("the fragile room admits a user before it fails");
        let mut control = fragile.recv;
        match recv_control(&mut control).await {
            Ok(Control::Leave { reason }) => assert!(reason.contains("failed"), "{reason}"),
            other => panic!("the failed room's user was not told: {other:?}"),
        }
        let steady = connect(&client, server.local_addr(), "localhost", &hello("x", "steady"), |_| Ok(join_link2()))
            .await
            .expect("the steady room goes on");
        let before = server.room_stats().into_iter().find(|r| r.name == "steady").unwrap().stats.ve.step_time.samples;
        tokio::time::sleep(Duration::from_millis(300)).await;
        let reports = server.room_stats();
        let steady_now = reports.iter().find(|r| r.name == "steady").unwrap();
        assert!(steady_now.stats.ve.step_time.samples > before, "the steady room stopped stepping");
        let failed = reports.iter().find(|r| r.name == "fragile").unwrap();
        assert!(failed.closed.as_deref().is_some_and(|c| c.contains("debug_panic_after_ticks")), "{:?}", failed.closed);
        let again = hello("x", "fragile");
        let gone = connect(&client, server.local_addr(), "localhost", &again, |_| Ok(join_link2()));
        assert!(matches!(gone.await, Err(ConnectError::Refused(_))), "a closed room admits no one");
        drop(steady);
        server.shutdown_rooms().await.expect("clean shutdown");
    })
    .await
}
