//! Test fixtures: built binaries, isolated sessions, temp dirs, child processes with
//! deadlines (killed on drop).

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// The folder holding `vr-sim`, `vr-agent` and `libvrsync_agent` (the C ABI library the
/// C/C++ tests install), built once per test process with the same profile as the tests.
///
/// `cargo test` builds other packages' binaries and cdylibs only on request, so we ask
/// for them — in a target dir of their own: a `cargo build` into the test's own target dir
/// while `cargo test` runs leaves a second `vrsync_bridge` rlib (another profile, another
/// hash) beside the test build's, and the doctests that run afterwards then find two.
pub fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let exe = std::env::current_exe().expect("test exe");
        // target/<profile>/deps/tests-<hash>
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target/<profile>")
            .to_path_buf();
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let target_dir = profile_dir.parent().expect("target").join("test-bins");
        let mut cmd = Command::new(env!("CARGO"));
        cmd.current_dir(workspace())
            .args(["build", "--quiet", "-p", "vrsync-sim", "-p", "vrsync-agent"])
            .arg("--target-dir")
            .arg(&target_dir);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("run cargo build");
        assert!(status.success(), "cargo build of the binaries failed");
        target_dir.join(if release { "release" } else { "debug" })
    })
}

/// Path of a workspace binary.
pub fn bin(name: &str) -> PathBuf {
    bin_dir().join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
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

/// `for_both_transports!(a, b)` makes tests `shm::a`, `tcp::a`, `shm::b`, `tcp::b` that call
/// `a(Transport::Shm)` … : one test body, the same assertions, over both transports.
macro_rules! for_both_transports {
    ($($name:ident),* $(,)?) => {
        mod shm {
            $( #[test] fn $name() { super::$name(crate::util::Transport::Shm) } )*
        }
        mod tcp {
            $( #[test] fn $name() { super::$name(crate::util::Transport::Tcp) } )*
        }
    };
}

/// Which transport a test runs over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    Shm,
    Tcp,
}

/// A loopback port that was free a moment ago (bind port 0, read it, release it).
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("bind 127.0.0.1:0")
        .port()
}

/// Options of a generated test config.
#[derive(Debug, Clone)]
pub struct TestConfig {
    pub transport: Transport,
    pub tcp_port: u16,
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
}

impl TestConfig {
    pub fn new(tag: &str, agents: u32) -> Self {
        Self::with_transport(tag, agents, Transport::Shm)
    }

    pub fn with_transport(tag: &str, agents: u32, transport: Transport) -> Self {
        Self {
            transport,
            tcp_port: if transport == Transport::Tcp {
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
        for id in 0..self.agents {
            s += &format!(
                "\n[[agent]]\nid = {id}\n[[agent.camera]]\nname = \"left\"\nwidth = {w}\n\
                 [[agent.camera]]\nname = \"right\"\nwidth = {w}\n",
                w = self.width
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
    stderr_lines: Receiver<String>,
    stderr_all: Arc<Mutex<String>>,
    stderr_thread: Option<JoinHandle<()>>,
}

impl Proc {
    /// Spawns `program args` with piped output.
    pub fn spawn(program: &Path, args: &[&str]) -> Self {
        let mut child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .env("RUST_LOG", "info")
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", program.display()));
        let mut out = child.stdout.take().expect("stdout");
        let err = child.stderr.take().expect("stderr");
        let stdout = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        let (tx, rx) = mpsc::channel();
        let all = Arc::new(Mutex::new(String::new()));
        let all2 = Arc::clone(&all);
        let stderr_thread = std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                {
                    let mut a = all2.lock().expect("lock");
                    a.push_str(&line);
                    a.push('\n');
                }
                let _ = tx.send(line);
            }
        });
        Self {
            name: format!(
                "{} {}",
                program
                    .file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default(),
                args.join(" ")
            ),
            child: Some(child),
            stdout: Some(stdout),
            stderr_lines: rx,
            stderr_all: all,
            stderr_thread: Some(stderr_thread),
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("child").id()
    }

    /// Waits until a stderr line contains `needle`; panics after `timeout` naming both.
    pub fn wait_for_stderr(&mut self, needle: &str, timeout: Duration) -> String {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.stderr_lines.recv_timeout(left) {
                Ok(line) if line.contains(needle) => return line,
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => panic!(
                    "`{}`: no stderr line with {needle:?} within {timeout:?}; stderr so far:\n{}",
                    self.name,
                    self.stderr_all.lock().expect("lock")
                ),
                Err(RecvTimeoutError::Disconnected) => panic!(
                    "`{}` closed stderr without a line containing {needle:?}; stderr:\n{}",
                    self.name,
                    self.stderr_all.lock().expect("lock")
                ),
            }
        }
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

/// Reads a `vr-sim --record` file: one JSON value per line.
pub fn record(path: &Path) -> Vec<serde_json::Value> {
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
