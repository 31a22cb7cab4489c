//! The Rust version the workspace promises (`rust-version` in Cargo.toml, and the README's "Set up") is one
//! that every locked dependency accepts: a newcomer with that Rust can build the checkout.

use crate::common;

use common::workspace::{self, rust_version};

/// The first Rust that knows `edition` (a package without a `rust-version` still needs that much).
fn edition_floor(edition: &str) -> [u64; 3] {
    match edition {
        "2015" => [1, 0, 0],
        "2018" => [1, 31, 0],
        "2021" => [1, 56, 0],
        "2024" => [1, 85, 0],
        other => panic!("edition {other}: add the Rust release that introduced it"),
    }
}

/// Every package the lock file resolves for this host (dependencies of every kind) declares a
/// `rust-version`, or an edition, that the workspace's `rust-version` meets. Packages for other platforms
/// are not on disk offline; they are left to the platform that builds them.
#[test]
fn every_locked_package_accepts_the_workspaces_rust_version() {
    let host = workspace::host_triple();
    let meta = workspace::metadata(&["--filter-platform", &host]);
    let packages = meta["packages"].as_array().expect("packages");
    let root = packages.iter().find(|p| p["name"] == "kinloop").expect("the root package");
    let promised = rust_version(root["rust_version"].as_str().expect("the workspace sets rust-version"));
    let mut needs: Vec<([u64; 3], String)> = packages
        .iter()
        .map(|p| {
            let declared = p["rust_version"].as_str().map_or([0, 0, 0], rust_version);
            let edition = edition_floor(p["edition"].as_str().expect("edition"));
            let name = format!("{} {}", p["name"].as_str().unwrap_or("?"), p["version"].as_str().unwrap_or("?"));
            (declared.max(edition), name)
        })
        .collect();
    needs.sort();
    let (newest, which) = needs.last().expect("some packages");
    println!("{} packages for {host}; the newest Rust one needs is {newest:?} ({which})", needs.len());
    let beyond: Vec<&([u64; 3], String)> = needs.iter().filter(|(need, _)| *need > promised).collect();
    assert!(
        beyond.is_empty(),
        "the workspace promises Rust {promised:?} (rust-version in Cargo.toml) but these locked packages need \
         newer: {beyond:?}; raise rust-version (and the README's Set up) or pin older versions"
    );
}
