//! The config file as serde reads it: every key optional (defaults are applied by the
//! checks), unknown keys rejected, values kept with their spans for error lines.

use serde::Deserialize;
use toml::Spanned;

use super::transport::RawTransport;
use super::{AgentLostPolicy, TransportKind, WaitForStop, WaitMode};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawConfig {
    pub(super) session: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) seed: u64,
    #[serde(default)]
    pub(super) sync: Option<RawSync>,
    #[serde(default)]
    pub(super) transport: Option<RawTransport>,
    #[serde(default)]
    pub(super) agent: Vec<Spanned<RawAgent>>,
    #[serde(default)]
    pub(super) world: Option<toml::Table>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSync {
    #[serde(alias = "SyncMode")]
    pub(super) sync_mode: Option<bool>,
    #[serde(alias = "SimulationTimePerFrame")]
    pub(super) simulation_time_per_frame: Option<Spanned<f64>>,
    #[serde(alias = "SyncModeFrameTimeOut")]
    pub(super) stop_timeout: Option<Spanned<f64>>,
    pub(super) connect_timeout: Option<Spanned<f64>>,
    pub(super) wait: Option<WaitMode>,
    pub(super) spin_before_block_us: Option<Spanned<i64>>,
    pub(super) on_agent_lost: Option<AgentLostPolicy>,
    pub(super) wait_for_stop: Option<WaitForStop>,
    pub(super) resume_window: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAgent {
    pub(super) id: Spanned<i64>,
    pub(super) transport: Option<TransportKind>,
    pub(super) wait_for_stop: Option<WaitForStop>,
    #[serde(default)]
    pub(super) camera: Vec<Spanned<RawCamera>>,
    #[serde(default)]
    pub(super) vector: Vec<Spanned<RawVector>>,
    #[serde(default)]
    pub(super) action: Vec<Spanned<RawAction>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCamera {
    pub(super) name: Spanned<String>,
    pub(super) width: Spanned<i64>,
    pub(super) height: Option<Spanned<i64>>,
    #[serde(default)]
    pub(super) format: Option<Spanned<String>>,
    #[serde(default = "default_fov_h")]
    pub(super) fov_horizontal_deg: Spanned<f64>,
    #[serde(default = "default_fov_v")]
    pub(super) fov_vertical_deg: Spanned<f64>,
}

fn default_fov_h() -> Spanned<f64> {
    Spanned::new(0..0, 120.0)
}
fn default_fov_v() -> Spanned<f64> {
    Spanned::new(0..0, 90.0)
}

/// `low` / `high`: one number for every value, or one per value.
#[derive(Deserialize, Clone)]
#[serde(untagged)]
pub(super) enum RawBound {
    One(f64),
    Each(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawVector {
    pub(super) name: Spanned<String>,
    pub(super) len: Spanned<i64>,
    pub(super) low: Option<Spanned<RawBound>>,
    pub(super) high: Option<Spanned<RawBound>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAction {
    pub(super) name: Spanned<String>,
    pub(super) len: Option<Spanned<i64>>,
    pub(super) low: Option<Spanned<RawBound>>,
    pub(super) high: Option<Spanned<RawBound>>,
    pub(super) n: Option<Spanned<i64>>,
}
