//! The server in-process over real QUIC on 127.0.0.1: a minimal client joins, sends uplinks, receives
//! snapshots and leaves; a bad token is refused with `BadToken` and nothing else; shutdown tells clients.

use std::future::Future;
use std::time::Duration;

use kinloop_linkage::model::builtin::{self, PAPER_WRENCH};
use kinloop_protocol::quic::{
    connect, recv_control, send_control, ConnectError, ConnectedSession, DatagramReceiver, DatagramSender,
};
use kinloop_protocol::{
    Control, Datagram, Hello, RefusalReason, Role, SceneKind, SessionShape, Uplink, PROTOCOL_VERSION,
};
use kinloop_server::{Access, Server, ServerConfig, ServerHandle};

use crate::loopback::{endpoint, join_link2, loopback};

async fn bounded<T>(test: impl Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(30), test).await.expect("the test took longer than 30 s")
}

fn start(tokens: &str) -> ServerHandle {
    let scene = builtin::scene("paper-testbed").unwrap().unwrap();
    let mut config = ServerConfig::new(scene, "paper-testbed", loopback());
    config.access = Access::parse(tokens, "test tokens").unwrap();
    config.realtime = false;
    Server::start(config).unwrap()
}

fn hello(token: &str, role: Role) -> Hello {
    Hello {
        version: PROTOCOL_VERSION,
        token: token.into(),
        client_name: "test client".into(),
        role,
        room: String::new(),
    }
}

async fn join(server: &ServerHandle, token: &str, role: Role) -> Result<ConnectedSession, ConnectError> {
    connect(&endpoint(server), server.local_addr(), "localhost", &hello(token, role), |_| Ok(join_link2())).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_joins_pushes_receives_snapshots_and_the_server_says_goodbye() {
    bounded(async {
        let server = start("good-token\nwatch-token observer\n");
        let session = join(&server, "good-token", Role::Manipulator).await.expect("welcome");
        let welcome = &session.welcome;
        assert_eq!(welcome.scene.op_name, "link2");
        assert_eq!((welcome.scene.n, welcome.scene.m, welcome.scene.kind), (4, 2, SceneKind::Planar));
        let shape = SessionShape { kind: SceneKind::Planar, n: 4, nq: 4, m: 2 };
        let sender = DatagramSender::new(session.connection.clone());
        let mut receiver = DatagramReceiver::new(session.connection.clone(), shape);

        // Follow the VE with the paper's hand wrench for 300 snapshots.
        let mut last_seq = 0;
        let mut first_pose = None;
        let mut pose = Vec::new();
        for seq in 1..=300u64 {
            let Datagram::Snapshot(snapshot) = receiver.recv().await.expect("snapshot") else {
                panic!("the server sent an uplink")
            };
            assert!(snapshot.seq > last_seq, "snapshots arrive newest-first or not at all");
            last_seq = snapshot.seq;
            assert_eq!(snapshot.user_id, welcome.user_id);
            first_pose.get_or_insert_with(|| snapshot.op_pose.clone());
            pose = snapshot.op_pose.clone();
            let uplink = Uplink {
                seq,
                client_time_s: seq as f64 * 1e-3,
                last_snapshot_seq: snapshot.seq,
                last_snapshot_age_s: 0.0,
                hand_wrench: PAPER_WRENCH.to_vec(),
                device_pose: snapshot.op_pose.clone(),
                device_twist: snapshot.op_twist.clone(),
                model_pose: snapshot.op_pose.clone(),
                model_twist: snapshot.op_twist.clone(),
                flags: 0,
                energy: kinloop_protocol::PortEnergy::zero(snapshot.op_twist.len()),
            };
            sender.send(&Datagram::Uplink(uplink)).expect("uplink sent");
        }
        let moved = (pose[0] - first_pose.unwrap()[0]).abs();
        assert!(moved > 1e-4, "the hand wrench did not move the linkage ({moved} m)");
        let stats = server.stats();
        assert_eq!(stats.users, 1);
        assert!(stats.per_user[0].uplinks_received > 0);
        assert!(stats.per_user[0].snapshots_sent >= 300);

        // A wrong token learns only that it is wrong; an observer token cannot manipulate.
        match join(&server, "wrong-token", Role::Manipulator).await {
            Err(ConnectError::Refused(refused)) => {
                assert_eq!(refused.reason, RefusalReason::BadToken);
                assert!(refused.message.is_empty());
            }
            other => panic!("expected BadToken, got {other:?}"),
        }
        match join(&server, "watch-token", Role::Manipulator).await {
            Err(ConnectError::Refused(refused)) => assert_eq!(refused.reason, RefusalReason::RoleNotAllowed),
            other => panic!("expected RoleNotAllowed, got {other:?}"),
        }

        // Shutdown tells the client to leave before closing.
        let mut control = session.recv;
        let mut send = session.send;
        let shutdown = tokio::spawn(server.shutdown());
        match recv_control(&mut control).await {
            Ok(Control::Leave { .. }) => {}
            other => panic!("expected Leave, got {other:?}"),
        }
        let _ = send_control(&mut send, &Control::Leave { reason: "ok".into() }).await;
        session.connection.close(0u32.into(), b"bye");
        let stats = shutdown.await.unwrap().expect("clean shutdown");
        assert!(stats.ve.step_time.samples > 300);
        assert_eq!(stats.ve.core.state_restores, 0);
        assert!(stats.ve.core.uplinks_accepted > 0);
    })
    .await;
}
