//! Writing a config back as TOML (the effective config handed to spawned agents): one
//! writer per section, in the order of `config/default.toml`.

use std::fmt::Write;

use super::ctx::toml_string;
use super::transport::write_transport;
use super::{ActionSpace, AgentConfig, AgentLostPolicy, Config, SyncConfig, WaitMode};

impl Config {
    /// The config as TOML again (for handing the effective config to spawned agents).
    pub fn to_toml_string(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# effective vrsync config (generated from {})",
            self.source.display().to_string().escape_debug()
        );
        let _ = writeln!(s, "session = {:?}\nseed = {}", self.session, self.seed);
        write_sync(&mut s, &self.sync);
        write_transport(&mut s, &self.transport);
        for a in &self.agents {
            write_agent(&mut s, a);
        }
        if let Some(world) = &self.world {
            let mut doc = toml::Table::new();
            doc.insert("world".into(), toml::Value::Table(world.clone()));
            if let Ok(text) = toml::to_string(&doc) {
                let _ = writeln!(s, "\n{text}");
            }
        }
        s
    }
}

/// `[sync]`.
fn write_sync(s: &mut String, sync: &SyncConfig) {
    let _ = writeln!(
        s,
        "\n[sync]\nsync_mode = {}\nsimulation_time_per_frame = {:?}\nstop_timeout = {:?}\nconnect_timeout = {:?}\nwait = {:?}\nspin_before_block_us = {}\non_agent_lost = {:?}",
        sync.sync_mode,
        sync.simulation_time_per_frame.as_secs_f64(),
        sync.stop_timeout.as_secs_f64(),
        sync.connect_timeout.as_secs_f64(),
        match sync.wait {
            WaitMode::Block => "block",
            WaitMode::Spin => "spin",
        },
        sync.spin_before_block.as_micros(),
        match sync.on_agent_lost {
            AgentLostPolicy::Evict => "evict",
            AgentLostPolicy::Wait => "wait",
            AgentLostPolicy::Abort => "abort",
        }
    );
    let _ = writeln!(s, "resume_window = {:?}", sync.resume_window.as_secs_f64());
    if let Some(w) = sync.wait_for_stop {
        let _ = writeln!(s, "wait_for_stop = {:?}", w.as_str());
    }
}

/// One `[[agent]]` with its `[[agent.camera]]` entries.
fn write_agent(s: &mut String, a: &AgentConfig) {
    let _ = writeln!(
        s,
        "\n[[agent]]\nid = {}\ntransport = {:?}\nwait_for_stop = {:?}",
        a.id,
        a.transport.as_str(),
        a.wait_for_stop.as_str()
    );
    for c in &a.cameras {
        let _ = writeln!(
            s,
            "[[agent.camera]]\nname = {}\nwidth = {}\nheight = {}\nformat = {:?}\nfov_horizontal_deg = {:?}\nfov_vertical_deg = {:?}",
            toml_string(&c.name),
            c.width_px,
            c.height_px,
            c.format.as_str(),
            f64::from(c.fov_horizontal_deg),
            f64::from(c.fov_vertical_deg)
        );
    }
    write_channels(s, a);
}

/// The `[[agent.vector]]` and `[[agent.action]]` entries of an agent.
fn write_channels(s: &mut String, a: &AgentConfig) {
    for v in &a.vectors {
        let _ = writeln!(
            s,
            "[[agent.vector]]\nname = {}\nlen = {}\nlow = {}\nhigh = {}",
            toml_string(&v.name),
            v.len,
            toml_floats(&v.low),
            toml_floats(&v.high)
        );
    }
    for act in &a.actions {
        let _ = writeln!(s, "[[agent.action]]\nname = {}", toml_string(&act.name));
        let _ = match &act.space {
            ActionSpace::Box { low, high } => writeln!(
                s,
                "len = {}\nlow = {}\nhigh = {}",
                low.len(),
                toml_floats(low),
                toml_floats(high)
            ),
            ActionSpace::Discrete { n } => writeln!(s, "n = {n}"),
        };
    }
}

/// A TOML array of floats (`inf` and `-inf` are TOML).
fn toml_floats(v: &[f32]) -> String {
    toml::Value::Array(
        v.iter()
            .map(|&x| toml::Value::Float(f64::from(x)))
            .collect(),
    )
    .to_string()
}
