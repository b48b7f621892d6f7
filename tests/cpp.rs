//! The C and C++ agent SDK as a user gets it: `agent-sdk/install.sh` into a prefix, the
//! examples built with CMake (`find_package(vrsync)`), with pkg-config, and with plain
//! `g++ -std=c++17` against the static library; then run against `vr-sim run` next to a
//! Rust `vr-agent`, over both transports.
//!
//! Needs cmake, a C and C++ compiler and pkg-config (CI installs them); without them the
//! tests fail and say so.
//!
//! The examples run with the library they were built against, the installed
//! `PREFIX/lib/libvrsync_agent.so` (found through their RUNPATH, as a user's program finds
//! it), not the one of the folders `cargo test` puts first in `LD_LIBRARY_PATH`
//! (`target/<profile>`): Cargo updates `target/<profile>/libvrsync_agent.so` only when it
//! builds `vrsync-agent-ffi` itself (`cargo test --workspace`), not for a `cargo test -p
//! vrsync-tests`, so after a protocol change the examples would load an old library and
//! their session would close right after connecting.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc;
use std::time::Duration;

use serde_json::Value;

use crate::util::{
    self, EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, TestConfig, Transport, bin, record,
    spawn_host, summary,
};

/// Deadline of one build step (configure, compile, link) on a loaded 2-core machine.
const BUILD_DEADLINE: Duration = Duration::from_secs(300);

/// The installed SDK and the example agents built against it.
pub struct Sdk {
    /// `PREFIX/lib`: the installed `libvrsync_agent.so` the examples must load.
    lib: PathBuf,
    /// `vrsync/agent.hpp` example, CMake, shared library.
    pub cpp_agent: PathBuf,
    /// `vrsync/agent.hpp` channels example (vectors and actions), CMake, shared library.
    cpp_channel_agent: PathBuf,
    /// `vrsync/compat.hpp` example, CMake, shared library.
    compat_agent: PathBuf,
    /// C example, CMake, shared library.
    c_agent: PathBuf,
    /// The compat example built with plain `g++ -std=c++17 -I agent-sdk/include` and the
    /// static `libvrsync_agent.a` of the cargo build (no install, no CMake).
    compat_static: PathBuf,
    /// The C example built with `gcc $(pkg-config --cflags --libs vrsync)`.
    c_pkg_config: PathBuf,
}

/// Runs a build tool to completion within [`BUILD_DEADLINE`]; panics with its output if
/// it fails, is missing, or hangs (then it is killed).
fn tool(cmd: &mut Command, what: &str) -> String {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{what}: cannot start {cmd:?}: {e}"));
    let mut out = child.stdout.take().expect("stdout");
    let mut err = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let (mut o, mut e) = (String::new(), String::new());
        let _ = out.read_to_string(&mut o);
        let _ = err.read_to_string(&mut e);
        (o, e)
    });
    let pid = child.id();
    let (tx, rx) = mpsc::channel();
    let waiter = std::thread::spawn(move || {
        let status = child.wait();
        let _ = tx.send(());
        status
    });
    let timed_out = rx.recv_timeout(BUILD_DEADLINE).is_err();
    if timed_out {
        // SAFETY: kill(2) on our own child, not reaped yet (the waiter still waits on it).
        unsafe {
            libc::kill(pid as i32, libc::SIGKILL);
        }
    }
    let status = waiter.join().expect("waiter").expect("wait");
    let (stdout, stderr) = reader.join().expect("reader");
    assert!(
        !timed_out,
        "{what}: {cmd:?} did not finish within {BUILD_DEADLINE:?}"
    );
    assert!(
        status.success(),
        "{what}: {cmd:?} failed ({status})\nstdout:\n{stdout}\nstderr:\n{stderr}"
    );
    stdout
}

/// Panics with a clear message when a required program is not installed.
fn require(program: &str) {
    let found = Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    assert!(
        found,
        "`{program}` is not installed: the C/C++ SDK tests build the examples as a user \
         would and need cmake, gcc, g++ and pkg-config \
         (apt-get install cmake g++ pkg-config)"
    );
}

/// A folder for this test process under cargo's target tmp dir; folders of earlier test
/// processes that are gone are removed (each holds a copy of the static library).
fn work_dir() -> PathBuf {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR"));
    if let Ok(entries) = std::fs::read_dir(root) {
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some(pid) = name
                .to_str()
                .and_then(|n| n.strip_prefix("cpp-sdk-"))
                .and_then(|p| p.parse::<u32>().ok())
            else {
                continue;
            };
            if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
    }
    let dir = root.join(format!("cpp-sdk-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create work dir");
    dir
}

/// Installs the SDK and builds the examples once per test process.
pub fn sdk() -> &'static Sdk {
    static SDK: OnceLock<Sdk> = OnceLock::new();
    SDK.get_or_init(|| {
        for program in ["cmake", "cc", "c++", "g++", "pkg-config"] {
            require(program);
        }
        let ws = util::workspace();
        let sdk_src = ws.join("agent-sdk");
        // The libraries Cargo built for these tests (vrsync-agent is a dev-dependency).
        let lib_dir = util::lib_dir();
        let work = work_dir();
        let prefix = work.join("prefix");

        tool(
            Command::new("bash")
                .arg(sdk_src.join("install.sh"))
                .arg("--lib-dir")
                .arg(&lib_dir)
                .arg(&prefix),
            "install the SDK",
        );

        // CMake, as a user would: find_package(vrsync) through CMAKE_PREFIX_PATH.
        let build = work.join("cmake-build");
        tool(
            Command::new("cmake")
                .arg("-S")
                .arg(sdk_src.join("examples"))
                .arg("-B")
                .arg(&build)
                .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display()))
                .arg("-DCMAKE_BUILD_TYPE=Release")
                .arg("-DCMAKE_C_FLAGS=-Wall -Wextra -Werror")
                .arg("-DCMAKE_CXX_FLAGS=-Wall -Wextra -Werror"),
            "cmake configure of agent-sdk/examples",
        );
        tool(
            Command::new("cmake").arg("--build").arg(&build).arg("-j2"),
            "cmake build of agent-sdk/examples",
        );

        // The "done when": plain g++ against agent-sdk/include and the static
        // library cargo built, no install step.
        let compat_static = work.join("compat_static");
        tool(
            Command::new("g++")
                .args(["-std=c++17", "-Wall", "-Wextra", "-Werror", "-O1", "-I"])
                .arg(sdk_src.join("include"))
                .arg(sdk_src.join("examples/compat_agent/main.cpp"))
                .arg(lib_dir.join("libvrsync_agent.a"))
                .args(["-lpthread", "-ldl", "-lm", "-lrt", "-lutil", "-o"])
                .arg(&compat_static),
            "g++ -std=c++17 of the compat example against libvrsync_agent.a",
        );

        // pkg-config.
        let flags = tool(
            Command::new("pkg-config")
                .args(["--cflags", "--libs", "vrsync"])
                .env("PKG_CONFIG_PATH", prefix.join("lib/pkgconfig")),
            "pkg-config --cflags --libs vrsync",
        );
        let c_pkg_config = work.join("c_agent_pkg_config");
        tool(
            Command::new("cc")
                .args(["-std=c99", "-Wall", "-Wextra", "-Werror"])
                .arg(sdk_src.join("examples/c_agent/main.c"))
                .args(flags.split_whitespace())
                .arg("-o")
                .arg(&c_pkg_config),
            "cc with pkg-config flags",
        );

        Sdk {
            lib: prefix.join("lib"),
            cpp_agent: build.join("cpp_agent/cpp_agent"),
            cpp_channel_agent: build.join("cpp_channel_agent/cpp_channel_agent"),
            compat_agent: build.join("compat_agent/compat_agent"),
            c_agent: build.join("c_agent/c_agent"),
            compat_static,
            c_pkg_config,
        }
    })
}

/// `program args` for a C/C++ example: as [`Proc::spawn`], with the folders of the
/// target dir removed from `LD_LIBRARY_PATH` (see the module docs).
pub fn example_command(program: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(program);
    cmd.args(args);
    let target = util::bin_dir().parent().expect("target dir").to_path_buf();
    let kept: Vec<PathBuf> = std::env::var_os("LD_LIBRARY_PATH")
        .map(|v| {
            std::env::split_paths(&v)
                .filter(|p| !p.starts_with(&target))
                .collect()
        })
        .unwrap_or_default();
    if kept.is_empty() {
        cmd.env_remove("LD_LIBRARY_PATH");
    } else {
        cmd.env(
            "LD_LIBRARY_PATH",
            std::env::join_paths(kept).expect("LD_LIBRARY_PATH"),
        );
    }
    cmd
}

/// Runs a C/C++ example (see [`example_command`]).
fn agent(program: &Path, args: &[&str]) -> Proc {
    Proc::spawn_command(example_command(program, args))
}

fn position(entry: &Value) -> [f64; 3] {
    let p = entry["position"].as_array().expect("position");
    [0, 1, 2].map(|i| p[i].as_f64().expect("coordinate"))
}

fn c_and_cpp_agents_run_100_sync_cycles(t: Transport) {
    let sdk = sdk();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("cpp-sync", 6, t);
    let config_path = cfg.write(dir.path());
    let config = config_path.to_str().unwrap();
    let s = dir.path().join("summary.json");
    let rec = dir.path().join("record.jsonl");
    let events = Events::in_dir(dir.path());
    let host = spawn_host(
        &config_path,
        &events,
        &[
            "--frames",
            "100",
            "--summary-json",
            s.to_str().unwrap(),
            "--record",
            rec.to_str().unwrap(),
        ],
    );
    cfg.follow_host(&events, &config_path);
    // Agent 0 is the Rust example; the others are the C and C++ examples.
    let rust = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "0"]);
    let agents: Vec<(u64, &str, Proc)> = vec![
        (1, "cpp_agent", agent(&sdk.cpp_agent, &[config, "1"])),
        (2, "compat_agent", agent(&sdk.compat_agent, &[config, "2"])),
        (3, "c_agent", agent(&sdk.c_agent, &[config, "3"])),
        (
            4,
            "compat_agent (g++, static)",
            agent(&sdk.compat_static, &[config, "4"]),
        ),
        (
            5,
            "c_agent (pkg-config)",
            agent(&sdk.c_pkg_config, &[config, "5"]),
        ),
    ];

    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "vr-sim stderr:\n{}", out.stderr);
    let out = rust.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "vr-agent stderr:\n{}", out.stderr);
    let mut names = Vec::new();
    for (id, name, agent) in agents {
        let out = agent.wait(RUN_DEADLINE);
        assert_eq!(
            out.code(),
            Some(0),
            "{name} {id}: stdout:\n{}\nstderr:\n{}",
            out.stdout,
            out.stderr
        );
        assert!(
            out.stdout.contains(": 100 cycles"),
            "{name} {id} should have run every cycle:\n{}",
            out.stdout
        );
        names.push((id, name));
    }

    let sum = summary(&s);
    assert_eq!(sum["frames"], 100);
    assert_eq!(sum["agents"], 6);
    assert_eq!(sum["mode"], "sync");
    assert_eq!(sum["transport"], t.as_str());
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["late_stops"], 0, "{sum}");
    assert_eq!(sum["commands_rejected"], 0, "{sum}");
    // cpp_agent and both compat agents send one command per cycle, the C agents 5 each.
    assert!(
        sum["commands_applied"].as_u64().unwrap() >= 310,
        "commands_applied: {sum}"
    );

    // Each C/C++ agent's commands reached the host and moved its body.
    let rec = record(&rec);
    for (id, name) in names {
        let entries: Vec<&Value> = rec.iter().filter(|v| v["agent"] == id).collect();
        assert_eq!(entries.len(), 100, "{name} {id}: one record line per cycle");
        assert!(
            entries.iter().all(|e| e["outcome"] == "stopped"),
            "{name} {id}: every cycle ends by its stop"
        );
        let with_commands = entries
            .iter()
            .filter(|e| e["commands"].as_array().is_some_and(|c| !c.is_empty()))
            .count();
        assert!(
            with_commands >= 5,
            "{name} {id}: commands in {with_commands} cycles"
        );
        let (first, last) = (position(entries[0]), position(entries[99]));
        let moved = ((last[0] - first[0]).powi(2) + (last[2] - first[2]).powi(2)).sqrt();
        assert!(
            moved > 0.1,
            "{name} {id}: its commands should move its body: {first:?} -> {last:?}"
        );
    }
}

fn agents_end_when_the_host_is_killed(t: Transport) {
    let sdk = sdk();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("cpp-dead-host", 2, t);
    let config_path = cfg.write(dir.path());
    let config = config_path.to_str().unwrap();
    let events = Events::in_dir(dir.path());
    // No --frames: the host runs until it is killed.
    let host = spawn_host(&config_path, &events, &[]);
    cfg.follow_host(&events, &config_path);
    let compat = agent(&sdk.compat_agent, &[config, "0"]);
    let cpp = agent(&sdk.cpp_agent, &[config, "1"]);
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    host.signal(libc::SIGKILL);
    let _ = host.wait(Duration::from_secs(30));

    // The polling compat agent: wait_start(0) must notice the dead host.
    let out = compat.wait(Duration::from_secs(60));
    assert_eq!(
        out.code(),
        Some(1),
        "compat_agent should fail when the host dies\nstdout:\n{}\nstderr:\n{}",
        out.stdout,
        out.stderr
    );
    if t == Transport::Shm {
        assert!(
            out.stderr.contains("VRS_ERROR_HOST_GONE"),
            "compat_agent stderr:\n{}",
            out.stderr
        );
    }
    // The blocking agent ends too, without hanging. (Whether it calls the end an error
    // depends on whether the dead host's node was already cleaned up by another process:
    // then it looks like a closed session.)
    let out = cpp.wait(Duration::from_secs(60));
    assert!(
        matches!(out.code(), Some(0 | 1)),
        "cpp_agent: {:?}\nstderr:\n{}",
        out.status,
        out.stderr
    );
    if out.code() == Some(1) {
        assert!(
            out.stderr.contains("HOST_GONE"),
            "cpp_agent stderr:\n{}",
            out.stderr
        );
    }
}

#[test]
fn c_abi_reports_connect_failures_to_a_cpp_program() {
    let sdk = sdk();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::new("cpp-nohost", 1);
    cfg.connect_timeout_s = 0.2;
    let config = cfg.write(dir.path());
    // No host: vrsync::Agent's constructor throws vrsync::Error with the library's message.
    let out = agent(&sdk.cpp_agent, &[config.to_str().unwrap(), "0"]).wait(Duration::from_secs(60));
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains("VRS_ERROR_CONNECT") && out.stderr.contains("no host"),
        "stderr:\n{}",
        out.stderr
    );
    // A missing config file.
    let out =
        agent(&sdk.compat_agent, &["/nonexistent/vrsync.toml", "0"]).wait(Duration::from_secs(60));
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains("VRS_ERROR_CONFIG"),
        "stderr:\n{}",
        out.stderr
    );
}

/// The examples linked against the shared library load the installed one, not a
/// `libvrsync_agent.so` that `cargo test` left on `LD_LIBRARY_PATH` (which is older than
/// the sources after a `cargo test -p vrsync-tests`). Asked of the dynamic loader without
/// running them (`LD_TRACE_LOADED_OBJECTS`, what `ldd` does).
#[test]
fn c_and_cpp_examples_load_the_installed_library() {
    let sdk = sdk();
    for program in [
        &sdk.cpp_agent,
        &sdk.cpp_channel_agent,
        &sdk.compat_agent,
        &sdk.c_agent,
        &sdk.c_pkg_config,
    ] {
        let mut cmd = example_command(program, &[]);
        cmd.env("LD_TRACE_LOADED_OBJECTS", "1");
        let out = tool(&mut cmd, "the dynamic loader's list of libraries");
        let line = out
            .lines()
            .find(|l| l.trim_start().starts_with("libvrsync_agent.so"))
            .unwrap_or_else(|| panic!("{}: no libvrsync_agent.so in\n{out}", program.display()));
        // `libvrsync_agent.so => /path/libvrsync_agent.so (0x...)`
        let path = line
            .split_once("=>")
            .map(|(_, r)| r.trim().split(" (").next().unwrap_or("").trim())
            .unwrap_or("");
        assert_eq!(
            Path::new(path).parent(),
            Some(sdk.lib.as_path()),
            "{} loads {path}, not the installed library in {}:\n{out}",
            program.display(),
            sdk.lib.display()
        );
    }
}

/// The C++ channels example (`vrsync/agent.hpp`: `frame.vector`, `agent.act`,
/// `agent.act_discrete`, the specs) and the C example (the C calls) through a whole
/// `vr-sim run`, whose world has no use for channels: the vectors arrive zeroed, the
/// actions are received and left alone. What can be seen from outside: every cycle stopped
/// in time with every action queued, the specs as configured, and a value of the wrong
/// length refused with its status, naming the action.
fn cpp_channel_agent_runs_against_vr_sim(t: Transport) {
    let sdk = sdk();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("cpp-channels", 2, t);
    cfg.agent_extra = "[[agent.vector]]\nname = \"joints\"\nlen = 7\n\
                       [[agent.vector]]\nname = \"vel\"\nlen = 3\n\
                       [[agent.action]]\nname = \"torque\"\nlen = 7\nlow = -2.0\nhigh = 2.0\n\
                       [[agent.action]]\nname = \"gear\"\nn = 3\n"
        .into();
    let config_path = cfg.write(dir.path());
    let config = config_path.to_str().unwrap();
    let s = dir.path().join("summary.json");
    let events = Events::in_dir(dir.path());
    let host = spawn_host(
        &config_path,
        &events,
        &["--frames", "40", "--summary-json", s.to_str().unwrap()],
    );
    cfg.follow_host(&events, &config_path);
    let cpp = agent(&sdk.cpp_channel_agent, &[config, "0", "3"]);
    let c = agent(&sdk.c_agent, &[config, "1"]);

    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "vr-sim stderr:\n{}", out.stderr);
    let out = c.wait(RUN_DEADLINE);
    assert_eq!(
        out.code(),
        Some(0),
        "c_agent: stdout:\n{}\nstderr:\n{}",
        out.stdout,
        out.stderr
    );
    // Two actions a cycle, a move every 20 cycles, the vectors zero.
    assert!(
        out.stdout
            .contains("c_agent 1: 40 cycles, 2 commands, 80 actions, vectors sum 0"),
        "c_agent stdout:\n{}",
        out.stdout
    );
    let out = cpp.wait(RUN_DEADLINE);
    assert_eq!(
        out.code(),
        Some(0),
        "cpp_channel_agent: stdout:\n{}\nstderr:\n{}",
        out.stdout,
        out.stderr
    );
    for expected in [
        // vrsync::Error from vrs_agent_act: its status and the library's message.
        "refused (VRS_ERROR_WRONG_LENGTH): vrs_agent_act: action \"torque\" takes 7 floats, got 1",
        // Two actions a cycle; the specs as configured; vr-sim leaves the vectors at zero.
        ": 40 cycles, 80 actions, vectors: joints[7] vel[3]; actions: torque[7] in [-2.000000, \
         2.000000] gear in 0..3, largest |vector value| 0",
    ] {
        assert!(
            out.stdout.contains(expected),
            "cpp_channel_agent stdout should contain {expected:?}:\n{}",
            out.stdout
        );
    }
    let sum = summary(&s);
    assert_eq!(sum["frames"], 40, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["late_stops"], 0, "{sum}");
    assert_eq!(sum["frames_read"], 80, "{sum}");
}

for_each_transport!(
    c_and_cpp_agents_run_100_sync_cycles,
    agents_end_when_the_host_is_killed,
    cpp_channel_agent_runs_against_vr_sim,
);
