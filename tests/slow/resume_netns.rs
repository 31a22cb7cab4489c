//! A room that survives its server across hosts: servers A and B each in a network namespace of their own,
//! with their own addresses on their own veth links (made by the test; it needs root, as CI runs, and fails
//! rather than skips without it); the client in the test's namespace. A is killed with SIGKILL mid-session
//! and the client moves to B, at another address, which resumes the linkage where A had it. See
//! docs/resume.md.

use crate::common;

use std::net::SocketAddr;
use std::process::Command;
use std::time::{Duration, Instant};

use common::child::ChildProcess;
use common::records;
use common::resume::{self, Moved};

/// Runs `ip ARGS`; panics naming the command and what it said when it fails.
fn ip(args: &[&str]) {
    let output = Command::new("ip").args(args).output().unwrap_or_else(|e| panic!("ip {args:?}: {e}"));
    assert!(
        output.status.success(),
        "ip {} failed (this test needs root and network namespaces): {}",
        args.join(" "),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Two namespaces, each joined to the test's by a veth pair on a /24 of its own; removed when dropped.
struct Hosts {
    names: Vec<String>,
}

impl Hosts {
    /// Namespaces `{prefix}a` and `{prefix}b` at `10.{net}.1.1` and `10.{net}.2.1` (the test's ends at `.2`).
    fn make(prefix: &str, net: u8) -> (Hosts, [String; 2]) {
        let mut hosts = Hosts { names: Vec::new() };
        let mut addresses = [String::new(), String::new()];
        for (i, side) in ["a", "b"].into_iter().enumerate() {
            let ns = format!("{prefix}{side}");
            let (outer, inner) = (format!("{prefix}{side}o"), format!("{prefix}{side}i"));
            let _ = Command::new("ip").args(["netns", "del", &ns]).output();
            ip(&["netns", "add", &ns]);
            hosts.names.push(ns.clone());
            ip(&["link", "add", &outer, "type", "veth", "peer", "name", &inner]);
            ip(&["link", "set", &inner, "netns", &ns]);
            ip(&["addr", "add", &format!("10.{net}.{}.2/24", i + 1), "dev", &outer]);
            ip(&["link", "set", &outer, "up"]);
            ip(&["netns", "exec", &ns, "ip", "addr", "add", &format!("10.{net}.{}.1/24", i + 1), "dev", &inner]);
            ip(&["netns", "exec", &ns, "ip", "link", "set", &inner, "up"]);
            ip(&["netns", "exec", &ns, "ip", "link", "set", "lo", "up"]);
            addresses[i] = format!("10.{net}.{}.1", i + 1);
        }
        (hosts, addresses)
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Deleting a namespace deletes the veth pair with it.
        for ns in &self.names {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
    }
}

#[test]
fn a_server_killed_on_one_host_is_replaced_on_another_and_the_linkage_resumes() {
    const NAME: &str = "a_server_killed_on_one_host_is_replaced_on_another_and_the_linkage_resumes";
    let stage = resume::Stage::set(NAME);
    let dir = &stage.dir;
    let path = |name: &str| stage.path(name);
    let pid = std::process::id();
    let (hosts, addresses) = Hosts::make(&format!("kl{}", pid % 10_000), 100 + (pid % 100) as u8);
    let mut servers = Vec::new();
    for (side, (ns, address)) in ["a", "b"].into_iter().zip(hosts.names.iter().zip(&addresses)) {
        let listen = format!("{address}:4433").parse().expect("address");
        let role = resume::server_role(dir.path(), side, listen);
        let mut server = ChildProcess::spawn_in_netns(NAME, &role, dir.path(), &format!("server-{side}"), ns);
        let addr: SocketAddr = server.ready(Duration::from_secs(15)).addr;
        servers.push((server, addr));
    }
    let (a_addr, b_addr) = (servers[0].1, servers[1].1);

    let client = resume::start_holder(dir.path(), a_addr, b_addr);
    let client_started = Instant::now();
    let a_user = client.welcome().user_id;
    std::thread::sleep(Duration::from_millis(2500));

    servers[0].0.kill();
    let killed = Instant::now();
    let t_kill = killed.duration_since(client_started).as_secs_f64();
    common::wait_until("the client moves to server B", Duration::from_secs(10), || client.stats().reconnects == 1);
    let back_s = killed.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(1500));
    let stats = client.shutdown();
    let (server_b, _) = &mut servers[1];
    assert!(server_b.stop(Duration::from_secs(10)), "server B stops cleanly:\n{}", server_b.log_tail());

    let moved = Moved::measure(&path("a.csv"), &path("b.csv"), &path("client.csv"), a_user, t_kill);
    let end = *records::client_ticks(&path("client.csv")).last().expect("ticks");
    println!("resume across hosts ({a_addr} → {b_addr}): {moved}; client back on B {back_s:.2} s after the kill");
    moved.assert_goals(back_s);
    assert_eq!(stats.resumes, 1, "B resumed from the client's state");
    assert!(end.gain >= 1.0 && end.snapshot_age < 0.05, "full force again on B: {end:?}");
    for (server, _) in &servers {
        assert!(!server.log().contains("panicked"), "{}", server.log_tail());
    }
}
