//! A room that survives its server, over real QUIC: server A (a child process) holds the paper's four-bar
//! for a client whose hand holds it still; A is killed with SIGKILL; the client moves to server B (another
//! port, the same room key and CA, none of A's disk) offering the state A signed last, and B resumes the
//! linkage where it was. Before the kill, a forged and a stale offer to B are refused and counted.
//! See docs/resume.md.

use crate::common;

use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

use common::child::ChildProcess;
use common::live::{self, OPS};
use common::records;
use common::resume::{self, Moved};
use kinloop_protocol::quic::{client_endpoint, connect_resuming, EndpointOptions, Trust};
use kinloop_protocol::room_key::{unix_ms, RoomKey, MAX_RESUME_AGE};
use kinloop_protocol::{ResumeAnswer, ResumeRefusal, RoomState};

/// Offers `offer` to the room server at `addr` as an observer that leaves right after the handshake; the
/// server's answer.
fn offer_to(rt: &tokio::runtime::Runtime, addr: SocketAddr, ca: &Path, offer: &RoomState) -> ResumeAnswer {
    let (mut hello, join) = live::paper_handshake("prober", OPS[1], "");
    hello.role = kinloop_protocol::Role::Observer;
    rt.block_on(async {
        let options = EndpointOptions { client_bind: live::LOOPBACK, ..EndpointOptions::default() };
        let endpoint = client_endpoint(&Trust::CaFile(ca.to_owned()), &options).expect("client endpoint");
        let session = connect_resuming(&endpoint, addr, "localhost", &hello, Some(offer), |_| Ok(join))
            .await
            .expect("the prober joins (an offer refused still lets a client in)");
        session.connection.close(kinloop_protocol::quic::close_codes::NORMAL, b"done");
        endpoint.wait_idle().await;
        session.resume.expect("an answer to the offer")
    })
}

#[test]
fn a_killed_server_is_replaced_and_the_linkage_resumes_where_it_was() {
    const NAME: &str = "a_killed_server_is_replaced_and_the_linkage_resumes_where_it_was";
    let stage = resume::Stage::set(NAME);
    let (dir, secret) = (&stage.dir, &stage.secret);
    let path = |name: &str| stage.path(name);
    let key = RoomKey::from_bytes(secret).expect("room key");

    let role = resume::server_role(dir.path(), "a", live::LOOPBACK);
    let mut server_a = ChildProcess::spawn(NAME, &role, dir.path(), "server-a");
    let a_addr = server_a.ready(Duration::from_secs(15)).addr;
    let rt = live::runtime();
    let server_b = live::start_server(&rt, resume::room_server(live::server_config(), dir.path(), "b"));
    let b_addr = server_b.local_addr();

    let client = resume::start_holder(dir.path(), a_addr, b_addr);
    let client_started = Instant::now();
    let a_user = client.welcome().user_id;
    std::thread::sleep(Duration::from_millis(2500));

    // B is idle: a forged state (A's, altered) and a stale one (signed with the room's key, but old) are
    // refused, counted, and leave B's room as it was for the authentic offer.
    let authentic = client.room_state().expect("server A sends its clients signed states");
    let mut forged = authentic.clone();
    forged.q[0] += 0.5;
    let mut stale = authentic.clone();
    stale.taken_unix_ms = unix_ms(SystemTime::now()) - 2 * MAX_RESUME_AGE.as_millis() as u64;
    key.sign(&mut stale);
    assert_eq!(offer_to(&rt, b_addr, &path("ca.pem"), &forged), ResumeAnswer::Refused(ResumeRefusal::BadSignature));
    let answer = offer_to(&rt, b_addr, &path("ca.pem"), &stale);
    assert!(matches!(answer, ResumeAnswer::Refused(ResumeRefusal::Stale { .. })), "{answer:?}");
    assert_eq!(server_b.stats().ve.core.resumes_refused, 2, "both refusals counted");
    std::thread::sleep(Duration::from_millis(500));

    server_a.kill();
    let killed = Instant::now();
    let t_kill = killed.duration_since(client_started).as_secs_f64();
    common::wait_until("the client moves to server B", Duration::from_secs(10), || client.stats().reconnects == 1);
    let back_s = killed.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(1500));
    let stats = client.shutdown();
    let b_stats = live::stop_server(&rt, server_b);

    let moved = Moved::measure(&path("a.csv"), &path("b.csv"), &path("client.csv"), a_user, t_kill);
    let end = *records::client_ticks(&path("client.csv")).last().expect("ticks");
    println!(
        "resume: {moved}; client back on B {back_s:.2} s after the kill; B counted {} resumes and {} refusals",
        b_stats.ve.core.resumes_accepted, b_stats.ve.core.resumes_refused,
    );
    moved.assert_goals(back_s);
    assert_eq!(stats.resumes, 1, "B resumed from the client's state");
    assert_eq!(b_stats.ve.core.resumes_accepted, 1);
    assert_eq!(b_stats.ve.core.resumes_refused, 2);
    assert!(end.gain >= 1.0 && end.snapshot_age < 0.05, "full force again on B: {end:?}");
    assert!(!server_a.log().contains("panicked"), "{}", server_a.log_tail());
}

/// When every server of the room is gone, the client fades to zero force and stays there while it keeps
/// looking (it never reconnects, since nothing answers), and its haptic loop runs on.
#[test]
fn a_client_whose_servers_are_all_gone_holds_zero_force_while_it_keeps_looking() {
    const NAME: &str = "a_client_whose_servers_are_all_gone_holds_zero_force_while_it_keeps_looking";
    let stage = resume::Stage::set(NAME);
    let dir = &stage.dir;
    let path = |name: &str| stage.path(name);
    let role = resume::server_role(dir.path(), "a", live::LOOPBACK);
    let mut server_a = ChildProcess::spawn(NAME, &role, dir.path(), "server-a");
    let a_addr = server_a.ready(Duration::from_secs(15)).addr;
    // B's address, with nothing listening on it: a port bound and let go.
    let b_addr = std::net::UdpSocket::bind(live::LOOPBACK).and_then(|s| s.local_addr()).expect("a free port");

    let client = resume::start_holder(dir.path(), a_addr, b_addr);
    let client_started = Instant::now();
    std::thread::sleep(Duration::from_millis(1500));
    server_a.kill();
    let t_kill = client_started.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(3000));
    let t_shutdown = client_started.elapsed().as_secs_f64();
    let stats = client.shutdown();

    assert_eq!(stats.reconnects, 0, "no server answered, so no session was reopened");
    let ticks = records::client_ticks(&path("client.csv"));
    assert!(ticks.iter().any(|t| t.t < t_kill && t.gain >= 1.0), "full force before the kill");
    // Stale after the snapshot age limit, then faded within the fade time; a generous margin for a busy host.
    let settled = t_kill + 1.0;
    let after: Vec<_> = ticks.iter().filter(|t| t.t > settled).collect();
    // The loop ran to the end, at no less than a quarter of its rate (a busy host costs it whole ticks).
    let last = after.last().map_or(0.0, |t| t.t);
    assert!(
        after.len() > 500 && t_shutdown - last < 0.2,
        "the haptic loop ran on while the client looked: {} ticks, the last {:.3} s before the shutdown",
        after.len(),
        t_shutdown - last
    );
    let worst = after.iter().map(|t| t.command.iter().fold(0.0f64, |m, c| m.max(c.abs()))).fold(0.0, f64::max);
    assert!(after.iter().all(|t| t.gain == 0.0), "the gate stayed closed");
    assert_eq!(worst, 0.0, "zero force while no server answers");
}
