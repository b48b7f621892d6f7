//! Unit tests of the agent API over every transport.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

#[test]
fn wait_timeout_message_rounds_the_wait() {
    let e = WaitStartError::Timeout {
        waited: Duration::new(10, 1),
        last_cycle: Some(3),
    };
    assert_eq!(
        e.to_string(),
        "no start from the host within 10 s (last cycle seen: 3)"
    );
    let first = WaitStartError::Timeout {
        waited: Duration::from_millis(250),
        last_cycle: None,
    };
    assert_eq!(
        first.to_string(),
        "no start from the host within 250 ms (no frame received yet)"
    );
}

use vrsync_bridge::Host;

use super::*;

/// A config with agents `ids` (one 8×4 camera each) over `kind`, its own session, and
/// TCP on a free loopback port.
fn config(tag: &str, kind: &str, ids: &[u32]) -> Config {
    static N: AtomicU32 = AtomicU32::new(0);
    let session = format!(
        "agent{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    let mut toml = format!(
        "session = {session:?}\n[sync]\nstop_timeout = 5.0\nconnect_timeout = 5.0\n\
         [transport]\nkind = {kind:?}\ntcp_listen = \"127.0.0.1:0\"\n"
    );
    for id in ids {
        toml.push_str(&format!(
            "[[agent]]\nid = {id}\n[[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n"
        ));
    }
    Config::from_toml_str(&toml, Path::new("<test>")).unwrap()
}

fn publish_cycle(host: &mut Host) {
    let frame = host.loan_frame(0).unwrap();
    host.publish(frame).unwrap();
    host.start().unwrap();
}

/// A host of `config` on its own thread (a TCP host answers hellos only while it
/// waits, and neither host nor agent may cross threads). It runs `cycles` cycles once
/// agent 0 is there (with `cycles == 0` it only answers connection attempts), then
/// waits for the returned sender, and checks that no termination was reported.
/// Returns the config with the bound TCP address.
fn spawn_host(
    mut config: Config,
    cycles: u64,
) -> (
    Config,
    std::sync::mpsc::Sender<()>,
    std::thread::JoinHandle<()>,
) {
    let (config_tx, config_rx) = std::sync::mpsc::channel();
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let join = std::thread::spawn(move || {
        let mut host = Host::builder(&config).create().unwrap();
        if let Some(addr) = host.tcp_local_addr() {
            config.transport.tcp_listen = addr;
        }
        config_tx.send(config).unwrap();
        if cycles == 0 {
            let deadline = Instant::now() + Duration::from_secs(30);
            while done_rx.try_recv().is_err() && Instant::now() < deadline {
                let _ = host.wait_for_agents(Duration::from_millis(20));
            }
        } else {
            host.wait_for_agents(Duration::from_secs(10)).unwrap();
            for _ in 0..cycles {
                publish_cycle(&mut host);
                host.collect().unwrap();
            }
            let _ = done_rx.recv_timeout(Duration::from_secs(30));
        }
        assert!(!host.termination_requested());
    });
    let config = config_rx.recv_timeout(Duration::from_secs(30)).unwrap();
    (config, done_tx, join)
}

fn an_id_the_host_does_not_serve_is_refused_naming_the_served_ids(kind: &str) {
    let (config, done, host) = spawn_host(config("unserved", kind, &[0, 1]), 0);
    let err = AgentBuilder::new(&config, 5)
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .unwrap_err();
    match &err {
        AgentConnectError::IdNotServed {
            session,
            agent,
            served,
        } => {
            assert_eq!(session, &config.session);
            assert_eq!(*agent, 5);
            assert_eq!(served, &[0, 1]);
        }
        other => panic!("{kind}: expected IdNotServed, got {other:?}"),
    }
    let message = err.to_string();
    assert!(
        message.contains("serves agents [0, 1], not agent 5"),
        "{message}"
    );
    assert!(!message.contains("vr-sim"), "{message}");
    done.send(()).unwrap();
    host.join().unwrap();
}

#[test]
fn an_id_the_host_does_not_serve_is_refused_naming_the_served_ids_shm() {
    an_id_the_host_does_not_serve_is_refused_naming_the_served_ids("shm");
}

#[test]
fn an_id_the_host_does_not_serve_is_refused_naming_the_served_ids_tcp() {
    an_id_the_host_does_not_serve_is_refused_naming_the_served_ids("tcp");
}

fn no_host_names_the_session_and_the_missing_side(kind: &str) {
    let config = config("nohost", kind, &[0]);
    let err = AgentBuilder::new(&config, 0)
        .connect_timeout(Duration::from_millis(100))
        .connect()
        .unwrap_err();
    assert!(
        matches!(&err, AgentConnectError::HostNotFound { session, agent: 0, .. }
            if *session == config.session),
        "{kind}: {err:?}"
    );
    let message = err.to_string();
    assert!(message.contains(&config.session), "{message}");
    assert!(message.contains("host side"), "{message}");
    assert!(!message.contains("vr-sim"), "{message}");
}

#[test]
fn no_host_names_the_session_and_the_missing_side_shm() {
    no_host_names_the_session_and_the_missing_side("shm");
}

#[test]
fn no_host_names_the_session_and_the_missing_side_tcp() {
    no_host_names_the_session_and_the_missing_side("tcp");
}

fn holding_too_many_frames_is_a_typed_error(kind: &str) {
    let (config, done, host) = spawn_host(config("held", kind, &[0]), 3);
    let mut agent = AgentBuilder::new(&config, 0).connect().unwrap();
    let wait = Some(Duration::from_secs(10));
    let mut held = Vec::new();
    for cycle in 0..2 {
        let frame = agent.wait_start(wait).unwrap();
        assert_eq!(frame.cycle(), cycle);
        held.push(frame);
        agent.stop().unwrap();
    }
    let err = agent.wait_start(wait).unwrap_err();
    assert!(
        matches!(err, WaitStartError::TooManyFramesHeld { max: 2 }),
        "{kind}: {err:?}"
    );
    assert!(err.to_string().contains("drop the frames"), "{err}");
    // Letting one go is enough to go on, with the frame that was waiting.
    held.remove(0);
    let frame = agent.wait_start(wait).unwrap();
    assert_eq!(frame.cycle(), 2);
    agent.stop().unwrap();
    done.send(()).unwrap();
    host.join().unwrap();
}

#[test]
fn holding_too_many_frames_is_a_typed_error_shm() {
    holding_too_many_frames_is_a_typed_error("shm");
}

#[test]
fn holding_too_many_frames_is_a_typed_error_tcp() {
    holding_too_many_frames_is_a_typed_error("tcp");
}

// --- SignalHandling::Leave, in a child process (signal handlers are process-wide,
// and other tests of this binary install ours through the C ABI).

const CHILD_ENV: &str = "VRSYNC_TEST_LEAVE_CHILD";
const CHILD_DONE_ENV: &str = "VRSYNC_TEST_LEAVE_DONE";
static OURS_RAN: AtomicBool = AtomicBool::new(false);

extern "C" fn our_handler(_: libc::c_int) {
    OURS_RAN.store(true, Ordering::SeqCst);
}

fn current_handler(sig: libc::c_int) -> libc::sighandler_t {
    // SAFETY: a query only (null new action), into a zeroed sigaction.
    unsafe {
        let mut old: libc::sigaction = core::mem::zeroed();
        assert_eq!(libc::sigaction(sig, core::ptr::null(), &mut old), 0);
        old.sa_sigaction
    }
}

/// The child's side: a process with its own SIGINT handler runs a host and an agent
/// with the default `Leave` through a cycle; the handler is still its own, SIGINT
/// runs it, and no wait reports a termination.
fn leave_child(kind: &str, done_file: &Path) {
    let handler: extern "C" fn(libc::c_int) = our_handler;
    // SAFETY: installs a handler that only stores to an atomic.
    unsafe {
        let mut action: libc::sigaction = core::mem::zeroed();
        action.sa_sigaction = handler as libc::sighandler_t;
        assert_eq!(
            libc::sigaction(libc::SIGINT, &action, core::ptr::null_mut()),
            0
        );
    }
    let sigterm_before = current_handler(libc::SIGTERM);

    let (config, done, host) = spawn_host(config("leave", kind, &[0]), 1);
    let mut agent = AgentBuilder::new(&config, 0).connect().unwrap();
    let frame = agent.wait_start(Some(Duration::from_secs(10))).unwrap();
    drop(frame);
    agent.stop().unwrap();

    assert_eq!(
        current_handler(libc::SIGINT),
        handler as libc::sighandler_t,
        "{kind}: SIGINT handler replaced"
    );
    assert_eq!(
        current_handler(libc::SIGTERM),
        sigterm_before,
        "{kind}: SIGTERM handler replaced"
    );
    // SAFETY: raising a signal whose handler is ours.
    assert_eq!(unsafe { libc::raise(libc::SIGINT) }, 0);
    assert!(
        OURS_RAN.load(Ordering::SeqCst),
        "{kind}: our handler did not run"
    );
    let err = agent
        .wait_start(Some(Duration::from_millis(20)))
        .unwrap_err();
    assert!(
        matches!(err, WaitStartError::Timeout { .. }),
        "{kind}: {err:?}"
    );
    done.send(()).unwrap();
    host.join().unwrap();
    std::fs::write(done_file, kind).unwrap();
}

#[test]
fn leave_keeps_the_process_signal_handlers() {
    if let (Ok(kind), Ok(done)) = (std::env::var(CHILD_ENV), std::env::var(CHILD_DONE_ENV)) {
        leave_child(&kind, Path::new(&done));
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for kind in ["shm", "tcp"] {
        let done = dir.path().join(format!("{kind}.done"));
        let child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "agent::tests::leave_keeps_the_process_signal_handlers",
                "--test-threads=1",
                "--nocapture",
            ])
            .env(CHILD_ENV, kind)
            .env(CHILD_DONE_ENV, &done)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let pid = child.id();
        let (tx, rx) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            let _ = tx.send(());
            child.wait_with_output()
        });
        rx.recv().unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        while !waiter.is_finished() && Instant::now() < deadline {
            std::thread::park_timeout(Duration::from_millis(20));
        }
        if !waiter.is_finished() {
            // SAFETY: kills our own child, still unreaped (the waiter holds it).
            unsafe { libc::kill(pid as i32, libc::SIGKILL) };
        }
        let out = waiter.join().unwrap().unwrap();
        assert!(
            out.status.success() && done.exists(),
            "{kind}: child failed ({:?}):\n{}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

fn try_next_frame_takes_a_waiting_frame_without_blocking(kind: &str) {
    let (config, done, host) = spawn_host(config("try", kind, &[0]), 3);
    let mut agent = AgentBuilder::new(&config, 0).connect().unwrap();
    let wait = Some(Duration::from_secs(10));
    let first = agent.wait_start(wait).unwrap();
    assert_eq!(first.cycle(), 0);
    // In sync mode nothing newer comes before this agent's stop: no frame, and no wait.
    assert!(agent.try_next_frame().unwrap().is_none(), "{kind}");
    drop(first);
    agent.stop().unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let frame = loop {
        if let Some(frame) = agent.try_next_frame().unwrap() {
            break frame;
        }
        assert!(Instant::now() < deadline, "{kind}: no frame of cycle 1");
        std::thread::yield_now();
    };
    assert_eq!(frame.cycle(), 1);
    assert_eq!(agent.last_cycle(), Some(1));
    assert!(
        agent.try_next_frame().unwrap().is_none(),
        "{kind}: a frame is taken once"
    );
    drop(frame);
    agent.stop().unwrap();
    // A blocking wait after tries that left the start signals pending still waits for
    // the next frame.
    let frame = agent.wait_start(wait).unwrap();
    assert_eq!(frame.cycle(), 2);
    assert_eq!(agent.frames_skipped(), 0);
    drop(frame);
    agent.stop().unwrap();
    done.send(()).unwrap();
    host.join().unwrap();
}

#[test]
fn try_next_frame_takes_a_waiting_frame_without_blocking_shm() {
    try_next_frame_takes_a_waiting_frame_without_blocking("shm");
}

#[test]
fn try_next_frame_takes_a_waiting_frame_without_blocking_tcp() {
    try_next_frame_takes_a_waiting_frame_without_blocking("tcp");
}
