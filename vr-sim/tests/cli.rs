//! `vr-sim`'s command line. (Also makes `cargo test` build `vr-sim`, which the workspace's
//! multi-process tests in `tests/` run.)

use std::process::Command;

#[test]
fn bad_usage_exits_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_vr-sim"))
        .args(["run", "--no-such-flag"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn run_help_documents_the_events_file() {
    let out = Command::new(env!("CARGO_BIN_EXE_vr-sim"))
        .args(["run", "--help"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let help = String::from_utf8(out.stdout).unwrap();
    for word in [
        "--events",
        "listening",
        "agent_evicted",
        "agent_rejoined",
        "finished",
    ] {
        assert!(help.contains(word), "{word} missing from:\n{help}");
    }
}
