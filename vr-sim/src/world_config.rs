//! The `[world]` section of the config: the room, its objects, the agents' bodies and start
//! poses, and the goal regions. Every key is documented in `config/default.toml`.
//!
//! The bridge keeps the table unparsed ([`vrsync_bridge::Config::world`]); it is parsed
//! here with serde, unknown keys rejected, and every error names the dotted key (with the
//! index of an array entry, e.g. `world.object[2].color`).

use std::path::PathBuf;

use glam::{Vec2, Vec3};
use serde::Deserialize;
use serde::de::DeserializeOwned;
use vrsync_bridge::Config;

/// Highest accepted object id; ids from 1000 on are walls and agents.
pub const MAX_OBJECT_ID: u32 = 999;

/// An 8-bit sRGB colour.
pub type Rgb = [u8; 3];

/// Why the `[world]` section could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WorldConfigError {
    /// A key has the wrong type, is unknown, or its value is out of range.
    #[error("{path}:{line}: invalid `{key}`: {reason}")]
    Invalid {
        /// The config file.
        path: PathBuf,
        /// 1-based line of the key (of its table when the key is missing); 0 when the
        /// config has no text to point into (built in code).
        line: usize,
        /// Dotted key, e.g. `world.object[1].radius`.
        key: String,
        /// What is wrong.
        reason: String,
    },
}

/// Shape of an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// An axis-aligned box with these full side lengths (x, y, z), metres.
    Box {
        /// Side lengths.
        size: Vec3,
    },
    /// A sphere.
    Sphere {
        /// Radius, metres.
        radius: f32,
    },
}

impl Shape {
    /// Half extents of the axis-aligned bounding box.
    pub fn half_extents(&self) -> Vec3 {
        match *self {
            Self::Box { size } => size * 0.5,
            Self::Sphere { radius } => Vec3::splat(radius),
        }
    }
}

/// One object of the room.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectConfig {
    /// Id (1..=999), reported as collider id and used by the *by id* commands.
    pub id: u32,
    /// Shape and size.
    pub shape: Shape,
    /// Centre, metres.
    pub position: Vec3,
    /// Colour.
    pub color: Rgb,
    /// Whether an agent can grasp (pick up) it.
    pub graspable: bool,
}

/// Where an agent starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgentStart {
    /// Agent id.
    pub id: u32,
    /// Position on the floor (x, z), metres.
    pub position: Vec2,
    /// Heading in degrees (0 = +z, 90 = +x).
    pub heading_deg: f32,
}

/// An action on an object that can earn a reward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GoalAction {
    /// Grasping the object.
    Grasp,
    /// Pointing at the object.
    Point,
    /// Interacting with the object.
    Interact,
}

/// What earns the reward of a goal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GoalKind {
    /// Entering a circle on the floor.
    Region {
        /// Centre (x, z), metres.
        center: Vec2,
        /// Radius, metres.
        radius: f32,
    },
    /// Doing `action` on object `object`.
    Object {
        /// Object id.
        object: u32,
        /// The action.
        action: GoalAction,
    },
}

/// A source of reward.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalConfig {
    /// What earns it.
    pub kind: GoalKind,
    /// Reward paid each time.
    pub reward: f32,
}

/// The validated `[world]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldConfig {
    /// Room width along x, metres (the room spans `-w/2..w/2`).
    pub room_width: f32,
    /// Room depth along z, metres.
    pub room_depth: f32,
    /// Wall height, metres.
    pub wall_height: f32,
    /// Walking speed, metres per simulated second.
    pub movement_speed: f32,
    /// Body turning speed, degrees per simulated second.
    pub turn_speed_deg: f32,
    /// Eye turning speed, degrees per simulated second.
    pub eye_speed_deg: f32,
    /// Longest accepted move, metres.
    pub max_move_distance: f32,
    /// Largest eye pan, degrees either way.
    pub max_pan_deg: f32,
    /// Largest eye tilt, degrees either way.
    pub max_tilt_deg: f32,
    /// Body radius, metres.
    pub agent_radius: f32,
    /// Body height, metres.
    pub body_height: f32,
    /// Eye height above the floor, metres.
    pub eye_height: f32,
    /// Distance between the eyes, metres.
    pub eye_separation: f32,
    /// Reach of grasp and interact, metres from the body's surface.
    pub reach_distance: f32,
    /// The two colours of the floor's 1 m checkerboard.
    pub floor_colors: [Rgb; 2],
    /// Wall colours: north (+z), east (+x), south (−z), west (−x).
    pub wall_colors: [Rgb; 4],
    /// Ceiling colour.
    pub ceiling_color: Rgb,
    /// Objects, in config order.
    pub objects: Vec<ObjectConfig>,
    /// Explicit start poses.
    pub agents: Vec<AgentStart>,
    /// Goals.
    pub goals: Vec<GoalConfig>,
}

impl Default for WorldConfig {
    /// The defaults documented in `config/default.toml`, with an empty room.
    fn default() -> Self {
        Self {
            room_width: 10.0,
            room_depth: 10.0,
            wall_height: 3.0,
            movement_speed: 3.0,
            turn_speed_deg: 180.0,
            eye_speed_deg: 300.0,
            max_move_distance: 50.0,
            max_pan_deg: 135.0,
            max_tilt_deg: 90.0,
            agent_radius: 0.3,
            body_height: 1.5,
            eye_height: 1.6,
            eye_separation: 0.065,
            reach_distance: 1.0,
            floor_colors: [[150, 150, 145], [120, 120, 118]],
            wall_colors: [
                [190, 200, 215],
                [215, 205, 180],
                [180, 210, 190],
                [205, 190, 210],
            ],
            ceiling_color: [235, 235, 235],
            objects: Vec::new(),
            agents: Vec::new(),
            goals: Vec::new(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorld {
    room_width: Option<f32>,
    room_depth: Option<f32>,
    wall_height: Option<f32>,
    movement_speed: Option<f32>,
    turn_speed_deg: Option<f32>,
    eye_speed_deg: Option<f32>,
    max_move_distance: Option<f32>,
    max_pan_deg: Option<f32>,
    max_tilt_deg: Option<f32>,
    agent_radius: Option<f32>,
    body_height: Option<f32>,
    eye_height: Option<f32>,
    eye_separation: Option<f32>,
    reach_distance: Option<f32>,
    floor_colors: Option<[Rgb; 2]>,
    wall_colors: Option<[Rgb; 4]>,
    ceiling_color: Option<Rgb>,
    #[serde(default)]
    object: Vec<toml::Value>,
    #[serde(default)]
    agent: Vec<toml::Value>,
    #[serde(default)]
    goal: Vec<toml::Value>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum RawShape {
    Box,
    Sphere,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    id: u32,
    shape: RawShape,
    position: [f32; 3],
    size: Option<[f32; 3]>,
    radius: Option<f32>,
    color: Rgb,
    #[serde(default)]
    graspable: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    id: u32,
    position: [f32; 2],
    #[serde(default)]
    heading_deg: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGoal {
    center: Option<[f32; 2]>,
    radius: Option<f32>,
    object: Option<u32>,
    action: Option<GoalAction>,
    reward: f32,
}

struct Ctx {
    path: PathBuf,
    /// The config's TOML text, to find the line of a key.
    text: Option<String>,
}

impl Ctx {
    fn err(&self, key: impl Into<String>, reason: impl Into<String>) -> WorldConfigError {
        let key = key.into();
        let reason = reason.into();
        let line = self.text.as_deref().map_or(0, |text| {
            // An unknown key: point at it rather than at its table.
            let unknown = reason
                .split_once("unknown field `")
                .and_then(|(_, rest)| rest.split_once('`'))
                .map(|(field, _)| format!("{key}.{field}"));
            match unknown.map(|k| locate(text, &k)) {
                Some((line, true)) => line,
                _ => locate(text, &key).0,
            }
        });
        WorldConfigError::Invalid {
            path: self.path.clone(),
            line,
            key,
            reason,
        }
    }

    /// Deserialises `value`, naming `key` (plus the nested key toml reports) on error.
    fn parse<T: DeserializeOwned>(
        &self,
        value: toml::Value,
        key: &str,
    ) -> Result<T, WorldConfigError> {
        value.try_into().map_err(|e: toml::de::Error| {
            let text = e.to_string();
            let mut inner = None;
            let mut reason = Vec::new();
            for line in text.lines() {
                match line.strip_prefix("in `").and_then(|l| l.strip_suffix('`')) {
                    Some(k) => inner = Some(k.to_string()),
                    None if !line.trim().is_empty() => reason.push(line.trim()),
                    None => {}
                }
            }
            let key = match inner {
                Some(k) => format!("{key}.{k}"),
                None => key.to_string(),
            };
            self.err(key, reason.join(" "))
        })
    }

    /// `value` if given and within `range`, else the default.
    fn num(
        &self,
        value: Option<f32>,
        default: f32,
        key: &str,
        min_exclusive: f32,
        max: f32,
    ) -> Result<f32, WorldConfigError> {
        let v = value.unwrap_or(default);
        if !v.is_finite() || v <= min_exclusive || v > max {
            return Err(self.err(
                format!("world.{key}"),
                format!("must be in ({min_exclusive}, {max}], found {v}"),
            ));
        }
        Ok(v)
    }
}

/// The 1-based line of dotted `key` (or of the deepest part of it found) in the file
/// `config` was loaded from; 0 if there is none.
pub fn line_in_source(config: &Config, key: &str) -> usize {
    std::fs::read_to_string(&config.source).map_or(0, |text| locate(&text, key).0)
}

/// Where dotted `key` (`world.object[1].radius`) is in TOML `text`: the 1-based line of the
/// deepest part of it found (0 if none), and whether all of it was found.
fn locate(text: &str, key: &str) -> (usize, bool) {
    use toml::de::{DeTable, DeValue};
    let Ok(root) = DeTable::parse(text) else {
        return (0, false);
    };
    let line_of = |span: core::ops::Range<usize>| {
        text[..span.start.min(text.len())].matches('\n').count() + 1
    };
    let mut table = root.get_ref();
    let mut line = 0;
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        let (name, indexes) = part
            .split_once('[')
            .map_or((part, ""), |(n, rest)| (n, rest));
        let Some((k, mut value)) = table.iter().find(|(k, _)| k.get_ref() == name) else {
            return (line, false);
        };
        line = line_of(k.span());
        for index in indexes.split('[') {
            let Some(i) = index
                .strip_suffix(']')
                .and_then(|i| i.parse::<usize>().ok())
            else {
                continue;
            };
            let DeValue::Array(items) = value.get_ref() else {
                return (line, false);
            };
            let Some(item) = items.get(i) else {
                return (line, false);
            };
            line = line_of(item.span());
            value = item;
        }
        if parts.peek().is_none() {
            return (line, true);
        }
        let DeValue::Table(t) = value.get_ref() else {
            return (line, false);
        };
        table = t;
    }
    (line, true)
}

fn finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl WorldConfig {
    /// Parses and validates the `[world]` section of `config` (defaults if it has none).
    ///
    /// # Errors
    /// [`WorldConfigError`] naming the file and the key.
    pub fn from_config(config: &Config) -> Result<Self, WorldConfigError> {
        // The text the config was loaded from, for line numbers (none for built-in configs).
        let text = std::fs::read_to_string(&config.source).ok();
        Self::from_config_text(config, text)
    }

    /// [`WorldConfig::from_config`] with the config's TOML text given (for line numbers).
    fn from_config_text(config: &Config, text: Option<String>) -> Result<Self, WorldConfigError> {
        let ctx = Ctx {
            path: config.source.clone(),
            text,
        };
        match &config.world {
            None => Ok(Self::default()),
            Some(table) => Self::from_table(table.clone(), &ctx),
        }
    }

    fn from_table(table: toml::Table, ctx: &Ctx) -> Result<Self, WorldConfigError> {
        let raw: RawWorld = ctx.parse(toml::Value::Table(table), "world")?;
        let d = Self::default();
        let mut w = Self {
            room_width: ctx.num(raw.room_width, d.room_width, "room_width", 0.5, 1000.0)?,
            room_depth: ctx.num(raw.room_depth, d.room_depth, "room_depth", 0.5, 1000.0)?,
            wall_height: ctx.num(raw.wall_height, d.wall_height, "wall_height", 0.5, 100.0)?,
            movement_speed: ctx.num(
                raw.movement_speed,
                d.movement_speed,
                "movement_speed",
                0.0,
                1000.0,
            )?,
            turn_speed_deg: ctx.num(
                raw.turn_speed_deg,
                d.turn_speed_deg,
                "turn_speed_deg",
                0.0,
                100_000.0,
            )?,
            eye_speed_deg: ctx.num(
                raw.eye_speed_deg,
                d.eye_speed_deg,
                "eye_speed_deg",
                0.0,
                100_000.0,
            )?,
            max_move_distance: ctx.num(
                raw.max_move_distance,
                d.max_move_distance,
                "max_move_distance",
                0.0,
                100_000.0,
            )?,
            max_pan_deg: ctx.num(raw.max_pan_deg, d.max_pan_deg, "max_pan_deg", 0.0, 180.0)?,
            max_tilt_deg: ctx.num(raw.max_tilt_deg, d.max_tilt_deg, "max_tilt_deg", 0.0, 90.0)?,
            agent_radius: ctx.num(raw.agent_radius, d.agent_radius, "agent_radius", 0.01, 10.0)?,
            body_height: ctx.num(raw.body_height, d.body_height, "body_height", 0.01, 100.0)?,
            eye_height: ctx.num(raw.eye_height, d.eye_height, "eye_height", 0.01, 100.0)?,
            eye_separation: ctx.num(
                raw.eye_separation,
                d.eye_separation,
                "eye_separation",
                0.0,
                10.0,
            )?,
            reach_distance: ctx.num(
                raw.reach_distance,
                d.reach_distance,
                "reach_distance",
                0.0,
                1000.0,
            )?,
            floor_colors: raw.floor_colors.unwrap_or(d.floor_colors),
            wall_colors: raw.wall_colors.unwrap_or(d.wall_colors),
            ceiling_color: raw.ceiling_color.unwrap_or(d.ceiling_color),
            objects: Vec::with_capacity(raw.object.len()),
            agents: Vec::with_capacity(raw.agent.len()),
            goals: Vec::with_capacity(raw.goal.len()),
        };
        if w.eye_height >= w.wall_height {
            return Err(ctx.err(
                "world.eye_height",
                format!(
                    "{} m is not below the walls ({} m high)",
                    w.eye_height, w.wall_height
                ),
            ));
        }
        if w.eye_separation / 2.0 >= w.agent_radius {
            return Err(ctx.err(
                "world.eye_separation",
                format!(
                    "half of it ({} m) must be less than agent_radius ({} m): the eyes stay inside the body",
                    w.eye_separation / 2.0,
                    w.agent_radius
                ),
            ));
        }
        for (i, v) in raw.object.into_iter().enumerate() {
            let object = w.object_from(ctx, i, v)?;
            w.objects.push(object);
        }
        for (i, v) in raw.agent.into_iter().enumerate() {
            let agent = w.agent_from(ctx, i, v)?;
            w.agents.push(agent);
        }
        for (i, v) in raw.goal.into_iter().enumerate() {
            let goal = w.goal_from(ctx, i, v)?;
            w.goals.push(goal);
        }
        Ok(w)
    }

    /// Object `i` of `[[world.object]]`, checked against the room and the objects before it.
    fn object_from(
        &self,
        ctx: &Ctx,
        i: usize,
        v: toml::Value,
    ) -> Result<ObjectConfig, WorldConfigError> {
        let (hw, hd) = (self.room_width / 2.0, self.room_depth / 2.0);
        let key = format!("world.object[{i}]");
        let o: RawObject = ctx.parse(v, &key)?;
        if !(1..=MAX_OBJECT_ID).contains(&o.id) {
            return Err(ctx.err(
                format!("{key}.id"),
                format!("must be 1..={MAX_OBJECT_ID}, found {}", o.id),
            ));
        }
        if self.objects.iter().any(|p| p.id == o.id) {
            return Err(ctx.err(format!("{key}.id"), format!("duplicate object id {}", o.id)));
        }
        let shape = match (o.shape, o.size, o.radius) {
            (RawShape::Box, Some(size), None) => {
                if !finite(&size) || size.iter().any(|&s| s <= 0.0) {
                    return Err(ctx.err(
                        format!("{key}.size"),
                        format!("sides must be positive, found {size:?}"),
                    ));
                }
                Shape::Box {
                    size: Vec3::from_array(size),
                }
            }
            (RawShape::Sphere, None, Some(radius)) => {
                if !(radius.is_finite() && radius > 0.0) {
                    return Err(ctx.err(
                        format!("{key}.radius"),
                        format!("must be positive, found {radius}"),
                    ));
                }
                Shape::Sphere { radius }
            }
            (RawShape::Box, _, _) => {
                return Err(ctx.err(
                    key,
                    "a box needs `size = [x, y, z]` and no `radius`".to_string(),
                ));
            }
            (RawShape::Sphere, _, _) => {
                return Err(ctx.err(key, "a sphere needs `radius` and no `size`".to_string()));
            }
        };
        let p = Vec3::from_array(o.position);
        let he = shape.half_extents();
        if !finite(&o.position)
            || p.x - he.x < -hw
            || p.x + he.x > hw
            || p.z - he.z < -hd
            || p.z + he.z > hd
            || p.y - he.y < 0.0
            || p.y + he.y > self.wall_height
        {
            return Err(ctx.err(
                format!("{key}.position"),
                format!(
                    "object {} at {:?} does not fit in the room",
                    o.id, o.position
                ),
            ));
        }
        Ok(ObjectConfig {
            id: o.id,
            shape,
            position: p,
            color: o.color,
            graspable: o.graspable,
        })
    }

    /// Agent start `i` of `[[world.agent]]`, checked against the starts before it.
    fn agent_from(
        &self,
        ctx: &Ctx,
        i: usize,
        v: toml::Value,
    ) -> Result<AgentStart, WorldConfigError> {
        let key = format!("world.agent[{i}]");
        let a: RawAgent = ctx.parse(v, &key)?;
        if self.agents.iter().any(|p| p.id == a.id) {
            return Err(ctx.err(format!("{key}.id"), format!("duplicate agent id {}", a.id)));
        }
        if !finite(&a.position) || !a.heading_deg.is_finite() {
            return Err(ctx.err(key, "position and heading must be finite"));
        }
        Ok(AgentStart {
            id: a.id,
            position: Vec2::from_array(a.position),
            heading_deg: a.heading_deg.rem_euclid(360.0),
        })
    }

    /// Goal `i` of `[[world.goal]]`, checked against the objects.
    fn goal_from(
        &self,
        ctx: &Ctx,
        i: usize,
        v: toml::Value,
    ) -> Result<GoalConfig, WorldConfigError> {
        let key = format!("world.goal[{i}]");
        let g: RawGoal = ctx.parse(v, &key)?;
        if !g.reward.is_finite() {
            return Err(ctx.err(format!("{key}.reward"), "must be finite"));
        }
        let kind = match (g.center, g.radius, g.object, g.action) {
            (Some(center), Some(radius), None, None) => {
                if !(finite(&center) && radius.is_finite() && radius > 0.0) {
                    return Err(ctx.err(
                        format!("{key}.radius"),
                        format!("must be positive, found {radius}"),
                    ));
                }
                GoalKind::Region {
                    center: Vec2::from_array(center),
                    radius,
                }
            }
            (None, None, Some(object), Some(action)) => {
                if !self.objects.iter().any(|o| o.id == object) {
                    return Err(ctx.err(
                        format!("{key}.object"),
                        format!("no object with id {object}"),
                    ));
                }
                GoalKind::Object { object, action }
            }
            _ => {
                return Err(ctx.err(
                    key,
                    "give either `center` and `radius` (a region) or `object` and `action` \
                     (grasp, point or interact)",
                ));
            }
        };
        Ok(GoalConfig {
            kind,
            reward: g.reward,
        })
    }

    /// The explicit start of agent `id`, if configured.
    pub fn start_of(&self, id: u32) -> Option<&AgentStart> {
        self.agents.iter().find(|a| a.id == id)
    }
}

#[cfg(test)]
mod tests;
