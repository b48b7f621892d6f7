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
            "cannot find {} (build it with `cargo build -p vrsync-agent-bin`)",
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

/// An effective config for spawned agents, readable by this user only (it may hold
/// `tcp_token`): `config.toml` with mode 0600 in a fresh temp dir with a random name and
/// mode 0700, so no other user can read it or plant a file at a path they could predict.
/// Removed with its folder on drop.
#[derive(Debug)]
pub struct PrivateConfig {
    _dir: tempfile::TempDir,
    path: PathBuf,
}

impl PrivateConfig {
    /// Writes `config`.
    ///
    /// # Errors
    /// The folder or the file cannot be created.
    pub fn write(config: &vrsync_bridge::Config) -> anyhow::Result<Self> {
        use std::io::Write;
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let dir = tempfile::Builder::new()
            .prefix("vrsync-")
            .permissions(std::fs::Permissions::from_mode(0o700))
            .tempdir()
            .context("cannot create a private temp dir for the effective config")?;
        let path = dir.path().join("config.toml");
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        file.write_all(config.to_toml_string().as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        Ok(Self { _dir: dir, path })
    }

    /// The file to give the agents.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    #[test]
    fn the_effective_config_is_private_unpredictable_and_removed() {
        let mut config = vrsync_bridge::Config::embedded_default().unwrap();
        config.transport.tcp_token = Some("s3cret".into());
        let a = PrivateConfig::write(&config).unwrap();
        let b = PrivateConfig::write(&config).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(a.path()), 0o600);
        assert_eq!(mode(a.path().parent().unwrap()), 0o700);
        assert_ne!(
            a.path().parent().unwrap(),
            b.path().parent().unwrap(),
            "a fresh folder per run"
        );
        let text = std::fs::read_to_string(a.path()).unwrap();
        let back = vrsync_bridge::Config::from_toml_str(&text, a.path()).unwrap();
        assert_eq!(back.transport.tcp_token.as_deref(), Some("s3cret"));
        let (dir, path) = (
            a.path().parent().unwrap().to_path_buf(),
            a.path().to_path_buf(),
        );
        drop(a);
        assert!(!path.exists() && !dir.exists());
    }
}
