//! The transport conformance suite: what every transport must do, written once and run
//! against each (`conformance!` below instantiates it per transport; a new transport adds
//! one line). The host runs on its own thread of this process (neither host nor agent may
//! cross threads), or in a child process where the test kills it or signals it; every wait
//! has a deadline and every child is killed and reaped.
//!
//! Checked here, over the public host and agent APIs and, where the SDK cannot misbehave on
//! purpose, over the transport's own agent side ([`AgentTransport`]):
//! - every cycle arrives once and in order, with no lost wake-up, and each stop brings its
//!   whole batch (a stop is visible only after its batch);
//! - a slow agent gets the newest frame and the older ones are dropped;
//! - a late stop never completes the next cycle (it is dropped and counted);
//! - a batch naming a future cycle is dropped and counted, and nothing of it is applied;
//! - a flood of batches leaves the host's memory bounded (commands beyond
//!   `max_commands_per_cycle` dropped and counted) and the cycle still ends by its stop;
//! - a dead peer is detected both ways: an agent that goes away is evicted without waiting
//!   for the stop timeout; an agent sees a killed host as gone (not closed) and a host that
//!   closed the session as closed;
//! - termination: with `SignalHandling::Install`, SIGTERM ends the agent's wait;
//! - channels: vectors arrive in the frame, each cycle's actions in that cycle's report
//!   (the last value sent wins), malformed ones are counted and never applied, and configs
//!   that disagree on a channel are refused naming it (`conformance/channels.rs`).
//!
//! Each `on_agent_lost` policy and the timeout naming the late agents are unit-tested over a
//! fake transport in `bridge/src/host.rs`; the frame-holding limit and the connect errors in
//! `agent-sdk/src/agent.rs`; `SignalHandling::Leave` in a child process there.

// Helpers outside `#[test]` functions panic on failure too: this is a test binary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use vrsync_agent::{AgentBuilder, Command, SignalHandling, WaitStartError};
use vrsync_bridge::{
    ActionValue, AgentFrame, AgentOutcome, AgentTransport, Config, Host, MOTOR_FLAG_LEAVE,
    MOTOR_FLAG_STOP, MotorCommand, MotorHeader, PROTOCOL_VERSION, wait_for_newer_frame,
};

const WAIT: Duration = Duration::from_secs(20);

#[path = "conformance/channels.rs"]
mod channels;
use channels::{
    a_channel_mismatch_is_refused_naming_the_channel,
    channels_carry_vectors_and_actions_each_cycle,
    the_longest_channel_layout_is_compared_at_connect,
};

fn config(kind: &str, sync_mode: bool) -> Config {
    config_with(kind, sync_mode, 20.0, 256)
}

fn config_with(kind: &str, sync_mode: bool, stop_timeout: f64, max_commands: u32) -> Config {
    static N: AtomicU32 = AtomicU32::new(0);
    let session = format!(
        "conf{}-{}-{kind}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    // zenoh: explicit loopback endpoints on a port free a moment ago (zenoh cannot
    // report a port-0 listener's port through its stable API); scouting is off.
    let zenoh = if kind == "zenoh" {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        format!("[transport.zenoh]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n")
    } else {
        String::new()
    };
    let text = format!(
        "session = {session:?}\n[sync]\nsync_mode = {sync_mode}\n\
         simulation_time_per_frame = 0.005\nstop_timeout = {stop_timeout:?}\n\
         connect_timeout = 20.0\n[transport]\nkind = {kind:?}\ntcp_listen = \"127.0.0.1:0\"\n\
         max_commands_per_cycle = {max_commands}\n{zenoh}\
         [[agent]]\nid = 4\n[[agent.camera]]\nname = \"left\"\nwidth = 16\nheight = 8\n"
    );
    Config::from_toml_str(&text, Path::new("<conformance>")).unwrap()
}

/// Runs `body` with the host of `config` on its own thread; returns the config with the
/// bound TCP address, and the thread (join it: the host's assertions panic there).
fn with_host(
    mut config: Config,
    body: impl FnOnce(&mut Host) + Send + 'static,
) -> (Config, JoinHandle<()>) {
    let (tx, rx) = channel();
    let join = std::thread::spawn(move || {
        let mut host = Host::builder(&config).create().unwrap();
        if let Some(addr) = host.tcp_local_addr() {
            config.transport.tcp_listen = addr;
        }
        tx.send(config).unwrap();
        host.wait_for_agents(WAIT).unwrap();
        body(&mut host);
    });
    (rx.recv_timeout(WAIT).unwrap(), join)
}

fn publish(host: &mut Host) {
    let frame = host.loan_frame(4).unwrap();
    host.publish(frame).unwrap();
    host.start().unwrap();
}

fn every_cycle_arrives_once_in_order_with_its_whole_batch(kind: &str) {
    const CYCLES: u64 = 60;
    let (config, host) = with_host(config(kind, true), |host| {
        for cycle in 0..CYCLES {
            publish(host);
            let report = host.collect().unwrap();
            assert_eq!(report.cycle, cycle);
            let a = &report.agents()[0];
            assert_eq!(a.outcome, AgentOutcome::Stopped, "cycle {cycle}");
            // The stop ended the cycle: every command sent before it is there.
            let ids: Vec<u32> = a.commands().iter().map(|c| c.action_id).collect();
            let want: Vec<u32> = (0..=(cycle % 3) as u32)
                .map(|i| cycle as u32 * 10 + i)
                .collect();
            assert_eq!(ids, want, "cycle {cycle}");
        }
        assert_eq!(host.stats().stop_timeouts, 0);
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    for cycle in 0..CYCLES {
        let frame = agent.wait_start(Some(WAIT)).unwrap();
        assert_eq!(frame.cycle(), cycle);
        assert_eq!(frame.header().agent_id, 4);
        drop(frame);
        for i in 0..=(cycle % 3) as u32 {
            let command = Command::Turn { angle_deg: 1.0 };
            agent.send_with_id(cycle as u32 * 10 + i, command).unwrap();
        }
        agent.stop().unwrap();
    }
    assert_eq!(agent.frames_skipped(), 0);
    host.join().unwrap();
    // The host is gone (dropped cleanly): the agent is told, not left waiting.
    let err = agent.wait_start(Some(WAIT)).unwrap_err();
    assert!(matches!(err, WaitStartError::HostClosed), "{kind}: {err:?}");
}

/// Frames the host publishes while the slow agent reads none.
const SLOW_AGENT_FRAMES: u64 = 20;

fn a_slow_agent_gets_the_newest_frame(kind: &str) {
    let (published_tx, published_rx): (Sender<()>, Receiver<()>) = channel();
    let (done_tx, done_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, false), move |host| {
        // Async mode: frames while the agent reads none.
        for _ in 0..SLOW_AGENT_FRAMES {
            publish(host);
            host.collect().unwrap();
        }
        published_tx.send(()).unwrap();
        done_rx.recv_timeout(WAIT).unwrap();
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    published_rx.recv_timeout(WAIT).unwrap();
    // Published is not arrived (zenoh delivers on threads of its own, after `publish`
    // returned; reading once here saw cycle 1 of 0..=2 in 2 of 11 runs under load): read
    // until the last frame is there. Each read is the newest frame that had arrived: never
    // an older one after a newer, and not every frame one by one (a queue hands out each;
    // newest-wins reads all 20 only if each arrived after the agent read the one before).
    let newest = SLOW_AGENT_FRAMES - 1;
    let mut read = Vec::new();
    while read.last() != Some(&newest) {
        let frame = agent.wait_start(Some(WAIT)).unwrap();
        read.push(frame.cycle());
    }
    assert!(read.windows(2).all(|w| w[0] < w[1]), "{kind}: {read:?}");
    // Skips count from the first frame read.
    assert_eq!(
        agent.frames_skipped() + read.len() as u64,
        newest + 1 - read[0],
        "{kind}: {read:?}"
    );
    assert!(
        (read.len() as u64) < SLOW_AGENT_FRAMES,
        "{kind}: every frame handed out, not the newest: {read:?}"
    );
    // Nothing older is delivered afterwards.
    let err = agent
        .wait_start(Some(Duration::from_millis(50)))
        .unwrap_err();
    assert!(
        matches!(err, WaitStartError::Timeout { .. }),
        "{kind}: {err:?}"
    );
    done_tx.send(()).unwrap();
    host.join().unwrap();
}

/// An agent dropped between cycles leaves gracefully: not waited for, not evicted.
fn an_agent_that_goes_away_leaves_without_a_timeout(kind: &'static str) {
    let (gone_tx, gone_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, true), move |host| {
        publish(host);
        // The leave may come with the stop, in the same cycle.
        let mut left = host.collect().unwrap().agents()[0].left;
        gone_rx.recv_timeout(WAIT).unwrap();
        publish(host);
        let report = host.collect().unwrap();
        assert!(!report.timed_out, "a gone agent is not waited for");
        assert_ne!(report.agents()[0].outcome, AgentOutcome::Stopped);
        left |= report.agents()[0].left;
        assert!(left, "{kind}: {:?}", report.agents()[0]);
        let stats = host.stats();
        assert_eq!((stats.leaves, stats.evictions), (1, 0), "{kind}: {stats:?}");
        assert!(stats.evicted_agents.is_empty(), "{kind}: {stats:?}");
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    drop(agent.wait_start(Some(WAIT)).unwrap());
    agent.stop().unwrap();
    drop(agent);
    gone_tx.send(()).unwrap();
    host.join().unwrap();
}

/// `close()` in the middle of a cycle, then a new connection of the same id in the same
/// process: the host stops waiting at once (no stop timeout: it is 60 s here, and the
/// default `wait_for_stop = "alive"` would wait for ever), counts a leave, and the new
/// connection takes part from the next cycle.
fn a_closed_agent_leaves_and_its_id_reconnects_at_the_next_cycle(kind: &'static str) {
    let (config, host) = with_host(config_with(kind, true, 60.0, 256), move |host| {
        publish(host);
        let report = host.collect().unwrap();
        assert_eq!(report.agents()[0].outcome, AgentOutcome::Stopped);
        publish(host);
        // The agent reads cycle 1 and closes without stopping it.
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!((report.cycle, a.outcome), (1, AgentOutcome::Left), "{kind}");
        assert!(a.left && !a.evicted, "{kind}: {a:?}");
        assert_eq!(report.left_agents().collect::<Vec<_>>(), [4]);
        host.wait_for_agents(WAIT).unwrap();
        publish(host);
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!(
            (report.cycle, a.outcome),
            (2, AgentOutcome::Stopped),
            "{kind}"
        );
        assert!(a.rejoined && !a.left, "{kind}: {a:?}");
        let stats = host.stats();
        assert_eq!(
            (stats.stop_timeouts, stats.slow_stops, stats.late_batches),
            (0, 0, 0),
            "{kind}: {stats:?}"
        );
        assert_eq!(
            (stats.leaves, stats.evictions, stats.rejoins),
            (1, 0, 1),
            "{kind}: {stats:?}"
        );
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    drop(agent.wait_start(Some(WAIT)).unwrap());
    agent.stop().unwrap();
    let frame = agent.wait_start(Some(WAIT)).unwrap();
    assert_eq!(frame.cycle(), 1);
    drop(frame);
    agent.close();
    let mut again = AgentBuilder::new(&config, 4).connect().unwrap();
    let frame = again.wait_start(Some(WAIT)).unwrap();
    assert_eq!(frame.cycle(), 2, "{kind}: the next cycle");
    drop(frame);
    again.stop().unwrap();
    host.join().unwrap();
}

/// An agent process says it leaves before its ports close: until they do, they are the
/// departed connection's, not a new one. The next frame is not delivered to them (no
/// rejoin), and their closing is not a loss (no eviction).
fn a_leaving_agents_open_ports_are_not_a_new_connection<T: AgentTransport + 'static>(
    kind: &'static str,
    connect: fn(&Config) -> T,
) {
    let (collected_tx, collected_rx): (Sender<()>, Receiver<()>) = channel();
    let (closed_tx, closed_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, true), move |host| {
        publish(host);
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!(a.outcome, AgentOutcome::Left, "{kind}: {a:?}");
        assert!(a.left && !a.evicted, "{kind}: {a:?}");
        // Cycle 1: the agent's ports are still open.
        publish(host);
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!(a.outcome, AgentOutcome::NotAwaited, "{kind}: {a:?}");
        assert!(!a.rejoined && !a.evicted, "{kind}: {a:?}");
        collected_tx.send(()).unwrap();
        // Cycle 2: they are closed.
        closed_rx.recv_timeout(WAIT).unwrap();
        publish(host);
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!(a.outcome, AgentOutcome::NotAwaited, "{kind}: {a:?}");
        assert!(!a.rejoined && !a.evicted, "{kind}: {a:?}");
        let stats = host.stats();
        assert_eq!(
            (stats.leaves, stats.evictions, stats.rejoins),
            (1, 0, 0),
            "{kind}: {stats:?}"
        );
        assert_eq!(stats.frames_undelivered, 2, "{kind}: {stats:?}");
    });
    let mut agent = connect(&config);
    assert_eq!(first_cycle(&mut agent), 0, "{kind}");
    let header = MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: 4,
        cycle: 0,
        flags: MOTOR_FLAG_STOP | MOTOR_FLAG_LEAVE,
        command_count: 0,
        ack_cycle: 0,
    };
    agent.send_batch(&header, &[]).unwrap();
    collected_rx.recv_timeout(WAIT).unwrap();
    drop(agent);
    closed_tx.send(()).unwrap();
    host.join().unwrap();
}

fn a_late_stop_never_completes_the_next_cycle(kind: &'static str) {
    let (published_tx, published_rx): (Sender<()>, Receiver<()>) = channel();
    let (sent_tx, sent_rx): (Sender<()>, Receiver<()>) = channel();
    // The stop timeout's own semantics (the default waits for a live agent).
    let mut config = config_with(kind, true, 2.0, 256);
    config.agents[0].wait_for_stop = vrsync_bridge::WaitForStop::Timeout;
    let (config, host) = with_host(config, move |host| {
        publish(host);
        let report = host.collect().unwrap();
        assert_eq!(report.agents()[0].outcome, AgentOutcome::TimedOut);
        publish(host); // cycle 1
        published_tx.send(()).unwrap();
        // The agent's stop for cycle 0 is on its way before this cycle's wait begins.
        sent_rx.recv_timeout(WAIT).unwrap();
        let report = host.collect().unwrap();
        assert_eq!(report.cycle, 1);
        let a = &report.agents()[0];
        assert_eq!(
            a.outcome,
            AgentOutcome::TimedOut,
            "{kind}: cycle 0's late stop completed cycle 1"
        );
        assert!(a.commands().is_empty(), "{kind}: a late batch was applied");
        assert_eq!(host.stats().late_batches, 1, "{kind}");
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    drop(agent.wait_start(Some(WAIT)).unwrap());
    published_rx.recv_timeout(WAIT).unwrap();
    // Cycle 0 has timed out and cycle 1 has started: this stop names cycle 0.
    agent
        .send_with_id(7, Command::Turn { angle_deg: 1.0 })
        .unwrap();
    agent.stop().unwrap();
    sent_tx.send(()).unwrap();
    host.join().unwrap();
}

fn turn(action_id: u32) -> MotorCommand {
    Command::Turn { angle_deg: 1.0 }.encode(action_id)
}

fn send_batch<T: AgentTransport>(agent: &mut T, cycle: u64, stop: bool, commands: &[MotorCommand]) {
    let header = MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: 4,
        cycle,
        flags: if stop { MOTOR_FLAG_STOP } else { 0 },
        command_count: commands.len() as u32,
        ack_cycle: 0,
    };
    agent.send_batch(&header, commands).unwrap();
}

/// The cycle of the first frame the transport's agent side receives.
fn first_cycle<T: AgentTransport>(agent: &mut T) -> u64 {
    let mut next_liveness = Instant::now();
    let deadline = Instant::now() + WAIT;
    let frame = wait_for_newer_frame(agent, None, Some(deadline), &mut next_liveness).unwrap();
    frame.header().cycle
}

/// Agent 4 over transport `T` (the contract's one connect).
fn connect<T: AgentTransport>(config: &Config) -> T {
    T::connect(config, 4, WAIT, SignalHandling::Leave).unwrap()
}

fn a_future_batch_is_dropped_and_counted<T: AgentTransport>(
    kind: &'static str,
    connect: fn(&Config) -> T,
) {
    let (config, host) = with_host(config(kind, true), move |host| {
        publish(host);
        let report = host.collect().unwrap();
        let a = &report.agents()[0];
        assert_eq!(a.outcome, AgentOutcome::Stopped, "{kind}");
        let ids: Vec<u32> = a.commands().iter().map(|c| c.action_id).collect();
        assert_eq!(ids, [1], "{kind}: the future batch was applied");
        assert_eq!(host.stats().future_batches, 1, "{kind}");
    });
    let mut agent = connect(&config);
    let cycle = first_cycle(&mut agent);
    // A batch (with a stop) for a cycle that has not started, then the real one.
    send_batch(&mut agent, cycle + 1, true, &[turn(2)]);
    send_batch(&mut agent, cycle, true, &[turn(1)]);
    host.join().unwrap();
}

/// The resident set of this process, in bytes.
fn rss_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap();
    let pages: u64 = statm.split_whitespace().nth(1).unwrap().parse().unwrap();
    // SAFETY: sysconf has no preconditions.
    pages * unsafe { libc::sysconf(libc::_SC_PAGESIZE) } as u64
}

fn a_flood_of_batches_leaves_memory_bounded<T: AgentTransport>(
    kind: &'static str,
    connect: fn(&Config) -> T,
) {
    // 40,000 batches of 16 commands: 20 MB of commands in one cycle. A host that kept
    // them all would grow by that much; it keeps at most 2 x max_commands_per_cycle.
    const BATCHES: u32 = 40_000;
    const MAX_COMMANDS: u32 = 64;
    const BOUND: u64 = 8 << 20;
    let (config, host) = with_host(config_with(kind, true, 60.0, MAX_COMMANDS), move |host| {
        let before = rss_bytes();
        publish(host);
        let report = host.collect().unwrap();
        let grown = rss_bytes().saturating_sub(before);
        let a = &report.agents()[0];
        assert_eq!(a.outcome, AgentOutcome::Stopped, "{kind}");
        assert!(
            a.commands().len() <= 2 * MAX_COMMANDS as usize,
            "{kind}: {} commands kept",
            a.commands().len()
        );
        let stats = host.stats();
        assert!(
            stats.commands_received <= 2 * u64::from(MAX_COMMANDS),
            "{kind}: {stats:?}"
        );
        assert!(grown < BOUND, "{kind}: the host grew by {grown} bytes");
    });
    let mut agent = connect(&config);
    let cycle = first_cycle(&mut agent);
    let commands: Vec<MotorCommand> = (0..16).map(turn).collect();
    for _ in 0..BATCHES {
        send_batch(&mut agent, cycle, false, &commands);
    }
    send_batch(&mut agent, cycle, true, &[]);
    host.join().unwrap();
}

// --- Roles in a child process: the test re-runs itself with these set.

const ROLE_CONFIG_ENV: &str = "VRSYNC_CONFORMANCE_CONFIG";
const READY: &str = "vrsync-conformance-ready ";
const TERMINATED: &str = "vrsync-conformance-terminated";

/// The config a child role runs with, if this process is one.
fn child_role_config() -> Option<Config> {
    let path = std::env::var_os(ROLE_CONFIG_ENV)?;
    Some(Config::load(Path::new(&path)).unwrap())
}

/// A test re-run in a child process for one role; killed and reaped when dropped.
struct ChildRole {
    pid: u32,
    lines: Receiver<String>,
    exit: Receiver<std::process::ExitStatus>,
    exited: Option<std::process::ExitStatus>,
}

impl ChildRole {
    fn spawn(test: &str, config: &Config, dir: &Path) -> Self {
        let path = dir.join("config.toml");
        std::fs::write(&path, config.to_toml_string()).unwrap();
        let mut child: Child = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", test, "--test-threads=1", "--nocapture"])
            .env(ROLE_CONFIG_ENV, &path)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (line_tx, lines) = channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if line_tx.send(line).is_err() {
                    break;
                }
            }
        });
        let pid = child.id();
        let (exit_tx, exit) = channel();
        std::thread::spawn(move || {
            if let Ok(status) = child.wait() {
                let _ = exit_tx.send(status);
            }
        });
        Self {
            pid,
            lines,
            exit,
            exited: None,
        }
    }

    /// What follows `prefix` on the first line of the child's output that has it.
    fn line(&self, prefix: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                // libtest may print "test <name> ... " before the test's own output.
                Ok(line) => match line.find(prefix) {
                    Some(at) => return line[at + prefix.len()..].trim().to_owned(),
                    None => eprintln!("child: {line}"),
                },
                Err(e) => panic!("no {prefix:?} line from the child: {e}"),
            }
        }
    }

    fn wait(&mut self, timeout: Duration) -> std::process::ExitStatus {
        if let Some(status) = self.exited {
            return status;
        }
        let status = self.exit.recv_timeout(timeout).unwrap();
        self.exited = Some(status);
        status
    }

    fn kill(&mut self) {
        if self.exited.is_none() {
            // SAFETY: our own child, unreaped until the waiter thread sees it exit.
            unsafe { libc::kill(self.pid as i32, libc::SIGKILL) };
            self.wait(WAIT);
        }
    }
}

impl Drop for ChildRole {
    fn drop(&mut self) {
        if self.exited.is_none() {
            // SAFETY: as in `kill`.
            unsafe { libc::kill(self.pid as i32, libc::SIGKILL) };
            let _ = self.exit.recv_timeout(WAIT);
        }
    }
}

fn a_killed_host_is_seen_as_gone(kind: &str, test: &str) {
    if let Some(config) = child_role_config() {
        // The host's role: serve cycle 0, then wait for a stop that never comes.
        let mut host = Host::builder(&config).create().unwrap();
        let addr = host
            .tcp_local_addr()
            .map_or("-".to_owned(), |a| a.to_string());
        println!("{READY}{addr}");
        host.wait_for_agents(WAIT).unwrap();
        publish(&mut host);
        let _ = host.collect();
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut config = config(kind, true);
    let mut child = ChildRole::spawn(test, &config, dir.path());
    let addr = child.line(READY);
    if kind == "tcp" {
        config.transport.tcp_listen = addr.parse().unwrap();
    }
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    assert_eq!(agent.wait_start(Some(WAIT)).unwrap().cycle(), 0);
    child.kill();
    let err = agent.wait_start(Some(WAIT)).unwrap_err();
    let WaitStartError::HostGone { session, reason } = &err else {
        panic!("{kind}: a killed host must be gone, not closed or silent: {err:?}");
    };
    // The error names the session and what the transport saw.
    assert_eq!(session, &config.session);
    assert!(!reason.is_empty());
    assert!(err.to_string().ends_with(reason.as_str()), "{err}");
    vrsync_bridge::shm::cleanup_dead_nodes(&config.session);
}

fn sigterm_ends_an_agents_wait(kind: &str, test: &str) {
    if let Some(config) = child_role_config() {
        // The agent's role, with our signal handling installed.
        let mut agent = AgentBuilder::new(&config, 4)
            .signal_handling(SignalHandling::Install)
            .connect()
            .unwrap();
        drop(agent.wait_start(Some(WAIT)).unwrap());
        agent.stop().unwrap();
        // SAFETY: raising a signal at ourselves; our handler only sets a flag.
        assert_eq!(unsafe { libc::raise(libc::SIGTERM) }, 0);
        let err = agent.wait_start(Some(WAIT)).unwrap_err();
        assert!(matches!(err, WaitStartError::Terminated), "{kind}: {err:?}");
        println!("{TERMINATED}");
        return;
    }
    let (done_tx, done_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, true), move |host| {
        publish(host);
        let report = host.collect().unwrap();
        assert_eq!(report.agents()[0].outcome, AgentOutcome::Stopped);
        done_rx.recv_timeout(WAIT).unwrap();
    });
    let dir = tempfile::tempdir().unwrap();
    let mut child = ChildRole::spawn(test, &config, dir.path());
    child.line(TERMINATED);
    let status = child.wait(WAIT);
    assert!(
        status.success(),
        "{kind}: the agent's role failed: {status:?}"
    );
    done_tx.send(()).unwrap();
    host.join().unwrap();
}

/// One world, one agent per transport, each with channels: every agent's vectors and
/// actions go through its own transport in the same cycles.
#[test]
fn channels_over_every_transport_in_one_world() {
    const CYCLES: u64 = 15;
    let zenoh = config("zenoh", true).to_toml_string();
    let endpoint = zenoh
        .lines()
        .find(|l| l.starts_with("listen = "))
        .unwrap()
        .to_owned();
    let channels = "[[agent.vector]]\nname = \"joints\"\nlen = 5\n\
                    [[agent.action]]\nname = \"torque\"\nlen = 5\nlow = -1e6\nhigh = 1e6\n";
    let agents: String = [(1, "shm"), (2, "tcp"), (3, "zenoh")]
        .iter()
        .map(|(id, t)| format!("[[agent]]\nid = {id}\ntransport = {t:?}\n{channels}"))
        .collect();
    let text = format!(
        "session = \"chmix{}\"\n[transport]\ntcp_listen = \"127.0.0.1:0\"\n\
         [transport.zenoh]\n{endpoint}\n{agents}",
        std::process::id()
    );
    let config = Config::from_toml_str(&text, Path::new("<mixed>")).unwrap();
    let (config, host) = with_host(config, |host| {
        for cycle in 0..CYCLES {
            for id in 1..=3 {
                let mut frame = host.loan_frame(id).unwrap();
                for (i, v) in frame.vector_mut("joints").unwrap().iter_mut().enumerate() {
                    *v = (id * 100) as f32 + cycle as f32 + i as f32;
                }
                host.publish(frame).unwrap();
            }
            host.start().unwrap();
            let report = host.collect().unwrap();
            for a in report.agents() {
                let want: Vec<f32> = (0..5)
                    .map(|i| -((a.agent_id * 100) as f32 + cycle as f32 + i as f32))
                    .collect();
                assert_eq!(a.outcome, AgentOutcome::Stopped, "agent {}", a.agent_id);
                assert_eq!(
                    a.action("torque"),
                    Some(ActionValue::Box(&want)),
                    "agent {} cycle {cycle}",
                    a.agent_id
                );
            }
        }
    });
    let threads: Vec<JoinHandle<()>> = (1..=3)
        .map(|id| {
            let config = config.clone();
            std::thread::spawn(move || {
                let mut agent = AgentBuilder::new(&config, id).connect().unwrap();
                for _ in 0..CYCLES {
                    let frame = agent.wait_start(Some(WAIT)).unwrap();
                    let torque: Vec<f32> =
                        frame.vector("joints").unwrap().iter().map(|v| -v).collect();
                    drop(frame);
                    agent.act("torque", &torque).unwrap();
                    agent.stop().unwrap();
                }
            })
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
    host.join().unwrap();
}

/// `by_kind!(shm: a, b)`: the tests `a`, `b` of the enclosing module call `super::a("shm")`, ...
macro_rules! by_kind {
    ($kind:ident: $($test:ident),* $(,)?) => {$(
        #[test]
        fn $test() {
            super::$test(stringify!($kind));
        }
    )*};
}

/// `with_agent!(shm, ShmAgent: a)`: the test `a` calls `super::a("shm", connect::<ShmAgent>)`:
/// it drives the transport's own agent side, where the SDK cannot misbehave on purpose.
macro_rules! with_agent {
    ($kind:ident, $agent:ty: $($test:ident),* $(,)?) => {$(
        #[test]
        fn $test() {
            super::$test(stringify!($kind), super::connect::<$agent>);
        }
    )*};
}

/// `in_a_child!(shm: a)`: the test `a` calls `super::a("shm", "shm::a")`, its own name, by
/// which it re-runs itself in a child process for one role.
macro_rules! in_a_child {
    ($kind:ident: $($test:ident),* $(,)?) => {$(
        #[test]
        fn $test() {
            super::$test(
                stringify!($kind),
                concat!(stringify!($kind), "::", stringify!($test)),
            );
        }
    )*};
}

/// A module per transport with every case of the suite.
macro_rules! conformance {
    ($($kind:ident => $agent:ty),* $(,)?) => {$(
        mod $kind {
            by_kind!($kind:
                every_cycle_arrives_once_in_order_with_its_whole_batch,
                a_slow_agent_gets_the_newest_frame,
                an_agent_that_goes_away_leaves_without_a_timeout,
                a_closed_agent_leaves_and_its_id_reconnects_at_the_next_cycle,
                a_late_stop_never_completes_the_next_cycle,
                channels_carry_vectors_and_actions_each_cycle,
                a_channel_mismatch_is_refused_naming_the_channel,
                the_longest_channel_layout_is_compared_at_connect,
            );
            with_agent!($kind, $agent:
                a_leaving_agents_open_ports_are_not_a_new_connection,
                a_future_batch_is_dropped_and_counted,
                a_flood_of_batches_leaves_memory_bounded,
            );
            in_a_child!($kind: a_killed_host_is_seen_as_gone, sigterm_ends_an_agents_wait);
        }
    )*};
}

conformance!(
    shm => vrsync_bridge::shm::ShmAgent,
    tcp => vrsync_bridge::tcp::TcpAgent,
    zenoh => vrsync_bridge::zenoh::ZenohAgent,
);
