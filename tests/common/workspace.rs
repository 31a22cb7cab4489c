//! What cargo knows of this workspace (`cargo metadata`), for tests that check what the docs and the
//! manifests promise a newcomer.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

/// `cargo metadata --format-version 1 --locked --offline` in the workspace, with `extra` arguments. Offline:
/// a test never fetches, and a built checkout has every package the build uses on disk.
pub fn metadata(extra: &[&str]) -> Value {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(env!("CARGO"))
        .args(["metadata", "--format-version", "1", "--locked", "--offline"])
        .args(extra)
        .current_dir(root)
        .output()
        .expect("cargo metadata runs");
    assert!(out.status.success(), "cargo metadata failed:\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON")
}

/// The workspace's own packages.
pub fn members() -> Vec<Value> {
    let meta = metadata(&["--no-deps"]);
    let ids: Vec<&Value> = meta["workspace_members"].as_array().expect("workspace_members").iter().collect();
    let packages = meta["packages"].as_array().expect("packages");
    packages.iter().filter(|p| ids.contains(&&p["id"])).cloned().collect()
}

/// The binary `cargo run -p PACKAGE` runs from the workspace's top: the package's only binary, or its
/// `default-run`. Panics saying why when there is none (no such member, no binary, several and no default).
pub fn binary_run_by(package: &str) -> String {
    let members = members();
    let names: Vec<&str> = members.iter().filter_map(|p| p["name"].as_str()).collect();
    let member = members
        .iter()
        .find(|p| p["name"] == package)
        .unwrap_or_else(|| panic!("`-p {package}`: no such workspace package (members: {})", names.join(", ")));
    let binaries: Vec<&str> = member["targets"]
        .as_array()
        .expect("targets")
        .iter()
        .filter(|t| t["kind"].as_array().is_some_and(|k| k.iter().any(|k| k == "bin")))
        .filter_map(|t| t["name"].as_str())
        .collect();
    match (binaries.as_slice(), member["default_run"].as_str()) {
        ([only], _) => (*only).to_owned(),
        (_, Some(default)) => default.to_owned(),
        ([], None) => panic!("`cargo run -p {package}`: the package has no binary"),
        (several, None) => panic!("`cargo run -p {package}`: several binaries ({several:?}) and no default-run"),
    }
}

/// The host's target triple, as `rustc -vV` reports it (the rustc beside the cargo running the tests).
pub fn host_triple() -> String {
    let cargo = Path::new(env!("CARGO"));
    let beside = cargo.with_file_name(format!("rustc{}", std::env::consts::EXE_SUFFIX));
    let rustc = if beside.exists() { beside.into_os_string() } else { "rustc".into() };
    let out = Command::new(&rustc).arg("-vV").output().expect("rustc -vV runs");
    let text = String::from_utf8_lossy(&out.stdout);
    text.lines()
        .find_map(|l| l.strip_prefix("host: "))
        .unwrap_or_else(|| panic!("no host line in rustc -vV:\n{text}"))
        .trim()
        .to_owned()
}

/// A Rust version `MAJOR.MINOR[.PATCH]` as three numbers.
pub fn rust_version(text: &str) -> [u64; 3] {
    let mut parts = text.split('.').map(|p| p.parse::<u64>().unwrap_or_else(|_| panic!("rust version {text:?}")));
    let mut next = || parts.next().unwrap_or(0);
    [next(), next(), next()]
}
