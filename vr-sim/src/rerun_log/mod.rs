//! Live view and recording in Rerun (`vr-sim run --rerun`, `--rrd FILE`): one logger fed by
//! the run loop, at the places `--record`, `--map` and `--dump-frames` take their data.
//!
//! Built with the cargo feature `rerun` only (the Rerun SDK adds Arrow, tonic, ... to a
//! clean build); without it [`RerunLog::open`] fails with [`RerunUnavailable`] (exit 2),
//! and the flags are still listed by `--help`.
//!
//! What is logged (timelines `cycle`, a sequence, and `sim_time`, a duration):
//! - static: `world` (view coordinates: y up), `world/room` (vr-sim's world is left-handed,
//!   as Unity's: this transform mirrors z so that the viewer, right-handed, shows it as the
//!   map does; everything below is in vr-sim's own coordinates), `world/room/walls`,
//!   `world/room/goals`, the agents' bodies `world/room/agents/<id>/body` (cylinders);
//! - `world/room/objects/boxes` and `.../spheres` at cycle 0 and whenever an object moved;
//! - every cycle, after the world advanced (the `--record` line's state, at `sim_time` =
//!   the end of the cycle): `world/room/agents/<id>/body` (Transform3D: position and
//!   rotation, as `--record`'s `position` and `rotation`), `world/room/agents/<id>/eyes/<camera>`
//!   (Transform3D + Pinhole: each camera's pose and frustum), `world/room/agents/<id>/trajectory/<k>`
//!   (line strips of up to [`TRAIL_CHUNK`] points each, a point per cycle in which the
//!   agent moved), `agents/<id>/commands` (TextLog: every command with its arguments as the
//!   record's `sent` writes it, rejected ones at level WARN with the reason),
//!   `agents/<id>/statuses` (TextLog: action status changes), `agents/<id>/events`
//!   (TextLog: collisions and rewards), `agents/<id>/reward_total` (Scalars),
//!   `host/wait_ms` (Scalars: the time the host waited for the agents' stops),
//!   `host/stop_timeouts` (Scalars: cycles ended by the stop timeout so far),
//!   `host/render_ms` (Scalars: sensors and images of the cycle);
//! - every `--rerun-every`-th cycle (0, N, 2N, ...), the camera images the agents got at the
//!   start of the cycle (`sim_time` = its start): `agents/<id>/cameras/<camera>` (Image,
//!   or DepthImage in metres).

// Without the feature only the stand-in uses (part of) what follows.
#![cfg_attr(not(feature = "rerun"), allow(dead_code))]

#[cfg(feature = "rerun")]
mod logger;
// Compiled in both builds (CI builds with the feature only): the stand-in the run loop uses
// without the feature.
#[cfg_attr(feature = "rerun", allow(dead_code))]
mod unavailable;

use std::path::PathBuf;

#[cfg(feature = "rerun")]
pub use logger::RerunLog;
#[cfg(not(feature = "rerun"))]
pub use unavailable::RerunLog;

/// Line strips of a trajectory hold at most this many points: a long run logs new short
/// strips rather than ever longer ones.
pub const TRAIL_CHUNK: usize = 128;

/// Where to send the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RerunOptions {
    /// Stream to a Rerun viewer: the one listening on the default port (9876), else a new
    /// `rerun` process from PATH.
    pub viewer: bool,
    /// Save the recording in this `.rrd` file.
    pub rrd: Option<PathBuf>,
    /// Log the camera images of every N-th cycle (poses and the rest: every cycle).
    pub image_every: u64,
}

/// This vr-sim was built without the `rerun` feature.
#[derive(Debug, thiserror::Error)]
#[error(
    "this vr-sim was built without the `rerun` feature; rebuild with `cargo build --release \
     -p vrsync-sim --features rerun` (or `cargo install --path vr-sim --features rerun`) to use \
     --rerun / --rrd"
)]
pub struct RerunUnavailable;

/// What the run loop hands the logger after a cycle.
#[derive(Debug)]
pub struct CycleData<'a> {
    /// The cycle.
    pub cycle: u64,
    /// The world after the cycle.
    pub world: &'a crate::world::World,
    /// Every agent's commands of the cycle (as recorded).
    pub commands: &'a [crate::record::AgentCommands],
    /// The agents, in the config's order.
    pub agents: &'a [u32],
    /// Whether the host wrote agent `agents[i]`'s sensor frame at the start of the cycle
    /// (which hands over and clears its pending statuses, collisions and reward).
    pub sensed: &'a [bool],
    /// How long the host waited for the agents' stops.
    pub wait: std::time::Duration,
    /// Writing sensors and rendering images in this cycle.
    pub render: std::time::Duration,
    /// Cycles ended by the stop timeout so far.
    pub stop_timeouts: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_the_feature_the_log_cannot_be_opened_and_says_how_to_rebuild() {
        let config = vrsync_bridge::Config::embedded_default().unwrap();
        let world = crate::world::World::from_config(&config).unwrap();
        let opts = RerunOptions {
            viewer: false,
            rrd: Some("never-written.rrd".into()),
            image_every: 1,
        };
        let err = unavailable::RerunLog::open(&opts, &config, &world).unwrap_err();
        let text = anyhow::Error::from(err);
        assert!(text.downcast_ref::<RerunUnavailable>().is_some());
        assert!(
            text.to_string().starts_with(
                "this vr-sim was built without the `rerun` feature; rebuild with `cargo build"
            ),
            "{text}"
        );
        assert!(!std::path::Path::new("never-written.rrd").exists());
    }
}
