//! A lost link that comes back within the resume window (`[sync] resume_window`, 30 s by
//! default) is resumed, not ended: over TCP (both sides declare the link lost after
//! [`LINK_TIMEOUT`]) and over zenoh, plain and mutual TLS (the lease runs out).

use std::path::Path;
use std::time::{Duration, Instant};

use super::nft::partition_table;
use super::{Bench, FRAMES, Fault, LEASE_S, REMOTE_IDS, Remote};
use crate::util::{self, EVENT_DEADLINE, Events};
use vrsync_bridge::tcp::LINK_TIMEOUT;

/// The zenoh lease of the resume cases: short, so that a partition outlasts it quickly.
const RESUME_LEASE_S: f64 = 4.0;

/// How long the link must be silent before `remote`'s transport declares it lost, with
/// the lease these cases use.
fn link_timeout(remote: Remote) -> (Duration, f64) {
    match remote {
        Remote::Tcp => (LINK_TIMEOUT, LEASE_S),
        Remote::Zenoh | Remote::ZenohTls => {
            (Duration::from_secs_f64(RESUME_LEASE_S), RESUME_LEASE_S)
        }
    }
}

/// CI: the link cut for longer than the transport's link timeout (TCP's 10 s, zenoh's
/// lease), so that both sides declare it lost (the host holds the remote agents' places,
/// they connect again by themselves), and back well within the window: the clean run's
/// trajectory, every command applied once, nobody evicted, both agents resumed, and they
/// answer within seconds of the link's return (TCP's own retransmission back-off answered
/// a 30 s partition 24 s late).
pub(super) fn a_link_lost_past_its_timeout_and_back_within_the_window_is_resumed(remote: Remote) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let (timeout, lease) = link_timeout(remote);
    let clean = bench.run(Fault::Clean, FRAMES, lease);
    clean.report(None);
    let secs = timeout.as_secs() + 4;
    let out = bench.run(Fault::Partition { at_cycle: 40, secs }, FRAMES, lease);
    out.report(Some(&clean));
    out.assert_intact(&clean);
    assert_eq!(out.resumes, REMOTE_IDS.len() as u64, "{out:#?}");
    let answered = out.resumed_after_s.unwrap_or(f64::INFINITY);
    // zenoh's next connection attempt may be one 10 s open timeout away.
    let bound = if remote == Remote::Tcp { 8.0 } else { 15.0 };
    assert!(
        answered < bound,
        "answered {answered} s after the link returned: {out:#?}"
    );
}

/// CI: the link cut until the resume window (2 s here) has passed: the host evicts the
/// remote agents within the bound (the link timeout, then the window), the world goes on
/// without them, they give up (exit 1, "the host is gone"), and, started again once the
/// link is back, they rejoin at the next cycle.
pub(super) fn not_back_within_the_window_is_evicted_in_bound_and_rejoins_when_back(remote: Remote) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let ns = &bench.ns;
    let (session, dir) = bench.case("nfwindow");
    let window = Duration::from_secs(2);
    let (timeout, lease) = link_timeout(remote);
    let config = |side: &str| {
        let text = super::config_text(&session, remote, lease, side, false, true);
        let with_window = format!("[sync]\nresume_window = {:?}\n", window.as_secs_f64());
        let path = dir.join(format!("{side}.toml"));
        std::fs::write(&path, text.replacen("[sync]\n", &with_window, 1)).unwrap();
        path
    };
    let (host_cfg, agent_cfg) = (config("host"), config("agent"));
    let events = Events::in_dir(&dir);
    let sum_path = dir.join("summary.json");
    // No --frames: the run goes on until SIGTERM.
    let host = super::spawn_host(
        ns,
        &host_cfg,
        &events,
        &["--summary-json", sum_path.to_str().unwrap()],
    );
    events.wait_for("listening", EVENT_DEADLINE);
    let agent = |id: u32, namespace: &str, cfg: &Path, log: &str| {
        let log = dir.join(log);
        (super::circle_agent(ns, namespace, cfg, id, &log), log)
    };
    let (shm_agent, shm_log) = agent(0, &ns.host, &host_cfg, "a0.log");
    let remotes: Vec<_> = REMOTE_IDS
        .iter()
        .map(|&id| agent(id, &ns.agents, &agent_cfg, &format!("a{id}.log")))
        .collect();
    for (_, log) in &remotes {
        util::wait_for_cycle_line(log, 20, EVENT_DEADLINE);
    }
    let cut = partition_table(ns);
    let cut_at = Instant::now();
    let bound = timeout + window + Duration::from_secs(5);
    for id in REMOTE_IDS {
        events.wait_for_match("agent_evicted", |e| e["agent"] == id, bound);
    }
    let evicted_after = cut_at.elapsed();
    // The world goes on without them.
    let at = super::last_cycle(&shm_log);
    util::wait_for_cycle_line(&shm_log, at + 5, EVENT_DEADLINE);
    // They give up once their own window passed (each counts it from when it saw the link
    // go, which may be later than the host did): the link stays cut until then, or an
    // agent whose window is still open would connect again and be taken back as a rejoin
    // (in one CI run under load an agent saw the loss 1.8 s before the cut ended, came
    // back and never exited).
    for (p, _) in remotes {
        let out = p.wait(EVENT_DEADLINE);
        assert_eq!(out.code(), Some(1), "gave up: {}", out.stderr);
        assert!(out.stderr.contains("host is gone"), "{}", out.stderr);
    }
    drop(cut);
    // Back (started again), each rejoins at the next cycle and takes part.
    let back: Vec<_> = REMOTE_IDS
        .iter()
        .map(|&id| agent(id, &ns.agents, &agent_cfg, &format!("back{id}.log")))
        .collect();
    for (&id, (_, log)) in REMOTE_IDS.iter().zip(&back) {
        let rejoined =
            events.wait_for_match("agent_rejoined", |e| e["agent"] == id, EVENT_DEADLINE);
        let cycle = rejoined["cycle"].as_u64().unwrap();
        util::wait_for_cycle_line(log, cycle + 1, EVENT_DEADLINE);
    }
    host.signal(libc::SIGTERM);
    let out = host.wait(EVENT_DEADLINE);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    assert_eq!(shm_agent.wait(EVENT_DEADLINE).code(), Some(0));
    for (p, _) in back {
        assert_eq!(p.wait(EVENT_DEADLINE).code(), Some(0));
    }
    let sum = util::summary(&sum_path);
    assert_eq!(sum["evictions"], 2, "{sum}");
    assert_eq!(sum["rejoins"], 2, "{sum}");
    assert_eq!(sum["resumes"], 0, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    eprintln!(
        "netfaults: {} link cut past the resume window ({} s): both remote agents evicted \
         {:.1} s after the cut (bound: link timeout {} s + window), rejoined when back",
        remote.name(),
        window.as_secs_f64(),
        evicted_after.as_secs_f64(),
        timeout.as_secs_f64()
    );
}
