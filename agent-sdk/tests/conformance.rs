//! The transport conformance suite: what every transport must do, written once and run
//! against each (`conformance!` below instantiates it per transport; a new transport adds
//! one line). Host and agent run in one process, the host on its own thread (neither may
//! cross threads); every wait has a deadline.
//!
//! Checked here, over the public host and agent APIs: every cycle arrives once and in
//! order, with no lost wake-up, and each stop brings its whole batch (a stop is visible
//! only after its batch); a slow agent gets the newest frame and the older ones are
//! dropped; an agent that goes away is evicted without waiting for the stop timeout; an
//! agent sees the host close the session. The barrier's rules (a late stop never completes
//! the next cycle, future batches dropped and counted, each `on_agent_lost` policy) are
//! unit-tested over a fake transport in `bridge/src/host.rs`; the frame-holding limit and
//! the connect errors in `agent-sdk/src/agent.rs`; signals in a child process there.

// Helpers outside `#[test]` functions panic on failure too: this is a test binary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;
use std::time::Duration;

use vrsync_agent::{AgentBuilder, Command, WaitStartError};
use vrsync_bridge::{AgentOutcome, Config, Host};

const WAIT: Duration = Duration::from_secs(20);

fn config(kind: &str, sync_mode: bool) -> Config {
    static N: AtomicU32 = AtomicU32::new(0);
    let session = format!(
        "conf{}-{}-{kind}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    let text = format!(
        "session = {session:?}\n[sync]\nsync_mode = {sync_mode}\n\
         simulation_time_per_frame = 0.005\nstop_timeout = 20.0\nconnect_timeout = 20.0\n\
         [transport]\nkind = {kind:?}\ntcp_listen = \"127.0.0.1:0\"\n\
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

fn a_slow_agent_gets_the_newest_frame(kind: &str) {
    let (published_tx, published_rx): (Sender<()>, Receiver<()>) = channel();
    let (done_tx, done_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, false), move |host| {
        // Async mode: three frames while the agent reads none.
        for _ in 0..3 {
            publish(host);
            host.collect().unwrap();
        }
        published_tx.send(()).unwrap();
        done_rx.recv_timeout(WAIT).unwrap();
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    published_rx.recv_timeout(WAIT).unwrap();
    let frame = agent.wait_start(Some(WAIT)).unwrap();
    assert_eq!(frame.cycle(), 2, "{kind}: not the newest frame");
    drop(frame);
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

fn an_agent_that_goes_away_is_evicted_without_a_timeout(kind: &str) {
    let (gone_tx, gone_rx): (Sender<()>, Receiver<()>) = channel();
    let (config, host) = with_host(config(kind, true), move |host| {
        publish(host);
        host.collect().unwrap();
        gone_rx.recv_timeout(WAIT).unwrap();
        publish(host);
        let report = host.collect().unwrap();
        assert!(!report.timed_out, "a lost agent is evicted, not waited for");
        assert_ne!(report.agents()[0].outcome, AgentOutcome::Stopped);
        assert_eq!(host.stats().evicted_agents, [4]);
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    drop(agent.wait_start(Some(WAIT)).unwrap());
    agent.stop().unwrap();
    drop(agent);
    gone_tx.send(()).unwrap();
    host.join().unwrap();
}

macro_rules! conformance {
    ($($kind:ident),* $(,)?) => {$(
        mod $kind {
            #[test]
            fn every_cycle_arrives_once_in_order_with_its_whole_batch() {
                super::every_cycle_arrives_once_in_order_with_its_whole_batch(stringify!($kind));
            }
            #[test]
            fn a_slow_agent_gets_the_newest_frame() {
                super::a_slow_agent_gets_the_newest_frame(stringify!($kind));
            }
            #[test]
            fn an_agent_that_goes_away_is_evicted_without_a_timeout() {
                super::an_agent_that_goes_away_is_evicted_without_a_timeout(stringify!($kind));
            }
        }
    )*};
}

conformance!(shm, tcp);
