//! Config files and bad configs, through the library and through the binaries.

use std::path::Path;
use std::time::Duration;

use vrsync_bridge::Config;

use crate::util::{self, TestConfig, workspace};

#[test]
fn every_config_file_parses() {
    let dir = workspace().join("config");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            Config::load(&path).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 1, "no config files in {}", dir.display());
}

#[test]
fn default_toml_documents_every_key() {
    let text = std::fs::read_to_string(workspace().join("config/default.toml")).unwrap();
    for key in [
        "session",
        "seed",
        "sync_mode",
        "SyncMode",
        "simulation_time_per_frame",
        "SimulationTimePerFrame",
        "stop_timeout",
        "connect_timeout",
        "kind",
        "tcp_listen",
        "max_commands_per_cycle",
        "[[agent]]",
        "id",
        "[[agent.camera]]",
        "name",
        "width",
        "height",
        "format",
        "fov_horizontal_deg",
        "fov_vertical_deg",
    ] {
        assert!(
            text.contains(key),
            "config/default.toml does not mention `{key}`"
        );
    }
    // Every key set in the file is explained by a comment block right above it, except
    // inside [[agent]] tables, whose keys are documented once in the block before them.
    let lines: Vec<&str> = text.lines().collect();
    let first_agent = lines
        .iter()
        .position(|l| l.starts_with("[[agent]]"))
        .unwrap();
    for (i, l) in lines[..first_agent].iter().enumerate() {
        let l = l.trim();
        if l.contains('=') && !l.starts_with('#') {
            assert!(
                i > 0 && lines[i - 1].trim_start().starts_with('#'),
                "config/default.toml line {}: `{l}` has no comment above it",
                i + 1
            );
        }
    }
}

fn bad(dir: &Path, name: &str, text: &str) -> util::Output {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            path.to_str().unwrap(),
            "--frames",
            "1",
            "--quiet",
        ],
        Duration::from_secs(60),
    )
}

#[test]
fn bad_configs_exit_2_naming_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let good = TestConfig::new("badcfg", 1).toml();
    let cases: [(&str, String, &str, &str); 6] = [
        (
            "unknown.toml",
            good.replacen("seed = 7", "seed = 7\nbogus = 1", 1),
            ":3:",
            "bogus",
        ),
        (
            "type.toml",
            good.replacen("sync_mode = true", "sync_mode = \"yes\"", 1),
            ":5:",
            "sync.sync_mode",
        ),
        (
            "negative.toml",
            good.replacen("stop_timeout = 5", "stop_timeout = -5", 1),
            ":7:",
            "sync.stop_timeout",
        ),
        (
            "zero.toml",
            good.replacen(
                "simulation_time_per_frame = 0.1",
                "simulation_time_per_frame = 0",
                1,
            ),
            ":6:",
            "sync.simulation_time_per_frame",
        ),
        (
            "dup.toml",
            good.clone() + "\n[[agent]]\nid = 0\n",
            "",
            "duplicate agent id 0",
        ),
        (
            "noagents.toml",
            good.split("\n[[agent]]").next().unwrap().to_string(),
            ":1:",
            "at least one agent",
        ),
    ];
    for (name, text, line, key) in cases {
        let out = bad(dir.path(), name, &text);
        assert_eq!(out.code(), Some(2), "{name}: stderr:\n{}", out.stderr);
        let line = if line.is_empty() {
            // the last line of the file holds the duplicate
            format!(":{}:", text.lines().count())
        } else {
            line.to_string()
        };
        let expect_loc = format!("{name}{line}");
        assert!(
            out.stderr.contains(&expect_loc),
            "{name}: expected {expect_loc:?} in:\n{}",
            out.stderr
        );
        assert!(
            out.stderr.contains(key),
            "{name}: expected {key:?} in:\n{}",
            out.stderr
        );
    }
}

#[test]
fn bad_usage_exits_2() {
    let out = util::run("vr-sim", &["run"], Duration::from_secs(30));
    assert_eq!(out.code(), Some(2), "{}", out.stderr);
    assert!(out.stderr.contains("--config"), "{}", out.stderr);
    let out = util::run("vr-agent", &["--config", "x.toml"], Duration::from_secs(30));
    assert_eq!(out.code(), Some(2), "{}", out.stderr);
    let out = util::run(
        "vr-agent",
        &["--config", "/nonexistent/x.toml", "--id", "0"],
        Duration::from_secs(30),
    );
    assert_eq!(out.code(), Some(2), "{}", out.stderr);
    assert!(out.stderr.contains("/nonexistent/x.toml"), "{}", out.stderr);
}
