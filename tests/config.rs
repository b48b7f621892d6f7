//! Config files and bad configs, through the library and through the binaries; the
//! loader on arbitrary and mutated text in `config/arbitrary.rs`.

mod arbitrary;

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
        "wait_for_stop",
        "kind",
        "tcp_listen",
        "max_commands_per_cycle",
        "tcp_token",
        "[transport.legacy]",
        "local_port",
        "LocalPort",
        "bind",
        "dialect",
        "png_compression",
        "send_eye_position",
        "send_head_motion",
        "[transport.shm]",
        "stacked_images",
        "[transport.zenoh]",
        "listen",
        "connect",
        "lease",
        "scouting",
        "token",
        "tls_ca",
        "tls_cert",
        "tls_key",
        "mtls",
        "[[agent]]",
        "id",
        "[[agent.camera]]",
        "name",
        "width",
        "height",
        "format",
        "fov_horizontal_deg",
        "fov_vertical_deg",
        "[[agent.vector]]",
        "[[agent.action]]",
        "len",
        "low",
        "high",
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

/// Where a bad config's error must point.
enum At {
    /// The first line containing this text.
    Text(&'static str),
    /// The last line containing this text.
    LastText(&'static str),
    /// This 1-based line.
    Line(usize),
}

/// One row of the bad-config table: a good config with one edit, where the error must
/// point, and the key (or words) it must name.
struct Bad {
    name: &'static str,
    text: String,
    at: At,
    key: &'static str,
}

/// `base` with the first `from` replaced by `to`; panics if `from` is missing, so a row
/// can never silently test the good config.
fn edit(base: &str, from: &str, to: &str) -> String {
    assert!(base.contains(from), "{from:?} not in the base config");
    base.replacen(from, to, 1)
}

/// A row whose text is `text`.
fn row(name: &'static str, text: String, at: At, key: &'static str) -> Bad {
    Bad {
        name,
        text,
        at,
        key,
    }
}

/// The good configs the rows edit: one agent over shared memory, and over TCP.
struct Base {
    shm: String,
    tcp: String,
}

impl Base {
    /// A row that edits the shared-memory config: its top level or `[sync]`.
    fn sync(&self, name: &'static str, from: &str, to: &str, at: At, key: &'static str) -> Bad {
        row(name, edit(&self.shm, from, to), at, key)
    }

    /// A row that edits the shared-memory config: its agent or camera.
    fn camera(&self, name: &'static str, from: &str, to: &str, at: At, key: &'static str) -> Bad {
        row(name, edit(&self.shm, from, to), at, key)
    }

    /// A row that edits the TCP config.
    fn transport(
        &self,
        name: &'static str,
        from: &str,
        to: &str,
        at: At,
        key: &'static str,
    ) -> Bad {
        row(name, edit(&self.tcp, from, to), at, key)
    }
}

fn bad_config_table() -> Vec<Bad> {
    let base = Base {
        shm: TestConfig::new("badcfg", 1).toml(),
        tcp: TestConfig::with_transport("badcfg", 1, util::Transport::Tcp).toml(),
    };
    [
        unknown_keys_and_wrong_types,
        times_enums_and_agents,
        cameras,
        transport_and_toml,
    ]
    .into_iter()
    .flat_map(|rows| rows(&base))
    .collect()
}

/// Unknown keys (at top level and in every table) and wrong types.
fn unknown_keys_and_wrong_types(b: &Base) -> Vec<Bad> {
    vec![
        // Unknown keys, at top level and in every table.
        b.sync(
            "unknown.toml",
            "seed = 7",
            "seed = 7\nbogus = 1",
            At::Text("bogus"),
            "bogus",
        ),
        b.sync(
            "unknown_sync.toml",
            "sync_mode = true",
            "sync_mode = true\nsync_mod = true",
            At::Text("sync_mod ="),
            "sync.sync_mod",
        ),
        b.camera(
            "unknown_camera.toml",
            "width = 64",
            "width = 64\nwidht = 64",
            At::Text("widht"),
            "agent.camera.widht",
        ),
        b.transport(
            "unknown_transport.toml",
            "kind = \"tcp\"",
            "kind = \"tcp\"\ntcp_port = 7400",
            At::Text("tcp_port"),
            "transport.tcp_port",
        ),
        row(
            "unknown_table.toml",
            b.shm.clone() + "\n[network]\nport = 1\n",
            At::Text("[network]"),
            "network",
        ),
        // Wrong types.
        b.sync(
            "type.toml",
            "sync_mode = true",
            "sync_mode = \"yes\"",
            At::Text("sync_mode"),
            "sync.sync_mode",
        ),
        b.sync(
            "type_timeout.toml",
            "stop_timeout = 5",
            "stop_timeout = \"5s\"",
            At::Text("stop_timeout"),
            "sync.stop_timeout",
        ),
        b.sync(
            "type_seed.toml",
            "seed = 7",
            "seed = -7",
            At::Text("seed"),
            "seed",
        ),
        b.camera(
            "type_width.toml",
            "width = 64",
            "width = \"64\"",
            At::Text("width"),
            "agent.camera.width",
        ),
        b.camera(
            "type_id.toml",
            "id = 0",
            "id = \"zero\"",
            At::Text("id ="),
            "agent.id",
        ),
    ]
}

/// Bad times, bad enum values in `[sync]`, bad agent ids.
fn times_enums_and_agents(b: &Base) -> Vec<Bad> {
    vec![
        // Negative, zero and non-finite times.
        b.sync(
            "negative.toml",
            "stop_timeout = 5",
            "stop_timeout = -5",
            At::Text("stop_timeout"),
            "sync.stop_timeout",
        ),
        b.sync(
            "zero_stop.toml",
            "stop_timeout = 5",
            "stop_timeout = 0",
            At::Text("stop_timeout"),
            "sync.stop_timeout",
        ),
        b.sync(
            "zero.toml",
            "simulation_time_per_frame = 0.1",
            "simulation_time_per_frame = 0",
            At::Text("simulation_time_per_frame"),
            "sync.simulation_time_per_frame",
        ),
        b.sync(
            "negative_frame.toml",
            "simulation_time_per_frame = 0.1",
            "simulation_time_per_frame = -0.1",
            At::Text("simulation_time_per_frame"),
            "sync.simulation_time_per_frame",
        ),
        b.sync(
            "negative_connect.toml",
            "connect_timeout = 20",
            "connect_timeout = -1",
            At::Text("connect_timeout"),
            "sync.connect_timeout",
        ),
        b.sync(
            "nan_timeout.toml",
            "stop_timeout = 5",
            "stop_timeout = nan",
            At::Text("stop_timeout"),
            "sync.stop_timeout",
        ),
        b.sync(
            "inf_timeout.toml",
            "stop_timeout = 5",
            "stop_timeout = inf",
            At::Text("stop_timeout"),
            "sync.stop_timeout",
        ),
        // Bad enum values in [sync].
        b.sync(
            "wait.toml",
            "connect_timeout = 20",
            "connect_timeout = 20\nwait = \"busy\"",
            At::Text("wait ="),
            "sync.wait",
        ),
        b.sync(
            "on_agent_lost.toml",
            "connect_timeout = 20",
            "connect_timeout = 20\non_agent_lost = \"ignore\"",
            At::Text("on_agent_lost"),
            "sync.on_agent_lost",
        ),
        // Agents: none, duplicate and out-of-range ids.
        row(
            "noagents.toml",
            b.shm.split("\n[[agent]]").next().unwrap().to_string(),
            At::Line(1),
            "at least one agent",
        ),
        row(
            "dup.toml",
            b.shm.clone() + "\n[[agent]]\nid = 0\n",
            At::LastText("id = 0"),
            "duplicate agent id 0",
        ),
        row(
            "dup_key.toml",
            b.shm.clone() + "\n[[agent]]\nid = 0\n",
            At::LastText("id = 0"),
            "agent.id",
        ),
        b.camera(
            "negative_id.toml",
            "id = 0",
            "id = -1",
            At::Text("id ="),
            "agent.id",
        ),
        b.camera(
            "big_id.toml",
            "id = 0",
            "id = 251",
            At::Text("id ="),
            "agent.id",
        ),
    ]
}

/// Cameras.
fn cameras(b: &Base) -> Vec<Bad> {
    let mut five_cameras = b.shm.clone();
    for cam in ["c", "d", "e"] {
        five_cameras += &format!("[[agent.camera]]\nname = \"{cam}\"\nwidth = 8\n");
    }
    vec![
        // Cameras.
        b.camera(
            "camera_width.toml",
            "width = 64",
            "width = 0",
            At::Text("width"),
            "agent.camera.width",
        ),
        b.camera(
            "camera_huge.toml",
            "width = 64",
            "width = 100000",
            At::Text("width"),
            "agent.camera.width",
        ),
        b.camera(
            "camera_height.toml",
            "width = 64",
            "width = 64\nheight = -1",
            At::Text("height"),
            "agent.camera.height",
        ),
        b.camera(
            "camera_format.toml",
            "width = 64",
            "width = 64\nformat = \"bgr\"",
            At::Text("format"),
            "agent.camera.format",
        ),
        b.camera(
            "camera_fov_h.toml",
            "width = 64",
            "width = 64\nfov_horizontal_deg = 180",
            At::Text("fov_horizontal_deg"),
            "agent.camera.fov_horizontal_deg",
        ),
        b.camera(
            "camera_fov_v.toml",
            "width = 64",
            "width = 64\nfov_vertical_deg = 0",
            At::Text("fov_vertical_deg"),
            "agent.camera.fov_vertical_deg",
        ),
        b.camera(
            "camera_name_long.toml",
            "name = \"left\"",
            "name = \"a-very-long-camera\"",
            At::Text("a-very-long-camera"),
            "agent.camera.name",
        ),
        b.camera(
            "camera_name_empty.toml",
            "name = \"left\"",
            "name = \"\"",
            At::Text("name = \"\""),
            "agent.camera.name",
        ),
        b.camera(
            "camera_name_twice.toml",
            "name = \"right\"",
            "name = \"left\"",
            At::LastText("name = \"left\""),
            "agent.camera.name",
        ),
        b.camera(
            "camera_no_width.toml",
            "width = 64",
            "",
            At::Text("[[agent.camera]]"),
            "width",
        ),
        row(
            "five_cameras.toml",
            five_cameras,
            At::Text("[[agent]]"),
            "agent.camera",
        ),
    ]
}

/// Transport, session and plain TOML errors.
fn transport_and_toml(b: &Base) -> Vec<Bad> {
    vec![
        // Transport.
        b.transport(
            "kind.toml",
            "kind = \"tcp\"",
            "kind = \"udp\"",
            At::Text("kind"),
            "transport.kind",
        ),
        b.transport(
            "tcp_listen_name.toml",
            "tcp_listen = \"127.0.0.1:",
            "tcp_listen = \"localhost:",
            At::Text("tcp_listen"),
            "transport.tcp_listen",
        ),
        b.transport(
            "tcp_listen_noport.toml",
            "tcp_listen = \"127.0.0.1:",
            "tcp_listen = \"127.0.0.1\"\n#",
            At::Text("tcp_listen"),
            "transport.tcp_listen",
        ),
        b.transport(
            "tcp_listen_port.toml",
            "tcp_listen = \"127.0.0.1:",
            "tcp_listen = \"127.0.0.1:99999\"\n#",
            At::Text("tcp_listen"),
            "transport.tcp_listen",
        ),
        b.transport(
            "tcp_listen_type.toml",
            "tcp_listen = \"127.0.0.1:",
            "tcp_listen = 7400\n#",
            At::Text("tcp_listen"),
            "transport.tcp_listen",
        ),
        b.transport(
            "tcp_token_empty.toml",
            "kind = \"tcp\"",
            "kind = \"tcp\"\ntcp_token = \"\"",
            At::Text("tcp_token"),
            "transport.tcp_token",
        ),
        row(
            "tcp_token_long.toml",
            edit(
                &b.tcp,
                "kind = \"tcp\"",
                &format!("kind = \"tcp\"\ntcp_token = \"{}\"", "x".repeat(257)),
            ),
            At::Text("tcp_token"),
            "transport.tcp_token",
        ),
        b.transport(
            "tcp_token_type.toml",
            "kind = \"tcp\"",
            "kind = \"tcp\"\ntcp_token = 1234",
            At::Text("tcp_token"),
            "transport.tcp_token",
        ),
        b.transport(
            "max_commands.toml",
            "kind = \"tcp\"",
            "kind = \"tcp\"\nmax_commands_per_cycle = 0",
            At::Text("max_commands_per_cycle"),
            "transport.max_commands_per_cycle",
        ),
        // Session and plain TOML errors.
        b.sync(
            "session.toml",
            "session = \"",
            "session = \"a/b",
            At::Text("session"),
            "session",
        ),
        b.sync("syntax.toml", "[sync]", "[sync", At::Text("[sync"), "sync"),
        b.sync(
            "dup_toml_key.toml",
            "seed = 7",
            "seed = 7\nseed = 8",
            At::LastText("seed"),
            "seed",
        ),
    ]
}

#[test]
fn bad_configs_exit_2_naming_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for case in bad_config_table() {
        let line = match case.at {
            At::Line(n) => n,
            At::Text(t) => case.text.lines().position(|l| l.contains(t)).unwrap() + 1,
            At::LastText(t) => {
                let lines: Vec<&str> = case.text.lines().collect();
                lines.iter().rposition(|l| l.contains(t)).unwrap() + 1
            }
        };
        let out = bad(dir.path(), case.name, &case.text);
        let loc = format!("{}:{line}:", case.name);
        let stderr = out.stderr.trim();
        if out.code() != Some(2) || !stderr.contains(&loc) || !stderr.contains(case.key) {
            failures.push(format!(
                "{}: exit {:?}, expected {loc:?} and {:?} in: {stderr}",
                case.name,
                out.code(),
                case.key
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn an_endless_or_huge_config_file_is_refused_without_reading_it_all() {
    // /dev/zero never ends; reading it whole would fill memory.
    let out = util::run(
        "vr-sim",
        &["run", "--config", "/dev/zero", "--frames", "1", "--quiet"],
        Duration::from_secs(60),
    );
    assert_eq!(out.code(), Some(2), "{}", out.stderr);
    assert!(
        out.stderr.contains("/dev/zero") && out.stderr.contains("larger than 4 MiB"),
        "{}",
        out.stderr
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.toml");
    let mut text = TestConfig::new("huge", 1).toml();
    text += &"# padding\n".repeat(500_000);
    std::fs::write(&path, text).unwrap();
    let e = Config::load(&path).unwrap_err().to_string();
    assert!(e.contains("huge.toml") && e.contains("larger than"), "{e}");
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

/// Each cause is printed once: an error whose message shows an I/O error must not also
/// hand it on as its `source()`, or `{:#}` prints it twice (issue 22: "No such file or
/// directory (os error 2): No such file or directory (os error 2)").
#[test]
fn a_missing_file_is_named_with_its_cause_once() {
    let once = |out: &util::Output, path: &str| {
        assert!(out.stderr.contains(path), "{}", out.stderr);
        assert_eq!(
            out.stderr.matches("os error 2").count(),
            1,
            "the cause once:\n{}",
            out.stderr
        );
    };
    let out = util::run(
        "vr-sim",
        &["run", "--config", "/nonexistent/x.toml", "--frames", "1"],
        Duration::from_secs(30),
    );
    assert_eq!(out.code(), Some(2), "{}", out.stderr);
    once(&out, "/nonexistent/x.toml");
    let out = util::run(
        "vr-agent",
        &["--config", "/nonexistent/x.toml", "--id", "0"],
        Duration::from_secs(30),
    );
    once(&out, "/nonexistent/x.toml");
    // An output path in a missing directory (the map is written through the picture
    // writer's error type, the other outputs through anyhow context).
    let dir = tempfile::tempdir().unwrap();
    for flag in ["--map", "--events", "--summary-json"] {
        // A session per run: the agent the last run spawned may still be closing its ports.
        let config = dir.path().join(format!("{}.toml", &flag[2..]));
        let session = format!("missing-path{flag}");
        std::fs::write(&config, TestConfig::new(&session, 1).toml()).unwrap();
        let out = util::run(
            "vr-sim",
            &[
                "run",
                "--config",
                config.to_str().unwrap(),
                "--frames",
                "1",
                "--spawn-agents",
                "1",
                "--quiet",
                flag,
                "/nonexistent/out",
            ],
            Duration::from_secs(60),
        );
        assert_eq!(out.code(), Some(1), "{flag}: {}", out.stderr);
        once(&out, "/nonexistent/out");
    }
}

#[test]
fn tcp_listens_on_loopback_unless_told_otherwise() {
    let c = Config::from_toml_str(
        "[transport]\nkind = \"tcp\"\n[[agent]]\nid = 0\n",
        Path::new("t.toml"),
    )
    .unwrap();
    assert!(c.transport.tcp_listen.ip().is_loopback(), "{c:?}");
    assert!(c.transport.tcp_token.is_none());
    let d = Config::embedded_default().unwrap();
    assert!(d.transport.tcp_listen.ip().is_loopback(), "{d:?}");
    // Any other interface is an explicit choice, and then accepted.
    let c = Config::from_toml_str(
        "[transport]\nkind = \"tcp\"\ntcp_listen = \"0.0.0.0:7400\"\n[[agent]]\nid = 0\n",
        Path::new("t.toml"),
    )
    .unwrap();
    assert!(c.transport.tcp_listen.ip().is_unspecified());
}

#[test]
fn effective_config_writes_names_and_tokens_as_toml_strings() {
    // Found by `effective_config_keeps_any_camera_name_and_token`: Rust's `{:?}` wrote
    // `\u{3347a}`, which TOML rejects, so spawned agents could not load their config.
    let text = "[transport]\ntcp_token = \"a\\tb\\u0001\\\"\"\n[[agent]]\nid = 0\n\
                [[agent.camera]]\nname = \"\\U0003347A\\u007f\"\nwidth = 8\n";
    let c = Config::from_toml_str(text, Path::new("t.toml")).unwrap();
    let back = Config::from_toml_str(&c.to_toml_string(), Path::new("e.toml")).unwrap();
    assert_eq!(back.agents[0].cameras[0].name, "\u{3347a}\u{7f}");
    assert_eq!(back.transport.tcp_token.as_deref(), Some("a\tb\u{1}\""));
}

/// A stacked config's agents are read by one process: `--spawn-agents` (a process per
/// agent) is refused before anything starts, naming the key and the way out.
#[test]
fn spawned_agents_of_a_stacked_config_are_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("stacked.toml");
    let text = TestConfig::new("stacked-spawn", 2).toml();
    let text = text.replacen(
        "[[agent]]",
        "[transport.shm]\nstacked_images = true\n[[agent]]",
        1,
    );
    std::fs::write(&config, text).unwrap();
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--frames",
            "1",
            "--spawn-agents",
            "2",
            "--quiet",
        ],
        Duration::from_secs(60),
    );
    assert_ne!(out.code(), Some(0), "{}", out.stderr);
    assert!(
        out.stderr.contains("stacked_images") && out.stderr.contains("--spawn-agents"),
        "{}",
        out.stderr
    );
}
