//! Test fixtures: built binaries, isolated sessions, temp dirs, child processes with
//! deadlines (killed on drop).

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// `target/<profile>` of this test build.
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test exe");
    // target/<profile>/deps/tests-<hash>
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf()
}

/// The folder holding `vr-sim`, `vr-agent` and `vr-bench-agent`: `target/<profile>` of this
/// test build. Cargo itself builds them there in the same `cargo test --workspace` (no
/// nested `cargo build`): `vrsync-sim` and `vrsync-agent-bin` have integration tests of their
/// own, and Cargo builds a package's binaries for its integration tests.
pub fn bin_dir() -> PathBuf {
    profile_dir()
}

/// The folder holding `libvrsync_agent.so` and `libvrsync_agent.a` (the C ABI library the
/// C/C++ tests install): `target/<profile>/deps`. `vrsync-agent-ffi` is a dev-dependency of
/// this package, so Cargo builds its library, with every crate type, for these tests.
pub fn lib_dir() -> PathBuf {
    profile_dir().join("deps")
}

/// Path of a workspace binary; panics with the command to run when it is missing or
/// older than one of its sources (a `cargo test -p vrsync-tests` does not rebuild it).
/// In `$VRSYNC_BIN_DIR` when that is set (e.g. `target/release`: these tests against the
/// optimized host and agents, as `scripts/under-load --release` runs them), else in
/// [`bin_dir`].
pub fn bin(name: &str) -> PathBuf {
    let dir = std::env::var_os("VRSYNC_BIN_DIR").map_or_else(bin_dir, PathBuf::from);
    built(dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX)))
}

/// Path of a workspace example (`target/<profile>/examples/NAME`), checked like [`bin`]:
/// `cargo test --workspace` builds every member's examples.
pub fn example(name: &str) -> PathBuf {
    built(
        profile_dir()
            .join("examples")
            .join(format!("{name}{}", std::env::consts::EXE_SUFFIX)),
    )
}

/// `path`, after checking that it exists and is newer than its sources.
fn built(path: PathBuf) -> PathBuf {
    let hint = "build the binaries and examples with `cargo build --workspace --bins --examples` \
                (or run the whole `cargo test --workspace`)";
    let built = std::fs::metadata(&path)
        .and_then(|m| m.modified())
        .unwrap_or_else(|e| panic!("{}: {e}; {hint}", path.display()));
    // Cargo's dep-info next to the binary: `<binary>: <source> <source> ...`. `cargo build`
    // writes it, but `cargo test` (which builds the binaries for their packages'
    // integration tests) does not, so a clean `cargo test --workspace` has none: then the
    // binary that run just built is taken as it is.
    let dep_info = path.with_extension("d");
    let Ok(text) = std::fs::read_to_string(&dep_info) else {
        return path;
    };
    let sources = text
        .lines()
        .next()
        .and_then(|l| l.split_once(": "))
        .map_or("", |(_, s)| s);
    // Paths with spaces are escaped as `\ `; none of ours has one, but keep them whole.
    let sources = sources.replace("\\ ", "\u{0}");
    for source in sources.split_whitespace() {
        let source = source.replace('\u{0}', " ");
        let newer = std::fs::metadata(&source)
            .and_then(|m| m.modified())
            .is_ok_and(|t| t > built);
        assert!(
            !newer,
            "{} is older than its source {source}; {hint}",
            path.display()
        );
    }
    path
}

/// A session name unique to this test process and call.
pub fn session(tag: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "t{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// `for_each_transport!(a, b)` makes tests `shm::a`, `tcp::a`, `zenoh::a`, `shm::b`, … that
/// call `a(Transport::Shm)` … : one test body, the same assertions, over every transport of
/// [`Transport::ALL`] (the multi-process suites take their transports from here only).
macro_rules! for_each_transport {
    ($($name:ident),* $(,)?) => {
        mod shm {
            $( #[test] fn $name() { super::$name(crate::util::Transport::Shm) } )*
        }
        mod tcp {
            $( #[test] fn $name() { super::$name(crate::util::Transport::Tcp) } )*
        }
        mod zenoh {
            $( #[test] fn $name() { super::$name(crate::util::Transport::Zenoh) } )*
        }
        /// Fails to compile when [`crate::util::Transport`] gains a transport this macro
        /// makes no tests for.
        #[allow(dead_code)]
        fn every_transport_has_its_module(t: crate::util::Transport) {
            match t {
                crate::util::Transport::Shm
                | crate::util::Transport::Tcp
                | crate::util::Transport::Zenoh => {}
            }
        }
    };
}

/// Which transport a test runs over: every transport of the bridge's registry
/// ([`vrsync_bridge::TransportKind::ALL`]) that serves the SDK's agents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    Shm,
    Tcp,
    /// zenoh over loopback, on a port free when the config was made (zenoh cannot report
    /// a port-0 listener's port through its stable API).
    Zenoh,
}

impl Transport {
    /// Every transport the multi-process suites run over ([`for_each_transport!`]).
    pub const ALL: [Transport; 3] = [Transport::Shm, Transport::Tcp, Transport::Zenoh];

    /// The suites' transport for a transport of the bridge, `None` for one they do not run
    /// over. The match is exhaustive: a transport added to the bridge does not compile here
    /// until it is in the suites or says why not.
    pub fn of_kind(kind: vrsync_bridge::TransportKind) -> Option<Self> {
        use vrsync_bridge::TransportKind as K;
        match kind {
            K::Shm => Some(Self::Shm),
            K::Tcp => Some(Self::Tcp),
            K::Zenoh => Some(Self::Zenoh),
            // Serves agents of the original protocol (the original Python clients), not
            // the SDK's agents these suites start: its own suite is `legacy.rs`, which runs
            // the original clients through the same host loop.
            K::Legacy => None,
        }
    }

    /// The `[transport] kind` spelling (also the run summary's `transport`).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Shm => "shm",
            Self::Tcp => "tcp",
            Self::Zenoh => "zenoh",
        }
    }
}

#[test]
fn the_suites_run_over_every_transport_of_the_bridge() {
    let expected: Vec<Transport> = vrsync_bridge::TransportKind::ALL
        .into_iter()
        .filter_map(Transport::of_kind)
        .collect();
    assert_eq!(expected, Transport::ALL);
}

/// A loopback port that was free a moment ago (bind port 0, read it, release it). Only for
/// tests that need a port nobody listens on: hosts bind port 0 and report the bound port
/// in their `listening` event ([`TestConfig::follow_host`]).
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("bind 127.0.0.1:0")
        .port()
}

/// A `[sync]` line (for [`TestConfig::sync_extra`]) for tests of the stop timeout's own
/// semantics: the cycle ends without a live but late agent (the default, `"alive"`,
/// waits for it).
pub const WAIT_FOR_STOP_TIMEOUT: &str = "wait_for_stop = \"timeout\"\n";

/// Options of a generated test config.
#[derive(Debug, Clone)]
pub struct TestConfig {
    pub transport: Transport,
    pub tcp_port: u16,
    /// The zenoh endpoint's port ([`Transport::Zenoh`]).
    pub zenoh_port: u16,
    pub session: String,
    pub agents: u32,
    pub sync_mode: bool,
    pub dt_s: f64,
    pub stop_timeout_s: f64,
    pub connect_timeout_s: f64,
    pub width: u32,
    pub extra: String,
    /// Lines appended to the `[sync]` table.
    pub sync_extra: String,
    /// Lines appended to every `[[agent]]` table (after its cameras).
    pub agent_extra: String,
}

impl TestConfig {
    pub fn new(tag: &str, agents: u32) -> Self {
        Self::with_transport(tag, agents, Transport::Shm)
    }

    /// Over TCP the host binds port 0: see [`TestConfig::follow_host`].
    pub fn with_transport(tag: &str, agents: u32, transport: Transport) -> Self {
        Self {
            transport,
            tcp_port: 0,
            zenoh_port: if transport == Transport::Zenoh {
                free_tcp_port()
            } else {
                0
            },
            session: session(tag),
            agents,
            sync_mode: true,
            dt_s: 0.1,
            stop_timeout_s: 5.0,
            connect_timeout_s: 20.0,
            width: 64,
            extra: String::new(),
            sync_extra: String::new(),
            agent_extra: String::new(),
        }
    }

    pub fn toml(&self) -> String {
        let mut s = format!(
            "session = {:?}\nseed = 7\n{}\n[sync]\nsync_mode = {}\nsimulation_time_per_frame = {}\n\
             stop_timeout = {}\nconnect_timeout = {}\n",
            self.session,
            self.extra,
            self.sync_mode,
            self.dt_s,
            self.stop_timeout_s,
            self.connect_timeout_s
        );
        s += &self.sync_extra;
        if self.transport == Transport::Tcp {
            s += &format!(
                "\n[transport]\nkind = \"tcp\"\ntcp_listen = \"127.0.0.1:{}\"\n",
                self.tcp_port
            );
        }
        if self.transport == Transport::Zenoh {
            s += &format!(
                "\n[transport]\nkind = \"zenoh\"\n[transport.zenoh]\n\
                 listen = [\"tcp/127.0.0.1:{}\"]\nlease = 2.0\n",
                self.zenoh_port
            );
        }
        for id in 0..self.agents {
            s += &format!(
                "\n[[agent]]\nid = {id}\n[[agent.camera]]\nname = \"left\"\nwidth = {w}\n\
                 [[agent.camera]]\nname = \"right\"\nwidth = {w}\n{extra}",
                w = self.width,
                extra = self.agent_extra
            );
        }
        s
    }

    /// Writes the config into `dir` and returns its path.
    pub fn write(&self, dir: &Path) -> PathBuf {
        let path = dir.join(format!("{}.toml", self.session));
        std::fs::write(&path, self.toml()).expect("write config");
        path
    }

    /// Waits for the host's `listening` event; over TCP, takes the port the host bound
    /// and rewrites the config at `path` with it, so agents started afterwards find the
    /// host. The host read its config before it listened, so rewriting is safe.
    pub fn follow_host(&mut self, events: &Events, path: &Path) {
        let listening = events.wait_for("listening", EVENT_DEADLINE);
        if self.transport == Transport::Tcp {
            let addr: std::net::SocketAddr = listening["address"]
                .as_str()
                .and_then(|a| a.parse().ok())
                .unwrap_or_else(|| panic!("listening event without an address: {listening}"));
            self.tcp_port = addr.port();
            std::fs::write(path, self.toml()).expect("rewrite config");
        }
    }
}

/// Deadline for one event of a running process on a loaded 2-core machine.
pub const EVENT_DEADLINE: Duration = Duration::from_secs(60);

/// The `vr-sim run --events` file of one run: waits read it, each with a deadline.
#[derive(Debug)]
pub struct Events {
    path: PathBuf,
}

impl Events {
    /// A new events file in `dir` (not created yet: vr-sim creates it).
    pub fn in_dir(dir: &Path) -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        Self {
            path: dir.join(format!(
                "events-{}.jsonl",
                N.fetch_add(1, Ordering::Relaxed)
            )),
        }
    }

    /// The path, for `--events`.
    pub fn arg(&self) -> &str {
        self.path.to_str().expect("UTF-8 path")
    }

    /// Every complete event so far.
    pub fn read(&self) -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(&self.path).unwrap_or_default();
        // A line without its newline may still be being written.
        let complete = text.rfind('\n').map_or("", |end| &text[..end]);
        complete
            .lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("event line {l:?}: {e}")))
            .collect()
    }

    /// Events of `kind` so far.
    pub fn of(&self, kind: &str) -> Vec<serde_json::Value> {
        self.read()
            .into_iter()
            .filter(|e| e["event"] == kind)
            .collect()
    }

    /// Waits for the first event of `kind`.
    pub fn wait_for(&self, kind: &str, timeout: Duration) -> serde_json::Value {
        self.wait_for_match(kind, |_| true, timeout)
    }

    /// Waits for the first event of `kind` that satisfies `pred`; panics after `timeout`,
    /// or as soon as the run ended (`finished` or `error`) without it, naming what it
    /// waited for and showing the events so far.
    pub fn wait_for_match(
        &self,
        kind: &str,
        pred: impl Fn(&serde_json::Value) -> bool,
        timeout: Duration,
    ) -> serde_json::Value {
        let deadline = Instant::now() + timeout;
        loop {
            let events = self.read();
            if let Some(e) = events.iter().find(|e| e["event"] == kind && pred(e)) {
                return e.clone();
            }
            let ended = events
                .iter()
                .any(|e| e["event"] == "finished" || e["event"] == "error");
            let show = || {
                events
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join("\n")
            };
            assert!(
                !ended,
                "{}: the run ended without the awaited `{kind}` event; events:\n{}",
                self.path.display(),
                show()
            );
            assert!(
                Instant::now() < deadline,
                "{}: no matching `{kind}` event within {timeout:?}; events so far:\n{}",
                self.path.display(),
                show()
            );
            // The file is appended to by another process: re-read it shortly.
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// Waits until the `vr-agent --log-cycles` file at `path` holds a line for `cycle` or a
/// later one (the agent writes and flushes it before it sends its stop): the agent has
/// got that far. A later one counts because an agent may skip frames (after a stall,
/// late, or when the host is faster than it), so a line for exactly `cycle` may never
/// come. Panics after `timeout`.
pub fn wait_for_cycle_line(path: &Path, cycle: u64, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    loop {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let complete = text.rfind('\n').map_or("", |end| &text[..end]);
        let seen = complete
            .lines()
            .filter_map(|l| l.split(' ').next()?.parse::<u64>().ok())
            .any(|c| c >= cycle);
        if seen {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{}: no line for cycle {cycle} within {timeout:?}; so far:\n{text}",
            path.display()
        );
        // The file is appended to by another process: re-read it shortly.
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Starts `vr-sim run --config CONFIG --events EVENTS --quiet ARGS...`.
pub fn spawn_host(config: &Path, events: &Events, args: &[&str]) -> Proc {
    Proc::spawn(&bin("vr-sim"), &host_args(config, events, args))
}

/// The arguments of [`spawn_host`]'s `vr-sim`.
pub fn host_args<'a>(config: &'a Path, events: &'a Events, args: &[&'a str]) -> Vec<&'a str> {
    let mut all = vec![
        "run",
        "--config",
        config.to_str().expect("UTF-8 path"),
        "--events",
        events.arg(),
        "--quiet",
    ];
    all.extend_from_slice(args);
    all
}

/// A `vr-sim run` host of a test config, in a temp dir of its own that also holds its
/// events file, its `--summary-json` and the cycle logs of the agents started with
/// [`HostRun::agent`]. [`HostRun::start`] returns once the host listens.
pub struct HostRun {
    /// The host: `vr-sim run --summary-json SUMMARY ARGS` (see [`spawn_host`]); first, so
    /// it is killed before its folder is removed.
    pub host: Proc,
    /// The config, with the port the host bound over TCP.
    pub cfg: TestConfig,
    /// The config file.
    pub config_path: PathBuf,
    /// Where the host writes its summary.
    pub summary: PathBuf,
    /// The host's events.
    pub events: Events,
    /// The temp dir (removed on drop, last).
    pub dir: tempfile::TempDir,
}

impl HostRun {
    /// Writes `cfg`, starts the host with `args` and waits until it listens
    /// ([`TestConfig::follow_host`]).
    pub fn start(cfg: TestConfig, args: &[&str]) -> Self {
        Self::start_in(tempfile::tempdir().expect("temp dir"), cfg, args)
    }

    /// [`HostRun::start`] in `dir` (for `args` naming files in it, e.g. `--record`).
    pub fn start_in(dir: tempfile::TempDir, mut cfg: TestConfig, args: &[&str]) -> Self {
        let config_path = cfg.write(dir.path());
        let summary = dir.path().join("summary.json");
        let events = Events::in_dir(dir.path());
        let mut all = vec!["--summary-json", summary.to_str().expect("UTF-8 path")];
        all.extend_from_slice(args);
        let host = spawn_host(&config_path, &events, &all);
        cfg.follow_host(&events, &config_path);
        Self {
            host,
            cfg,
            config_path,
            summary,
            events,
            dir,
        }
    }

    /// The config file's path as a `--config` argument.
    pub fn config(&self) -> &str {
        self.config_path.to_str().expect("UTF-8 path")
    }

    /// A file `name` in the run's temp dir.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Starts `vr-agent --config CONFIG --id ID ARGS --log-cycles DIR/LOG` and returns it
    /// with its cycle log's path.
    pub fn agent(&self, id: u32, log: &str, args: &[&str]) -> (Proc, PathBuf) {
        let log = self.path(log);
        let id = id.to_string();
        let mut all = vec!["--config", self.config(), "--id", &id];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--log-cycles", log.to_str().expect("UTF-8 path")]);
        (Proc::spawn(&bin("vr-agent"), &all), log)
    }
}

/// Captured output of a finished process.
#[derive(Debug)]
pub struct Output {
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

impl Output {
    pub fn code(&self) -> Option<i32> {
        self.status.code()
    }
}

/// A running child process: output captured, killed and reaped on drop.
pub struct Proc {
    name: String,
    child: Option<Child>,
    stdout: Option<JoinHandle<String>>,
    stderr_all: Arc<Mutex<String>>,
    stderr_thread: Option<JoinHandle<()>>,
}

impl Proc {
    /// Spawns `program args` with piped output.
    pub fn spawn(program: &Path, args: &[&str]) -> Self {
        let mut cmd = Command::new(program);
        cmd.args(args);
        Self::spawn_command(cmd)
    }

    /// Spawns `cmd` (program, arguments and environment set by the caller) with piped
    /// output.
    pub fn spawn_command(mut cmd: Command) -> Self {
        let name = std::iter::once(
            Path::new(cmd.get_program())
                .file_name()
                .unwrap_or_default()
                .to_string_lossy(),
        )
        .chain(cmd.get_args().map(|a| a.to_string_lossy()))
        .collect::<Vec<_>>()
        .join(" ");
        let program = cmd.get_program().to_string_lossy().into_owned();
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .env("RUST_LOG", "info")
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
        let mut out = child.stdout.take().expect("stdout");
        let err = child.stderr.take().expect("stderr");
        let stdout = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        let all = Arc::new(Mutex::new(String::new()));
        let all2 = Arc::clone(&all);
        let stderr_thread = std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                {
                    let mut a = all2.lock().expect("lock");
                    a.push_str(&line);
                    a.push('\n');
                }
            }
        });
        Self {
            name,
            child: Some(child),
            stdout: Some(stdout),
            stderr_all: all,
            stderr_thread: Some(stderr_thread),
        }
    }

    /// Whether the process has exited (without reaping its output: [`Proc::wait`] still
    /// returns it).
    pub fn try_exited(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| matches!(c.try_wait(), Ok(Some(_))))
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("child").id()
    }

    /// Waits for the process to exit; kills it and panics after `timeout`.
    pub fn wait(mut self, timeout: Duration) -> Output {
        let mut child = self.child.take().expect("child");
        let pid = child.id();
        let (tx, rx) = mpsc::channel();
        let waiter = std::thread::spawn(move || {
            let status = child.wait();
            let _ = tx.send(());
            status
        });
        let timed_out = rx.recv_timeout(timeout).is_err();
        if timed_out {
            // SAFETY: plain kill(2) on our own child's pid; it is not reaped yet (the waiter
            // thread still waits on it), so the pid cannot have been reused.
            unsafe {
                libc::kill(pid as i32, libc::SIGKILL);
            }
        }
        let status = waiter.join().expect("waiter").expect("wait");
        if let Some(t) = self.stderr_thread.take() {
            let _ = t.join();
        }
        let stdout = self
            .stdout
            .take()
            .map(|h| h.join().unwrap_or_default())
            .unwrap_or_default();
        let stderr = self.stderr_all.lock().expect("lock").clone();
        assert!(
            !timed_out,
            "`{}` did not exit within {timeout:?} (killed)\nstdout:\n{stdout}\nstderr:\n{stderr}",
            self.name
        );
        Output {
            status,
            stdout,
            stderr,
        }
    }

    /// Whether the process is stopped (by a signal): its state in `/proc/PID/stat` is `T`.
    pub fn is_stopped(&self) -> bool {
        let Some(c) = &self.child else { return false };
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", c.id())).unwrap_or_default();
        // `PID (COMM) STATE ...`; COMM may hold spaces and parentheses, so after the last ')'.
        stat.rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            == Some("T")
    }

    /// Sends a signal.
    pub fn signal(&self, sig: i32) {
        if let Some(c) = &self.child {
            // SAFETY: kill(2) on our own unreaped child.
            unsafe {
                libc::kill(c.id() as i32, sig);
            }
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Runs a binary to completion with a deadline.
pub fn run(name: &str, args: &[&str], timeout: Duration) -> Output {
    Proc::spawn(&bin(name), args).wait(timeout)
}

/// Reads a summary JSON file.
pub fn summary(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read summary {}: {e}", path.display()));
    serde_json::from_str(&text).expect("summary JSON")
}

/// Reads a `vr-sim --record` file's agent lines (one per agent per cycle; the header and
/// end lines, which have `record` instead of `agent`, are left out).
pub fn record(path: &Path) -> Vec<serde_json::Value> {
    record_lines(path)
        .into_iter()
        .filter(|v| v.get("agent").is_some())
        .collect()
}

/// Reads every line of a `vr-sim --record` file: header, agent lines, end.
pub fn record_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read record {}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).expect("record line"))
        .collect()
}

/// One line of `vr-agent --log-cycles`.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleLine {
    pub cycle: u64,
    pub sim_time_ns: u64,
    pub skipped: u64,
    pub action_ids: Vec<u32>,
}

/// Reads a `vr-agent --log-cycles` file.
pub fn cycle_log(path: &Path) -> Vec<CycleLine> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read cycle log {}: {e}", path.display()))
        .lines()
        .map(|l| {
            let mut it = l.split(' ');
            let mut num = || it.next().expect("field").parse::<u64>().expect("number");
            let (cycle, sim_time_ns, skipped) = (num(), num(), num());
            let ids = l.splitn(4, ' ').nth(3).unwrap_or("");
            CycleLine {
                cycle,
                sim_time_ns,
                skipped,
                action_ids: ids
                    .split(',')
                    .filter(|s| !s.is_empty())
                    .map(|s| s.parse().expect("action id"))
                    .collect(),
            }
        })
        .collect()
}

/// Generous deadline for a whole run in a debug build on a loaded 2-core machine.
pub const RUN_DEADLINE: Duration = Duration::from_secs(120);

/// A CA (`ca.pem`) and, signed by it, the host's certificate naming `host_ip` (`host.pem`,
/// `host.key`) and an agent's (`agent.pem`, `agent.key`); and a stranger's certificate
/// (`stranger.pem`, `stranger.key`) signed by another CA, in `dir`.
pub fn make_certificates(dir: &Path, host_ip: &str) {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair,
    };
    let ca = |name: &str| {
        let mut p = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        p.distinguished_name.push(DnType::CommonName, name);
        CertifiedIssuer::self_signed(p, KeyPair::generate().expect("CA key")).expect("CA")
    };
    let (ours, other) = (ca("vrsync test CA"), ca("another CA"));
    std::fs::write(dir.join("ca.pem"), ours.pem()).expect("write ca.pem");
    for (name, names, usage, issuer) in [
        (
            "host",
            vec![host_ip.to_string()],
            ExtendedKeyUsagePurpose::ServerAuth,
            &ours,
        ),
        ("agent", vec![], ExtendedKeyUsagePurpose::ClientAuth, &ours),
        (
            "stranger",
            vec![],
            ExtendedKeyUsagePurpose::ClientAuth,
            &other,
        ),
    ] {
        let mut p = CertificateParams::new(names).expect("params");
        p.distinguished_name.push(DnType::CommonName, name);
        p.extended_key_usages = vec![usage];
        let key = KeyPair::generate().expect("key");
        let cert = p.signed_by(&key, issuer).expect("sign");
        std::fs::write(dir.join(format!("{name}.pem")), cert.pem()).expect("write cert");
        std::fs::write(dir.join(format!("{name}.key")), key.serialize_pem()).expect("write key");
    }
}
