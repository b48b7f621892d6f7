//! What a user's build links: the agent SDK's own dependency tree, as `cargo tree` (the
//! cargo running these tests, from the committed `Cargo.lock`) reports it. (Not
//! `--offline`: after a build everything it reads is in cargo's cache, and where a cache
//! lacks a manifest, cargo may fetch it from the registry.)

use std::process::Command;
use std::time::Duration;

use crate::util::{self, Proc};

/// The packages `package` links with `features` (comma-separated, may be empty), by name.
fn packages(package: &str, features: &str) -> Vec<String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(util::workspace()).args([
        "tree", "--locked", "-p", package, "-e", "normal", "--prefix", "none", "-f", "{p}",
    ]);
    if !features.is_empty() {
        cmd.args(["--features", features]);
    }
    let out = Proc::spawn_command(cmd).wait(Duration::from_secs(120));
    assert!(out.status.success(), "cargo tree failed:\n{}", out.stderr);
    let mut names: Vec<String> = out
        .stdout
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect();
    names.sort();
    names.dedup();
    names
}

/// What a Rust agent does not compile: the host (`vrsync-bridge`), the programs' CLI,
/// benchmark and random-number crates, the C ABI plumbing, the original protocol's host
/// (`vrsync-legacy`, with its protobuf and PNG crates), and (without the feature) zenoh with
/// its runtime.
const NOT_IN_THE_SDK: [&str; 12] = [
    "vrsync-bridge",
    "vrsync-legacy",
    "vrsync-floor",
    "clap",
    "anyhow",
    "rand",
    "tracing-subscriber",
    "vrsync-cabi",
    "zenoh",
    "tokio",
    "prost",
    "png",
];

#[test]
fn the_agent_sdk_links_no_program_crates_and_zenoh_only_with_its_feature() {
    let lean = packages("vrsync-agent", "");
    assert!(lean.iter().any(|p| p == "vrsync-transport"), "{lean:?}");
    for name in NOT_IN_THE_SDK {
        assert!(
            !lean.iter().any(|p| p == name),
            "`cargo tree -p vrsync-agent -e normal` has {name}: {lean:?}"
        );
    }
    // The feature is what brings zenoh (and with it, its own anyhow, rand, tokio and
    // tracing-subscriber), and nothing of the programs.
    let with_zenoh = packages("vrsync-agent", "zenoh");
    for name in ["zenoh", "tokio"] {
        assert!(
            with_zenoh.iter().any(|p| p == name),
            "with --features zenoh: no {name} in {with_zenoh:?}"
        );
    }
    for name in ["vrsync-bridge", "vrsync-floor", "clap", "vrsync-cabi"] {
        assert!(
            !with_zenoh.iter().any(|p| p == name),
            "with --features zenoh: {name} in {with_zenoh:?}"
        );
    }
}

/// The Python extension counts its allocations with `vrsync-alloc-count` and links nothing
/// else of the benchmark (the transport floors of `vrsync-floor`).
#[test]
fn the_python_extension_links_the_counting_allocator_and_no_floors() {
    let python = packages("vrsync-python", "");
    assert!(
        python.iter().any(|p| p == "vrsync-alloc-count"),
        "{python:?}"
    );
    assert!(!python.iter().any(|p| p == "vrsync-floor"), "{python:?}");
}
