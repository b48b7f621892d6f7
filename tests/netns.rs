//! Agents on another machine over zenoh, for real: two network namespaces joined by a
//! veth pair, the host (`vr-sim run`) and one local shm agent in one, two zenoh agents in
//! the other, talking over the veth addresses (not loopback), over plain TCP and over
//! mutual TLS. Needs root (CI runs as root); skipped with a message only where
//! `ip netns add` fails.

use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use crate::util::{
    self, EVENT_DEADLINE, Events, Proc, bin, cycle_log, summary, wait_for_cycle_line,
};

const RUN_DEADLINE: Duration = Duration::from_secs(300);
/// The host namespace's end of the veth pair (also used by `netfaults.rs`).
pub(crate) const HOST_IP: &str = "10.77.0.1";
/// The agents' namespace's end of the veth pair.
pub(crate) const AGENT_IP: &str = "10.77.0.2";
/// The zenoh lease of these runs: a pulled link is noticed after about this long.
const LEASE_S: f64 = 1.0;
/// Far beyond the lease: an agent lost with its link is evicted by the lease, never by a
/// stop timeout (asserted through the summary's `stop_timeouts`).
const STOP_TIMEOUT_S: f64 = 30.0;

/// Two namespaces and the veth pair between them; deleted on drop (which deletes the
/// veth pair too, and every nftables rule inside them). Each end of the pair is named
/// after its namespace. Shared with `netfaults.rs`.
pub(crate) struct Netns {
    pub(crate) host: String,
    pub(crate) agents: String,
}

pub(crate) fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("cannot run ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Netns {
    /// `None` (and a message why) when namespaces cannot be created here.
    pub(crate) fn create() -> Option<Self> {
        // Unique per test process and per call: tests in one process run in parallel.
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let tag = format!(
            "{}x{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let (host, agents) = (format!("vzh{tag}"), format!("vza{tag}"));
        if let Err(e) = ip(&["netns", "add", &host]) {
            eprintln!(
                "SKIPPED: network namespaces cannot be created here ({e}); this test needs root"
            );
            return None;
        }
        let ns = Self {
            host: host.clone(),
            agents: agents.clone(),
        };
        let setup = || -> Result<(), String> {
            ip(&["netns", "add", &agents])?;
            // Interface names are the namespace names (at most 15 bytes).
            ip(&[
                "link", "add", &host, "type", "veth", "peer", "name", &agents,
            ])?;
            ip(&["link", "set", &host, "netns", &host])?;
            ip(&["link", "set", &agents, "netns", &agents])?;
            for (n, addr) in [(&host, HOST_IP), (&agents, AGENT_IP)] {
                ip(&["-n", n, "addr", "add", &format!("{addr}/30"), "dev", n])?;
                ip(&["-n", n, "link", "set", "lo", "up"])?;
                ip(&["-n", n, "link", "set", n, "up"])?;
            }
            Ok(())
        };
        setup().unwrap_or_else(|e| panic!("netns set-up failed after `ip netns add` worked: {e}"));
        Some(ns)
    }

    /// Starts `program args` inside namespace `ns`.
    pub(crate) fn spawn(&self, ns: &str, program: &Path, args: &[&str]) -> Proc {
        Proc::spawn_command(Self::command(Command::new("ip"), ns, program, args))
    }

    /// `base` (a `Command` for `ip`, with its environment set) running `program args`
    /// inside namespace `ns`. `ip netns exec` execs the program with the environment it
    /// was given: the child's pid is the program's.
    pub(crate) fn command(mut base: Command, ns: &str, program: &Path, args: &[&str]) -> Command {
        base.args(["netns", "exec", ns]).arg(program).args(args);
        base
    }

    /// Runs `program args` inside namespace `ns` to completion, with `stdin` as its
    /// input; its stdout, or an error naming the command and its stderr.
    pub(crate) fn exec(
        ns: &str,
        program: &str,
        args: &[&str],
        stdin: &str,
    ) -> Result<String, String> {
        use std::io::Write;
        use std::process::Stdio;
        let what = || format!("ip netns exec {ns} {program} {}", args.join(" "));
        let mut child = Command::new("ip")
            .args(["netns", "exec", ns, program])
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("{}: {e}", what()))?;
        if let Some(mut input) = child.stdin.take() {
            input
                .write_all(stdin.as_bytes())
                .map_err(|e| format!("{}: {e}", what()))?;
        }
        // Both tools these tests run this way (ip, nft) end at once: no deadline needed.
        let out = child
            .wait_with_output()
            .map_err(|e| format!("{}: {e}", what()))?;
        if out.status.success() {
            Ok(String::from_utf8_lossy(&out.stdout).into_owned())
        } else {
            Err(format!(
                "{}: {}{}",
                what(),
                String::from_utf8_lossy(&out.stderr).trim(),
                input_note(stdin)
            ))
        }
    }

    /// Sets the agents' end of the link down or up.
    fn link(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.agents, "link", "set", &self.agents, state]).unwrap();
    }
}

/// `stdin`, for an error message, when there was one.
fn input_note(stdin: &str) -> String {
    if stdin.is_empty() {
        String::new()
    } else {
        format!("\ninput:\n{stdin}")
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = ip(&["netns", "del", &self.host]);
        let _ = ip(&["netns", "del", &self.agents]);
    }
}

/// 3 agents with one camera each: agent 0 over shm, 1 and 2 over `remote` (zenoh, or shm
/// for the reference run).
fn config_text(session: &str, remote: &str) -> String {
    config_text_n(session, remote, 3)
}

/// `agents` agents with one camera each: agent 0 over shm, the others over `remote`.
fn config_text_n(session: &str, remote: &str, agents: u32) -> String {
    let mut s = format!(
        "session = {session:?}\nseed = 11\n[sync]\nsync_mode = true\n\
         simulation_time_per_frame = 0.1\nstop_timeout = {STOP_TIMEOUT_S}\n\
         connect_timeout = 60.0\nresume_window = 0.0\n[transport]\nkind = \"shm\"\n\
         [transport.zenoh]\nlisten = [\"tcp/{HOST_IP}:7447\"]\n\
         connect = [\"tcp/{HOST_IP}:7447\"]\nlease = {LEASE_S}\n"
    );
    for id in 0..agents {
        let transport = if id == 0 { "shm" } else { remote };
        s += &format!(
            "\n[[agent]]\nid = {id}\ntransport = {transport:?}\n[[agent.camera]]\n\
             name = \"left\"\nwidth = 160\nheight = 120\n"
        );
    }
    s
}

fn agent_args<'a>(config: &'a str, id: &'a str, log: &'a Path) -> Vec<&'a str> {
    vec![
        "--config",
        config,
        "--id",
        id,
        "--policy",
        "seek",
        "--log-cycles",
        log.to_str().unwrap(),
    ]
}

#[test]
fn zenoh_agents_across_network_namespaces_run_in_lock_step_and_survive_faults() {
    let Some(ns) = Netns::create() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    runs_the_all_shm_trajectory(&ns, dir.path());
    survives_faults(&ns, dir.path());
    drop(ns);
}

/// 300 cycles, two agents across the link and one local: the all-shm trajectory, 0
/// timeouts, every agent in every cycle. Leaves `dir/zenoh.toml`.
fn runs_the_all_shm_trajectory(ns: &Netns, dir: &Path) {
    let reference = dir.join("shm.toml");
    std::fs::write(&reference, config_text(&util::session("nsref"), "shm")).unwrap();
    let ref_sum = dir.join("shm.json");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            reference.to_str().unwrap(),
            "--frames",
            "300",
            "--spawn-agents",
            "3",
            "--agent-arg=--policy",
            "--agent-arg=seek",
            "--summary-json",
            ref_sum.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "reference run: {}", out.stderr);

    let config_path = dir.join("zenoh.toml");
    std::fs::write(&config_path, config_text(&util::session("ns"), "zenoh")).unwrap();
    let config = config_path.to_str().unwrap();
    let sum_path = dir.join("zenoh.json");
    let host = ns.spawn(
        &ns.host,
        &bin("vr-sim"),
        &[
            "run",
            "--config",
            config,
            "--frames",
            "300",
            "--summary-json",
            sum_path.to_str().unwrap(),
            "--quiet",
        ],
    );
    let logs: Vec<_> = (0..3).map(|i| dir.join(format!("a{i}.log"))).collect();
    let a0 = ns.spawn(
        &ns.host,
        &bin("vr-agent"),
        &agent_args(config, "0", &logs[0]),
    );
    let a1 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "1", &logs[1]),
    );
    let a2 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "2", &logs[2]),
    );
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "host: {}", out.stderr);
    for (i, a) in [a0, a1, a2].into_iter().enumerate() {
        let out = a.wait(Duration::from_secs(30));
        assert_eq!(out.code(), Some(0), "agent {i}: {}", out.stderr);
    }
    let (zs, rs) = (summary(&sum_path), summary(&ref_sum));
    assert_eq!(zs["frames"], 300, "{zs}");
    assert_eq!(zs["stop_timeouts"], 0, "{zs}");
    assert_eq!(zs["evicted_agents"], serde_json::json!([]), "{zs}");
    assert_eq!(zs["trajectory_hash"], rs["trajectory_hash"], "{zs}\n{rs}");
    for log in &logs {
        let cycles: Vec<u64> = cycle_log(log).iter().map(|l| l.cycle).collect();
        assert_eq!(cycles, (0..300).collect::<Vec<_>>(), "{}", log.display());
    }
    // For BENCHMARKS.md: the cycle time of this run (not asserted).
    let wall = zs["wall_s"].as_f64().unwrap_or(0.0);
    eprintln!(
        "netns zenoh run: 300 cycles in {wall:.2} s, {:.2} ms per cycle (2 remote zenoh agents + 1 shm agent, 3 x 160x120 rgb8)",
        wall * 1000.0 / 300.0
    );
}

/// A killed remote agent is evicted and another rejoins; a pulled link evicts both remote
/// agents by the lease, not the stop timeout, and they see their host gone; after the link
/// comes back new agents join; a killed host is gone for them all.
fn survives_faults(ns: &Netns, dir: &Path) {
    let config_path = dir.join("zenoh.toml");
    let config = config_path.to_str().unwrap();
    let session = util::session("nsfault");
    std::fs::write(&config_path, config_text(&session, "zenoh")).unwrap();
    let events = Events::in_dir(dir);
    let sum_path = dir.join("faults.json");
    let host = ns.spawn(
        &ns.host,
        &bin("vr-sim"),
        &[
            "run",
            "--config",
            config,
            "--events",
            events.arg(),
            "--summary-json",
            sum_path.to_str().unwrap(),
            "--quiet",
        ],
    );
    let logs: Vec<_> = (0..3).map(|i| dir.join(format!("f{i}.log"))).collect();
    let a0 = ns.spawn(
        &ns.host,
        &bin("vr-agent"),
        &agent_args(config, "0", &logs[0]),
    );
    let a1 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "1", &logs[1]),
    );
    let a2 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "2", &logs[2]),
    );
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    wait_for_cycle_line(&logs[1], 5, EVENT_DEADLINE);

    // A remote agent is killed: evicted, the others go on, a new one rejoins.
    a1.signal(libc::SIGKILL);
    let _ = a1.wait(Duration::from_secs(10));
    let evicted = events.wait_for_match("agent_evicted", |e| e["agent"] == 1, EVENT_DEADLINE);
    let at = evicted["cycle"].as_u64().unwrap();
    wait_for_cycle_line(&logs[2], at + 3, EVENT_DEADLINE);
    wait_for_cycle_line(&logs[0], at + 3, EVENT_DEADLINE);
    let back_log = dir.join("f1-back.log");
    let a1 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "1", &back_log),
    );
    let rejoined = events.wait_for_match("agent_rejoined", |e| e["agent"] == 1, EVENT_DEADLINE);
    let rejoined_at = rejoined["cycle"].as_u64().unwrap();
    assert!(rejoined_at > at, "{rejoined}");
    wait_for_cycle_line(&back_log, rejoined_at + 2, EVENT_DEADLINE);

    // The link goes down: both remote agents are evicted by the lease (not by the 30 s
    // stop timeout), the local agent goes on, the remote agents see their host gone.
    let before = events.of("agent_evicted").len();
    ns.link(false);
    let pulled = Instant::now();
    for id in [1, 2] {
        events.wait_for_match(
            "agent_evicted",
            |e| e["agent"] == id && e["cycle"].as_u64().unwrap() > rejoined_at,
            EVENT_DEADLINE,
        );
    }
    eprintln!(
        "netns zenoh run: link down -> both remote agents evicted after {:.2} s (lease {LEASE_S} s)",
        pulled.elapsed().as_secs_f64()
    );
    assert_eq!(events.of("agent_evicted").len(), before + 2);
    // Every cycle event so far: no agent was waited for until the stop timeout.
    let timeouts: Vec<_> = events
        .of("cycle")
        .into_iter()
        .filter(|e| e["timed_out_agents"] != serde_json::json!([]))
        .collect();
    assert!(timeouts.is_empty(), "stop timeouts: {timeouts:?}");
    let last0 = cycle_log(&logs[0]).last().unwrap().cycle;
    wait_for_cycle_line(&logs[0], last0 + 3, EVENT_DEADLINE);
    for (id, a) in [(1, a1), (2, a2)] {
        let out = a.wait(EVENT_DEADLINE);
        assert_eq!(out.code(), Some(1), "agent {id}: {}", out.stderr);
        assert!(
            out.stderr.contains("host is gone"),
            "agent {id}: {}",
            out.stderr
        );
    }

    // The link comes back: new remote agents join; then the host is killed and they exit
    // with "host gone".
    ns.link(true);
    let r1_log = dir.join("f1-again.log");
    let r2_log = dir.join("f2-again.log");
    let r1 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "1", &r1_log),
    );
    let r2 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(config, "2", &r2_log),
    );
    for id in [1, 2] {
        events.wait_for_match(
            "agent_rejoined",
            |e| e["agent"] == id && e["cycle"].as_u64().unwrap() > rejoined_at + 2,
            EVENT_DEADLINE,
        );
    }
    let r1_first = cycle_log(&r1_log).first().map_or(0, |l| l.cycle);
    wait_for_cycle_line(&r1_log, r1_first + 2, EVENT_DEADLINE);
    host.signal(libc::SIGKILL);
    let _ = host.wait(Duration::from_secs(10));
    for (id, a) in [(1, r1), (2, r2)] {
        let out = a.wait(EVENT_DEADLINE);
        assert_eq!(out.code(), Some(1), "agent {id}: {}", out.stderr);
        assert!(
            out.stderr.contains("host is gone"),
            "agent {id}: {}",
            out.stderr
        );
    }
    let out = a0.wait(EVENT_DEADLINE);
    assert_eq!(out.code(), Some(1), "agent 0: {}", out.stderr);
}

/// The same lock-step run as the plain zenoh one, over mutual TLS: the host's config
/// (`tls/` listen, its certificate) and the agents' (`tls/` connect, their own
/// certificate) are separate files, as on two machines. 300 cycles, the all-shm
/// trajectory hash, every agent in every cycle, 0 timeouts.
#[test]
fn zenoh_agents_across_network_namespaces_run_in_lock_step_over_mutual_tls() {
    let Some(ns) = Netns::create() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    util::make_certificates(dir.path(), HOST_IP);
    let reference = dir.path().join("shm.toml");
    std::fs::write(&reference, config_text(&util::session("nstref"), "shm")).unwrap();
    let ref_sum = dir.path().join("shm.json");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            reference.to_str().unwrap(),
            "--frames",
            "300",
            "--spawn-agents",
            "3",
            "--agent-arg=--policy",
            "--agent-arg=seek",
            "--summary-json",
            ref_sum.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "reference run: {}", out.stderr);

    let session = util::session("nstls");
    let endpoint = format!("tls/{HOST_IP}:7447");
    let tls_text = |cert: &str| {
        config_text(&session, "zenoh")
            .replace(&format!("tcp/{HOST_IP}:7447"), &endpoint)
            .replace(
                "[transport.zenoh]\n",
                &format!(
                    "[transport.zenoh]\ntls_ca = \"ca.pem\"\ntls_cert = \"{cert}.pem\"\n\
                     tls_key = \"{cert}.key\"\nmtls = true\n"
                ),
            )
    };
    let host_path = dir.path().join("host.toml");
    let agent_path = dir.path().join("agent.toml");
    std::fs::write(&host_path, tls_text("host")).unwrap();
    std::fs::write(&agent_path, tls_text("agent")).unwrap();
    let (host_config, agent_config) = (host_path.to_str().unwrap(), agent_path.to_str().unwrap());
    assert!(
        std::fs::read_to_string(&agent_path)
            .unwrap()
            .contains(&endpoint)
    );
    let sum_path = dir.path().join("tls.json");
    let host = ns.spawn(
        &ns.host,
        &bin("vr-sim"),
        &[
            "run",
            "--config",
            host_config,
            "--frames",
            "300",
            "--summary-json",
            sum_path.to_str().unwrap(),
            "--quiet",
        ],
    );
    let logs: Vec<_> = (0..3)
        .map(|i| dir.path().join(format!("a{i}.log")))
        .collect();
    let a0 = ns.spawn(
        &ns.host,
        &bin("vr-agent"),
        &agent_args(host_config, "0", &logs[0]),
    );
    let a1 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(agent_config, "1", &logs[1]),
    );
    let a2 = ns.spawn(
        &ns.agents,
        &bin("vr-agent"),
        &agent_args(agent_config, "2", &logs[2]),
    );
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "host: {}", out.stderr);
    for (i, a) in [a0, a1, a2].into_iter().enumerate() {
        let out = a.wait(Duration::from_secs(30));
        assert_eq!(out.code(), Some(0), "agent {i}: {}", out.stderr);
    }
    let (zs, rs) = (summary(&sum_path), summary(&ref_sum));
    assert_eq!(zs["frames"], 300, "{zs}");
    assert_eq!(zs["stop_timeouts"], 0, "{zs}");
    assert_eq!(zs["evicted_agents"], serde_json::json!([]), "{zs}");
    assert_eq!(zs["trajectory_hash"], rs["trajectory_hash"], "{zs}\n{rs}");
    for log in &logs {
        let cycles: Vec<u64> = cycle_log(log).iter().map(|l| l.cycle).collect();
        assert_eq!(cycles, (0..300).collect::<Vec<_>>(), "{}", log.display());
    }
    let wall = zs["wall_s"].as_f64().unwrap_or(0.0);
    eprintln!(
        "netns zenoh mutual-TLS run: 300 cycles in {wall:.2} s, {:.2} ms per cycle (2 remote zenoh agents + 1 shm agent, 3 x 160x120 rgb8)",
        wall * 1000.0 / 300.0
    );
    drop(ns);
}

/// The C++ SDK's example agent (built with CMake against the installed SDK, as in
/// `cpp.rs`) on the other side of the veth pair over zenoh, beside a local shm agent:
/// 100 lock-step cycles, every one ended by every agent's stop.
#[test]
fn cpp_agent_across_network_namespaces_runs_in_lock_step() {
    let Some(ns) = Netns::create() else {
        return;
    };
    let sdk = crate::cpp::sdk();
    let dir = tempfile::tempdir().unwrap();
    let config_path = dir.path().join("cpp.toml");
    std::fs::write(
        &config_path,
        config_text_n(&util::session("nscpp"), "zenoh", 2),
    )
    .unwrap();
    let config = config_path.to_str().unwrap();
    let sum_path = dir.path().join("cpp.json");
    let host = ns.spawn(
        &ns.host,
        &bin("vr-sim"),
        &[
            "run",
            "--config",
            config,
            "--frames",
            "100",
            "--summary-json",
            sum_path.to_str().unwrap(),
            "--quiet",
        ],
    );
    let log0 = dir.path().join("a0.log");
    let a0 = ns.spawn(&ns.host, &bin("vr-agent"), &agent_args(config, "0", &log0));
    // The example loads the installed library, not target/<profile>'s (cpp.rs's docs).
    let cpp = Proc::spawn_command(Netns::command(
        crate::cpp::example_command(Path::new("ip"), &[]),
        &ns.agents,
        &sdk.cpp_agent,
        &[config, "1"],
    ));
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "host: {}", out.stderr);
    let out = a0.wait(Duration::from_secs(30));
    assert_eq!(out.code(), Some(0), "agent 0: {}", out.stderr);
    let out = cpp.wait(Duration::from_secs(30));
    assert_eq!(
        out.code(),
        Some(0),
        "cpp_agent: stdout:\n{}\nstderr:\n{}",
        out.stdout,
        out.stderr
    );
    assert!(
        out.stdout.contains(": 100 cycles"),
        "cpp_agent should have run every cycle:\n{}",
        out.stdout
    );
    let sum = summary(&sum_path);
    assert_eq!(sum["frames"], 100, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["evicted_agents"], serde_json::json!([]), "{sum}");
    assert!(sum["commands_applied"].as_u64().unwrap() >= 100, "{sum}");
    drop(ns);
}
