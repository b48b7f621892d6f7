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

#[test]
fn vr_agent_help_states_how_long_the_policies_wait_for_a_status() {
    use vrsync_agent_bin::policy::{SEEK_SEARCH_WAIT_CYCLES, STATUS_WAIT_CYCLES};
    let out = Command::new(env!("CARGO_BIN_EXE_vr-agent"))
        .arg("--help")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let help = String::from_utf8(out.stdout).unwrap().replace('\n', " ");
    let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
    for expected in [
        format!("or after {STATUS_WAIT_CYCLES} cycles without such a status"),
        format!("({SEEK_SEARCH_WAIT_CYCLES} for a search turn of `seek`)"),
        format!("one command per agent every {STATUS_WAIT_CYCLES} cycles"),
    ] {
        assert!(
            help.contains(&expected),
            "`vr-agent --help` lacks {expected:?}:\n{help}"
        );
    }
}
