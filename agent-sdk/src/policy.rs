//! Example policies of `vr-agent`. Deterministic: every decision depends only on the seed,
//! the agent id and the frames received, never on time, so a run is reproducible.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vrsync_bridge::wire::{ActionState, Command};

use crate::Frame;

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
}

/// A policy instance.
#[derive(Debug)]
pub struct Policy {
    kind: PolicyKind,
    rng: ChaCha8Rng,
    running: Option<u32>,
    cycles_in_action: u32,
    heading_deg: f32,
}

/// What the policy wants to send this cycle (at most two commands).
pub type Decision = heapless_pair::Pair;

mod heapless_pair {
    use vrsync_bridge::wire::Command;

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

/// Moves that take longer than this many cycles are given up and re-decided.
const MAX_CYCLES_PER_ACTION: u32 = 60;

impl Policy {
    /// A policy seeded from `seed` and the agent id.
    pub fn new(kind: PolicyKind, seed: u64, agent_id: u32) -> Self {
        Self {
            kind,
            rng: ChaCha8Rng::seed_from_u64(
                seed ^ (u64::from(agent_id) + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ),
            running: None,
            cycles_in_action: 0,
            heading_deg: 0.0,
        }
    }

    /// Tells the policy which action id its last command got.
    pub fn started(&mut self, action_id: u32) {
        self.running = Some(action_id);
        self.cycles_in_action = 0;
    }

    /// Decides on this frame.
    pub fn decide(&mut self, frame: &Frame) -> Decision {
        let mut out = Decision::default();
        match self.kind {
            PolicyKind::Idle => return out,
            PolicyKind::Circle => {
                out.push(Command::Move {
                    heading_deg: (frame.cycle() % 360 * 7 % 360) as f32,
                    distance: 0.05,
                });
                return out;
            }
            PolicyKind::Wander => {}
        }
        let h = frame.header();
        let yaw = frame.pose().rotation().to_euler(glam::EulerRot::YXZ).0;
        self.heading_deg = yaw.to_degrees().rem_euclid(360.0);
        let collided = self
            .running
            .is_some_and(|id| h.collisions().iter().any(|c| c.action_id == id));
        let finished = self.running.is_none_or(|id| {
            h.statuses().iter().any(|s| {
                s.action_id == id
                    && matches!(
                        ActionState::from_u32(s.state),
                        Some(ActionState::Finished | ActionState::Aborted)
                    )
            })
        });
        self.cycles_in_action += 1;
        if collided {
            let away = self.heading_deg + 180.0 + self.rng.random_range(-45.0f32..45.0);
            out.push(Command::Move {
                heading_deg: away.rem_euclid(360.0),
                distance: self.rng.random_range(0.5f32..1.5),
            });
        } else if finished || self.cycles_in_action > MAX_CYCLES_PER_ACTION {
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
}
