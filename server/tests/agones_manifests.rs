//! `deploy/agones/`: the manifests parse, carry every field Agones requires of each kind (as its CRDs'
//! schemas and validation state them: required fields, enums, ranges), and agree with each other and with
//! the server (the `rooms` Counter and `users` List names, the annotations an allocation names its room
//! with, the ports the image listens on, health settings that notice a stalled VE within a few seconds given
//! the server's ping period). The Dockerfile names its bases.

use std::path::PathBuf;

use kinloop_server::fleet::agones::{ROOMS_COUNTER, USERS_LIST};
use kinloop_server::fleet::allocation::room_request;
use kinloop_server::fleet::DEFAULT_HEALTH_PERIOD;
use serde_norway::Value;

/// The longest time Agones may take to notice a stalled VE with the shipped settings (s).
const NOTICE_WITHIN_S: u64 = 5;

fn deploy(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../deploy/agones").join(name)
}

fn manifest(name: &str) -> Value {
    let text = std::fs::read_to_string(deploy(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    serde_norway::from_str(&text).unwrap_or_else(|e| panic!("{name} is not YAML: {e}"))
}

/// The value at a dotted `path` (numbers index sequences); a missing one fails naming the file and path.
fn at<'a>(file: &str, value: &'a Value, path: &str) -> &'a Value {
    path.split('.').fold(value, |v, key| {
        let next = match key.parse::<usize>() {
            Ok(i) => v.get(i),
            Err(_) => v.get(key),
        };
        next.unwrap_or_else(|| panic!("{file}: {path} is required (missing at {key})"))
    })
}

fn text<'a>(file: &str, value: &'a Value, path: &str) -> &'a str {
    at(file, value, path).as_str().unwrap_or_else(|| panic!("{file}: {path} must be a string"))
}

fn int(file: &str, value: &Value, path: &str) -> i64 {
    at(file, value, path).as_i64().unwrap_or_else(|| panic!("{file}: {path} must be an integer"))
}

fn seq<'a>(file: &str, value: &'a Value, path: &str) -> &'a Vec<Value> {
    at(file, value, path).as_sequence().unwrap_or_else(|| panic!("{file}: {path} must be a list"))
}

fn one_of(file: &str, value: &Value, path: &str, allowed: &[&str]) -> String {
    let found = text(file, value, path);
    assert!(allowed.contains(&found), "{file}: {path} is {found:?}, not one of {allowed:?}");
    found.to_owned()
}

/// A Kubernetes name (RFC 1123 label: the pattern and length the CRDs give container names).
fn is_dns_label(name: &str) -> bool {
    let bytes = name.as_bytes();
    !name.is_empty()
        && name.len() <= 63
        && bytes.iter().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || *b == b'-')
        && bytes[0] != b'-'
        && bytes[bytes.len() - 1] != b'-'
}

fn header(file: &str, value: &Value, api_version: &str, kind: &str) {
    assert_eq!(text(file, value, "apiVersion"), api_version, "{file}");
    assert_eq!(text(file, value, "kind"), kind, "{file}");
}

#[test]
fn the_fleet_has_every_field_agones_requires_and_notices_a_stall_within_seconds() {
    let file = "fleet.yaml";
    let fleet = manifest(file);
    header(file, &fleet, "agones.dev/v1", "Fleet");
    assert!(is_dns_label(text(file, &fleet, "metadata.name")));
    one_of(file, &fleet, "spec.scheduling", &["Packed", "Distributed"]);
    let gs = at(file, &fleet, "spec.template.spec");

    // The pod: at least one container, each named and with an image; `container` names one of them.
    let containers = seq(file, gs, "template.spec.containers");
    assert!(!containers.is_empty(), "{file}: at least one container");
    let names: Vec<&str> = containers
        .iter()
        .map(|c| {
            assert!(!text(file, c, "image").is_empty(), "{file}: a container's image");
            text(file, c, "name")
        })
        .collect();
    assert!(names.iter().all(|n| is_dns_label(n)), "{names:?}");
    let server = text(file, gs, "container");
    assert!(names.contains(&server), "{file}: spec.container {server} is one of {names:?}");

    // Ports: a UDP one for QUIC and a TCP one for the view, each with a stated policy; Dynamic and Static
    // need the container port, Static the host port too.
    let ports = seq(file, gs, "ports");
    let mut protocols = Vec::new();
    for (i, port) in ports.iter().enumerate() {
        let path = |field: &str| format!("spec.template.spec.ports.{i}.{field}");
        let policy = one_of(file, port, "portPolicy", &["Dynamic", "Static", "Passthrough"]);
        protocols.push(one_of(file, port, "protocol", &["UDP", "TCP", "TCPUDP"]));
        assert!(!text(file, port, "name").is_empty(), "{}", path("name"));
        if policy != "Passthrough" {
            assert!((1..=65535).contains(&int(file, port, "containerPort")), "{}", path("containerPort"));
        }
        if policy == "Static" {
            assert!((1..=65535).contains(&int(file, port, "hostPort")), "{}", path("hostPort"));
        }
        if let Some(container) = port.get("container") {
            assert!(names.contains(&container.as_str().unwrap_or_default()), "{}", path("container"));
        }
    }
    assert!(protocols.iter().any(|p| p == "UDP"), "{file}: a UDP port for QUIC");
    assert!(protocols.iter().any(|p| p == "TCP"), "{file}: a TCP port for the view");

    // Health: on, checked often enough to notice a stalled VE within a few seconds, and slowly enough that
    // the server's pings (every DEFAULT_HEALTH_PERIOD) land in every check.
    assert_eq!(at(file, gs, "health.disabled").as_bool(), Some(false), "{file}: health checking on");
    let period_s = int(file, gs, "health.periodSeconds");
    let failures = int(file, gs, "health.failureThreshold");
    assert!(period_s >= 1 && failures >= 1);
    assert!(int(file, gs, "health.initialDelaySeconds") >= 0);
    let notice_s = (period_s * (failures + 1)) as u64;
    assert!(notice_s <= NOTICE_WITHIN_S, "a stall is noticed after up to {notice_s} s");
    assert!(
        DEFAULT_HEALTH_PERIOD.as_secs_f64() * 2.0 <= period_s as f64,
        "two pings per check at the server's default period"
    );

    // The counts the server keeps.
    let rooms = at(file, gs, &format!("counters.{ROOMS_COUNTER}"));
    assert!(int(file, rooms, "capacity") >= 1 && int(file, rooms, "count") == 0);
    assert!(int(file, at(file, gs, &format!("lists.{USERS_LIST}")), "capacity") >= 1);
}

#[test]
fn the_autoscaler_scales_the_fleet_on_its_rooms_counter() {
    let file = "fleetautoscaler.yaml";
    let fleet = manifest("fleet.yaml");
    let scaler = manifest(file);
    header(file, &scaler, "autoscaling.agones.dev/v1", "FleetAutoscaler");
    assert!(is_dns_label(text(file, &scaler, "metadata.name")));
    assert_eq!(text(file, &scaler, "spec.fleetName"), text("fleet.yaml", &fleet, "metadata.name"));
    assert_eq!(
        one_of(file, &scaler, "spec.policy.type", &["Buffer", "Webhook", "Counter", "List", "Chain"]),
        "Counter"
    );
    let counter = at(file, &scaler, "spec.policy.counter");
    assert_eq!(text(file, counter, "key"), ROOMS_COUNTER);
    let buffer = at(file, counter, "bufferSize");
    assert!(buffer.as_i64().is_some_and(|b| b >= 1) || buffer.as_str().is_some_and(|b| b.ends_with('%')));
    let (min, max) = (int(file, counter, "minCapacity"), int(file, counter, "maxCapacity"));
    assert!(max >= 1 && (0..=max).contains(&min), "capacities {min}..{max}");
    let per_server = int("fleet.yaml", &fleet, &format!("spec.template.spec.counters.{ROOMS_COUNTER}.capacity"));
    assert!(max >= per_server, "room for at least one server");
    if let Some(sync) = scaler.get("spec").and_then(|s| s.get("sync")) {
        one_of(file, sync, "type", &["FixedInterval"]);
        assert!(int(file, sync, "fixedInterval.seconds") >= 1);
    }
}

#[test]
fn the_allocation_picks_a_fleet_server_with_room_and_names_a_room_the_server_can_read() {
    let file = "allocation.yaml";
    let fleet = manifest("fleet.yaml");
    let allocation = manifest(file);
    header(file, &allocation, "allocation.agones.dev/v1", "GameServerAllocation");
    let fleet_name = text("fleet.yaml", &fleet, "metadata.name");
    let selectors = seq(file, &allocation, "spec.selectors");
    assert!(!selectors.is_empty(), "{file}: at least one selector");
    for selector in selectors {
        let label = at(file, selector, "matchLabels").get("agones.dev/fleet").and_then(Value::as_str);
        assert_eq!(label, Some(fleet_name), "{file}: selectors pick the fleet's servers");
        one_of(file, selector, "gameServerState", &["Ready", "Allocated"]);
        assert!(int(file, selector, &format!("counters.{ROOMS_COUNTER}.minAvailable")) >= 1);
    }
    one_of(file, &allocation, "spec.scheduling", &["Packed", "Distributed"]);
    let raise = at(file, &allocation, &format!("spec.counters.{ROOMS_COUNTER}"));
    assert_eq!(one_of(file, raise, "action", &["Increment", "Decrement"]), "Increment");
    assert_eq!(int(file, raise, "amount"), 1);
    let annotations = at(file, &allocation, "spec.metadata.annotations").as_mapping().expect("annotations");
    let annotations =
        annotations.iter().map(|(k, v)| (k.as_str().unwrap().to_owned(), v.as_str().unwrap().to_owned())).collect();
    let request = room_request(&annotations).expect("the server reads the room the allocation names");
    assert!(kinloop_server::driver::load_scene(&request.scene).is_ok(), "{} is a scene the image holds", request.scene);
}

#[test]
fn the_image_names_its_bases_and_listens_where_the_fleet_forwards() {
    let dockerfile = std::fs::read_to_string(deploy("Dockerfile")).expect("Dockerfile");
    let bases: Vec<&str> = dockerfile
        .lines()
        .filter_map(|l| l.strip_prefix("FROM "))
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert!(!bases.is_empty());
    for base in &bases {
        let (_, tag) = base.split_once(':').unwrap_or_else(|| panic!("{base}: the base names a tag"));
        assert!(!tag.is_empty() && tag != "latest", "{base}: a named, fixed base");
    }
    assert!(dockerfile.contains("\"--agones\""), "the server runs with --agones");
    let fleet = manifest("fleet.yaml");
    for port in seq("fleet.yaml", &fleet, "spec.template.spec.ports") {
        let number = int("fleet.yaml", port, "containerPort");
        let protocol = text("fleet.yaml", port, "protocol").to_lowercase();
        assert!(dockerfile.contains(&format!("{number}/{protocol}")), "the image exposes {number}/{protocol}");
        assert!(dockerfile.contains(&format!("0.0.0.0:{number}")), "the server listens on {number}");
    }
}
