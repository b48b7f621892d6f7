//! Reading an agent connection: its frames (stop, commands), keep-alives, and dropping
//! it.

use super::*;

impl LegacyHost {
    pub(super) fn drop_conn(s: &mut Slot, why: &str) {
        if let Some(c) = s.conn.take() {
            warn!(agent = s.id, peer = %c.peer, "legacy agent dropped: {why}");
        }
        s.open = false;
        s.batch.clear();
        s.batch_stop = false;
        s.queued.clear();
        s.queued_stop = None;
    }

    /// Queues a command for the agent's open cycle, or the next one.
    pub(super) fn queue_command(s: &mut Slot, cmd: MotorCommand, sync: bool) {
        if s.open || !sync {
            s.batch.push(cmd);
            s.in_cycle += 1;
        } else {
            s.queued.push(cmd);
        }
    }

    /// Applies one decoded frame of agent slot `s`: a stop ends its cycle, a command is
    /// queued and acknowledged in `acks`, a reset queued, a version check answered.
    pub(super) fn apply_frame(
        stats: &mut LegacyStats,
        s: &mut Slot,
        acks: &mut Vec<u8>,
        dialect: Dialect,
        incoming: Incoming,
        sync: bool,
        max_commands: usize,
    ) {
        match incoming {
            Incoming::Stop => Self::apply_stop(stats, s, sync),
            Incoming::Command { action_id, command } => {
                Self::apply_command(stats, s, acks, action_id, command, sync, max_commands);
            }
            Incoming::Reset(cmd) => {
                Self::queue_command(s, cmd.encode(RESET_ACTION_ID), sync);
            }
            Incoming::VersionCheck(_) => {
                codec::push_message(
                    acks,
                    dialect.version_check_field(),
                    &VersionCheck {
                        version: Some(VERSION.into()),
                    },
                );
            }
            Incoming::Ignored(what) => {
                debug!(agent = s.id, "legacy {what} ignored");
            }
        }
    }

    /// A stop: it ends the open cycle, or the next one if none is open (the wire carries
    /// no cycle number), once; async mode ignores stops.
    pub(super) fn apply_stop(stats: &mut LegacyStats, s: &mut Slot, sync: bool) {
        if !sync {
            // Async mode: stops are accepted and ignored.
        } else if s.open {
            s.batch_stop = true;
            s.open = false;
        } else if s.queued_stop.is_none() {
            s.queued_stop = Some(s.queued.len());
            stats.stops_without_cycle += 1;
            debug!(
                agent = s.id,
                "legacy stop while no cycle is open: it ends the next one"
            );
        } else {
            stats.stops_ignored += 1;
            debug!(
                agent = s.id,
                "legacy stop ignored: one is waiting for the next cycle already"
            );
        }
    }

    /// A command: acknowledged at once and queued, or answered Aborted when it is invalid
    /// or over `max_commands` in its cycle.
    pub(super) fn apply_command(
        stats: &mut LegacyStats,
        s: &mut Slot,
        acks: &mut Vec<u8>,
        action_id: u32,
        command: Command,
        sync: bool,
        max_commands: usize,
    ) {
        let ack = match command {
            Command::Turn { .. } => ActionState::Rotating,
            Command::Move { .. } | Command::MoveTo { .. } => ActionState::Walking,
            _ => ActionState::InExecution,
        };
        let wire = command.encode(action_id);
        let in_cycle = if s.open || !sync {
            s.in_cycle
        } else {
            s.queued.len() - s.queued_stop.unwrap_or(0)
        };
        let refused = if let Err(e) = wire.decode() {
            Some(e.to_string())
        } else if in_cycle >= max_commands {
            Some(format!(
                "more than max_commands_per_cycle = {max_commands} in one cycle"
            ))
        } else {
            None
        };
        if let Some(why) = refused {
            stats.commands_refused += 1;
            if stats.commands_refused.is_power_of_two() {
                warn!(
                    agent = s.id,
                    action_id,
                    total = stats.commands_refused,
                    "legacy command answered Aborted: {why}"
                );
            }
            push_status(acks, action_id, ActionState::Aborted);
        } else {
            push_status(acks, action_id, ack);
            Self::queue_command(s, wire, sync);
        }
    }

    pub(super) fn read_agent(&mut self, i: usize) {
        let sync = self.sync_mode;
        let max_commands = self.max_commands;
        let stall_timeout = self.stall_timeout;
        let s = &mut self.slots[i];
        // Taken out while its frames are applied to the slot; put back unless dropped.
        let Some(mut conn) = s.conn.take() else {
            return;
        };
        let c = &mut conn;
        let mut acks = std::mem::take(&mut s.out);
        acks.clear();
        let mut drop_why = None;
        for _ in 0..MAX_FRAMES_PER_PASS {
            match c.reader.read_from(&mut c.stream) {
                Ok(FrameProgress::Frame) => {
                    c.partial_since = None;
                    match codec::decode_frame(c.reader.body(), c.dialect) {
                        Ok(incoming) => Self::apply_frame(
                            &mut self.stats,
                            s,
                            &mut acks,
                            c.dialect,
                            incoming,
                            sync,
                            max_commands,
                        ),
                        Err(e) => {
                            self.stats.frames_refused += 1;
                            warn!(agent = s.id, peer = %c.peer, "legacy frame refused, nothing of it applied: {e}");
                        }
                    }
                }
                Ok(FrameProgress::Skipped(n)) => {
                    self.stats.frames_refused += 1;
                    warn!(agent = s.id, peer = %c.peer, "legacy frame of {n} bytes skipped unread: longer than {MAX_INCOMING_FRAME}");
                }
                Ok(FrameProgress::Pending) => {
                    if c.reader.mid_frame() {
                        let now = Instant::now();
                        let since = *c.partial_since.get_or_insert(now);
                        if now.duration_since(since) >= stall_timeout {
                            drop_why = Some(format!(
                                "stalled mid-frame: {} within {}",
                                c.reader.progress(),
                                Rounded(stall_timeout)
                            ));
                        }
                    }
                    break;
                }
                Ok(FrameProgress::Closed) if c.reader.mid_frame() => {
                    drop_why = Some(format!(
                        "connection closed mid-frame after {} (truncated frame not applied)",
                        c.reader.progress()
                    ));
                    break;
                }
                Ok(FrameProgress::Closed) => {
                    drop_why = Some("connection closed".into());
                    break;
                }
                Err(e) => {
                    drop_why = Some(e.to_string());
                    break;
                }
            }
        }
        if drop_why.is_none() && !acks.is_empty() {
            let deadline = Instant::now() + self.write_timeout;
            match send_all(&mut c.stream, &acks, deadline) {
                Ok(()) => c.last_write = Instant::now(),
                Err(e) => drop_why = Some(format!("cannot send statuses: {e}")),
            }
        }
        s.out = acks;
        s.conn = Some(conn);
        if let Some(why) = drop_why {
            Self::drop_conn(s, &why);
        }
    }

    pub(super) fn keepalive(&mut self, i: usize) {
        let s = &mut self.slots[i];
        let Some(c) = &mut s.conn else {
            return;
        };
        if c.last_write.elapsed() < KEEPALIVE_PERIOD {
            return;
        }
        let mut out = std::mem::take(&mut s.out);
        out.clear();
        codec::push_debug(&mut out, "vrsync keep-alive");
        let r = send_all(&mut c.stream, &out, Instant::now() + self.write_timeout);
        s.out = out;
        match r {
            Ok(()) => c.last_write = Instant::now(),
            Err(e) => Self::drop_conn(s, &format!("cannot send a keep-alive: {e}")),
        }
    }
}
