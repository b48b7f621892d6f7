//! The agent binaries' command lines. (Also makes `cargo test` build `vr-agent` and
//! `vr-bench-agent`, which the workspace's multi-process tests in `tests/` run.)

use std::process::Command;

#[test]
fn vr_agent_bad_usage_exits_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_vr-agent"))
        .arg("--no-such-flag")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn vr_bench_agent_bad_usage_exits_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_vr-bench-agent"))
        .arg("--no-such-flag")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}
