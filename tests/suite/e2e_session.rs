//! End to end over real QUIC on 127.0.0.1: a multi-user session through the server and client drivers,
//! the refusals a user meets through them, and the scene errors `kinloop-server --scene` reports.

use crate::common;

use std::time::Duration;

use common::live::{self, OPS};
use common::records::{self, linear};
use kinloop_client::device::DevicePreset;
use kinloop_client::driver::{Client, ClientError};
use kinloop_linkage::math::space::SceneKind;
use kinloop_protocol::quic::{ConnectError, ServerIdentity, Trust, CERT_FILE};
use kinloop_protocol::{Hello, RefusalReason, PROTOCOL_VERSION};
use kinloop_server::driver::load_scene;
use kinloop_server::{Access, Identity, Server, ServerConfig};

/// Three users, each on their own device and operational point of the paper's testbed, push it together
/// for 2 s: every one of them gets snapshots and renders force within its own device's limits, the loop
/// stays closed, and when they leave the server sees every user go.
#[test]
fn three_users_manipulate_the_testbed_together_and_leave_cleanly() {
    let _bounded =
        common::bounded("three_users_manipulate_the_testbed_together_and_leave_cleanly", Duration::from_secs(40));
    let dir = common::temp_dir();
    let rt = live::runtime();
    let mut config = live::server_config();
    config.record = Some(dir.path().join("ve.csv"));
    let server = live::start_server(&rt, config);

    // Two kinds of device. Not the Touch: at 400 N/m it cannot render the testbed's closure stiffly, its
    // user drifts about 1 cm from the OP even alone, and a session mixing it with stiff devices is marginal
    // (README, known limits; in virtual time it stays bounded, in real time on a loaded machine it did not).
    let devices = [DevicePreset::Paper, DevicePreset::Falcon, DevicePreset::Paper];
    let share = live::paper_share(3);
    let clients: Vec<_> = OPS
        .iter()
        .zip(devices)
        .enumerate()
        .map(|(i, (op, device))| {
            let name = format!("user{i}");
            let mut config =
                live::recorded_client_of(&server, &name, op, &share, &dir.path().join(format!("{name}.csv")));
            config.device = Some(device);
            let client = live::start_client(config);
            assert_eq!(client.welcome().scene.op_name, *op);
            client
        })
        .collect();
    common::wait_until("three users in the VE", Duration::from_secs(5), || server.stats().users == 3);
    std::thread::sleep(Duration::from_secs(2));

    let ids: Vec<u32> = clients.iter().map(|c| c.welcome().user_id).collect();
    let finals: Vec<_> = clients.into_iter().map(|c| c.shutdown()).collect();
    // Leaving users are no longer counted at once; they are removed once their coupling has faded out.
    let left = common::wait_until("every user gone from the VE", Duration::from_secs(5), || {
        let ve = server.stats().ve.core;
        ve.users == 0 && ve.users_left == 3
    });
    let stats = live::stop_server(&rt, server);

    println!(
        "VE: {} ticks, closure max {:.2e} m, step p99 {} ns, misses {}, users left after {left:?}",
        stats.ve.core.ticks, stats.ve.core.max_closure_error, stats.ve.step_time.p99_ns, stats.ve.deadline_misses
    );
    assert!(stats.ve.core.max_closure_error <= 1e-6, "loop closure {:.3e} m", stats.ve.core.max_closure_error);
    assert_eq!(stats.ve.core.state_restores, 0);
    assert_eq!((stats.ve.core.users_joined, stats.ve.core.users_left), (3, 3));
    assert_eq!(stats.per_user.len(), 3);
    for u in &stats.per_user {
        assert!(!u.connected, "{} still connected", u.name);
        // Traffic flowed the whole session: a quarter of the nominal 2000 each way. Not a rate check (rates
        // belong to benchmarks): three 1 kHz loops and the VE share two cores here, and host stalls on this VM
        // cost the loops whole ticks (975 uplinks in 2 s seen on a bad run).
        assert!(u.uplinks_received > 500, "{}: {} uplinks in 2 s", u.name, u.uplinks_received);
        assert!(u.snapshots_sent > 500, "{}: {} snapshots in 2 s", u.name, u.snapshots_sent);
    }

    let steps = records::ve_steps(&dir.path().join("ve.csv"));
    assert!(steps.iter().all(|s| s.closure_error <= 1e-6), "the recorded closure error stays within 1e-6 m");
    for (i, (client, device)) in finals.iter().zip(devices).enumerate() {
        let spec = device.spec(SceneKind::Planar).unwrap();
        let ticks = records::client_ticks(&dir.path().join(format!("user{i}.csv")));
        let peak = ticks.iter().map(|t| linear(t.command)).fold(0.0, f64::max);
        let peak_torque = ticks.iter().map(|t| t.command[2].abs()).fold(0.0, f64::max);
        let core = client.core.unwrap_or_default();
        println!(
            "user{i} ({}): {} ticks, {} snapshots, force ratio {:.3}, peak {peak:.3} N / {} N, torque {peak_torque:.4} N m, tracking rms {:.3} mm, rtt {:?} ms",
            device.name(), client.lateness.ticks, client.snapshots_received, client.max_force_ratio,
            spec.max_force_n, core.tracking_error_rms() * 1e3, client.rtt_ms_p50
        );
        assert!(client.max_force_ratio <= 1.0 && client.max_force_ratio > 0.0, "user{i}: {}", client.max_force_ratio);
        // The limit checked again on what was recorded, independently of the core's own account.
        assert!(peak <= spec.max_force_n * (1.0 + 1e-6), "user{i}: {peak} N over {} N", spec.max_force_n);
        assert!(peak_torque <= spec.max_torque_nm + 1e-6, "user{i}: {peak_torque} N m over {}", spec.max_torque_nm);
        assert!(ticks.iter().any(|t| t.gain >= 1.0), "user{i}: the force ramped in");
        // A quarter of the nominal 2000, like the server's counts above: a CI run on this VM delivered 972 in
        // 2 s while its host cost the VE 464 deadline misses in 2485 ticks (not a fault of the session).
        assert!(client.snapshots_received > 500, "user{i}: {} snapshots in 2 s", client.snapshots_received);
        assert_eq!(core.non_finite_events, 0);
        assert_eq!(client.reconnects, 0);
        // The user held the linkage: its operational point in the VE moved under the shared push.
        let ops: Vec<_> = steps.iter().filter_map(|s| s.users.iter().find(|u| u.user_id == ids[i])).collect();
        let moved = linear([ops[ops.len() - 1].op[0] - ops[0].op[0], ops[ops.len() - 1].op[1] - ops[0].op[1], 0.0]);
        println!("user{i}: OP moved {:.2} mm", moved * 1e3);
    }
    let link2: Vec<_> = steps.iter().filter_map(|s| s.users.iter().find(|u| u.user_id == ids[0])).collect();
    let moved = (link2[link2.len() - 1].op[0] - link2[0].op[0]).hypot(link2[link2.len() - 1].op[1] - link2[0].op[1]);
    assert!(moved > 1e-3, "the shared push moved link 2 by only {moved} m");
}

fn refused_start(config: kinloop_client::driver::ClientConfig) -> (ConnectError, String) {
    match Client::start(config) {
        Err(ClientError::Connect { source, .. }) => {
            let message = source.to_string();
            (source, message)
        }
        Err(other) => panic!("expected a connection refusal, got {other}"),
        Ok(client) => {
            let welcome = client.welcome().clone();
            client.shutdown();
            panic!("the client was admitted: {welcome:?}")
        }
    }
}

/// Through the drivers: a wrong token, a pinned fingerprint or CA file of another server, and another
/// protocol version are each refused with a typed reason the user can act on (the token is never echoed),
/// `Client::start` returns instead of retrying, and the server carries on admitting the right client.
#[test]
fn wrong_token_certificate_and_version_are_refused_clearly_and_the_server_carries_on() {
    let _bounded = common::bounded(
        "wrong_token_certificate_and_version_are_refused_clearly_and_the_server_carries_on",
        Duration::from_secs(40),
    );
    let dir = common::temp_dir();
    let rt = live::runtime();
    let mut config = live::server_config();
    config.access = Access::parse("right-token\n", "tokens.txt").expect("token file");
    config.identity = Identity::CertDir(dir.path().join("server"));
    let server = live::start_server(&rt, config);
    let share = live::paper_share(1);
    let client = |name: &str, token: &str| {
        let mut config = live::client_of(&server, name, "link2", &share);
        config.token = token.into();
        config
    };

    let (error, message) = refused_start(client("guesser", "wrong-token"));
    match error {
        ConnectError::Refused(refused) => {
            assert_eq!(refused.reason, RefusalReason::BadToken);
            assert!(refused.message.is_empty(), "a wrong token learns nothing more: {:?}", refused.message);
        }
        other => panic!("expected BadToken, got {other:?}"),
    }
    assert!(message.contains("access token was not accepted") && !message.contains("right-token"), "{message}");

    let stranger = ServerIdentity::load_or_create(&dir.path().join("stranger")).expect("another identity");
    let mut pinned_elsewhere = client("pinned", "right-token");
    pinned_elsewhere.trust = Trust::Fingerprint(stranger.fingerprint.clone());
    let mut other_ca = client("other-ca", "right-token");
    other_ca.trust = Trust::CaFile(dir.path().join("stranger").join(CERT_FILE));
    for config in [pinned_elsewhere, other_ca] {
        let name = config.client_name.clone();
        let (error, message) = refused_start(config);
        assert!(matches!(error, ConnectError::UntrustedCertificate { .. }), "{name}: {error:?}");
        assert!(message.starts_with("untrusted server certificate"), "{name}: {message}");
        if name == "pinned" {
            // Both fingerprints, so the user can tell a moved server from an impostor.
            assert!(message.contains(&stranger.fingerprint) && message.contains(server.fingerprint()), "{message}");
        }
    }

    let version = PROTOCOL_VERSION + 1;
    let (hello, join) = live::paper_handshake("from the future", "link2", "right-token");
    let (endpoint, refused) = live::raw_session(&rt, &server, &(Hello { version, ..hello }, join));
    rt.block_on(endpoint.wait_idle());
    match refused {
        Err(ConnectError::Refused(r)) => {
            assert_eq!(r.reason, RefusalReason::UnsupportedVersion { server: PROTOCOL_VERSION, client: version })
        }
        other => panic!("expected UnsupportedVersion, got {other:?}"),
    }

    // The CA file of the server's own certificate directory, and the right token: admitted.
    let mut good = client("welcome", "right-token");
    good.trust = Trust::CaFile(dir.path().join("server").join(CERT_FILE));
    let good = live::start_client(good);
    common::wait_until("snapshots reach the admitted client", Duration::from_secs(5), || {
        good.stats().snapshots_received > 100
    });
    let admitted = good.shutdown();
    let stats = live::stop_server(&rt, server);
    println!("refusals: {message}; admitted client then got {} snapshots", admitted.snapshots_received);
    assert_eq!(stats.per_user.len(), 1, "only the admitted client became a user");
    assert_eq!(stats.per_user[0].name, "welcome");
    assert_eq!(stats.ve.core.users_joined, 1);
    assert_eq!(admitted.reconnects, 0);
}

/// What `kinloop-server --scene FILE` does with a broken file (the driver's scene loader, then the server's
/// compilation of it): a clear error naming the file and the offending key, and no server. The
/// validation rules themselves are linkage's tests; this is the path from a file on disk to the message.
#[test]
fn malformed_scene_files_are_refused_naming_the_file_and_the_key() {
    let _bounded =
        common::bounded("malformed_scene_files_are_refused_naming_the_file_and_the_key", Duration::from_secs(20));
    let dir = common::temp_dir();
    let testbed = kinloop_linkage::model::builtin::SCENE_FILES
        .iter()
        .find(|(name, _)| *name == "paper-testbed")
        .map(|(_, text)| *text)
        .expect("the testbed's scene file");
    let edit = |from: &str, to: &str| {
        assert!(testbed.contains(from), "fixture: {from}");
        testbed.replacen(from, to, 1)
    };
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        ("unclosed-table.toml", edit("[[body]]", "[[body]\n"), vec!["unclosed-table.toml", "line"]),
        ("negative-mass.toml", edit("mass = 0.5", "mass = -0.5"), vec!["body[3] (link4).mass", "positive"]),
        (
            "unknown-body.toml",
            edit("body = \"link2\"\npoint", "body = \"link9\"\npoint"),
            vec!["op[0]", "unknown body 'link9'", "link1, link2"],
        ),
        (
            "open-loop.toml",
            edit("body_b = \"ground\"", "body_b = \"ground\"\npoint_b = [0.05, 0.05]"),
            vec!["cut[0] (tip-pin)", "not closed at q0", "--assemble"],
        ),
    ];
    let rt = live::runtime();
    for (file, text, expected) in cases {
        let path = dir.path().join(file);
        std::fs::write(&path, text).unwrap();
        let message = match load_scene(path.to_str().unwrap()) {
            Err(e) => e.to_string(),
            Ok((scene, label)) => {
                let _inside = rt.enter();
                match Server::start(ServerConfig::new(scene, label, live::LOOPBACK)) {
                    Err(e) => e.to_string(),
                    Ok(server) => {
                        drop(server);
                        panic!("{file}: the server started")
                    }
                }
            }
        };
        println!("{file}: {message}");
        assert!(message.contains(&path.display().to_string()), "{file}: the message names the file: {message}");
        for e in expected {
            assert!(message.contains(e), "{file}: expected {e:?} in {message}");
        }
    }
    let missing = dir.path().join("missing.toml");
    let message = load_scene(missing.to_str().unwrap()).expect_err("no such file").to_string();
    assert!(message.contains(&missing.display().to_string()) && message.contains("cannot read"), "{message}");
}
