//! Example policies of `vr-agent`. Deterministic: every decision depends only on the seed,
//! the agent id and the frames received, never on time, so a run is reproducible.
//!
//! `wander` and `seek` run one action at a time: after a command they wait for its
//! `Finished`/`Aborted` status (or a collision) in a later frame ([`Frame::statuses`]:
//! each status once, also after skipped frames) before they send the next. A host that reports no statuses gets the next command only once
//! [`STATUS_WAIT_CYCLES`] cycles have passed without one (`seek`'s search turns give up after
//! [`SEEK_SEARCH_WAIT_CYCLES`]). `circle` sends every cycle, `idle` never.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vrsync_transport::{ActionState, ActionStatus, Collision, Command, PixelFormat, SensorHeader};

use vrsync_agent::{Frame, Image};

/// Which policy `vr-agent` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PolicyKind {
    /// Send nothing, just stop every cycle.
    Idle,
    /// Walk in random directions; turn away after a collision.
    Wander,
    /// Send one short move every cycle, heading advancing 7° per cycle (a steady stream of
    /// commands, for load and protocol tests).
    Circle,
    /// Find the red object with the eyes and walk to it: tilt the eyes down, look for red
    /// pixels in the left and right images, turn towards them, walk, stop near it. Turns
    /// on the spot while nothing red is seen; steps aside after bumping into something
    /// else.
    Seek,
}

/// A policy instance.
#[derive(Debug)]
pub struct Policy {
    kind: PolicyKind,
    rng: ChaCha8Rng,
    running: Option<u32>,
    /// Cycle of the newest frame decided on.
    cycle: u64,
    /// Cycle of the frame on which the running action was decided.
    action_cycle: u64,
    heading_deg: f32,
    seek: SeekState,
}

/// What `seek` remembers between frames.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct SeekState {
    /// The eyes were tilted down.
    eyes_set: bool,
    /// Stopped near the target.
    arrived: bool,
    /// Cycles left of a detour around an obstacle.
    detour_cycles: u32,
    /// Direction of the search turn (+1 clockwise, -1 counter-clockwise).
    search_sign: f32,
}

/// Eye tilt `seek` uses so that the target stays in view up close, degrees.
pub const SEEK_TILT_DEG: f32 = -25.0;
/// Fraction of red pixels at which `seek` considers itself arrived.
pub const SEEK_NEAR_FRACTION: f32 = 0.06;
/// Half the horizontal field of view `seek` assumes (the default 120° cameras), degrees.
const SEEK_HALF_FOV_DEG: f32 = 60.0;

/// Red pixels found in an image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RedBlob {
    /// Number of red pixels.
    pub count: u32,
    /// Their fraction of all pixels.
    pub fraction: f32,
    /// Mean column, -1 (left edge) to 1 (right edge).
    pub center_x: f32,
}

/// Finds red pixels (`r > 90`, `r > 2g`, `r > 2b`) in raw `rgb8`/`rgba8` pixels, `stride`
/// bytes per row. `None` when there are none or the format has no colour.
pub fn find_red(
    data: &[u8],
    width: u32,
    height: u32,
    stride: usize,
    format: PixelFormat,
) -> Option<RedBlob> {
    let bpp = match format {
        PixelFormat::Rgb8 => 3,
        PixelFormat::Rgba8 => 4,
        PixelFormat::Gray8 | PixelFormat::Depth32f => return None,
    };
    let (mut count, mut sum_x) = (0u32, 0u64);
    for row in data.chunks_exact(stride).take(height as usize) {
        for (x, px) in row.chunks_exact(bpp).take(width as usize).enumerate() {
            let (r, g, b) = (u16::from(px[0]), u16::from(px[1]), u16::from(px[2]));
            if r > 90 && r > 2 * g && r > 2 * b {
                count += 1;
                sum_x += x as u64;
            }
        }
    }
    (count > 0).then(|| RedBlob {
        count,
        fraction: count as f32 / (width as f32 * height as f32),
        center_x: ((sum_x as f32 / count as f32 + 0.5) / width as f32) * 2.0 - 1.0,
    })
}

fn red_in(image: Option<Image<'_>>) -> Option<RedBlob> {
    let i = image?;
    find_red(i.data(), i.width(), i.height(), i.stride(), i.format())
}

/// The events a frame brings (each once).
#[derive(Debug, Clone, Copy)]
struct Events<'a> {
    statuses: &'a [ActionStatus],
    collisions: &'a [Collision],
}

/// What the policy wants to send this cycle (at most two commands).
pub type Decision = heapless_pair::Pair;

mod heapless_pair {
    use vrsync_transport::Command;

    /// Up to two commands, without allocating.
    #[derive(Debug, Clone, Copy, Default, PartialEq)]
    pub struct Pair {
        items: [Option<Command>; 2],
    }

    impl Pair {
        pub(crate) fn push(&mut self, c: Command) {
            if let Some(slot) = self.items.iter_mut().find(|s| s.is_none()) {
                *slot = Some(c);
            }
        }
        /// The commands, in order.
        pub fn iter(&self) -> impl Iterator<Item = Command> + '_ {
            self.items.iter().flatten().copied()
        }
    }
}

/// How many cycles `wander` waits for its action's `Finished`/`Aborted` status before it
/// decides anew (the fallback for a host that reports no statuses, or whose status the agent
/// missed). 30 cycles are 3 s of simulated time at the default 0.1 s per cycle: over 4 times
/// the longest `wander` action in vr-sim's default world (a 2 m walk at 3 m/s, or a 90° turn
/// at 180°/s), so with a host that reports statuses the fallback does not cut actions short.
pub const STATUS_WAIT_CYCLES: u64 = 30;

/// How many cycles a search turn of `seek` (45°) waits for its status before the next one.
pub const SEEK_SEARCH_WAIT_CYCLES: u64 = 20;

impl Policy {
    /// A policy seeded from `seed` and the agent id.
    pub fn new(kind: PolicyKind, seed: u64, agent_id: u32) -> Self {
        Self {
            kind,
            rng: ChaCha8Rng::seed_from_u64(
                seed ^ (u64::from(agent_id) + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ),
            running: None,
            cycle: 0,
            action_cycle: 0,
            heading_deg: 0.0,
            seek: SeekState {
                search_sign: if agent_id.is_multiple_of(2) {
                    1.0
                } else {
                    -1.0
                },
                ..SeekState::default()
            },
        }
    }

    /// Tells the policy which action id its last command got.
    pub fn started(&mut self, action_id: u32) {
        self.running = Some(action_id);
        self.action_cycle = self.cycle;
    }

    /// Decides on this frame.
    pub fn decide(&mut self, frame: &Frame) -> Decision {
        let events = Events {
            statuses: frame.statuses(),
            collisions: frame.collisions(),
        };
        self.decide_on(frame.header(), events, Some(frame))
    }

    /// Decides on a frame's header and the events it brings; `frame` gives `seek` its
    /// images (`None`: sees nothing).
    fn decide_on(
        &mut self,
        h: &SensorHeader,
        events: Events<'_>,
        frame: Option<&Frame>,
    ) -> Decision {
        let mut out = Decision::default();
        self.cycle = h.cycle;
        match self.kind {
            PolicyKind::Idle => return out,
            PolicyKind::Circle => {
                out.push(Command::Move {
                    heading_deg: (h.cycle % 360 * 7 % 360) as f32,
                    distance: 0.05,
                });
                return out;
            }
            PolicyKind::Wander | PolicyKind::Seek => {}
        }
        let yaw = h
            .pose
            .rotation()
            .to_euler(vrsync_agent::glam::EulerRot::YXZ)
            .0;
        self.heading_deg = yaw.to_degrees().rem_euclid(360.0);
        let collided = self
            .running
            .is_some_and(|id| events.collisions.iter().any(|c| c.action_id == id));
        let finished = self.running.is_none_or(|id| {
            events.statuses.iter().any(|s| {
                s.action_id == id
                    && matches!(
                        ActionState::from_u32(s.state),
                        Some(ActionState::Finished | ActionState::Aborted)
                    )
            })
        });
        // Frames skipped (a late or stalled agent) count: the wait is in cycles of the host.
        let waited = h.cycle.saturating_sub(self.action_cycle);
        if self.kind == PolicyKind::Seek {
            self.seek(frame, collided, finished, waited, &mut out);
            return out;
        }
        if collided {
            let away = self.heading_deg + 180.0 + self.rng.random_range(-45.0f32..45.0);
            out.push(Command::Move {
                heading_deg: away.rem_euclid(360.0),
                distance: self.rng.random_range(0.5f32..1.5),
            });
        } else if finished || waited >= STATUS_WAIT_CYCLES {
            if self.rng.random_bool(0.75) {
                let heading = self.heading_deg + self.rng.random_range(-60.0f32..60.0);
                out.push(Command::Move {
                    heading_deg: heading.rem_euclid(360.0),
                    distance: self.rng.random_range(0.5f32..2.0),
                });
            } else {
                out.push(Command::Turn {
                    angle_deg: self.rng.random_range(-90.0f32..90.0),
                });
            }
        }
        out
    }

    /// One step of `seek`: a perception loop over the zero-copy left/right images.
    fn seek(
        &mut self,
        frame: Option<&Frame>,
        collided: bool,
        finished: bool,
        waited: u64,
        out: &mut Decision,
    ) {
        if !self.seek.eyes_set {
            self.seek.eyes_set = true;
            out.push(Command::EyeMovement {
                pan_left_deg: 0.0,
                pan_right_deg: 0.0,
                tilt_deg: SEEK_TILT_DEG,
            });
        }
        let image = |name: &str| frame.and_then(|f| f.image_by_name(name));
        let mut blobs = [red_in(image("left")), red_in(image("right"))];
        if blobs.iter().all(Option::is_none) && image("left").is_none() {
            blobs[0] = red_in(frame.and_then(|f| f.image(0)));
        }
        let seen: Vec<RedBlob> = blobs.into_iter().flatten().collect();
        if self.seek.detour_cycles > 0 {
            self.seek.detour_cycles -= 1;
            if !finished && !collided {
                return;
            }
        }
        if seen.is_empty() {
            self.seek.arrived = false;
            // Search: turn on the spot, a bit less than the field of view at a time.
            if finished || collided || waited >= SEEK_SEARCH_WAIT_CYCLES {
                out.push(Command::Turn {
                    angle_deg: 45.0 * self.seek.search_sign,
                });
            }
            return;
        }
        let n = seen.len() as f32;
        let center_x = seen.iter().map(|b| b.center_x).sum::<f32>() / n;
        let fraction = seen.iter().map(|b| b.fraction).fold(0.0f32, f32::max);
        let bearing_deg = (center_x * SEEK_HALF_FOV_DEG.to_radians().tan())
            .atan()
            .to_degrees();
        let near = fraction >= SEEK_NEAR_FRACTION
            || (collided && bearing_deg.abs() < 20.0 && fraction >= SEEK_NEAR_FRACTION / 3.0);
        if near {
            if !self.seek.arrived {
                self.seek.arrived = true;
                out.push(Command::CancelMove);
            }
            return;
        }
        if self.seek.arrived && fraction >= SEEK_NEAR_FRACTION / 2.0 {
            return; // still close enough: no dithering at the threshold
        }
        self.seek.arrived = false;
        if collided {
            // Bumped into something that is not the target: step aside, then look again.
            let side = if bearing_deg >= 0.0 { -90.0 } else { 90.0 };
            out.push(Command::Move {
                heading_deg: (self.heading_deg + side).rem_euclid(360.0),
                distance: 0.8,
            });
            self.seek.detour_cycles = 6;
        } else if bearing_deg.abs() > 12.0 {
            out.push(Command::Turn {
                angle_deg: bearing_deg,
            });
        } else {
            out.push(Command::Move {
                heading_deg: (self.heading_deg + bearing_deg).rem_euclid(360.0),
                distance: 0.6,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: u32, height: u32, red: &[(u32, u32)]) -> Vec<u8> {
        let mut data = vec![128u8; (width * height * 3) as usize];
        for &(x, y) in red {
            let i = ((y * width + x) * 3) as usize;
            data[i..i + 3].copy_from_slice(&[200, 20, 30]);
        }
        data
    }

    #[test]
    fn finds_red_pixels_and_their_side() {
        let data = image(10, 4, &[(8, 1), (9, 1), (8, 2), (9, 2)]);
        let blob = find_red(&data, 10, 4, 30, PixelFormat::Rgb8).unwrap();
        assert_eq!(blob.count, 4);
        assert!((blob.fraction - 0.1).abs() < 1e-6);
        assert!((blob.center_x - 0.8).abs() < 1e-6, "{}", blob.center_x);
        let data = image(10, 4, &[(0, 0)]);
        assert!(
            find_red(&data, 10, 4, 30, PixelFormat::Rgb8)
                .unwrap()
                .center_x
                < -0.8
        );
        assert!(find_red(&image(10, 4, &[]), 10, 4, 30, PixelFormat::Rgb8).is_none());
        assert!(find_red(&data, 10, 4, 30, PixelFormat::Gray8).is_none());
    }

    /// A header of `cycle` facing along +z.
    fn header(cycle: u64) -> SensorHeader {
        let mut h = SensorHeader {
            cycle,
            ..SensorHeader::default()
        };
        h.pose.rotation = [0.0, 0.0, 0.0, 1.0];
        h
    }

    fn events(h: &SensorHeader) -> Events<'_> {
        Events {
            statuses: h.statuses(),
            collisions: h.collisions(),
        }
    }

    /// Runs `policy` over `cycles` frames from a host that reports no statuses, and returns
    /// the cycles on which it sent a command.
    fn commands_without_statuses(policy: &mut Policy, cycles: std::ops::Range<u64>) -> Vec<u64> {
        let mut sent = Vec::new();
        for (action_id, cycle) in (1..).zip(cycles) {
            if policy
                .decide_on(&header(cycle), events(&header(cycle)), None)
                .iter()
                .next()
                .is_some()
            {
                policy.started(action_id);
                sent.push(cycle);
            }
        }
        sent
    }

    #[test]
    fn wander_without_statuses_sends_its_next_command_after_the_bound() {
        let mut wander = Policy::new(PolicyKind::Wander, 7, 0);
        let sent = commands_without_statuses(&mut wander, 0..100);
        let bound = STATUS_WAIT_CYCLES;
        assert_eq!(sent, [0, bound, 2 * bound, 3 * bound], "{sent:?}");
    }

    #[test]
    fn wander_bound_counts_cycles_the_agent_skipped() {
        let mut wander = Policy::new(PolicyKind::Wander, 7, 0);
        assert_eq!(commands_without_statuses(&mut wander, 0..1), [0]);
        // A stalled agent sees cycle 1, then cycle 1 + STATUS_WAIT_CYCLES.
        assert!(
            wander
                .decide_on(&header(1), events(&header(1)), None)
                .iter()
                .next()
                .is_none()
        );
        let late = header(STATUS_WAIT_CYCLES);
        assert!(
            wander
                .decide_on(&late, events(&late), None)
                .iter()
                .next()
                .is_some()
        );
    }

    #[test]
    fn wander_sends_its_next_command_on_the_finished_status() {
        let mut wander = Policy::new(PolicyKind::Wander, 7, 0);
        assert_eq!(commands_without_statuses(&mut wander, 0..1), [0]);
        assert!(
            wander
                .decide_on(&header(1), events(&header(1)), None)
                .iter()
                .next()
                .is_none()
        );
        let mut h = header(2);
        h.push_status(1, ActionState::Finished);
        assert!(
            wander
                .decide_on(&h, events(&h), None)
                .iter()
                .next()
                .is_some()
        );
    }

    #[test]
    fn seek_without_statuses_turns_again_after_its_search_bound() {
        let mut seek = Policy::new(PolicyKind::Seek, 7, 0);
        let sent = commands_without_statuses(&mut seek, 0..50);
        let bound = SEEK_SEARCH_WAIT_CYCLES;
        assert_eq!(sent, [0, bound, 2 * bound], "{sent:?}");
    }

    #[test]
    fn orange_grey_and_dark_pixels_are_not_red() {
        let mut data = vec![0u8; 12];
        data[..3].copy_from_slice(&[255, 140, 0]); // orange
        data[3..6].copy_from_slice(&[200, 200, 200]); // grey
        data[6..9].copy_from_slice(&[60, 5, 5]); // too dark
        data[9..12].copy_from_slice(&[140, 95, 55]); // brown
        assert!(find_red(&data, 4, 1, 12, PixelFormat::Rgb8).is_none());
    }
}
