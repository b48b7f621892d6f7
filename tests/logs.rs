//! Log colours: `vr-sim` and `vr-agent` write ANSI codes only when stderr is a terminal and
//! `NO_COLOR` is unset or empty (<https://no-color.org>).

use std::io::Read;
use std::os::fd::{FromRawFd, OwnedFd};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{
    EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, TestConfig, Transport, bin, run, spawn_host,
    summary,
};

/// How a test gives the child its stderr.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stderr {
    /// A pipe (what a log file or Unity's `Editor.log` looks like to the child).
    Pipe,
    /// A pseudo-terminal.
    Tty,
}

/// Runs `program args` with `NO_COLOR` as given (`None`: removed) and stderr on `stderr`;
/// returns its stderr after it exited (killed after [`EVENT_DEADLINE`]).
fn stderr_of(program: &str, args: &[&str], no_color: Option<&str>, stderr: Stderr) -> String {
    let mut cmd = Command::new(bin(program));
    cmd.args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .env("RUST_LOG", "info");
    match no_color {
        Some(v) => cmd.env("NO_COLOR", v),
        None => cmd.env_remove("NO_COLOR"),
    };
    let reader: Box<dyn Read + Send> = match stderr {
        Stderr::Pipe => {
            cmd.stderr(Stdio::piped());
            let mut child = cmd.spawn().unwrap();
            let err = child.stderr.take().unwrap();
            return finish(child, Box::new(err));
        }
        Stderr::Tty => {
            let (mut master, mut slave) = (0, 0);
            // SAFETY: openpty writes two fds into the out-params; null name/termios/winsize
            // are allowed.
            let rc = unsafe {
                libc::openpty(
                    &mut master,
                    &mut slave,
                    std::ptr::null_mut(),
                    std::ptr::null(),
                    std::ptr::null(),
                )
            };
            assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
            // SAFETY: both fds were just opened by openpty and are owned by nobody else.
            let (master, slave) =
                unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
            cmd.stderr(Stdio::from(slave));
            Box::new(std::fs::File::from(master))
        }
    };
    let child = cmd.spawn().unwrap();
    // Our copy of the terminal's slave side goes with `cmd`, so reading the master ends
    // (EIO) once the child is gone.
    drop(cmd);
    finish(child, reader)
}

/// Reads `reader` to its end while waiting for `child` (killed after the deadline).
fn finish(mut child: std::process::Child, mut reader: Box<dyn Read + Send>) -> String {
    let read = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        // A terminal's master side reports EIO when the last slave closes: the end.
        let _ = reader.read_to_end(&mut bytes);
        String::from_utf8_lossy(&bytes).into_owned()
    });
    let deadline = Instant::now() + EVENT_DEADLINE;
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the child did not exit within {EVENT_DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    read.join().unwrap()
}

/// `vr-sim run` of a session no agent joins, with a short connect timeout: it logs (INFO)
/// and exits 1. Returns its stderr.
fn vr_sim_stderr(no_color: Option<&str>, stderr: Stderr) -> String {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::new("colour", 1);
    cfg.connect_timeout_s = 0.2;
    let path = cfg.write(dir.path());
    let out = stderr_of(
        "vr-sim",
        &["run", "--config", path.to_str().unwrap(), "--quiet"],
        no_color,
        stderr,
    );
    assert!(out.contains("INFO"), "no log line:\n{out}");
    out
}

/// `vr-agent` for 2 cycles of a running host; returns its stderr.
fn vr_agent_stderr(no_color: Option<&str>, stderr: Stderr) -> String {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::new("colour-agent", 1);
    let path = cfg.write(dir.path());
    let events = Events::in_dir(dir.path());
    let host = spawn_host(&path, &events, &["--frames", "2"]);
    events.wait_for("listening", EVENT_DEADLINE);
    let p = path.to_str().unwrap();
    let out = stderr_of(
        "vr-agent",
        &["--config", p, "--id", "0", "--policy", "idle"],
        no_color,
        stderr,
    );
    let _ = Proc::wait(host, EVENT_DEADLINE);
    assert!(out.contains("INFO"), "no log line:\n{out}");
    out
}

const ESC: &str = "\x1b[";

#[test]
fn vr_sim_colours_only_a_terminal_without_no_color() {
    assert!(!vr_sim_stderr(None, Stderr::Pipe).contains(ESC));
    assert!(!vr_sim_stderr(Some("1"), Stderr::Pipe).contains(ESC));
    assert!(!vr_sim_stderr(Some("1"), Stderr::Tty).contains(ESC));
    assert!(vr_sim_stderr(None, Stderr::Tty).contains(ESC));
    assert!(vr_sim_stderr(Some(""), Stderr::Tty).contains(ESC));
}

#[test]
fn vr_agent_colours_only_a_terminal_without_no_color() {
    assert!(!vr_agent_stderr(None, Stderr::Pipe).contains(ESC));
    assert!(!vr_agent_stderr(Some("1"), Stderr::Tty).contains(ESC));
    assert!(vr_agent_stderr(None, Stderr::Tty).contains(ESC));
}

#[test]
fn vr_sim_prints_its_connect_timeout_rounded() {
    let out = vr_sim_stderr(None, Stderr::Pipe);
    assert!(
        out.contains("agents [0] did not connect within 200 ms"),
        "{out}"
    );
}

/// The end of a zenoh run logs no error: the host closes its session, and its agents, which
/// see it closed, leave without a goodbye. (A leave batch sent after the host closed was
/// logged by the host's closing zenoh session as data for an unknown key expression: two
/// to four ERROR lines at the end of every 4-agent run.)
#[test]
fn a_zenoh_run_ends_without_error_lines() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::with_transport("zenoh-end", 4, Transport::Zenoh);
    let path = cfg.write(dir.path());
    let s = dir.path().join("summary.json");
    let out = run(
        "vr-sim",
        &[
            "run",
            "--config",
            path.to_str().unwrap(),
            "--frames",
            "50",
            "--spawn-agents",
            "4",
            "--agent-arg=--policy",
            "--agent-arg=wander",
            "--summary-json",
            s.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let summary = summary(&s);
    assert_eq!(summary["frames"], 50);
    assert_eq!(summary["frames_delivered"], 200);
    let errors: Vec<&str> = out
        .stderr
        .lines()
        .filter(|l| l.contains(" ERROR "))
        .collect();
    assert!(errors.is_empty(), "error lines:\n{}", errors.join("\n"));
}
