//! Network faults on a real link: the host (`vr-sim run`) and one shared-memory agent in
//! one network namespace, two remote agents (TCP, zenoh or zenoh over mutual TLS) in
//! another, joined by a veth pair (`netns.rs`'s [`Netns`]), and faults on the agents'
//! side of the link:
//! - **loss**: nftables rules in the agents' namespace drop P % of the TCP packets in
//!   each direction (`numgen random mod 100 < P drop`, on input and on output);
//! - **partition**: a drop-everything table in the agents' namespace, added when the
//!   remote agents reached a cycle and deleted D seconds later; a **one-way** partition
//!   drops only the data packets towards the host or only those towards the agents, so that
//!   one side's lease runs out and the other's does not;
//! - **duplication**: nftables `dup` in the output hook of both namespaces sends a second
//!   copy of P % of the packets;
//! - **delay with jitter**: this kernel has no netem qdisc and nothing else that delays
//!   packets (its qdiscs are HTB, TBF, FIFO, ingress; no NFQUEUE in nftables), so the
//!   remote agents connect through [`Relay`], a TCP relay in the host's namespace that
//!   holds every chunk it reads for `delay ± jitter` (uniform) before forwarding it, in
//!   order, in both directions. It delays the byte stream, not packets: TCP's own
//!   behaviour under packet delay (its RTT estimate, its window) is not what a netem
//!   link would give.
//! - **reordering**: P % of the packets each way take a second, slower veth pair between
//!   the namespaces (a token bucket qdisc on it; an nftables route chain marks them,
//!   policy routing sends the marked ones that way) and arrive behind packets sent after
//!   them ([`Reorder`]); the TCP stacks' counters (`TCPOFOQueue`, `TCPSACKReorder`, ...)
//!   show it happened.
//!
//! Each case runs the same lock-step world (`circle` agents: a command every cycle) as a
//! clean run on the same link and compares: the trajectory hash, every agent's commands
//! in the host's `--record` against what the agent logged it sent (every command applied
//! once, in its cycle), evictions, stop timeouts, cycles/s. Every case prints one
//! `netfaults:` line with what it measured (the README's "Failure behaviour" table
//! comes from these lines).
//!
//! CI runs, per remote transport: the clean link, 1 % and 5 % loss, a 3 s partition
//! (shorter than the zenoh lease of these runs, 10 s); a partition past the link timeout
//! (TCP's 10 s, zenoh's lease), back within the resume window, and one past the window
//! ([`resume`]); and the heavy faults in short ([`SHORT_FRAMES`] cycles): 20 % loss and a
//! 30 s partition, at once on two namespace pairs; 5 % reordering; ended or lost
//! ([`ending`]): one-way stalls past the lease, the host ended during a partition and its
//! last cycles under 30 % loss; and what stays bounded
//! ([`bounded`]): async mode under 5 % loss and a 3 s partition with a TCP and a zenoh
//! agent (the frame interval, the newest frame, the host's memory), and the host's memory
//! across 10 partitions in a row (TCP, sync mode). The heavy cases over 200
//! cycles (20 % loss, a 30 s partition, a 3 s partition with the default 2 s lease), delay,
//! duplication and 25 % reordering are `#[ignore]`d: `cargo test --workspace --features
//! vrsync-sim/rerun --test tests -- --ignored --nocapture netfaults`.
//!
//! Both veth ends carry one TCP segment per packet (`gso_max_segs 1`), as a wire does:
//! otherwise a veth passes 64 KiB offload packets and one dropped "packet" is a whole
//! camera frame.
//!
//! Needs root, `ip`, `tc` and `nft` (CI runs as root; `scripts/test-all` and `.ci/run` install
//! iproute2 and nftables): skipped with a message otherwise. Namespaces (and with them
//! every rule), nftables tables, relays and processes are removed by drop guards, also
//! when a test fails.

mod bounded;
mod ending;
mod fault;
mod nft;
mod outcome;
mod relay;
mod reorder;
mod resume;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::netns::{AGENT_IP, HOST_IP, Netns};
use crate::util::{self, EVENT_DEADLINE, Events, Proc, bin, record, summary};
use fault::{Fault, Towards};
use nft::{duplicate_table, loss_table, one_way_table, partition_table};
use outcome::{Outcome, commands_applied_once};
use relay::Relay;
use reorder::Reorder;

/// The host's TCP transport port (inside the host namespace: no other test sees it).
const TCP_PORT: u16 = 7400;
/// The host's zenoh port.
const ZENOH_PORT: u16 = 7447;
/// Where [`Relay`] listens for the remote agents, in the host namespace.
const RELAY_PORT: u16 = 7500;
/// Cycles of the CI cases.
const FRAMES: u64 = 200;
/// Cycles of the CI's short versions of the heavy cases (20 % loss, a 30 s partition):
/// at 20 % loss a TCP cycle takes seconds.
const SHORT_FRAMES: u64 = 20;
/// The zenoh lease of the CI cases: longer than their 3 s partition (the runs
/// used zenoh's default, 10 s).
const LEASE_S: f64 = 10.0;
/// Far beyond any stall here: the host waits for a live agent anyway (`wait_for_stop =
/// "alive"`, the default); this only bounds `vr-agent`'s own start timeout.
const STOP_TIMEOUT_S: f64 = 30.0;
/// Deadline of one run's host (a 30 s partition, 20 % loss in a debug build on a loaded
/// 2-core machine).
const HOST_DEADLINE: Duration = Duration::from_secs(600);

/// The remote agents' transport.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Remote {
    Tcp,
    Zenoh,
    /// zenoh over `tls/` endpoints with mutual TLS (`mtls = true`).
    ZenohTls,
}

impl Remote {
    fn name(self) -> &'static str {
        match self {
            Self::Tcp => "tcp",
            Self::Zenoh => "zenoh",
            Self::ZenohTls => "zenoh-tls",
        }
    }

    /// The `[[agent]] transport` spelling.
    fn transport(self) -> &'static str {
        match self {
            Self::Tcp => "tcp",
            Self::Zenoh | Self::ZenohTls => "zenoh",
        }
    }
}

/// The world of every case: agent 0 over shared memory (in the host's namespace), agents
/// 1 and 2 over `remote`, one 160×120 camera each, in sync mode or not. `side` is `host`
/// or `agent` (with TLS, each side its own certificate); `via_relay` points the agents at
/// [`Relay`].
fn config_text(
    session: &str,
    remote: Remote,
    lease_s: f64,
    side: &str,
    via_relay: bool,
    sync_mode: bool,
) -> String {
    let (tcp_port, zenoh_port) = if via_relay && side == "agent" {
        (RELAY_PORT, RELAY_PORT)
    } else {
        (TCP_PORT, ZENOH_PORT)
    };
    let scheme = if remote == Remote::ZenohTls {
        "tls"
    } else {
        "tcp"
    };
    let mut s = format!(
        "session = {session:?}\nseed = 11\n[sync]\nsync_mode = {sync_mode}\n\
         simulation_time_per_frame = 0.1\nstop_timeout = {STOP_TIMEOUT_S}\n\
         connect_timeout = 60.0\n[transport]\nkind = \"shm\"\n\
         tcp_listen = \"{HOST_IP}:{tcp_port}\"\n\
         [transport.zenoh]\nlisten = [\"{scheme}/{HOST_IP}:{ZENOH_PORT}\"]\n\
         connect = [\"{scheme}/{HOST_IP}:{zenoh_port}\"]\nlease = {lease_s:?}\n"
    );
    if remote == Remote::ZenohTls {
        s += &format!(
            "tls_ca = \"ca.pem\"\ntls_cert = \"{side}.pem\"\ntls_key = \"{side}.key\"\nmtls = true\n"
        );
    }
    for id in 0..3 {
        let transport = if id == 0 { "shm" } else { remote.transport() };
        s += &format!(
            "\n[[agent]]\nid = {id}\ntransport = {transport:?}\n[[agent.camera]]\n\
             name = \"left\"\nwidth = 160\nheight = 120\n"
        );
    }
    s
}

/// `None` (and a message why) when this machine cannot run these tests.
fn link() -> Option<Netns> {
    let nft = Command::new("nft").arg("--version").output();
    if !nft.is_ok_and(|o| o.status.success()) {
        eprintln!(
            "SKIPPED: `nft` (nftables) is not installed; `apt-get install nftables` (scripts/test-all does, as root)"
        );
        return None;
    }
    Netns::create()
}

/// The remote agents' ids.
const REMOTE_IDS: [u32; 2] = [1, 2];

/// `vr-agent --policy circle` as agent `id` of `cfg` in network namespace `namespace`,
/// logging each cycle to `log` (what every case's agents run).
fn circle_agent(ns: &Netns, namespace: &str, cfg: &Path, id: u32, log: &Path) -> Proc {
    let id_arg = id.to_string();
    ns.spawn(
        namespace,
        &bin("vr-agent"),
        &[
            "--config",
            cfg.to_str().unwrap(),
            "--id",
            &id_arg,
            "--policy",
            "circle",
            "--log-cycles",
            log.to_str().unwrap(),
        ],
    )
}

/// Runs the world for `frames` cycles with `fault` on the link of `ns`, in `dir`
/// (which holds the certificates for TLS).
fn run_case(
    ns: &Netns,
    dir: &Path,
    remote: Remote,
    fault: Fault,
    frames: u64,
    lease_s: f64,
) -> Outcome {
    let session = util::session(&format!("nf{}", remote.name()));
    let case_dir = dir.join(&session);
    std::fs::create_dir_all(&case_dir).unwrap();
    copy_certificates(dir, &case_dir, remote);
    wire_sized_packets(ns);
    let via_relay = matches!(fault, Fault::Delay { .. });
    let host_cfg = case_dir.join("host.toml");
    let agent_cfg = case_dir.join("agent.toml");
    std::fs::write(
        &host_cfg,
        config_text(&session, remote, lease_s, "host", false, true),
    )
    .unwrap();
    std::fs::write(
        &agent_cfg,
        config_text(&session, remote, lease_s, "agent", via_relay, true),
    )
    .unwrap();

    // The fault's guards live until the end of this function (after every process ended).
    let mut tables = Vec::new();
    let mut relay = None;
    let mut reorder = None;
    match fault {
        Fault::Loss { percent } => tables.push(loss_table(ns, percent)),
        Fault::Duplicate { percent } => {
            tables.push(duplicate_table(&ns.agents, &ns.agents, HOST_IP, percent));
            tables.push(duplicate_table(&ns.host, &ns.host, AGENT_IP, percent));
        }
        Fault::Delay { ms, jitter_ms } => {
            let upstream_port = if remote == Remote::Tcp {
                TCP_PORT
            } else {
                ZENOH_PORT
            };
            relay = Some(Relay::start(
                &ns.host,
                format!("{HOST_IP}:{RELAY_PORT}").parse().unwrap(),
                format!("{HOST_IP}:{upstream_port}").parse().unwrap(),
                Duration::from_millis(ms),
                Duration::from_millis(jitter_ms),
            ));
        }
        Fault::Reorder { percent } => reorder = Some(Reorder::install(ns, percent)),
        Fault::Clean
        | Fault::Partition { .. }
        | Fault::Partitions { .. }
        | Fault::OneWay { .. }
        | Fault::LossFrom { .. } => {}
    }

    let events = Events::in_dir(&case_dir);
    let sum_path = case_dir.join("summary.json");
    let rec_path = case_dir.join("record.jsonl");
    let frames_arg = frames.to_string();
    let host = spawn_host(
        ns,
        &host_cfg,
        &events,
        &[
            "--frames",
            &frames_arg,
            "--summary-json",
            sum_path.to_str().unwrap(),
            "--record",
            rec_path.to_str().unwrap(),
        ],
    );
    let log = |id: u32| case_dir.join(format!("a{id}.log"));
    let agent =
        |id: u32, namespace: &str, cfg: &Path| circle_agent(ns, namespace, cfg, id, &log(id));
    // A relayed TCP agent that connects before the host listens loses its connection in
    // the hello (the relay cannot reach the host) and exits: start agents afterwards.
    events.wait_for("listening", EVENT_DEADLINE);
    let shm_agent = agent(0, &ns.host, &host_cfg);
    let mut remotes: Vec<(u32, Proc)> = REMOTE_IDS
        .iter()
        .map(|&id| (id, agent(id, &ns.agents, &agent_cfg)))
        .collect();

    if let Fault::LossFrom { at_cycle, percent } = fault {
        for &id in &REMOTE_IDS {
            util::wait_for_cycle_line(&log(id), at_cycle, EVENT_DEADLINE);
        }
        tables.push(loss_table(ns, percent));
    }
    let mut resumed_after_s = None;
    let mut partition_counters = BTreeMap::<String, u64>::new();
    let mut rss_kib = Vec::new();
    let partitions = match fault {
        Fault::Partition { at_cycle, secs } | Fault::OneWay { at_cycle, secs, .. } => {
            Some((at_cycle, 0, secs, 1))
        }
        Fault::Partitions {
            at_cycle,
            every,
            secs,
            count,
        } => Some((at_cycle, every, secs, count)),
        _ => None,
    };
    if let Some((mut at_cycle, every, secs, count)) = partitions {
        for _ in 0..count {
            for &id in &REMOTE_IDS {
                util::wait_for_cycle_line(&log(id), at_cycle, EVENT_DEADLINE);
            }
            let table = match fault {
                Fault::OneWay { towards, .. } => one_way_table(ns, towards),
                _ => partition_table(ns),
            };
            // The fault itself: the link stays cut this long.
            std::thread::sleep(Duration::from_secs(secs));
            let cut_at = last_cycle(&log(REMOTE_IDS[0]));
            for (k, v) in table.counters() {
                *partition_counters.entry(k).or_default() += v;
            }
            drop(table);
            let healed = Instant::now();
            resumed_after_s = answered_again(&log(REMOTE_IDS[0]), cut_at, &mut remotes)
                .then(|| healed.elapsed().as_secs_f64());
            if resumed_after_s.is_none() {
                break;
            }
            rss_kib.push(vm_rss_kib(host.pid()));
            at_cycle = cut_at + every;
        }
    }

    let host_out = host.wait(HOST_DEADLINE);
    let shm_out = shm_agent.wait(Duration::from_secs(60));
    let agents: Vec<(u32, Option<i32>, String)> = remotes
        .into_iter()
        .map(|(id, p)| {
            let out = p.wait(Duration::from_secs(60) + Duration::from_secs_f64(lease_s * 2.0));
            let last = out
                .stderr
                .lines()
                .rev()
                .find(|l| l.contains("error") || l.contains("gone"))
                .unwrap_or("")
                .trim()
                .chars()
                .take(200)
                .collect();
            (id, out.code(), last)
        })
        .collect();

    let mut counters = BTreeMap::new();
    for t in &tables {
        for (k, v) in t.counters() {
            let side = if t.ns == ns.host { "host" } else { "agents" };
            counters.insert(format!("{side}.{}.{k}", t.name), v);
        }
    }
    for (k, v) in partition_counters {
        counters.insert(format!("partition.{k}"), v);
    }
    if let Some(r) = &relay {
        counters.insert("relay.chunks".into(), r.chunks.load(Ordering::Relaxed));
    }
    if let Some(r) = &reorder {
        for (k, v) in r.counters() {
            counters.insert(format!("reorder.{k}"), v);
        }
    }
    drop(relay);
    drop(reorder);
    drop(tables);

    assert!(
        sum_path.exists(),
        "host exit {:?} without a summary: {}",
        host_out.code(),
        host_out.stderr
    );
    assert_eq!(shm_out.code(), Some(0), "shm agent: {}", shm_out.stderr);
    let sum = summary(&sum_path);
    let all = events.read();
    let connected = all
        .iter()
        .find(|e| e["event"] == "all_agents_connected")
        .and_then(|e| e["wall_s"].as_f64())
        .unwrap_or(0.0);
    let finished = all
        .iter()
        .find(|e| e["event"] == "finished")
        .and_then(|e| e["wall_s"].as_f64())
        .unwrap_or(f64::NAN);
    let frames_done = sum["frames"].as_u64().unwrap();
    let rec = record(&rec_path);
    let commands = (0..3)
        .map(|id| (id, commands_applied_once(&rec, &log(id), id, frames_done)))
        .collect();
    Outcome {
        remote,
        fault,
        lease_s,
        host_code: host_out.code(),
        frames: frames_done,
        cycles_per_s: frames_done as f64 / (finished - connected),
        hash: sum["trajectory_hash"].as_str().unwrap_or("").to_string(),
        evicted: sum["evicted_agents"].clone(),
        stop_timeouts: sum["stop_timeouts"].as_u64().unwrap(),
        late_stops: sum["late_stops"].as_u64().unwrap(),
        commands_applied: sum["commands_applied"].as_u64().unwrap(),
        agents,
        commands,
        evictions: all
            .into_iter()
            .filter(|e| e["event"] == "agent_evicted")
            .collect(),
        counters,
        resumed_after_s,
        resumes: sum["resumes"].as_u64().unwrap(),
        rss_kib,
    }
}

/// The resident set (`VmRSS`, KiB) of process `pid`.
fn vm_rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_else(|e| panic!("/proc/{pid}/status: {e}"));
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or_else(|| panic!("no VmRSS in /proc/{pid}/status"))
}

/// Starts the host, `vr-sim run --config CONFIG --events EVENTS --quiet ARGS...` (the
/// arguments of [`util::spawn_host`]), in the host's namespace.
fn spawn_host(ns: &Netns, config: &Path, events: &Events, args: &[&str]) -> Proc {
    ns.spawn(
        &ns.host,
        &bin("vr-sim"),
        &util::host_args(config, events, args),
    )
}

/// With TLS, the certificates of `dir` into `case_dir` (where the configs name them).
fn copy_certificates(dir: &Path, case_dir: &Path, remote: Remote) {
    if remote == Remote::ZenohTls {
        for f in ["ca.pem", "host.pem", "host.key", "agent.pem", "agent.key"] {
            std::fs::copy(dir.join(f), case_dir.join(f)).unwrap();
        }
    }
}

/// One segment per packet on both veth ends, as on a wire: by default a veth passes TCP's
/// segmentation-offload packets of up to 64 KiB, so a dropped "packet" would be a whole
/// camera frame and the loss rules would see ~40 times fewer packets than a link would.
fn wire_sized_packets(ns: &Netns) {
    for side in [&ns.host, &ns.agents] {
        crate::netns::ip(&["-n", side, "link", "set", "dev", side, "gso_max_segs", "1"])
            .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// The last cycle in a `--log-cycles` file (0 when it has none yet).
fn last_cycle(path: &Path) -> u64 {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let complete = text.rfind('\n').map_or("", |end| &text[..end]);
    complete
        .lines()
        .filter_map(|l| l.split(' ').next()?.parse::<u64>().ok())
        .max()
        .unwrap_or(0)
}

/// Waits until the agent logging to `path` logged a cycle after `cycle` (`true`), or every
/// remote agent exited (`false`); panics after [`HOST_DEADLINE`].
fn answered_again(path: &Path, cycle: u64, remotes: &mut [(u32, Proc)]) -> bool {
    let deadline = Instant::now() + HOST_DEADLINE;
    loop {
        if last_cycle(path) > cycle {
            return true;
        }
        if remotes.iter_mut().all(|(_, p)| p.try_exited()) {
            return last_cycle(path) > cycle;
        }
        assert!(
            Instant::now() < deadline,
            "{}: no cycle after {cycle} within {HOST_DEADLINE:?}",
            path.display()
        );
        // The file is appended to by another process: re-read it shortly.
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A namespace pair and a temp dir (with certificates for TLS) for one transport's cases.
struct Bench {
    ns: Netns,
    dir: tempfile::TempDir,
    remote: Remote,
}

impl Bench {
    fn new(remote: Remote) -> Option<Self> {
        let ns = link()?;
        let dir = tempfile::tempdir().unwrap();
        util::make_certificates(dir.path(), HOST_IP);
        Some(Self { ns, dir, remote })
    }

    /// A case of its own: a session named `prefix` + the transport, its folder (with the
    /// certificates over TLS), and the link's packet sizes set as on the wire.
    fn case(&self, prefix: &str) -> (String, std::path::PathBuf) {
        let session = util::session(&format!("{prefix}{}", self.remote.name()));
        let dir = self.dir.path().join(&session);
        std::fs::create_dir_all(&dir).unwrap();
        copy_certificates(self.dir.path(), &dir, self.remote);
        wire_sized_packets(&self.ns);
        (session, dir)
    }

    fn run(&self, fault: Fault, frames: u64, lease_s: f64) -> Outcome {
        run_case(
            &self.ns,
            self.dir.path(),
            self.remote,
            fault,
            frames,
            lease_s,
        )
    }
}

/// CI: the clean link, 1 % and 5 % loss each way, a 3 s partition: the clean run's
/// trajectory, every command once, no eviction, no stop timeout.
fn loss_and_a_short_partition_leave_the_run_intact(remote: Remote) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let clean = bench.run(Fault::Clean, FRAMES, LEASE_S);
    clean.report(None);
    clean.assert_intact(&clean);
    for fault in [
        Fault::Loss { percent: 1 },
        Fault::Loss { percent: 5 },
        Fault::Partition {
            at_cycle: 40,
            secs: 3,
        },
    ] {
        let out = bench.run(fault, FRAMES, LEASE_S);
        out.report(Some(&clean));
        out.assert_intact(&clean);
        if let Fault::Loss { .. } = fault {
            assert!(
                out.counters.values().any(|&v| v > 0),
                "the loss rules dropped nothing: {:?}",
                out.counters
            );
        }
        if let Fault::Partition { .. } = fault {
            assert!(out.resumed_after_s.is_some(), "{out:#?}");
        }
    }
}

/// CI: the heavy faults, short ([`SHORT_FRAMES`] cycles): 20 % loss each way, and a 30 s
/// partition (past TCP's 10 s link timeout and zenoh's 10 s lease, back within the 30 s
/// resume window): the clean run's trajectory, every command once, no eviction, the
/// agents back by themselves. The two faulty runs go at once, each on a namespace pair of
/// its own (the partition's run mostly waits). On demand the same faults run 200 cycles
/// ([`heavy_faults_are_recorded`]).
fn heavy_faults_in_short_leave_the_run_intact(remote: Remote) {
    let (Some(bench), Some(lossy)) = (Bench::new(remote), Bench::new(remote)) else {
        return;
    };
    let clean = bench.run(Fault::Clean, SHORT_FRAMES, LEASE_S);
    clean.report(None);
    clean.assert_intact(&clean);
    let partition = Fault::Partition {
        at_cycle: 5,
        secs: 30,
    };
    let (loss, cut) = std::thread::scope(|s| {
        let loss = s.spawn(|| lossy.run(Fault::Loss { percent: 20 }, SHORT_FRAMES, LEASE_S));
        let cut = bench.run(partition, SHORT_FRAMES, LEASE_S);
        (loss.join().unwrap(), cut)
    });
    for out in [&loss, &cut] {
        out.report(Some(&clean));
        out.assert_intact(&clean);
    }
    assert!(cut.resumed_after_s.is_some(), "{cut:#?}");
    assert_eq!(cut.resumes, REMOTE_IDS.len() as u64, "{cut:#?}");
}

/// On demand: delay with jitter and duplication must leave the run intact too.
fn delay_and_duplication_leave_the_run_intact(remote: Remote) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let clean = bench.run(Fault::Clean, FRAMES, LEASE_S);
    clean.report(None);
    for fault in [
        Fault::Delay {
            ms: 20,
            jitter_ms: 10,
        },
        Fault::Delay {
            ms: 80,
            jitter_ms: 40,
        },
        Fault::Duplicate { percent: 5 },
    ] {
        let out = bench.run(fault, FRAMES, LEASE_S);
        out.report(Some(&clean));
        out.assert_intact(&clean);
    }
}

/// CI: 5 % of the packets each way reordered (on demand: 25 %): the run is intact, and
/// the TCP stacks saw segments out of order.
fn reordering_leaves_the_run_intact(remote: Remote, percents: &[u32]) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let clean = bench.run(Fault::Clean, FRAMES, LEASE_S);
    clean.report(None);
    clean.assert_intact(&clean);
    for &percent in percents {
        let out = bench.run(Fault::Reorder { percent }, FRAMES, LEASE_S);
        out.report(Some(&clean));
        out.assert_intact(&clean);
        let grew = |k: &str| out.counters.get(k).copied().unwrap_or(0);
        assert!(
            grew("reorder.agents.TCPOFOQueue") + grew("reorder.host.TCPOFOQueue") > 0,
            "no segment arrived out of order: {:?}",
            out.counters
        );
    }
}

/// On demand: 20 % loss, a 30 s partition, a 3 s partition with the default lease, 200
/// cycles each. What must hold whatever happens to the remote agents: the host ends its
/// run, the shared-memory agent takes part in every cycle, nobody is waited for until a
/// stop timeout. The partitions must leave the run intact over every transport (the
/// resume window), and so must 20 % loss over TCP; over zenoh 20 % loss for 200 cycles
/// may stall one direction of a link only, and when the side that still hears declares the
/// link lost first, the agent sees its host's connection close as a host that ended and
/// gives up (the host holds its place meanwhile): that outcome is recorded.
fn heavy_faults_are_recorded(remote: Remote) {
    let Some(bench) = Bench::new(remote) else {
        return;
    };
    let clean = bench.run(Fault::Clean, FRAMES, LEASE_S);
    clean.report(None);
    let mut cases = vec![
        (Fault::Loss { percent: 20 }, LEASE_S),
        (
            Fault::Partition {
                at_cycle: 40,
                secs: 30,
            },
            LEASE_S,
        ),
    ];
    if remote != Remote::Tcp {
        // The lease is zenoh's: over TCP this would be the CI's 3 s partition again.
        cases.push((
            Fault::Partition {
                at_cycle: 40,
                secs: 3,
            },
            2.0,
        ));
    }
    for (fault, lease) in cases {
        let out = bench.run(fault, FRAMES, lease);
        out.report(Some(&clean));
        assert_eq!(out.host_code, Some(0), "{out:#?}");
        assert_eq!(out.frames, FRAMES, "{out:#?}");
        assert_eq!(out.stop_timeouts, 0, "{out:#?}");
        assert!(out.commands[0].1.is_ok(), "shm agent: {out:#?}");
        if remote == Remote::Tcp || matches!(fault, Fault::Partition { .. }) {
            out.assert_intact(&clean);
        }
    }
}

/// `remotes!(tcp => Tcp, ...)` makes the modules `tcp`, ... whose tests call each case
/// above with that [`Remote`]: one list of cases, run over every remote transport (as
/// `util.rs`'s `for_each_transport!` does for the SDK's transports).
macro_rules! remotes {
    ($($module:ident => $remote:ident),* $(,)?) => {
        $(mod $module {
            use super::Remote;
            #[test]
            fn loss_and_a_short_partition_leave_the_run_intact() {
                super::loss_and_a_short_partition_leave_the_run_intact(Remote::$remote);
            }
            #[test]
            fn heavy_faults_in_short_leave_the_run_intact() {
                super::heavy_faults_in_short_leave_the_run_intact(Remote::$remote);
            }
            #[test]
            fn a_link_lost_past_its_timeout_and_back_within_the_window_is_resumed() {
                super::resume::a_link_lost_past_its_timeout_and_back_within_the_window_is_resumed(
                    Remote::$remote,
                );
            }
            #[test]
            fn not_back_within_the_window_is_evicted_in_bound_and_rejoins_when_back() {
                super::resume::not_back_within_the_window_is_evicted_in_bound_and_rejoins_when_back(
                    Remote::$remote,
                );
            }
            #[test]
            fn one_way_stalls_past_the_lease_are_resumed() {
                super::ending::one_way_stalls_past_the_lease_are_resumed(Remote::$remote);
            }
            #[test]
            fn the_hosts_end_under_heavy_loss_is_a_close() {
                super::ending::the_hosts_end_under_heavy_loss_is_a_close(Remote::$remote);
            }
            #[test]
            fn the_hosts_end_during_a_partition_is_a_close_once_it_heals() {
                super::ending::the_hosts_end_during_a_partition_is_a_close_once_it_heals(
                    Remote::$remote,
                );
            }
            #[test]
            #[ignore = "on demand (minutes): cargo test --workspace --test tests -- --ignored netfaults"]
            fn delay_and_duplication_leave_the_run_intact() {
                super::delay_and_duplication_leave_the_run_intact(Remote::$remote);
            }
            #[test]
            fn reordering_leaves_the_run_intact() {
                super::reordering_leaves_the_run_intact(Remote::$remote, &[5]);
            }
            #[test]
            #[ignore = "on demand (minutes): cargo test --workspace --test tests -- --ignored netfaults"]
            fn heavy_reordering_leaves_the_run_intact() {
                super::reordering_leaves_the_run_intact(Remote::$remote, &[25]);
            }
            #[test]
            #[ignore = "on demand (minutes): cargo test --workspace --test tests -- --ignored netfaults"]
            fn heavy_faults_are_recorded() {
                super::heavy_faults_are_recorded(Remote::$remote);
            }
        })*
        /// Fails to compile when [`Remote`] gains a transport this list makes no tests for.
        #[allow(dead_code)]
        fn every_remote_has_its_module(remote: Remote) {
            match remote {
                $(Remote::$remote)|* => {}
            }
        }
    };
}

remotes!(tcp => Tcp, zenoh => Zenoh, zenoh_tls => ZenohTls);
