//! Spawned agent processes: started next to our executable, reaped at the end, killed if
//! we leave early.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// The `vr-agent` executable next to the running `vr-sim`.
pub fn agent_executable() -> anyhow::Result<PathBuf> {
    let me = std::env::current_exe().context("cannot locate the vr-sim executable")?;
    let dir = me
        .parent()
        .context("vr-sim executable has no parent folder")?;
    let agent = dir.join(format!("vr-agent{}", std::env::consts::EXE_SUFFIX));
    if !agent.is_file() {
        bail!(
            "cannot find {} (build it with `cargo build -p vrsync-agent`)",
            agent.display()
        );
    }
    Ok(agent)
}

/// Spawned agents; killed and reaped on drop.
#[derive(Debug, Default)]
pub struct Agents {
    children: Vec<(u32, Child)>,
}

impl Agents {
    /// Starts `vr-agent --config CONFIG --id i EXTRA...` for every id.
    pub fn spawn(config: &Path, ids: &[u32], extra: &[String]) -> anyhow::Result<Self> {
        let exe = agent_executable()?;
        let mut agents = Self::default();
        for &id in ids {
            let child = Command::new(&exe)
                .arg("--config")
                .arg(config)
                .arg("--id")
                .arg(id.to_string())
                .args(extra)
                .spawn()
                .with_context(|| format!("cannot start {} for agent {id}", exe.display()))?;
            agents.children.push((id, child));
        }
        Ok(agents)
    }

    /// The first spawned agent that already exited with a failure, if any.
    pub fn failed(&mut self) -> Option<(u32, ExitStatus)> {
        for (id, child) in &mut self.children {
            if let Ok(Some(status)) = child.try_wait()
                && !status.success()
            {
                return Some((*id, status));
            }
        }
        None
    }

    /// Waits up to `timeout` for every agent to exit, then kills the rest. Returns the
    /// ids and statuses of agents that failed.
    pub fn finish(mut self, timeout: Duration) -> Vec<(u32, String)> {
        let deadline = Instant::now() + timeout;
        let mut failures = Vec::new();
        for (id, child) in &mut self.children {
            loop {
                match child.try_wait() {
                    Ok(Some(status)) => {
                        if !status.success() {
                            failures.push((*id, status.to_string()));
                        }
                        break;
                    }
                    Ok(None) if Instant::now() < deadline => {
                        // Reaping needs polling: std offers no wait with a timeout.
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    _ => {
                        let _ = child.kill();
                        let _ = child.wait();
                        failures.push((*id, "did not exit, killed".to_string()));
                        break;
                    }
                }
            }
        }
        self.children.clear();
        failures
    }
}

impl Drop for Agents {
    fn drop(&mut self) {
        for (_, child) in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A file removed when this value is dropped.
#[derive(Debug)]
pub struct RemoveOnDrop(pub PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}
