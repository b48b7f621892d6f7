//! The Rerun logger (feature `rerun`); what it logs is listed in the parent module.

use std::path::PathBuf;
use std::time::Duration;

use glam::{Mat3, Quat, Vec3};
use rerun::external::re_uri::RedapUri;
use rerun::sink::{FileSink, GrpcSink, LogSink};
use rerun::{
    Boxes3D, Color, Cylinders3D, DepthImage, Ellipsoids3D, Image, LineStrips3D, Pinhole,
    RecordingStream, RecordingStreamBuilder, Scalars, TextLog, Transform3D, ViewCoordinates,
};
use vrsync_bridge::{Config, ImageMut, PixelFormat};

use super::{CycleData, RerunOptions, TRAIL_CHUNK};
use crate::picture::{goal_labels, packed_pixels};
use crate::render::AGENT_COLORS;
use crate::world::{Body, World, describe_collider};
use crate::world_config::{GoalKind, Shape};

/// The `cycle` timeline (sequence).
const CYCLE: &str = "cycle";
/// The `sim_time` timeline (duration, seconds).
const SIM_TIME: &str = "sim_time";
/// The `rerun` crate's version (the workspace's pin): the viewer's must match.
const RERUN_VERSION: &str = "0.36.3";
/// How long the end of the run waits for the viewer to take the last messages.
const FLUSH_TIMEOUT: Duration = Duration::from_secs(10);

/// Why the Rerun log could not be opened or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RerunError {
    /// `--rerun`: no viewer was listening and none could be started.
    #[error(
        "--rerun: no Rerun viewer is listening on port {port} and none could be started: \
         {reason}. Install the viewer with `pip install rerun-sdk=={version}` (it puts \
         `rerun` on PATH) or start one with `rerun`; --rrd FILE records without a viewer"
    )]
    Viewer {
        /// The port tried.
        port: u16,
        /// The SDK's error.
        reason: String,
        /// The SDK's version (the viewer's must match).
        version: &'static str,
    },
    /// `--rrd`: the file could not be created.
    #[error("--rrd: cannot create {path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// The SDK's error.
        reason: String,
    },
    /// The SDK refused a message or the stream (a bug of this logger, or of the SDK).
    #[error("Rerun log: {0}")]
    Stream(String),
}

fn stream_err(e: impl std::fmt::Display) -> RerunError {
    RerunError::Stream(e.to_string())
}

/// One agent's state in the logger.
#[derive(Debug)]
struct AgentLog {
    id: u32,
    /// Statuses and collisions of the body's pending lists already logged (the lists
    /// grow until the host hands them over with a sensor frame).
    statuses_logged: usize,
    collisions_logged: usize,
    reward_logged: f32,
    reward_total: f64,
    /// The trajectory strip being extended, and how many strips came before it.
    trail: Vec<[f32; 3]>,
    trail_index: usize,
}

/// The Rerun recording of a run: fed by the run loop, once per agent image and once per
/// cycle.
pub struct RerunLog {
    rec: RecordingStream,
    image_every: u64,
    dt_s: f64,
    agents: Vec<AgentLog>,
    /// The objects' positions as last logged.
    objects: Vec<Vec3>,
}

impl std::fmt::Debug for RerunLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RerunLog")
            .field("image_every", &self.image_every)
            .field("agents", &self.agents.len())
            .finish_non_exhaustive()
    }
}

impl RerunLog {
    /// Connects to (or starts) the viewer and/or creates the `.rrd` file, then logs the
    /// static scene: the room, goals, bodies, and the objects at cycle 0.
    ///
    /// # Errors
    /// [`RerunError`].
    pub fn open(opts: &RerunOptions, config: &Config, world: &World) -> Result<Self, RerunError> {
        let mut sinks: Vec<Box<dyn LogSink>> = Vec::new();
        if opts.viewer {
            let spawn = rerun::SpawnOptions::default();
            let info = rerun::spawn(&spawn).map_err(|e| RerunError::Viewer {
                port: spawn.port,
                reason: e
                    .to_string()
                    .lines()
                    .next()
                    .unwrap_or_default()
                    .trim_end_matches('.')
                    .to_owned(),
                version: RERUN_VERSION,
            })?;
            let url = format!("rerun+http://127.0.0.1:{}/proxy", info.port);
            let uri = match url.parse::<RedapUri>() {
                Ok(RedapUri::Proxy(uri)) => uri,
                Ok(_) => return Err(RerunError::Stream(format!("{url} is not a proxy URL"))),
                Err(e) => return Err(stream_err(e)),
            };
            sinks.push(Box::new(GrpcSink::new(uri)));
        }
        if let Some(path) = &opts.rrd {
            let sink = FileSink::new(path).map_err(|e| RerunError::File {
                path: path.clone(),
                reason: e.to_string(),
            })?;
            sinks.push(Box::new(sink));
        }
        let rec = RecordingStreamBuilder::new("vr-sim")
            .set_sinks(sinks)
            .map_err(stream_err)?;
        let mut log = Self {
            rec,
            image_every: opts.image_every.max(1),
            dt_s: config.sync.simulation_time_per_frame.as_secs_f64(),
            agents: world
                .bodies()
                .iter()
                .map(|b| AgentLog {
                    id: b.id,
                    statuses_logged: 0,
                    collisions_logged: 0,
                    reward_logged: 0.0,
                    reward_total: 0.0,
                    trail: vec![b.position.to_array()],
                    trail_index: 0,
                })
                .collect(),
            objects: Vec::new(),
        };
        log.log_scene(world)?;
        log.set_time(0, 0.0);
        log.log_objects(world)?;
        Ok(log)
    }

    fn set_time(&self, cycle: u64, sim_time_s: f64) {
        self.rec
            .set_time_sequence(CYCLE, i64::try_from(cycle).unwrap_or(i64::MAX));
        self.rec.set_duration_secs(SIM_TIME, sim_time_s);
    }

    /// The static scene: coordinates, walls, goals, the bodies' shapes.
    fn log_scene(&self, world: &World) -> Result<(), RerunError> {
        let rec = &self.rec;
        let cfg = world.config();
        rec.log_static("world", &ViewCoordinates::RIGHT_HAND_Y_UP())
            .map_err(stream_err)?;
        // vr-sim's world is left-handed (x east, y up, z north, as Unity's): mirrored in z
        // the viewer shows it as the map does (north up seen from above, east right).
        rec.log_static(
            "world/room",
            &Transform3D::from_mat3x3([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
        )
        .map_err(stream_err)?;
        let (min, max) = world.room_bounds();
        rec.log_static(
            "world/room/walls",
            &Boxes3D::from_centers_and_half_sizes(
                [((min + max) / 2.0).to_array()],
                [((max - min) / 2.0).to_array()],
            )
            .with_colors([Color::from_rgb(120, 120, 120)])
            .with_labels(["room"]),
        )
        .map_err(stream_err)?;
        let labels = goal_labels(cfg);
        let mut strips = Vec::new();
        let mut strip_labels = Vec::new();
        for (g, label) in cfg.goals.iter().zip(&labels) {
            if let GoalKind::Region { center, radius } = g.kind {
                strips.push(
                    (0..=48)
                        .map(|i| {
                            let a = i as f32 / 48.0 * std::f32::consts::TAU;
                            [
                                center.x + radius * a.cos(),
                                0.01,
                                center.y + radius * a.sin(),
                            ]
                        })
                        .collect::<Vec<_>>(),
                );
                strip_labels.push(label.clone());
            }
        }
        if !strips.is_empty() {
            rec.log_static(
                "world/room/goals",
                &LineStrips3D::new(strips)
                    .with_colors([Color::from_rgb(70, 200, 90)])
                    .with_labels(strip_labels),
            )
            .map_err(stream_err)?;
        }
        for b in world.bodies() {
            let [r, g, bl] = agent_color(b.id);
            // Cylinders stand along z: turned to stand along y, centred half a body up.
            rec.log_static(
                format!("world/room/agents/{}/body", b.id),
                &Cylinders3D::from_lengths_and_radii([cfg.body_height], [cfg.agent_radius])
                    .with_centers([[0.0, cfg.body_height / 2.0, 0.0]])
                    .with_quaternions([rerun::Quaternion::from_xyzw(
                        Quat::from_rotation_x(std::f32::consts::FRAC_PI_2).to_array(),
                    )])
                    .with_colors([Color::from_rgb(r, g, bl)])
                    .with_labels([format!("agent {}", b.id)]),
            )
            .map_err(stream_err)?;
        }
        Ok(())
    }

    /// The objects as they are now, when any moved since the last time (and the first time).
    fn log_objects(&mut self, world: &World) -> Result<(), RerunError> {
        let now: Vec<Vec3> = world.objects().iter().map(|o| o.position).collect();
        if now == self.objects || world.objects().is_empty() {
            return Ok(());
        }
        self.objects = now;
        let (mut boxes, mut balls) = (Vec::new(), Vec::new());
        for o in world.objects() {
            match o.shape {
                Shape::Box { .. } => boxes.push(o),
                Shape::Sphere { .. } => balls.push(o),
            }
        }
        let label = |o: &crate::world::Object| format!("#{}", o.id);
        let color = |o: &crate::world::Object| Color::from_rgb(o.color[0], o.color[1], o.color[2]);
        self.rec
            .log(
                "world/room/objects/boxes",
                &Boxes3D::from_centers_and_half_sizes(
                    boxes.iter().map(|o| o.position.to_array()),
                    boxes.iter().map(|o| o.shape.half_extents().to_array()),
                )
                .with_colors(boxes.iter().map(|&o| color(o)))
                .with_labels(boxes.iter().map(|&o| label(o)))
                .with_fill_mode(rerun::components::FillMode::Solid),
            )
            .map_err(stream_err)?;
        self.rec
            .log(
                "world/room/objects/spheres",
                &Ellipsoids3D::from_centers_and_half_sizes(
                    balls.iter().map(|o| o.position.to_array()),
                    balls.iter().map(|o| o.shape.half_extents().to_array()),
                )
                .with_colors(balls.iter().map(|&o| color(o)))
                .with_labels(balls.iter().map(|&o| label(o)))
                .with_fill_mode(rerun::components::FillMode::Solid),
            )
            .map_err(stream_err)
    }

    /// Whether the images of `cycle` are logged (`--rerun-every`).
    pub fn wants_images(&self, cycle: u64) -> bool {
        cycle.is_multiple_of(self.image_every)
    }

    /// Logs one camera image agent `agent` gets at the start of `cycle`.
    ///
    /// # Errors
    /// [`RerunError::Stream`].
    pub fn log_image(
        &mut self,
        cycle: u64,
        agent: u32,
        image: &ImageMut<'_>,
    ) -> Result<(), RerunError> {
        self.set_time(cycle, cycle as f64 * self.dt_s);
        let d = image.desc;
        let size = [d.width_px, d.height_px];
        let pixels = packed_pixels(image).into_owned();
        let path = format!("agents/{agent}/cameras/{}", d.name());
        match d.pixel_format().unwrap_or_default() {
            PixelFormat::Rgb8 => self.rec.log(path, &Image::from_rgb24(pixels, size)),
            PixelFormat::Rgba8 => self.rec.log(path, &Image::from_rgba32(pixels, size)),
            PixelFormat::Gray8 => self.rec.log(path, &Image::from_l8(pixels, size)),
            PixelFormat::Depth32f => self.rec.log(
                path,
                &DepthImage::new(
                    pixels,
                    rerun::components::ImageFormat::depth(
                        size,
                        rerun::datatypes::ChannelDatatype::F32,
                    ),
                )
                .with_meter(1.0),
            ),
        }
        .map_err(stream_err)
    }

    /// Logs the cycle's end: poses, eyes, trajectories, commands, statuses, collisions,
    /// rewards, the host's wait and stop timeouts.
    ///
    /// # Errors
    /// [`RerunError::Stream`].
    pub fn log_cycle(&mut self, c: &CycleData<'_>) -> Result<(), RerunError> {
        self.set_time(c.cycle, (c.cycle as f64 + 1.0) * self.dt_s);
        let rec = &self.rec;
        rec.log("host/wait_ms", &Scalars::single(c.wait.as_secs_f64() * 1e3))
            .map_err(stream_err)?;
        rec.log(
            "host/stop_timeouts",
            &Scalars::single(c.stop_timeouts as f64),
        )
        .map_err(stream_err)?;
        rec.log(
            "host/render_ms",
            &Scalars::single(c.render.as_secs_f64() * 1e3),
        )
        .map_err(stream_err)?;
        for agent in c.commands {
            for sent in &agent.sent {
                let text = serde_json::to_string(sent).map_err(stream_err)?;
                let entry = match &sent.error {
                    None => TextLog::new(text).with_level(rerun::TextLogLevel::INFO),
                    Some(_) => TextLog::new(text).with_level(rerun::TextLogLevel::WARN),
                };
                rec.log(format!("agents/{}/commands", agent.agent), &entry)
                    .map_err(stream_err)?;
            }
        }
        for a in &mut self.agents {
            let Some(body) = c.world.bodies().iter().find(|b| b.id == a.id) else {
                continue;
            };
            let sensed = c
                .agents
                .iter()
                .position(|&id| id == a.id)
                .is_some_and(|i| c.sensed.get(i).copied().unwrap_or(false));
            if sensed {
                // The sensor frame handed the pending lists over and cleared them.
                a.statuses_logged = 0;
                a.collisions_logged = 0;
                a.reward_logged = 0.0;
            }
            log_agent(rec, c.world, body, a)?;
        }
        self.log_objects(c.world)
    }

    /// Flushes the sinks (the viewer gets up to 10 s to take the rest).
    ///
    /// # Errors
    /// [`RerunError::Stream`].
    pub fn finish(self) -> Result<(), RerunError> {
        self.rec
            .flush_with_timeout(FLUSH_TIMEOUT)
            .map_err(stream_err)?;
        self.rec.disconnect();
        Ok(())
    }
}

fn agent_color(id: u32) -> [u8; 3] {
    AGENT_COLORS[id as usize % AGENT_COLORS.len()]
}

/// One agent's cycle: pose, eyes, trajectory, statuses, collisions, reward.
fn log_agent(
    rec: &RecordingStream,
    world: &World,
    body: &Body,
    a: &mut AgentLog,
) -> Result<(), RerunError> {
    let base = format!("world/room/agents/{}", body.id);
    let pose = body.pose();
    rec.log(
        format!("{base}/body"),
        &Transform3D::from_translation_rotation(
            pose.position,
            rerun::Quaternion::from_xyzw(pose.rotation),
        ),
    )
    .map_err(stream_err)?;
    for spec in body.cameras() {
        let cam = world.camera(body, spec);
        // The camera's axes in the room: right, down (image rows), forward, the pinhole's
        // RDF. In the room's left-handed coordinates that basis is a reflection; with the
        // mirror of `world/room` it is a rotation in the viewer's space.
        let axes = Mat3::from_cols(cam.right, -cam.up, cam.forward).to_cols_array_2d();
        let (w, h) = (spec.width_px as f32, spec.height_px as f32);
        let focal = [w / 2.0 / cam.tan_half_h, h / 2.0 / cam.tan_half_v];
        rec.log(
            format!("{base}/eyes/{}", spec.name),
            &[
                &Transform3D::from_translation_mat3x3(cam.origin.to_array(), axes)
                    as &dyn rerun::AsComponents,
                &Pinhole::from_focal_length_and_resolution(focal, [w, h])
                    .with_camera_xyz(rerun::components::ViewCoordinates::RDF)
                    .with_image_plane_distance(0.3),
            ],
        )
        .map_err(stream_err)?;
    }
    // The trajectory: a point per cycle in which the body moved, in strips of TRAIL_CHUNK.
    let p = body.position.to_array();
    if a.trail.last() != Some(&p) {
        if a.trail.len() >= TRAIL_CHUNK {
            let last = a.trail.last().copied().unwrap_or(p);
            a.trail.clear();
            a.trail.push(last);
            a.trail_index += 1;
        }
        a.trail.push(p);
        let [r, g, b] = agent_color(body.id);
        rec.log(
            format!("{base}/trajectory/{}", a.trail_index),
            &LineStrips3D::new([a.trail.clone()]).with_colors([Color::from_rgb(r, g, b)]),
        )
        .map_err(stream_err)?;
    }
    let agent_path = format!("agents/{}", body.id);
    for &(action, state) in body.pending_statuses().iter().skip(a.statuses_logged) {
        rec.log(
            format!("{agent_path}/statuses"),
            &TextLog::new(format!("action {action}: {state:?}"))
                .with_level(rerun::TextLogLevel::INFO),
        )
        .map_err(stream_err)?;
    }
    a.statuses_logged = body.pending_statuses().len();
    for &(action, collider) in body.pending_collisions().iter().skip(a.collisions_logged) {
        rec.log(
            format!("{agent_path}/events"),
            &TextLog::new(format!(
                "collision: action {action} hit {} (collider {collider})",
                describe_collider(collider)
            ))
            .with_level(rerun::TextLogLevel::WARN),
        )
        .map_err(stream_err)?;
    }
    a.collisions_logged = body.pending_collisions().len();
    let reward = body.pending_reward() - a.reward_logged;
    if reward != 0.0 {
        a.reward_total += f64::from(reward);
        rec.log(
            format!("{agent_path}/events"),
            &TextLog::new(format!("reward {reward:+}")).with_level(rerun::TextLogLevel::INFO),
        )
        .map_err(stream_err)?;
    }
    a.reward_logged = body.pending_reward();
    rec.log(
        format!("{agent_path}/reward_total"),
        &Scalars::single(a.reward_total),
    )
    .map_err(stream_err)
}
