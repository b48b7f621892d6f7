//! The zenoh transport's host side: the hello queryable, presence from liveliness tokens
//! and matching, one publisher per agent, one subscriber for every agent's batches.

use std::time::Instant;

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken;
use ::zenoh::matching::MatchingListener;
use ::zenoh::pubsub::{Publisher, Subscriber};
use ::zenoh::qos::CongestionControl;
use ::zenoh::query::Queryable;
use tracing::{debug, info, warn};
use zerocopy::IntoBytes;

use super::super::{
    BatchSink, FrameLoanMut, HostConnections, HostReadiness, HostTransport, HostTransportError,
    PeerRefusal, Refusals,
};
use super::host_state::*;
use super::*;
use crate::config::Config;
use crate::rounded::Rounded;
use crate::signal::SignalHandling;
use crate::wire::{MotorCommand, SensorHeader};

/// A loaned zenoh frame: a pooled buffer the images are written into, sent from in place.
#[derive(Debug)]
pub struct ZenohFrameLoan {
    header: Box<SensorHeader>,
    buf: AlignedBuf,
}

impl FrameLoanMut for ZenohFrameLoan {
    /// Header and image bytes, both writable. The header is copied into the buffer when
    /// the frame is published; the images are sent from where they are written.
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        (&mut self.header, &mut self.buf.bytes_mut()[HEADER..])
    }

    fn header(&self) -> &SensorHeader {
        &self.header
    }
}

/// Why the zenoh host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ZenohHostCreateError {
    /// The zenoh session could not be opened (e.g. a listen endpoint is taken).
    #[error(
        "cannot open the zenoh session listening on {listen:?}: {reason} (set [transport.zenoh] listen to a free address)"
    )]
    Open {
        /// The listen endpoints.
        listen: Vec<String>,
        /// zenoh's message.
        reason: String,
    },
    /// Declaring a key (queryable, publisher, subscriber, token) failed.
    #[error("cannot declare zenoh {what}: {reason}")]
    Declare {
        /// What was declared.
        what: String,
        /// zenoh's message.
        reason: String,
    },
}

struct SlotPort {
    publisher: Publisher<'static>,
    /// The frame published last (zenoh's reference to its pooled buffer): sent again to
    /// an agent back after a lost link.
    last: Option<::zenoh::bytes::ZBytes>,
    _matching: MatchingListener<()>,
    header: Option<Box<SensorHeader>>,
    body_len: usize,
}

/// The host side of the zenoh transport.
pub struct ZenohHost {
    shared: Arc<Shared>,
    ports: Vec<SlotPort>,
    pool: Arc<Mutex<Vec<AlignedBuf>>>,
    scratch: Vec<(usize, AlignedBuf)>,
    _queryable: Queryable<()>,
    _motor: Subscriber<()>,
    _tokens: Subscriber<()>,
    _beats: Subscriber<()>,
    alive: Option<LivelinessToken>,
    session: ::zenoh::Session,
}

impl core::fmt::Debug for ZenohHost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ZenohHost")
            .field("keys", &self.shared.keys)
            .finish_non_exhaustive()
    }
}

/// A pooled frame buffer on its way through zenoh: back to the pool when zenoh is done.
struct Outgoing {
    buf: AlignedBuf,
    pool: Arc<Mutex<Vec<AlignedBuf>>>,
}

impl AsRef<[u8]> for Outgoing {
    fn as_ref(&self) -> &[u8] {
        self.buf.bytes()
    }
}

impl Drop for Outgoing {
    fn drop(&mut self) {
        let buf = std::mem::take(&mut self.buf);
        lock(&self.pool).push(buf);
    }
}

impl ZenohHost {
    /// Opens a zenoh peer listening on `transport.zenoh.listen`, declares the hello
    /// queryable, the host's liveliness token, one sensor publisher per agent (blocking
    /// congestion control in sync mode) and the batch subscriber; `signals` says whether
    /// SIGINT/SIGTERM handlers are installed (see [`SignalHandling`]).
    ///
    /// # Errors
    /// [`ZenohHostCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, ZenohHostCreateError> {
        signals.apply();
        let z = &config.transport.zenoh;
        let keys = Keys::new(&config.session);
        let max_motor_body = MOTOR_HEADER
            + config.transport.max_commands_per_cycle as usize
                * core::mem::size_of::<MotorCommand>();
        // zenoh reassembles a message before our callback sees it: bound it to a little
        // more than the largest hello or batch, so a peer cannot make the host allocate
        // more.
        let max_rx = (max_motor_body + 4096).max(64 * 1024);
        let open_err = |reason: String| ZenohHostCreateError::Open {
            listen: z.listen.clone(),
            reason,
        };
        let zc = session_config(config, &z.listen, &[], Some(max_rx)).map_err(open_err)?;
        let session = ::zenoh::open(zc)
            .wait()
            .map_err(|e| open_err(e.to_string()))?;
        let declare = |what: &str| {
            let what = what.to_string();
            move |e: ::zenoh::Error| ZenohHostCreateError::Declare {
                what,
                reason: e.to_string(),
            }
        };
        let wake = WakeFd::new().map_err(|e| ZenohHostCreateError::Declare {
            what: "the wake-up eventfd".into(),
            reason: e.to_string(),
        })?;
        let frame_bodies: Vec<usize> = config
            .agents
            .iter()
            .map(|a| HEADER + a.frame_bytes())
            .collect();
        let shared = Arc::new(Shared {
            state: Mutex::new(HostState {
                slots: config.agents.iter().map(|a| SlotState::new(a.id)).collect(),
                next_nonce: 1,
                free: (0..config.agents.len() * 4)
                    .map(|_| AlignedBuf::with_capacity(max_motor_body))
                    .collect(),
                stats: ZenohHostStats::default(),
                refusals: Refusals::default(),
                resumed: 0,
            }),
            wake,
            keys: keys.clone(),
            session: config.session.clone(),
            token: z.token.clone().map(String::into_bytes),
            max_motor_body,
            frame_bodies: frame_bodies.clone(),
            layouts: config
                .agents
                .iter()
                .map(crate::config::AgentConfig::channel_layout)
                .collect(),
            resume_window: config.sync.resume_window,
            lease: z.lease,
        });
        let congestion = if config.sync.sync_mode {
            CongestionControl::Block
        } else {
            CongestionControl::Drop
        };
        let mut ports = Vec::with_capacity(config.agents.len());
        for (slot, a) in config.agents.iter().enumerate() {
            let publisher = session
                .declare_publisher(keys.sensors(a.id))
                .congestion_control(congestion)
                .wait()
                .map_err(declare("a sensor publisher"))?;
            let sh = shared.clone();
            let matching = publisher
                .matching_listener()
                .callback(move |status| {
                    let mut st = lock(&sh.state);
                    if let Some(s) = st.slots.get_mut(slot) {
                        let was_connected = s.connected();
                        s.matched = status.matching();
                        if !s.matched {
                            s.lose(was_connected, sh.resume_window, sh.lease);
                        }
                    }
                    st.note_back(slot);
                    drop(st);
                    sh.wake.wake();
                })
                .wait()
                .map_err(declare("a matching listener"))?;
            ports.push(SlotPort {
                publisher,
                last: None,
                _matching: matching,
                header: Some(Box::default()),
                body_len: frame_bodies[slot],
            });
        }
        let sh = shared.clone();
        let motor = session
            .declare_subscriber(keys.motor_any())
            .callback(move |sample| sh.on_batch(&sample))
            .wait()
            .map_err(declare("the batch subscriber"))?;
        let sh = shared.clone();
        let tokens = session
            .liveliness()
            .declare_subscriber(keys.agent_alive_any())
            .history(true)
            .callback(move |sample| sh.on_token(&sample))
            .wait()
            .map_err(declare("the agents' liveliness subscriber"))?;
        let sh = shared.clone();
        let beats = session
            .declare_subscriber(keys.beat_any())
            .callback(move |sample| sh.on_beat(&sample))
            .wait()
            .map_err(declare("the agents' beat subscriber"))?;
        let sh = shared.clone();
        let queryable = session
            .declare_queryable(keys.hello())
            .callback(move |query| sh.on_hello(&query))
            .wait()
            .map_err(declare("the hello queryable"))?;
        let alive = session
            .liveliness()
            .declare_token(keys.host_alive())
            .wait()
            .map_err(declare("the host's liveliness token"))?;
        for endpoint in z.listen.iter().filter(|e| e.starts_with("tls/")) {
            let sink: Arc<dyn super::tls_refusals::TlsRefusalSink> = shared.clone();
            super::tls_refusals::register(&sink, endpoint.clone());
        }
        info!(listen = ?z.listen, session = %config.session, "zenoh host listening");
        Ok(Self {
            shared,
            ports,
            pool: Arc::default(),
            scratch: Vec::with_capacity(MAX_BATCHES_PER_DRAIN),
            _queryable: queryable,
            _motor: motor,
            _tokens: tokens,
            _beats: beats,
            alive: Some(alive),
            session,
        })
    }

    /// What was dropped or refused so far.
    pub fn stats(&self) -> ZenohHostStats {
        lock(&self.shared.state).stats.clone()
    }

    /// The key expressions of this host's session.
    pub fn keys(&self) -> &Keys {
        &self.shared.keys
    }

    /// Sends the frame published last again to each agent back within the resume window,
    /// unless its stop of that cycle arrived (it then has nothing to answer).
    fn resend_to_the_returned(&mut self) {
        let mut due = Vec::new();
        {
            let mut st = lock(&self.shared.state);
            for (slot, s) in st.slots.iter_mut().enumerate() {
                if std::mem::take(&mut s.resend_due)
                    && let Some(cycle) = s.published
                    && s.stopped.is_none_or(|stopped| stopped < cycle)
                {
                    due.push((slot, s.id, cycle));
                }
            }
        }
        for (slot, id, cycle) in due {
            let Some(frame) = self.ports.get(slot).and_then(|p| p.last.clone()) else {
                continue;
            };
            debug!(
                agent = id,
                cycle, "zenoh frame sent again to an agent back after a lost link"
            );
            if let Err(e) = self.ports[slot].publisher.put(frame).wait() {
                warn!(agent = id, cycle, "zenoh frame not sent again: {e}");
            }
        }
    }
}

impl ZenohHost {
    /// Waits until every connected agent confirmed the host's `host/closed` or its token
    /// went, at most the lease (an agent behind a link that does not deliver would be
    /// lost by then anyway). `host/closed` is then known to have arrived: the rest of
    /// the close may be cut short by zenoh's bounded flush without an agent taking the
    /// close for a lost link.
    fn wait_for_the_close_to_arrive(&self) {
        let began = Instant::now();
        let deadline = began + self.shared.lease;
        loop {
            let waiting: Vec<u32> = lock(&self.shared.state)
                .slots
                .iter()
                .filter(|s| s.connected() && !s.saw_close)
                .map(|s| s.id)
                .collect();
            let now = Instant::now();
            if waiting.is_empty() {
                debug!(
                    waited_s = began.elapsed().as_secs_f64(),
                    "every zenoh agent saw the host's close"
                );
                return;
            }
            if now >= deadline {
                warn!(
                    agents = ?waiting,
                    "zenoh agents did not confirm the host's close within the lease ({}): \
                     closing anyway",
                    Rounded(self.shared.lease)
                );
                return;
            }
            self.shared.wake.wait(deadline - now);
            self.shared.wake.clear();
        }
    }
}

#[cfg(test)]
impl ZenohHost {
    /// Ends the host's session without `host/closed`, as a killed process's ends: its
    /// links close and its listener with them.
    pub(super) fn end_without_closing(mut self) {
        self.alive = None;
        let _ = self.session.close().wait();
    }
}

impl Drop for ZenohHost {
    fn drop(&mut self) {
        // A clean close: agents see `host/closed` before `host/alive` vanishes (both are
        // declarations, sent in order on a link), and the host waits until they did.
        let closed = self
            .session
            .liveliness()
            .declare_token(self.shared.keys.host_closed())
            .wait();
        if closed.is_ok() {
            self.wait_for_the_close_to_arrive();
        }
        if let Some(t) = self.alive.take() {
            let _ = t.undeclare().wait();
        }
        drop(closed);
        let _ = self.session.close().wait();
    }
}

impl HostTransport for ZenohHost {
    type Loan = ZenohFrameLoan;

    fn loan(&mut self, slot: usize) -> Result<ZenohFrameLoan, HostTransportError> {
        let p = self
            .ports
            .get_mut(slot)
            .ok_or(HostTransportError::NoSuchSlot { slot })?;
        // Steady state: the buffer zenoh released after sending the frame before last.
        let mut buf = lock(&self.pool)
            .pop()
            .unwrap_or_else(|| AlignedBuf::with_capacity(p.body_len));
        buf.set_len(p.body_len);
        let mut header = p.header.take().unwrap_or_default();
        *header = SensorHeader::default();
        Ok(ZenohFrameLoan { header, buf })
    }

    fn publish(&mut self, slot: usize, frame: ZenohFrameLoan) -> Result<bool, HostTransportError> {
        let ZenohFrameLoan { header, mut buf } = frame;
        buf.bytes_mut()[..HEADER].copy_from_slice(header.as_bytes());
        let cycle = header.cycle;
        let (connected, held) = {
            let mut st = lock(&self.shared.state);
            match st.slots.get_mut(slot) {
                Some(s) => {
                    s.published = Some(cycle);
                    (s.connected_for_host(), s.held.is_some())
                }
                None => (false, false),
            }
        };
        let Some(p) = self.ports.get_mut(slot) else {
            return Err(HostTransportError::NoSuchSlot { slot });
        };
        p.header = Some(header);
        if !connected {
            p.last = None;
            lock(&self.pool).push(buf);
            return Ok(false);
        }
        let out = Outgoing {
            buf,
            pool: self.pool.clone(),
        };
        let payload = ::zenoh::bytes::ZBytes::from(bytes::Bytes::from_owner(out));
        p.last = Some(payload.clone());
        if held {
            // Held for its agent's return: the frame goes out when it is back.
            return Ok(true);
        }
        p.publisher
            .put(payload)
            .wait()
            .map_err(|e| HostTransportError::Send {
                what: format!("the sensor frame of slot {slot} over zenoh"),
                reason: e.to_string(),
            })?;
        lock(&self.shared.state).stats.frames_sent += 1;
        Ok(true)
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        // The frame is the start.
        Ok(())
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        self.resend_to_the_returned();
        {
            let mut st = lock(&self.shared.state);
            for (slot, s) in st.slots.iter_mut().enumerate() {
                for _ in 0..MAX_BATCHES_PER_DRAIN {
                    match s.queue.pop_front() {
                        Some(b) => self.scratch.push((slot, b)),
                        None => break,
                    }
                }
                if s.queue.is_empty() {
                    s.leave_queued = false;
                }
            }
        }
        for (slot, buf) in &self.scratch {
            // Validated on receipt.
            if let Ok((header, commands)) = super::super::record::decode_motor(buf.bytes()) {
                sink(*slot, &header, commands);
            }
        }
        if !self.scratch.is_empty() {
            let mut st = lock(&self.shared.state);
            st.free.extend(self.scratch.drain(..).map(|(_, b)| b));
        }
        Ok(())
    }
}

impl HostReadiness for ZenohHost {
    fn activity_fd(&self) -> RawFd {
        self.shared.wake.raw()
    }

    /// The end of a loss grace (`LOSS_GRACE`) or of a resume window: the host then sees
    /// that connection lost.
    fn next_deadline(&self) -> Option<Instant> {
        lock(&self.shared.state)
            .slots
            .iter()
            .flat_map(|s| [s.lost_at.map(|t| t + LOSS_GRACE), s.held.map(|h| h.until)])
            .flatten()
            .filter(|&end| end > Instant::now())
            .min()
    }

    fn after_wait(&mut self) {
        self.shared.wake.clear();
        self.resend_to_the_returned();
    }
}

impl HostConnections for ZenohHost {
    fn is_connected(&self, slot: usize) -> bool {
        lock(&self.shared.state)
            .slots
            .get(slot)
            .is_some_and(SlotState::connected_for_host)
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        lock(&self.shared.state).refusals.take(sink)
    }

    fn forget_connection(&mut self, slot: usize) {
        // Evicted (its resume window passed) or left: a connection of the id starts afresh.
        if let Some(s) = lock(&self.shared.state).slots.get_mut(slot) {
            s.held = None;
        }
    }

    fn take_resumes(&mut self) -> u64 {
        std::mem::take(&mut lock(&self.shared.state).resumed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::time::Duration;

    const LEASE: Duration = Duration::from_secs(10);

    fn connected_slot() -> SlotState {
        SlotState {
            admitted: Some((1, Instant::now())),
            alive: true,
            matched: true,
            ..SlotState::new(0)
        }
    }

    #[test]
    fn a_connection_lost_without_a_leave_stays_connected_for_the_host_during_the_grace() {
        // The token vanished before any leave batch: lost for the transport, not yet for
        // the host (the batch may follow).
        let mut s = connected_slot();
        s.lose(s.connected(), Duration::ZERO, LEASE);
        s.admitted = None;
        s.alive = false;
        assert!(!s.connected());
        assert!(s.connected_for_host());
        // After the grace: lost.
        s.lost_at = Instant::now().checked_sub(LOSS_GRACE);
        assert!(!s.connected_for_host());

        // A leave batch queued first: the end is a leave, no grace; connected for the
        // host until it drained the batch.
        let mut s = connected_slot();
        s.leave_queued = true;
        s.lose(s.connected(), Duration::ZERO, LEASE);
        s.matched = false;
        assert!(s.lost_at.is_none());
        assert!(s.connected_for_host());
        s.leave_queued = false;
        assert!(!s.connected_for_host());

        // Never connected (welcomed, no subscriber yet): nothing to wait for.
        let mut s = connected_slot();
        s.matched = false;
        s.lose(s.connected(), Duration::ZERO, LEASE);
        assert!(s.lost_at.is_none());
        assert!(!s.connected_for_host());
    }

    #[test]
    fn with_a_resume_window_a_lost_link_is_held_and_the_same_connection_resumes() {
        let window = Duration::from_secs(30);
        // Silent for the lease (zenoh's lease ran out): held for the window.
        let mut s = connected_slot();
        s.heard = Instant::now().checked_sub(LEASE).unwrap();
        s.lose(s.connected(), window, LEASE);
        s.alive = false;
        s.matched = false;
        let held = s.held.expect("held");
        assert!(held.until - held.since == window);
        assert!(s.connected_for_host());
        assert!(!s.try_resume(), "not back yet");
        // Its token and subscriber back: resumed, the frame published last is due again.
        s.alive = true;
        s.matched = true;
        assert!(s.try_resume());
        assert!(s.held.is_none() && s.resend_due);
        // Past the window: lost.
        let mut s = connected_slot();
        s.heard = Instant::now().checked_sub(LEASE).unwrap();
        s.lose(true, window, LEASE);
        s.alive = false;
        s.held = s.held.map(|h| Held {
            until: Instant::now(),
            ..h
        });
        assert!(!s.connected_for_host());

        // Closed while it beat (its process ended, or its side gave up first): held for
        // the lease only, and a leave batch that the close overtook is still taken.
        let mut s = connected_slot();
        s.lose(true, window, LEASE);
        let held = s.held.expect("held");
        assert!(held.until - held.since == LEASE);
        assert!(s.lost_at.is_some());
    }
}
