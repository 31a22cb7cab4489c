//! Real QUIC over 127.0.0.1: the handshake, its distinct failures, datagrams, oversize snapshots and the
//! emulated link's delay. Every test is bounded by a timeout and uses ephemeral ports.

use std::future::Future;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use kinloop_protocol::bench::{testbed_shape, testbed_snapshot};
use kinloop_protocol::emulator::LinkConfig;
use kinloop_protocol::quic::*;
use kinloop_protocol::*;
use tokio::task::JoinHandle;

const TEST_TIMEOUT: Duration = Duration::from_secs(30);
const TOKEN: &str = "let-me-in";

async fn bounded<T>(test: impl Future<Output = T>) -> T {
    tokio::time::timeout(TEST_TIMEOUT, test).await.expect("test exceeded its time bound")
}

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn options() -> EndpointOptions {
    EndpointOptions { client_bind: loopback(), ..EndpointOptions::default() }
}

fn hello(version: u16, token: &str) -> Hello {
    Hello {
        version,
        token: token.into(),
        client_name: "test-client".into(),
        role: Role::Manipulator,
        room: String::new(),
    }
}

/// The join the tests make: the first operational point the scene offers, with a small desktop device.
fn join_first(scene: &SceneInfo) -> Result<Join, String> {
    let op = scene.ops.first().cloned().ok_or("no operational point")?;
    let device = DeviceCaps { max_force_n: 5.0, continuous_force_n: 2.0, ..DeviceCaps::generous("simulated", 3) };
    Ok(Join { op, device, form: LocalModelForm::OpSpace, mapping: MappingRequest::default() })
}

/// The tiny admission the handshake tests use: one token, the planar testbed scene with OP `ee`.
fn admit(hello: &Hello) -> Result<SceneInfo, Refused> {
    if hello.token != TOKEN {
        return Err(Refused { reason: RefusalReason::BadToken, message: String::new() });
    }
    Ok(SceneInfo { name: "testbed".into(), kind: SceneKind::Planar, ops: vec!["ee".into()] })
}

/// The tiny decision on a join: `ee` only.
fn decide(_hello: &Hello, join: &Join) -> Result<Welcome, Refused> {
    if join.op != "ee" {
        let reason = RefusalReason::UnknownOp { requested: join.op.clone(), available: vec!["ee".into()] };
        return Err(Refused { reason, message: String::new() });
    }
    let shape = testbed_shape();
    Ok(Welcome {
        session_id: 77,
        user_id: 1,
        scene: SceneSummary {
            name: "testbed".into(),
            kind: shape.kind,
            n: shape.n as u32,
            m: shape.m as u32,
            ball_rates: Vec::new(),
            op_dim: 3,
            op_name: "ee".into(),
            length_scale: 0.05,
        },
        ve_rate_hz: 1000.0,
        snapshot_rate_hz: 1000.0,
        mapping: Mapping::identity(),
        coupling: CouplingGains { stiffness: vec![500.0; 3], damping: vec![2.0; 3] },
        op: OpSummary {
            position: vec![0.0; 2],
            reach_min: vec![-0.1; 2],
            reach_max: vec![0.1; 2],
            tour: Vec::new(),
            static_force_n: 0.0,
            static_torque_nm: 0.0,
            inverse_mass_max: 1.0,
            inverse_rotational_inertia_max: 100.0,
            path: Vec::new(),
            path_rest_acceleration: None,
            path_shape: PathShape::Open,
        },
    })
}

struct TestServer {
    addr: SocketAddr,
    identity: ServerIdentity,
    session: JoinHandle<Result<AcceptedSession, AcceptError>>,
}

/// A server that accepts one connection and runs the handshake with [`admit`] and [`decide`].
fn start_server(opts: &EndpointOptions) -> TestServer {
    let identity = ServerIdentity::generate(&DEFAULT_NAMES).unwrap();
    let endpoint = server_endpoint(loopback(), &identity, opts).unwrap();
    let addr = endpoint.local_addr().unwrap();
    let accepting = endpoint.clone();
    let session = tokio::spawn(async move {
        let incoming = accepting.accept().await.expect("endpoint open");
        accept(incoming, admit, decide).await
    });
    TestServer { addr, identity, session }
}

async fn connect_with(
    server: &TestServer,
    trust: Trust,
    opts: &EndpointOptions,
    hello: &Hello,
) -> Result<ConnectedSession, ConnectError> {
    let client = client_endpoint(&trust, opts).unwrap();
    connect(&client, server.addr, "localhost", hello, join_first).await
}

fn pinned(server: &TestServer) -> Trust {
    Trust::Fingerprint(server.identity.fingerprint.clone())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn handshake_then_snapshots_and_uplinks_flow_as_datagrams() {
    bounded(async {
        let server = start_server(&options());
        let client = connect_with(&server, pinned(&server), &options(), &hello(PROTOCOL_VERSION, TOKEN)).await.unwrap();
        let accepted = server.session.await.unwrap().unwrap();
        assert_eq!(client.welcome.session_id, 77);
        assert_eq!(accepted.hello.client_name, "test-client");

        let shape = testbed_shape();
        let to_client = DatagramSender::new(accepted.connection.clone());
        let mut at_client = DatagramReceiver::new(client.connection.clone(), shape);
        let snapshot = Datagram::Snapshot(testbed_snapshot());
        assert_eq!(to_client.send(&snapshot).unwrap(), Route::Datagram);
        assert_eq!(at_client.recv().await.unwrap(), snapshot);

        let uplink = Datagram::Uplink(Uplink {
            seq: 1,
            client_time_s: 0.001,
            last_snapshot_seq: 123_456,
            last_snapshot_age_s: 0.0005,
            hand_wrench: vec![1.0, 0.0, 0.0],
            device_pose: vec![0.0; 3],
            device_twist: vec![0.0; 3],
            model_pose: vec![0.0; 3],
            model_twist: vec![0.0; 3],
            flags: 0,
            energy: PortEnergy::zero(3),
        });
        let mut at_server = DatagramReceiver::new(accepted.connection.clone(), shape);
        DatagramSender::new(client.connection.clone()).send(&uplink).unwrap();
        assert_eq!(at_server.recv().await.unwrap(), uplink);
        assert_eq!(at_client.stats().datagrams, 1);
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversize_snapshot_travels_on_a_stream_and_arrives_whole() {
    bounded(async {
        let server = start_server(&options());
        let client = connect_with(&server, pinned(&server), &options(), &hello(PROTOCOL_VERSION, TOKEN)).await.unwrap();
        let accepted = server.session.await.unwrap().unwrap();

        // Configuration-space terms of a 40-coordinate scene: ≈ 14 KB, far over the ≈ 1.2 KB datagram limit.
        let shape = SessionShape { kind: SceneKind::Planar, n: 40, nq: 40, m: 8 };
        let mut snapshot = testbed_snapshot();
        snapshot.config = Some(ConfigTerms {
            q: vec![0.1; 40],
            qd: vec![0.0; 40],
            mass_matrix: vec![0.5; triangle_len(40)],
            closure_jacobian: vec![0.25; 8 * 40],
            closure_bias_stab: vec![0.0; 8],
            generalized_bias: vec![1.0; 40],
            op_jacobian: vec![0.5; 3 * 40],
            op_bias: vec![0.0; 3],
        });
        let snapshot = Datagram::Snapshot(snapshot);
        let encoded_len = codec::encode_datagram(&snapshot).unwrap().len();
        assert!(encoded_len > accepted.connection.max_datagram_size().unwrap());

        let sender = DatagramSender::new(accepted.connection.clone());
        let mut receiver = DatagramReceiver::new(client.connection.clone(), shape);
        assert_eq!(sender.send(&snapshot).unwrap(), Route::Stream);
        assert_eq!(receiver.recv().await.unwrap(), snapshot);
        assert_eq!(sender.stats().oversize_streams, 1);
        assert_eq!(receiver.stats().oversize_streams, 1);
        assert_eq!(sender.stats().oversize_failed, 0);
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn injected_25ms_each_way_gives_a_50ms_round_trip() {
    bounded(async {
        let delayed = EndpointOptions {
            link: Some(LinkConfig { delay: Duration::from_millis(25), ..LinkConfig::default() }),
            ..options()
        };
        let server = start_server(&delayed);
        let (client_endpoint, link_stats) = client_endpoint_with_link_stats(&pinned(&server), &delayed).unwrap();
        let client = connect(&client_endpoint, server.addr, "localhost", &hello(PROTOCOL_VERSION, TOKEN), join_first)
            .await
            .unwrap();
        let mut accepted = server.session.await.unwrap().unwrap();
        let echo = tokio::spawn(async move {
            while let Ok(Control::Ping { nonce, t_s }) = recv_control(&mut accepted.recv).await {
                send_control(&mut accepted.send, &Control::Pong { nonce, t_s }).await.unwrap();
            }
        });

        let (mut send, mut recv) = (client.send, client.recv);
        let mut rtts_ms = Vec::new();
        for nonce in 0..10 {
            let start = Instant::now();
            send_control(&mut send, &Control::Ping { nonce, t_s: 0.0 }).await.unwrap();
            match recv_control(&mut recv).await.unwrap() {
                Control::Pong { nonce: echoed, .. } => assert_eq!(echoed, nonce),
                other => panic!("expected Pong, got {other:?}"),
            }
            rtts_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        rtts_ms.sort_by(f64::total_cmp);
        let median = rtts_ms[rtts_ms.len() / 2];
        assert!((45.0..80.0).contains(&median), "ping/pong RTT {median} ms ({rtts_ms:?})");
        let quic_rtt = client.connection.rtt().as_secs_f64() * 1e3;
        eprintln!("ping/pong RTT median {median:.1} ms, QUIC RTT estimate {quic_rtt:.1} ms");
        assert!((45.0..80.0).contains(&quic_rtt), "QUIC RTT estimate {quic_rtt} ms");
        let sent_through_link = link_stats.expect("a delayed link is emulated").get().link;
        assert!(sent_through_link.sent >= 10 && sent_through_link.delivered > 0, "{sent_through_link:?}");
        echo.abort();
    })
    .await
}

/// What each side saw of a handshake that was meant to fail.
struct FailedHandshake {
    client: ConnectError,
    server: Result<AcceptedSession, AcceptError>,
    server_fingerprint: String,
}

async fn failed_handshake(client_opts: EndpointOptions, trust: Option<Trust>, hello: Hello) -> FailedHandshake {
    bounded(async {
        let server = start_server(&options());
        let trust = trust.unwrap_or_else(|| pinned(&server));
        let client = connect_with(&server, trust, &client_opts, &hello).await.expect_err("handshake must fail");
        FailedHandshake {
            client,
            server: server.session.await.unwrap(),
            server_fingerprint: server.identity.fingerprint.clone(),
        }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_alpn_is_reported_as_no_common_protocol() {
    let other_protocol = EndpointOptions { alpn_protocols: vec![b"other/1".to_vec()], ..options() };
    let failed = failed_handshake(other_protocol, None, hello(PROTOCOL_VERSION, TOKEN)).await;
    assert!(matches!(failed.client, ConnectError::Alpn), "{:?}", failed.client);
    assert!(matches!(failed.server, Err(AcceptError::Connection(_))));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_protocol_version_is_refused_with_both_versions() {
    let failed = failed_handshake(options(), None, hello(PROTOCOL_VERSION + 1, TOKEN)).await;
    let expected = RefusalReason::UnsupportedVersion { server: PROTOCOL_VERSION, client: PROTOCOL_VERSION + 1 };
    assert!(matches!(&failed.client, ConnectError::Refused(r) if r.reason == expected), "{:?}", failed.client);
    assert!(matches!(failed.server, Err(AcceptError::Refused(_))));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_token_is_refused_as_bad_token() {
    let failed = failed_handshake(options(), None, hello(PROTOCOL_VERSION, "guess")).await;
    let error = failed.client;
    assert!(matches!(&error, ConnectError::Refused(r) if r.reason == RefusalReason::BadToken), "{error:?}");
    assert_eq!(error.to_string(), "the server refused: the access token was not accepted");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn untrusted_certificate_is_reported_with_both_fingerprints() {
    let stranger = ServerIdentity::generate(&DEFAULT_NAMES).unwrap();
    let trust = Trust::Fingerprint(stranger.fingerprint.clone());
    let failed = failed_handshake(options(), Some(trust), hello(PROTOCOL_VERSION, TOKEN)).await;
    match failed.client {
        ConnectError::UntrustedCertificate { expected, got } => {
            assert_eq!(expected, stranger.fingerprint);
            assert_eq!(got, failed.server_fingerprint);
        }
        other => panic!("expected UntrustedCertificate, got {other:?}"),
    }
    assert!(matches!(failed.server, Err(AcceptError::Connection(_))));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ca_file_trusts_the_stored_certificate_and_no_other() {
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let identity = ServerIdentity::load_or_create(dir.path()).unwrap();
        let endpoint = server_endpoint(loopback(), &identity, &options()).unwrap();
        let addr = endpoint.local_addr().unwrap();
        let accepting = endpoint.clone();
        tokio::spawn(async move {
            while let Some(incoming) = accepting.accept().await {
                tokio::spawn(async move {
                    // Keep each session until the client closes it, or the welcome may never leave.
                    if let Ok(session) = accept(incoming, admit, decide).await {
                        session.connection.closed().await;
                    }
                });
            }
        });
        let trusted = client_endpoint(&Trust::CaFile(dir.path().join(CERT_FILE)), &options()).unwrap();
        connect(&trusted, addr, "localhost", &hello(PROTOCOL_VERSION, TOKEN), join_first).await.unwrap();

        let other_dir = tempfile::tempdir().unwrap();
        ServerIdentity::load_or_create(other_dir.path()).unwrap();
        let untrusting = client_endpoint(&Trust::CaFile(other_dir.path().join(CERT_FILE)), &options()).unwrap();
        let error =
            connect(&untrusting, addr, "localhost", &hello(PROTOCOL_VERSION, TOKEN), join_first).await.unwrap_err();
        assert!(matches!(error, ConnectError::UntrustedCertificate { .. }), "{error:?}");
    })
    .await
}

#[test]
fn identity_is_made_once_then_reused_with_a_private_key_file() {
    let dir = tempfile::tempdir().unwrap();
    let first = ServerIdentity::load_or_create(dir.path()).unwrap();
    let second = ServerIdentity::load_or_create(dir.path()).unwrap();
    assert_eq!(first.fingerprint, second.fingerprint);
    assert_eq!(first.fingerprint.len(), 64);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(dir.path().join(KEY_FILE)).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    std::fs::remove_file(dir.path().join(KEY_FILE)).unwrap();
    assert!(matches!(ServerIdentity::load_or_create(dir.path()), Err(IdentityError::HalfPresent { .. })));
}

#[tokio::test]
async fn fingerprints_are_accepted_with_colons_and_capitals_and_garbage_is_refused() {
    let hex = "ab".repeat(32);
    let openssl_style = vec!["AB"; 32].join(":");
    assert_eq!(normalize_fingerprint(&openssl_style), Some(hex.clone()));
    assert_eq!(normalize_fingerprint(&hex[..62]), None);
    let error = client_endpoint(&Trust::Fingerprint("nope".into()), &options()).unwrap_err();
    assert!(matches!(error, EndpointError::Trust(TrustError::BadFingerprint(_))), "{error:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_sees_the_scene_before_it_joins_and_may_decline() {
    bounded(async {
        let server = start_server(&options());
        let client = client_endpoint(&pinned(&server), &options()).unwrap();
        let mut seen = None;
        let error = connect(&client, server.addr, "localhost", &hello(PROTOCOL_VERSION, TOKEN), |scene| {
            seen = Some(scene.clone());
            Err(format!("no device for a {:?} scene", scene.kind))
        })
        .await
        .unwrap_err();
        assert_eq!(seen.map(|s| s.ops), Some(vec!["ee".to_string()]));
        assert!(matches!(&error, ConnectError::Declined(why) if why.contains("Planar")), "{error}");
        match server.session.await.unwrap() {
            Err(AcceptError::Declined(why)) => assert!(why.contains("no device"), "{why}"),
            other => panic!("the server should see the client decline: {other:?}"),
        }
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_join_for_an_unknown_op_is_refused_after_the_scene_info() {
    bounded(async {
        let server = start_server(&options());
        let client = client_endpoint(&pinned(&server), &options()).unwrap();
        let error = connect(&client, server.addr, "localhost", &hello(PROTOCOL_VERSION, TOKEN), |scene| {
            join_first(scene).map(|join| Join { op: "knee".into(), ..join })
        })
        .await
        .unwrap_err();
        match error {
            ConnectError::Refused(Refused { reason: RefusalReason::UnknownOp { requested, available }, .. }) => {
                assert_eq!((requested.as_str(), available), ("knee", vec!["ee".to_string()]));
            }
            other => panic!("expected an unknown-op refusal, got {other}"),
        }
    })
    .await;
}

/// A join that fails the wire's checks is answered with a refusal naming the field, not a silent close:
/// the device's numbers (or the scales asked for) as the device's problem, anything else as malformed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_join_that_fails_the_wires_checks_is_refused_naming_the_field() {
    /// How a case spoils a good join, the field the refusal names, and whether it is the device's problem.
    type Case = (fn(Join) -> Join, &'static str, bool);
    let cases: [Case; 3] = [
        (
            |j| Join { device: DeviceCaps { max_force_n: -1.0, ..j.device.clone() }, ..j },
            "join.device.max_force_n",
            true,
        ),
        (
            |j| Join { mapping: MappingRequest { force_scale: Some(f64::NAN), ..j.mapping.clone() }, ..j },
            "join.mapping.force_scale",
            true,
        ),
        (|j| Join { op: "x".repeat(10_000), ..j }, "join.op", false),
    ];
    for (spoil, field, device) in cases {
        bounded(async {
            let server = start_server(&options());
            let client = client_endpoint(&pinned(&server), &options()).unwrap();
            let hello = hello(PROTOCOL_VERSION, TOKEN);
            let error = connect(&client, server.addr, "localhost", &hello, |scene| join_first(scene).map(spoil))
                .await
                .unwrap_err();
            let reason = match &error {
                ConnectError::Refused(refused) => &refused.reason,
                other => panic!("{field}: expected a refusal, got {other:?}"),
            };
            assert_eq!(matches!(reason, RefusalReason::Device { .. }), device, "{field}: {reason:?}");
            assert!(matches!(reason, RefusalReason::Device { .. } | RefusalReason::Malformed { .. }), "{reason:?}");
            assert!(error.to_string().contains(field), "{field}: {error}");
            assert!(matches!(server.session.await.unwrap(), Err(AcceptError::Refused(_))), "{field}");
        })
        .await;
    }
}
