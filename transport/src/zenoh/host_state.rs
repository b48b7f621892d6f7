//! The zenoh host's state shared with zenoh's callback threads, and those callbacks: the
//! hello queryable (admission), the agents' liveliness tokens, their motor batches.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::query::Query;
use ::zenoh::sample::{Sample, SampleKind};
use tracing::{debug, info, warn};

use super::super::record::{Hello, Reject, admit, decode_hello, reject};
use super::super::{PeerRefusal, RefusalKind, Refusals};
use super::*;
use crate::wire::{MotorHeader, SensorHeader};

pub(super) const HEADER: usize = core::mem::size_of::<SensorHeader>();
pub(super) const MOTOR_HEADER: usize = core::mem::size_of::<MotorHeader>();

/// What the zenoh host dropped or refused, by reason (each is also logged).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct ZenohHostStats {
    /// Hellos refused: wrong version or layout.
    pub refused_version: u64,
    /// Hellos refused: missing or wrong token.
    pub refused_token: u64,
    /// Hellos refused: the agent id is not part of the session.
    pub refused_unknown_agent: u64,
    /// Hellos refused: the agent id is connected already.
    pub refused_id_in_use: u64,
    /// Hellos refused: the agent's channels differ from the host's config.
    pub refused_channels: u64,
    /// Hellos refused: not a hello (garbage, too long, truncated).
    pub refused_malformed: u64,
    /// Peers dropped in the TLS handshake (counted when the process's `tracing`
    /// subscriber has [`super::tls_refusal_layer`]).
    pub refused_tls: u64,
    /// Batches dropped: too long, or not a header plus its commands, or naming another agent.
    pub dropped_malformed: u64,
    /// Batches dropped: from an agent id that is not connected.
    pub dropped_not_connected: u64,
    /// Batches dropped: more than [`MAX_QUEUED_BATCHES`] waiting (a flood).
    pub dropped_flood: u64,
    /// Liveliness tokens ignored: no welcome with that nonce.
    pub ignored_tokens: u64,
    /// Frames sent, for the log at close.
    pub frames_sent: u64,
    /// Agents held after a lost link and back within the resume window.
    pub resumes: u64,
}
use crate::rounded::Rounded;
use crate::wire::{LAYOUT_HASH, PROTOCOL_VERSION};
use vrsync_protocol::channel_layout::ChannelLayout;

/// How long after an agent's token vanished its leave batch is still taken (the two travel
/// on different zenoh channels, so the deletion may overtake the batch).
pub(super) const LEAVE_AFTER_TOKEN: Duration = Duration::from_secs(2);

/// How long a connection that ended without a leave batch (its token vanished, or its
/// sensor subscriber went) still counts as connected for the host: an agent that leaves
/// sends its leave batch and then closes its session, and the token's deletion or the
/// subscriber's end, on other zenoh channels, may overtake the batch. Reporting the agent
/// lost at once would make a graceful leave look like a crash (the host evicts it, and
/// with nobody attached stops cycling before the batch is read); within this grace the
/// batch is taken as the leave it is. A crashed agent is seen lost this much later.
pub(super) const LOSS_GRACE: Duration = Duration::from_secs(1);

/// With a resume window, how long the host holds the place of an agent whose connection
/// closed while it was heard from (at least; the lease if longer, at most the window): its
/// process may have ended, or its side declared the link lost first (a link that stalls
/// one way: the agent then connects again at once). A leave batch racing the close still
/// frees the place at once.
pub(super) const CLOSED_GRACE: Duration = Duration::from_secs(2);

/// A slot held for its agent's return after its link was lost (`[sync] resume_window`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Held {
    /// When the host saw the link go.
    pub(super) since: Instant,
    /// When the slot is let go (the host then evicts the agent).
    pub(super) until: Instant,
}

#[derive(Debug)]
pub(super) struct SlotState {
    pub(super) id: u32,
    /// The nonce of the last welcome and when it was sent.
    pub(super) admitted: Option<(u64, Instant)>,
    /// The token of the admitted nonce exists.
    pub(super) alive: bool,
    /// The sensor publisher matches a subscriber.
    pub(super) matched: bool,
    pub(super) queue: VecDeque<AlignedBuf>,
    /// A leave batch waits in `queue`: a token deletion keeps the queue for the host.
    pub(super) leave_queued: bool,
    /// When the admitted connection's token vanished: its leave batch, racing the deletion
    /// on another zenoh channel, is still taken for [`LEAVE_AFTER_TOKEN`].
    pub(super) gone_at: Option<Instant>,
    /// When the connection stopped being connected without a leave batch (token deleted,
    /// subscriber gone); cleared by a leave batch or a new admission. See [`LOSS_GRACE`].
    pub(super) lost_at: Option<Instant>,
    /// Its link was lost (nothing heard from the agent for at least half the lease when its
    /// token vanished: zenoh's lease ran out, the process did not end): the slot is held
    /// for its return and counts as connected meanwhile.
    pub(super) held: Option<Held>,
    /// When the host last heard from the admitted connection: its welcome, a batch, a
    /// beat (`agent/<id>/beat`, every lease / 4).
    pub(super) heard: Instant,
    /// The cycle of the frame the host published last to this slot.
    pub(super) published: Option<u64>,
    /// The newest cycle whose stop batch arrived from this agent.
    pub(super) stopped: Option<u64>,
    /// Back within the resume window: the frame published last goes out again (by the
    /// host's thread) unless its stop arrived.
    pub(super) resend_due: bool,
    /// The admitted connection confirmed the host's `host/closed` ([`CLOSED_BEAT`]).
    pub(super) saw_close: bool,
}

impl SlotState {
    pub(super) fn connected(&self) -> bool {
        self.admitted.is_some() && self.alive && self.matched
    }

    /// Connected, with a leave batch the host has not drained yet (it learns of the leave
    /// from the batch, in its cycle report; seen disconnected before, the leave would be
    /// reported as a loss), or lost without a leave less than [`LOSS_GRACE`] ago: what the
    /// host sees.
    pub(super) fn connected_for_host(&self) -> bool {
        self.connected()
            || self.leave_queued
            || self.lost_at.is_some_and(|t| t.elapsed() < LOSS_GRACE)
            || self.held.is_some_and(|h| Instant::now() < h.until)
    }

    /// A slot just created for agent `id`: nobody connected.
    pub(super) fn new(id: u32) -> Self {
        Self {
            id,
            admitted: None,
            alive: false,
            matched: false,
            queue: VecDeque::with_capacity(MAX_QUEUED_BATCHES),
            leave_queued: false,
            gone_at: None,
            lost_at: None,
            held: None,
            heard: Instant::now(),
            published: None,
            stopped: None,
            resend_due: false,
            saw_close: false,
        }
    }

    /// Records that a connection ends now without a leave batch (if it was connected).
    /// Without a resume window it is lost after [`LOSS_GRACE`] (its leave batch may still
    /// come). With one (`window`), the slot is held for the agent's return: for the window
    /// when nothing was heard from the agent for at least half its `lease` (zenoh's lease
    /// ran out: its link was lost, its process may well live); otherwise (its connection
    /// closed while it beat: its process ended, or its side declared the link lost first)
    /// for [`CLOSED_GRACE`] or the lease, whichever is longer, and its leave batch is
    /// still taken meanwhile.
    pub(super) fn lose(&mut self, was_connected: bool, window: Duration, lease: Duration) {
        if !was_connected || self.leave_queued || self.held.is_some() {
            return;
        }
        let now = Instant::now();
        if window.is_zero() {
            self.lost_at = Some(now);
            return;
        }
        let silent = now.duration_since(self.heard);
        let hold = if silent >= lease / 2 {
            warn!(
                agent = self.id,
                "zenoh agent's link lost (nothing heard for {}); its place is held for {} \
                 (sync.resume_window)",
                Rounded(silent),
                Rounded(window)
            );
            window
        } else {
            let hold = window.min(lease.max(CLOSED_GRACE));
            warn!(
                agent = self.id,
                "zenoh agent's connection closed (its process ended, or its side declared \
                 the link lost); its place is held for {} in case it is back",
                Rounded(hold)
            );
            // A leave batch that the close overtook is still taken (see `on_batch`).
            self.lost_at = Some(now);
            hold
        };
        self.held = Some(Held {
            since: now,
            until: now + hold,
        });
    }

    /// Back within the resume window (its token and subscriber are there again): the
    /// frame published last is due again. `true` when the agent resumed just now.
    pub(super) fn try_resume(&mut self) -> bool {
        if !self.connected() {
            return false;
        }
        let Some(held) = self.held.take() else {
            return false;
        };
        info!(
            agent = self.id,
            down_s = held.since.elapsed().as_secs_f64(),
            "zenoh agent back within the resume window: resumed"
        );
        self.resend_due = true;
        true
    }
}

#[derive(Debug)]
pub(super) struct HostState {
    pub(super) slots: Vec<SlotState>,
    pub(super) next_nonce: u64,
    pub(super) free: Vec<AlignedBuf>,
    pub(super) stats: ZenohHostStats,
    pub(super) refusals: Refusals,
    /// Agents back within the resume window since the host last took the count.
    pub(super) resumed: u64,
}

impl HostState {
    /// Slot `slot`'s agent may be back (a token or a subscriber appeared): counts it.
    pub(super) fn note_back(&mut self, slot: usize) {
        if let Some(s) = self.slots.get_mut(slot)
            && s.try_resume()
        {
            self.resumed += 1;
            self.stats.resumes += 1;
        }
    }
}

#[derive(Debug)]
pub(super) struct Shared {
    pub(super) state: Mutex<HostState>,
    pub(super) wake: WakeFd,
    pub(super) keys: Keys,
    pub(super) session: String,
    pub(super) token: Option<Vec<u8>>,
    pub(super) max_motor_body: usize,
    pub(super) frame_bodies: Vec<usize>,
    /// Each slot's channels, as the hellos must declare them.
    pub(super) layouts: Vec<ChannelLayout>,
    /// `[sync] resume_window` (zero: a lost link ends the connection after its lease).
    pub(super) resume_window: Duration,
    /// `[transport.zenoh] lease`.
    pub(super) lease: Duration,
}

impl super::tls_refusals::TlsRefusalSink for Shared {
    fn tls_refused(&self, refusal: PeerRefusal) {
        {
            let mut st = lock(&self.state);
            st.stats.refused_tls += 1;
            st.refusals.push(refusal);
        }
        self.wake.wake();
    }
}

impl Shared {
    pub(super) fn slot_of(state: &HostState, id: u32) -> Option<usize> {
        state.slots.iter().position(|s| s.id == id)
    }

    /// The hello queryable: admits, or refuses with a reason.
    pub(super) fn on_hello(&self, query: &Query) {
        // Bounded before it is made contiguous (zenoh's own reassembly is bounded too).
        let payload = query
            .payload()
            .filter(|p| p.len() <= super::super::record::MAX_HELLO)
            .map(|p| p.to_bytes());
        let hello = match payload.as_deref().map(decode_hello) {
            Some(Ok(h)) => h,
            Some(Err(e)) => {
                return self.refuse(query, None, Reject::new(reject::MALFORMED, e.to_string()));
            }
            None => {
                let why = "no hello payload, or one longer than a hello";
                return self.refuse(query, None, Reject::new(reject::MALFORMED, why));
            }
        };
        let mut st = lock(&self.state);
        let verdict = self.admit(&mut st, &hello);
        drop(st);
        match verdict {
            Ok((nonce, body_len)) => {
                let mut b = Vec::with_capacity(4 + WELCOME_LEN);
                b.extend_from_slice(&reply::WELCOME.to_le_bytes());
                b.extend_from_slice(&PROTOCOL_VERSION.to_le_bytes());
                b.extend_from_slice(&LAYOUT_HASH.to_le_bytes());
                b.extend_from_slice(&(body_len as u32).to_le_bytes());
                b.extend_from_slice(&nonce.to_le_bytes());
                if let Err(e) = query.reply(query.key_expr().clone(), b).wait() {
                    warn!(agent = hello.agent_id, "zenoh welcome not sent: {e}");
                }
                info!(
                    agent = hello.agent_id,
                    nonce, "zenoh agent admitted (waiting for its token and subscriber)"
                );
            }
            Err(r) => self.refuse(query, Some(hello.agent_id), r),
        }
    }

    pub(super) fn admit(&self, st: &mut HostState, hello: &Hello) -> Result<(u64, usize), Reject> {
        let served: Vec<u32> = st.slots.iter().map(|s| s.id).collect();
        let token_message = "wrong or missing transport.zenoh.token";
        let slot = admit(
            hello,
            self.token.as_deref(),
            token_message,
            &served,
            &self.layouts,
        )?;
        // Only a connection whose token exists holds the id. Welcomed but no token yet: a
        // hello of the same id is that agent asking again (its query timed out before the
        // welcome reached it, as on a loaded machine), so it gets a new welcome and the
        // earlier one is void (a token with the old nonce is not this connection).
        let s = &st.slots[slot];
        let in_use = s.admitted.is_some() && s.alive;
        if in_use {
            return Err(Reject::id_in_use(hello.agent_id));
        }
        let nonce = st.next_nonce;
        st.next_nonce += 1;
        let s = &mut st.slots[slot];
        // A slot held for its agent's return stays held: this hello may be that agent
        // (restarted, or its session opened again), and until its token and subscriber
        // are there the host waits for it as before.
        let now = Instant::now();
        s.admitted = Some((nonce, now));
        s.heard = now;
        s.alive = false;
        s.gone_at = None;
        s.lost_at = None;
        s.saw_close = false;
        let body_len = self.frame_bodies.get(slot).copied().unwrap_or(HEADER);
        Ok((nonce, body_len))
    }

    pub(super) fn refuse(&self, query: &Query, agent: Option<u32>, r: Reject) {
        let why = r.message.clone();
        {
            let mut st = lock(&self.state);
            let s = &mut st.stats;
            let kind = RefusalKind::of_reject(r.code);
            *match kind {
                RefusalKind::Version => &mut s.refused_version,
                RefusalKind::Token => &mut s.refused_token,
                RefusalKind::UnknownAgent => &mut s.refused_unknown_agent,
                RefusalKind::IdInUse => &mut s.refused_id_in_use,
                RefusalKind::Channels => &mut s.refused_channels,
                _ => &mut s.refused_malformed,
            } += 1;
            st.refusals.push(PeerRefusal {
                kind,
                agent,
                // zenoh's stable API does not name the querying peer.
                peer: format!("zenoh hello on {}", self.keys.hello()),
                reason: why.clone(),
            });
        }
        warn!(?agent, session = %self.session, "zenoh agent refused: {why}");
        let mut b = reply::REJECT.to_le_bytes().to_vec();
        b.extend_from_slice(&r.encode());
        let _ = query.reply(query.key_expr().clone(), b).wait();
    }

    /// An agent's liveliness token appeared or vanished.
    pub(super) fn on_token(&self, sample: &Sample) {
        let Some((id, Some(nonce))) = self.keys.parse_agent(sample.key_expr().as_str()) else {
            return;
        };
        let mut st = lock(&self.state);
        let Some(slot) = Self::slot_of(&st, id) else {
            return;
        };
        let current = st.slots[slot].admitted.map(|(n, _)| n);
        match sample.kind() {
            SampleKind::Put if current == Some(nonce) => {
                st.slots[slot].alive = true;
                st.slots[slot].heard = Instant::now();
                st.note_back(slot);
                drop(st);
                info!(agent = id, "zenoh agent's token is there");
            }
            SampleKind::Put => {
                st.stats.ignored_tokens += 1;
                let n = st.stats.ignored_tokens;
                drop(st);
                if worth_logging(n) {
                    warn!(
                        agent = id,
                        nonce,
                        total = n,
                        "zenoh token ignored: no welcome with that nonce"
                    );
                }
            }
            SampleKind::Delete if current == Some(nonce) => {
                let s = &mut st.slots[slot];
                let was_connected = s.connected();
                s.lose(was_connected, self.resume_window, self.lease);
                s.alive = false;
                if s.held.is_some() {
                    // Its session may come back with this very token (zenoh declares it
                    // again on the new link): the nonce stays admitted, and the batches
                    // that arrived before the link went stay for the host.
                    drop(st);
                    self.wake.wake();
                    return;
                }
                s.admitted = None;
                s.gone_at = Some(Instant::now());
                // A leave batch in the queue is for the host still (the agent left
                // gracefully); anything else of a vanished agent is not.
                if !s.leave_queued {
                    let dropped: Vec<AlignedBuf> = s.queue.drain(..).collect();
                    st.free.extend(dropped);
                }
                drop(st);
                warn!(
                    agent = id,
                    "zenoh agent's token vanished (process ended or link lost)"
                );
            }
            SampleKind::Delete => {}
        }
        self.wake.wake();
    }

    /// A motor batch arrived on `…/agent/<id>/motor`.
    pub(super) fn on_batch(&self, sample: &Sample) {
        let payload = sample.payload();
        let len = payload.len();
        let parsed = self.keys.parse_agent(sample.key_expr().as_str());
        let mut st = lock(&self.state);
        let slot = parsed.and_then(|(id, _)| Self::slot_of(&st, id));
        // Not connected any more, but its token vanished just now: only a leave batch is
        // taken (checked below).
        let just_gone = |s: &SlotState| {
            !s.connected()
                && (s.gone_at.is_some_and(|t| t.elapsed() < LEAVE_AFTER_TOKEN)
                    || s.lost_at.is_some_and(|t| t.elapsed() < LEAVE_AFTER_TOKEN))
        };
        let Some(slot) = slot.filter(|&s| st.slots[s].connected() || just_gone(&st.slots[s]))
        else {
            st.stats.dropped_not_connected += 1;
            let n = st.stats.dropped_not_connected;
            drop(st);
            if worth_logging(n) {
                warn!(key = %sample.key_expr(), total = n, "zenoh batch dropped: not from a connected agent");
            }
            return;
        };
        let id = st.slots[slot].id;
        if len > self.max_motor_body || len < MOTOR_HEADER {
            return self.malformed(
                st,
                id,
                format!(
                    "{len} bytes (a batch is {MOTOR_HEADER}..={} bytes)",
                    self.max_motor_body
                ),
            );
        }
        // A buffer from the free list (allocated up front, or by an earlier batch: at
        // most 2 x MAX_QUEUED_BATCHES per agent are ever queued), never sized from the
        // payload.
        let mut buf = st
            .free
            .pop()
            .unwrap_or_else(|| AlignedBuf::with_capacity(self.max_motor_body));
        buf.fill_from(payload);
        let (stop, leave, cycle) = match super::super::record::decode_motor(buf.bytes()) {
            Ok((h, _)) if h.agent_id == id && (h.is_leave() || st.slots[slot].connected()) => {
                (h.is_stop(), h.is_leave(), h.cycle)
            }
            Ok((h, _)) if h.agent_id == id => {
                st.free.push(buf);
                st.stats.dropped_not_connected += 1;
                return;
            }
            Ok((h, _)) => {
                st.free.push(buf);
                return self.malformed(st, id, format!("names agent {}", h.agent_id));
            }
            Err(e) => {
                st.free.push(buf);
                return self.malformed(st, id, e.to_string());
            }
        };
        // A flood fills the queue; batches that end a cycle keep room of their own, so
        // the agent's stop still arrives after a flood of its own batches.
        let limit = if stop || leave {
            2 * MAX_QUEUED_BATCHES
        } else {
            MAX_QUEUED_BATCHES
        };
        if st.slots[slot].queue.len() >= limit {
            st.free.push(buf);
            st.stats.dropped_flood += 1;
            let n = st.stats.dropped_flood;
            drop(st);
            if worth_logging(n) {
                warn!(
                    agent = id,
                    total = n,
                    "zenoh batch dropped: {limit} batches wait already (flood)"
                );
            }
            return;
        }
        let s = &mut st.slots[slot];
        s.heard = Instant::now();
        // A stop for a cycle not published yet is the host's to drop (a future batch): not
        // this agent's stop of any cycle.
        if stop && !leave && s.published.is_some_and(|p| cycle <= p) {
            if s.stopped.is_some_and(|c| c >= cycle) {
                // Its stop of this cycle arrived already (an agent back after a lost link
                // sends the stop the host asks for again): applied once.
                st.free.push(buf);
                drop(st);
                debug!(
                    agent = id,
                    cycle, "zenoh stop batch dropped: it arrived already"
                );
                return;
            }
            s.stopped = Some(cycle);
        }
        s.queue.push_back(buf);
        if leave {
            // A graceful leave: the id is free for a new connection at once (its token's
            // deletion may come later); the host reads the batch at its next drain.
            let s = &mut st.slots[slot];
            s.admitted = None;
            s.alive = false;
            s.leave_queued = true;
            s.lost_at = None;
            s.held = None;
            drop(st);
            info!(agent = id, "zenoh agent left");
            self.wake.wake();
            return;
        }
        drop(st);
        self.wake.wake();
    }

    /// An agent's beat arrived on `…/agent/<id>/beat` (every lease / 4, from a live
    /// agent process): it tells a link that went silent from a connection that closed
    /// while the agent was heard from. [`CLOSED_BEAT`]: the agent saw the host's
    /// `host/closed` (the host's close waits for it).
    pub(super) fn on_beat(&self, sample: &Sample) {
        let Some((id, _)) = self.keys.parse_agent(sample.key_expr().as_str()) else {
            return;
        };
        let closed = sample.payload().len() == CLOSED_BEAT.len()
            && sample.payload().to_bytes().as_ref() == CLOSED_BEAT;
        let mut st = lock(&self.state);
        if let Some(slot) = Self::slot_of(&st, id)
            && st.slots[slot].connected()
        {
            let s = &mut st.slots[slot];
            s.heard = Instant::now();
            if closed {
                s.saw_close = true;
                drop(st);
                self.wake.wake();
            }
        }
    }

    pub(super) fn malformed(&self, mut st: MutexGuard<'_, HostState>, id: u32, why: String) {
        st.stats.dropped_malformed += 1;
        let n = st.stats.dropped_malformed;
        drop(st);
        if worth_logging(n) {
            warn!(agent = id, total = n, "zenoh batch dropped: {why}");
        }
    }
}
