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

#[test]
fn git_ignores_the_demo_output_folder() {
    let out = Command::new(env!("CARGO_BIN_EXE_vr-sim"))
        .args(["demo", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8(out.stdout).unwrap();
    let default = help
        .split("[default: ")
        .map(|s| s.split(']').next().unwrap())
        .find(|d| d.starts_with("vrsync-demo"))
        .unwrap_or_else(|| panic!("no default output folder in:\n{help}"));
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let status = Command::new("git")
        .current_dir(&root)
        .args(["check-ignore", "--quiet", "--no-index"])
        .arg(format!("{default}/summary.json"))
        .status()
        .expect("git is needed for this test");
    assert!(status.success(), "{default}/ is not in .gitignore");
}
