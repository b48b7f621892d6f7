//! Before the first cycle: the host's event hooks, the agents spawned (`--spawn`) and the
//! wait until every agent is connected.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use tracing::warn;
use vrsync_bridge::{Config, Host, HostWaitError};

use super::RunOptions;
use crate::events::{Event, Events};
use crate::spawn::{Agents, PrivateConfig};

/// Reports evictions, slow agents and refused peers as they happen: collect may block for
/// a lost agent (`on_agent_lost = "wait"`).
pub(super) fn install_event_hooks(host: &mut Host, events: &Events) {
    let mut hook_events = events.clone();
    host.on_evicted(move |agent, cycle| {
        let event = Event::AgentEvicted {
            agent,
            cycle,
            reason: "lost: process died or disconnected".into(),
        };
        if let Err(e) = hook_events.emit(event) {
            warn!("{e:#}");
        }
    });
    let mut hook_events = events.clone();
    host.on_slow(move |agent, cycle, waited| {
        let event = Event::AgentSlow {
            agent,
            cycle,
            waited_s: waited.as_secs_f64(),
        };
        if let Err(e) = hook_events.emit(event) {
            warn!("{e:#}");
        }
    });
    let mut hook_events = events.clone();
    host.on_peer_refused(move |r| {
        let event = Event::PeerRefused {
            kind: r.kind.as_str(),
            agent: r.agent,
            peer: r.peer.clone(),
            reason: r.reason.clone(),
        };
        if let Err(e) = hook_events.emit(event) {
            warn!("{e:#}");
        }
    });
}

/// `tcp_listen` with port 0 binds a free port: spawned agents must learn the real one, from
/// a private copy of the config (`None`: they read the user's file).
pub(super) fn bound_config_for_spawn(
    opts: &RunOptions,
    host: &Host,
) -> anyhow::Result<Option<PrivateConfig>> {
    let config = &opts.config;
    if let Some(addr) = host.tcp_local_addr()
        && addr != config.transport.tcp_listen
        && opts.spawn
    {
        let mut bound = config.clone();
        bound.transport.tcp_listen = addr;
        return Ok(Some(PrivateConfig::write(&bound)?));
    }
    Ok(None)
}

/// Spawns `vr-agent` for every configured agent but the legacy ones: those are programs
/// written for the original system, started by the user, never by vr-sim.
pub(super) fn spawn_agents(
    config: &Config,
    agent_config_path: &Path,
    agent_args: &[String],
) -> anyhow::Result<Agents> {
    let spawn_ids: Vec<u32> = config
        .agents
        .iter()
        .filter(|a| a.transport != vrsync_bridge::TransportKind::Legacy)
        .map(|a| a.id)
        .collect();
    Agents::spawn(agent_config_path, &spawn_ids, agent_args)
}

/// Waits for every agent, in slices so a spawned agent that fails is reported at once (and
/// connections are reported as events).
pub(super) fn wait_for_agents(
    host: &mut Host,
    agents: &mut Agents,
    ids: &[u32],
    events: &mut Events,
    opts: &RunOptions,
) -> anyhow::Result<()> {
    let config = &opts.config;
    let mut missing_before: Vec<u32> = ids
        .iter()
        .copied()
        .filter(|&id| !host.is_connected(id))
        .collect();
    if !missing_before.is_empty() {
        events.emit(Event::WaitingForAgents {
            agents: missing_before.clone(),
        })?;
    }
    let wait_started = Instant::now();
    loop {
        let left = config
            .sync
            .connect_timeout
            .saturating_sub(wait_started.elapsed());
        let result = host.wait_for_agents(left.min(Duration::from_millis(500)));
        let missing: &[u32] = match &result {
            Err(HostWaitError::AgentsMissing { missing, .. }) => missing,
            _ => &[],
        };
        if result.is_ok() || matches!(result, Err(HostWaitError::AgentsMissing { .. })) {
            for &agent in missing_before.iter().filter(|id| !missing.contains(id)) {
                events.emit(Event::AgentConnected { agent, cycle: None })?;
            }
            missing_before = missing.to_vec();
        }
        match result {
            Ok(()) => {
                events.emit(Event::AllAgentsConnected { agents: ids.len() })?;
                return Ok(());
            }
            Err(HostWaitError::AgentsMissing {
                missing,
                left: gone,
                ..
            }) => {
                if let Some((id, status)) = agents.failed() {
                    bail!("agent {id} exited before connecting ({status})");
                }
                if left.is_zero() {
                    return Err(agents_missing(opts, &missing, &gone));
                }
            }
            Err(HostWaitError::Terminated) => bail!("interrupted while waiting for agents"),
            Err(e) => return Err(e).context("waiting for agents"),
        }
    }
}

/// The error when agents are still missing at `sync.connect_timeout`: agents that
/// connected and left again are named as such, not as agents that never came, and legacy
/// agents (programs written for the original system, not vr-agent) with where they connect.
pub(super) fn agents_missing(opts: &RunOptions, missing: &[u32], gone: &[u32]) -> anyhow::Error {
    let config = &opts.config;
    let never: Vec<u32> = missing
        .iter()
        .copied()
        .filter(|id| !gone.contains(id))
        .collect();
    let mut why = Vec::new();
    if !never.is_empty() {
        why.push(format!(
            "agents {never:?} did not connect within {}",
            vrsync_bridge::Rounded(config.sync.connect_timeout)
        ));
    }
    if !gone.is_empty() {
        why.push(format!("agents {gone:?} connected and left again"));
    }
    let legacy: Vec<u32> = missing
        .iter()
        .copied()
        .filter(|&id| {
            config
                .agent(id)
                .is_some_and(|a| a.transport == vrsync_bridge::TransportKind::Legacy)
        })
        .collect();
    if !legacy.is_empty() {
        let port = config.transport.legacy.local_port;
        why.push(format!(
            "agents {legacy:?} use the original system's protocol: start their \
             programs against port {port} (agent N listens on {port} + 1 + N)"
        ));
    }
    // vr-agent's hint only for the agents vr-agent can be (not the legacy ones).
    let ours: Vec<u32> = missing
        .iter()
        .copied()
        .filter(|id| !legacy.contains(id))
        .collect();
    if !ours.is_empty() {
        let whom = if legacy.is_empty() {
            "them".to_string()
        } else {
            format!("agents {ours:?}")
        };
        why.push(format!(
            "start {whom} with `vr-agent --config {} --id <id>`",
            opts.agent_config_path.display()
        ));
    }
    anyhow::anyhow!("{}", why.join("; "))
}

/// The progress bar of `--progress`: a bar of `frames` cycles, or a spinner without them.
pub(super) fn progress_bar(frames: Option<u64>) -> indicatif::ProgressBar {
    let bar = match frames {
        Some(n) => indicatif::ProgressBar::new(n),
        None => indicatif::ProgressBar::new_spinner(),
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} cycles {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

#[cfg(test)]
mod tests {
    use super::*;
    use vrsync_bridge::TransportKind;

    fn opts(transports: &[TransportKind]) -> RunOptions {
        let mut config = Config::embedded_default().unwrap();
        let first = config.agents[0].clone();
        config.agents = (0u32..)
            .zip(transports)
            .map(|(id, &transport)| {
                let mut a = first.clone();
                a.id = id;
                a.transport = transport;
                a
            })
            .collect();
        RunOptions {
            config,
            agent_config_path: "agents.toml".into(),
            frames: None,
            spawn: false,
            agent_args: Vec::new(),
            record: None,
            progress: false,
            map: None,
            dump_frames: None,
            render_threads: 1,
            render_affinity: crate::render::Affinity::Auto,
            rerun: None,
        }
    }

    #[test]
    fn missing_agents_are_told_how_to_start_each() {
        let o = opts(&[TransportKind::Shm, TransportKind::Legacy]);
        let text = agents_missing(&o, &[0, 1], &[]).to_string();
        assert!(text.contains("agents [0, 1] did not connect"), "{text}");
        assert!(
            text.contains("agents [1] use the original system's protocol"),
            "{text}"
        );
        assert!(
            text.contains("start agents [0] with `vr-agent --config agents.toml"),
            "{text}"
        );

        let text = agents_missing(&o, &[1], &[]).to_string();
        assert!(
            !text.contains("vr-agent"),
            "a legacy agent is not a vr-agent: {text}"
        );

        let o = opts(&[TransportKind::Shm]);
        let text = agents_missing(&o, &[0], &[]).to_string();
        assert!(
            text.contains("start them with `vr-agent --config agents.toml --id <id>`"),
            "{text}"
        );
    }
}
