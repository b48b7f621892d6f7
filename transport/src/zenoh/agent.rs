//! The zenoh transport's agent side: hello, the newest frame, batches, the host's token,
//! and the wait for the host after a lost link (`[sync] resume_window`).
//!
//! # Ended or lost
//! A host that ends cleanly says so: it declares `host/closed` before its `host/alive`
//! token goes (both declarations, in order on one link), and waits (at most its lease)
//! until each connected agent confirmed it (a `closed` beat, sent once from a thread of its
//! own) or is gone. The agent that saw `host/closed` is told the host closed (its waits end
//! at once, as a close). Whatever else makes the host's token vanish is taken for a lost
//! link, however recently the host was heard from: the lease ran out on either side (a
//! partition, heavy loss, a link that stalls one way and is closed by the side that stops
//! hearing first), or the host's process ended without closing (killed): zenoh shows them
//! all the same way.
//!
//! # A lost link
//! With a resume window, the agent's waits see a live host for that long after it saw the
//! token go, while its zenoh session connects again by itself (the `connect` endpoints
//! are retried every 0.5 s at most) and declares the agent's token and subscriber again
//! on the new link. The token back, the agent goes on. The host, back, sends the frame of
//! the cycle it waits for again if this agent's stop for it did not arrive: if the agent
//! had sent that stop (the latest stop batch is kept), it sends the batch again instead of
//! handing the frame to the caller once more. Past the window the agent gives up: its
//! waits say the host is gone. Meanwhile, as the TCP agent does, it tries the host's
//! address every [`PROBE_PERIOD`] (a plain TCP connect to each `tcp/` or `tls/` connect
//! endpoint, bounded by [`PROBE_TIMEOUT`]): when every one refuses (the host's machine
//! answers and nothing listens) the host's process is gone, and the agent gives up at
//! once. A host whose machine does not answer (a partition, a machine down) is gone once
//! the window passed (30 s by default; without a window, at once). Meanwhile the agent beats
//! (`agent/<id>/beat`, every lease / 4), so that the host tells its silent link from a
//! closed connection.

use std::rc::Rc;
use std::time::{Duration, Instant};

use ::zenoh::Wait;
use ::zenoh::liveliness::LivelinessToken;
use ::zenoh::pubsub::{Publisher, Subscriber};
use ::zenoh::qos::CongestionControl;
use ::zenoh::sample::{Sample, SampleKind};
use tracing::{debug, info, warn};
use zerocopy::{FromBytes, IntoBytes};

use super::super::record::{Hello, Reject, encode_hello};
use super::super::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, Attempt, HostLiveness, retry_until,
};
use super::*;
use crate::config::Config;
use crate::rounded::Rounded;
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};
use vrsync_protocol::channel_layout::ChannelLayout;

const HEADER: usize = core::mem::size_of::<SensorHeader>();

mod close;
mod probe;

use close::Closing;
use probe::every_address_refuses;
pub(super) use probe::probe_addresses;
pub use probe::{PROBE_PERIOD, PROBE_TIMEOUT};

/// A received frame's bytes: zenoh's own buffer when it arrived in one piece (no copy),
/// else an aligned copy.
#[derive(Debug)]
enum Body {
    Zenoh(::zenoh::bytes::ZBytes),
    Copied(AlignedBuf),
}

impl Body {
    fn bytes(&self) -> &[u8] {
        match self {
            // One slice: checked when the frame arrived.
            Self::Zenoh(z) => z.slices().next().unwrap_or(&[]),
            Self::Copied(b) => b.bytes(),
        }
    }
}

#[derive(Debug, Default)]
struct AgentState {
    newest: Option<Body>,
    pool: Vec<AlignedBuf>,
    /// The host's `alive` token was seen.
    host_seen: bool,
    closed: bool,
    gone: Option<String>,
    max_frame_body: usize,
    dropped: u64,
    /// When the host's token vanished without `host/closed` (with a resume window).
    lost_since: Option<Instant>,
    /// The host's `host/alive` token vanished (after a close too).
    host_left: bool,
    /// The latest stop batch sent and its cycle.
    stop: Vec<u8>,
    stop_cycle: Option<u64>,
    /// The host, back after a lost link, sent the frame of `stop_cycle` again: it did not
    /// get that stop, which goes again.
    resend_stop: bool,
}

#[derive(Debug)]
struct AgentShared {
    state: Mutex<AgentState>,
    wake: WakeFd,
    keys: Keys,
    /// `[sync] resume_window`.
    resume_window: Duration,
    /// The agent's session and its beat key: the confirmation of the host's close goes
    /// there (see [`AgentShared::confirm_close`]).
    session: ::zenoh::Session,
    beat_key: String,
}

/// The cycle in the header of the frame `payload` (wherever its bytes lie).
fn cycle_of(payload: &::zenoh::bytes::ZBytes) -> Option<u64> {
    let at = core::mem::offset_of!(SensorHeader, cycle);
    let mut bytes = [0u8; 8];
    let mut seen = 0;
    let mut filled = 0;
    for s in payload.slices() {
        let (from, to) = (seen, seen + s.len());
        seen = to;
        if to <= at + filled || from >= at + 8 {
            continue;
        }
        while filled < 8 && at + filled < to {
            bytes[filled] = s[at + filled - from];
            filled += 1;
        }
        if filled == 8 {
            return Some(u64::from_ne_bytes(bytes));
        }
    }
    None
}

/// Whether the frame whose first bytes are `frame` carries vectors (`[[agent.vector]]`):
/// read from its header's `vector_count`, wherever the bytes lie.
fn has_vectors(frame: &[u8]) -> bool {
    let at = core::mem::offset_of!(SensorHeader, vector_count);
    frame
        .get(at..at + 4)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .is_some_and(|b| u32::from_ne_bytes(b) != 0)
}

impl AgentShared {
    fn on_frame(&self, sample: &Sample) {
        let payload = sample.payload();
        let len = payload.len();
        let mut st = lock(&self.state);
        if len < HEADER || len > st.max_frame_body {
            st.dropped += 1;
            let (n, max) = (st.dropped, st.max_frame_body);
            drop(st);
            if worth_logging(n) {
                warn!(
                    total = n,
                    "zenoh frame dropped: {len} bytes (a frame is {HEADER}..={max})"
                );
            }
            return;
        }
        if st.stop_cycle.is_some() && cycle_of(payload) == st.stop_cycle {
            // The host, back after a lost link, asks for this cycle's stop again.
            st.resend_stop = true;
            drop(st);
            self.wake.wake();
            return;
        }
        let in_place = payload.slices().count() == 1
            && payload
                .slices()
                .next()
                .is_some_and(|s| (s.as_ptr() as usize).is_multiple_of(8) || !has_vectors(s));
        let body = if in_place {
            // In one piece (and aligned, when it carries vectors, whose `f32`s are read
            // in place): kept as zenoh delivered it, read in place.
            drop(st);
            Body::Zenoh(payload.clone())
        } else {
            // In pieces (or misaligned): copied outside the lock into a pooled buffer of
            // the largest frame's size.
            let mut buf = st.pool.pop().unwrap_or_default();
            let max = st.max_frame_body;
            drop(st);
            if buf.capacity() < max {
                buf = AlignedBuf::with_capacity(max);
            }
            buf.fill_from(payload);
            Body::Copied(buf)
        };
        let mut st = lock(&self.state);
        if let Some(Body::Copied(old)) = st.newest.replace(body) {
            st.pool.push(old);
        }
        drop(st);
        self.wake.wake();
    }

    /// Tells the host that this agent saw its `host/closed` (a `closed` beat): the host's
    /// close waits for it, so that the close is known to have arrived before the host's
    /// session goes. Sent from a thread of its own: a zenoh callback must not block on a
    /// full queue.
    fn confirm_close(&self) {
        let session = self.session.clone();
        let key = self.beat_key.clone();
        let spawned = std::thread::Builder::new()
            .name("vrsync-zenoh-closed".into())
            .spawn(move || {
                let put = session
                    .put(&key, CLOSED_BEAT.to_vec())
                    .congestion_control(CongestionControl::Block);
                if let Err(e) = put.wait() {
                    debug!("the host's close not confirmed: {e}");
                }
            });
        if let Err(e) = spawned {
            // The host then waits for this agent's token to go (or its lease).
            warn!("no thread to confirm the host's close: {e}");
        }
    }

    fn on_host_token(&self, sample: &Sample) {
        let key = sample.key_expr().as_str();
        let mut st = lock(&self.state);
        match sample.kind() {
            SampleKind::Put if key == self.keys.host_closed() => {
                if !std::mem::replace(&mut st.closed, true) {
                    self.confirm_close();
                }
            }
            SampleKind::Put if key == self.keys.host_alive() => {
                st.host_seen = true;
                if let Some(since) = st.lost_since.take() {
                    info!(
                        down_s = since.elapsed().as_secs_f64(),
                        "the host's zenoh token is back: resumed"
                    );
                }
            }
            SampleKind::Delete if key == self.keys.host_alive() && st.closed => {
                // The end of a clean close: the agent's own close may go on.
                st.host_left = true;
            }
            SampleKind::Delete if key == self.keys.host_alive() => {
                st.host_left = true;
                // Without `host/closed` first: not a clean end. A lost link and a killed
                // host look the same here (however recently the host was heard from: a
                // link that stalls one way is closed by the side that stops hearing first,
                // while the other still hears it), so both are waited for.
                if self.resume_window.is_zero() {
                    st.gone = Some(
                        "the host's zenoh liveliness token vanished without its close (its \
                         process ended, or the link was lost for longer than the lease)"
                            .into(),
                    );
                } else if st.lost_since.is_none() && st.gone.is_none() {
                    warn!(
                        "the host's zenoh liveliness token vanished without its close (the \
                         link was lost, or the host's process ended without closing): waiting \
                         for it for up to {} (sync.resume_window)",
                        Rounded(self.resume_window)
                    );
                    st.lost_since = Some(Instant::now());
                }
            }
            _ => return,
        }
        drop(st);
        self.wake.wake();
    }
}

/// A received zenoh frame: zenoh's buffer, or an aligned copy that goes back to the
/// agent's pool when dropped.
#[derive(Debug)]
pub struct ZenohFrame {
    /// Copied out of zenoh's buffer (which need not be aligned), and boxed: a frame is
    /// moved several times on its way to the caller, and an inline header (1.3 KB) made
    /// each move a copy of it (and every transport's frame as large, shared memory's too).
    header: Box<SensorHeader>,
    buf: Option<Body>,
    shared: Arc<AgentShared>,
    _held: Rc<()>,
}

impl AgentFrame for ZenohFrame {
    fn header(&self) -> &SensorHeader {
        &self.header
    }

    fn payload(&self) -> &[u8] {
        self.buf
            .as_ref()
            .and_then(|b| b.bytes().get(HEADER..))
            .unwrap_or(&[])
    }
}

impl Drop for ZenohFrame {
    fn drop(&mut self) {
        if let Some(Body::Copied(buf)) = self.buf.take() {
            lock(&self.shared.state).pool.push(buf);
        }
    }
}

/// The agent side of the zenoh transport.
pub struct ZenohAgent {
    id: u32,
    shared: Arc<AgentShared>,
    held: Rc<()>,
    out: Vec<u8>,
    signals: SignalHandling,
    publisher: Publisher<'static>,
    _frames: Subscriber<()>,
    _host: Subscriber<()>,
    _token: LivelinessToken,
    /// Dropped to end the beat thread.
    beat_stop: Option<std::sync::mpsc::Sender<()>>,
    session: ::zenoh::Session,
    closing: Closing,
    /// The host's addresses, tried after its token vanished without its close.
    probe: Vec<String>,
    /// When the host's addresses may be tried next.
    next_probe: Instant,
}

impl core::fmt::Debug for ZenohAgent {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ZenohAgent")
            .field("id", &self.id)
            .finish_non_exhaustive()
    }
}

/// What the host answered to a hello.
enum Answer {
    Welcome { max_frame_body: usize, nonce: u64 },
    Refused(AgentConnectError),
}

/// What else a link that never opens may mean with `tls/` endpoints: zenoh refuses a
/// TLS handshake without telling either session why.
fn tls_hint(connect: &[String]) -> &'static str {
    let tls = connect.iter().any(|e| e.starts_with("tls/"));
    let plain = connect.iter().any(|e| e.starts_with("tcp/"));
    if tls {
        "; a tls/ link also fails when the host's certificate is not signed by tls_ca or does \
         not name the address connected to, when the host has mtls and this side has no \
         certificate signed by its CA (mtls = true with tls_cert and tls_key), or when the \
         host listens on plain tcp/"
    } else if plain {
        "; a plain tcp/ link is also dropped by a host that listens on tls/"
    } else {
        ""
    }
}

impl ZenohAgent {
    /// Opens a zenoh peer connecting to `transport.zenoh.connect`, says hello (retrying
    /// until `timeout` while no host answers), then subscribes to its frames and declares
    /// its liveliness token. `token` is the session's secret, if it has one.
    ///
    /// # Errors
    /// [`AgentConnectError`]: no host, protocol mismatch, id not served or in use, wrong
    /// token.
    pub(crate) fn connect_with_token(
        config: &Config,
        id: u32,
        timeout: Duration,
        token: Option<&[u8]>,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        signals.apply();
        let session_name = &config.session;
        let z = &config.transport.zenoh;
        let started = Instant::now();
        let deadline = started + timeout;
        let fail = |detail: String| AgentConnectError::Transport {
            session: session_name.clone(),
            agent: id,
            detail,
        };
        let zc = session_config(config, &[], &z.connect, None).map_err(&fail)?;
        let session = ::zenoh::open(zc)
            .wait()
            .map_err(|e| fail(format!("cannot open a zenoh session: {e}")))?;
        let keys = Keys::new(session_name);
        let shared = Arc::new(AgentShared {
            state: Mutex::new(AgentState::default()),
            wake: WakeFd::new().map_err(|e| fail(format!("eventfd: {e}")))?,
            keys: keys.clone(),
            resume_window: config.sync.resume_window,
            session: session.clone(),
            beat_key: keys.beat(id),
        });
        let declare = |what: &'static str| {
            move |e: ::zenoh::Error| fail(format!("cannot declare {what}: {e}"))
        };
        let sh = shared.clone();
        let host = session
            .liveliness()
            .declare_subscriber(keys.host_any())
            .history(true)
            .callback(move |s| sh.on_host_token(&s))
            .wait()
            .map_err(declare("the host's liveliness subscriber"))?;
        let channels = config.channel_layout_of(id);
        let hello = encode_hello(&Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            channels: channels.hash(),
            token: token.map(<[u8]>::to_vec).unwrap_or_default(),
        });
        let answer = retry_until(
            deadline,
            || signals.termination_requested(),
            || {
                let left = deadline.saturating_duration_since(Instant::now());
                let replies = session
                    .get(keys.hello())
                    .payload(hello.clone())
                    .timeout(left.clamp(Duration::from_millis(1), Duration::from_secs(2)))
                    .wait();
                let replies = match replies {
                    Ok(r) => r,
                    Err(e) => return Attempt::Failed(fail(format!("hello query: {e}"))),
                };
                let mut last = String::from("no host answered the hello");
                while let Ok(reply) = replies.recv() {
                    match reply.result() {
                        Ok(sample) => {
                            let body = sample.payload().to_bytes();
                            return match parse_answer(&body, session_name, id, &channels) {
                                Ok(a) => Attempt::Done(a),
                                Err(e) => Attempt::Failed(fail(e)),
                            };
                        }
                        Err(e) => last = format!("hello answered with an error: {e:?}"),
                    }
                }
                Attempt::NotYet(last)
            },
        );
        let (max_frame_body, nonce) = match answer {
            Ok(Answer::Welcome {
                max_frame_body,
                nonce,
            }) => (max_frame_body, nonce),
            Ok(Answer::Refused(e)) => return Err(e),
            Err(Err(e)) => return Err(e),
            Err(Ok(missing)) => {
                return Err(AgentConnectError::HostNotFound {
                    session: session_name.clone(),
                    agent: id,
                    waited: started.elapsed(),
                    looked_for: format!(
                        "a zenoh host answering {} via {:?} ({missing}{})",
                        keys.hello(),
                        z.connect,
                        tls_hint(&z.connect)
                    ),
                });
            }
        };
        {
            let mut st = lock(&shared.state);
            st.max_frame_body = max_frame_body;
            // Two frames held, one newest, one being filled.
            st.pool = (0..AGENT_MAX_HELD_FRAMES + 2)
                .map(|_| AlignedBuf::with_capacity(max_frame_body))
                .collect();
        }
        let sh = shared.clone();
        let frames = session
            .declare_subscriber(keys.sensors(id))
            .callback(move |s| sh.on_frame(&s))
            .wait()
            .map_err(declare("the frame subscriber"))?;
        // Batches are small and a stop must never be lost: block rather than drop.
        let publisher = session
            .declare_publisher(keys.motor(id))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(declare("the batch publisher"))?;
        // Declared last: the host counts the agent connected once it sees this token and
        // the subscriber above (declarations arrive in order).
        let token = session
            .liveliness()
            .declare_token(keys.agent_alive(id, nonce))
            .wait()
            .map_err(declare("the agent's liveliness token"))?;
        debug!(agent = id, nonce, "zenoh agent welcomed");
        let beat_stop = start_beats(&session, keys.beat(id), z.lease / 4);
        Ok(Self {
            id,
            shared,
            held: Rc::new(()),
            out: Vec::with_capacity(
                core::mem::size_of::<MotorHeader>()
                    + config.transport.max_commands_per_cycle as usize
                        * core::mem::size_of::<MotorCommand>(),
            ),
            signals,
            publisher,
            _frames: frames,
            _host: host,
            _token: token,
            beat_stop,
            session,
            closing: Closing::Open,
            probe: probe_addresses(&z.connect),
            next_probe: Instant::now(),
        })
    }

    /// This agent's id.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// Frames dropped on receipt (too short or too long).
    pub fn frames_dropped(&self) -> u64 {
        lock(&self.shared.state).dropped
    }

    /// Sends the latest stop batch again if the host, back after a lost link, asked for
    /// its cycle again.
    fn resend_stop_if_asked(&mut self) {
        let mut st = lock(&self.shared.state);
        if !std::mem::take(&mut st.resend_stop) {
            return;
        }
        self.out.clear();
        self.out.extend_from_slice(&st.stop);
        let cycle = st.stop_cycle;
        drop(st);
        debug!(agent = self.id, ?cycle, "stop sent again after a lost link");
        if let Err(e) = self.publisher.put(self.out.as_slice()).wait() {
            warn!(agent = self.id, ?cycle, "zenoh stop not sent again: {e}");
        }
    }
}

fn parse_answer(
    body: &[u8],
    session: &str,
    id: u32,
    ours: &ChannelLayout,
) -> Result<Answer, String> {
    let u32_at = |at: usize| {
        body.get(at..at + 4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
    };
    let u64_at = |at: usize| {
        body.get(at..at + 8)
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes)
    };
    let mismatch = |host_protocol: u32, host_layout: u64| AgentConnectError::VersionMismatch {
        session: session.to_string(),
        host_protocol: host_protocol.to_string(),
        host_layout: format!("{host_layout:016x}"),
        agent_protocol: PROTOCOL_VERSION,
        agent_layout: format!("{LAYOUT_HASH:016x}"),
    };
    match u32_at(0) {
        Some(reply::WELCOME) => {
            let (Some(proto), Some(layout), Some(max), Some(nonce)) =
                (u32_at(4), u64_at(8), u32_at(16), u64_at(20))
            else {
                return Err("malformed welcome".into());
            };
            if proto != PROTOCOL_VERSION || layout != LAYOUT_HASH {
                return Ok(Answer::Refused(mismatch(proto, layout)));
            }
            Ok(Answer::Welcome {
                max_frame_body: max as usize,
                nonce,
            })
        }
        Some(reply::REJECT) => {
            let r = Reject::decode(&body[4..]).ok_or("malformed refusal")?;
            Ok(Answer::Refused(AgentConnectError::from_reject(
                r, session, id, ours, mismatch,
            )))
        }
        _ => Err("the hello's answer is neither a welcome nor a refusal".into()),
    }
}

impl AgentTransport for ZenohAgent {
    type Frame = ZenohFrame;

    fn connect(
        config: &Config,
        id: u32,
        timeout: Duration,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        let token = config.transport.zenoh.token.as_deref().map(str::as_bytes);
        Self::connect_with_token(config, id, timeout, token, signals)
    }

    fn try_receive_newest(&mut self) -> Result<Option<ZenohFrame>, AgentReceiveError> {
        self.resend_stop_if_asked();
        if Rc::strong_count(&self.held) > AGENT_MAX_HELD_FRAMES {
            return Err(AgentReceiveError::TooManyFramesHeld {
                max: AGENT_MAX_HELD_FRAMES,
            });
        }
        let Some(buf) = lock(&self.shared.state).newest.take() else {
            return Ok(None);
        };
        let header = buf
            .bytes()
            .get(..HEADER)
            .and_then(|h| SensorHeader::read_from_bytes(h).ok())
            .ok_or_else(|| AgentReceiveError::Protocol("frame header".into()))?;
        Ok(Some(ZenohFrame {
            header: Box::new(header),
            buf: Some(buf),
            shared: self.shared.clone(),
            _held: self.held.clone(),
        }))
    }

    fn wait_readable(&mut self, timeout: Duration) {
        {
            let st = lock(&self.shared.state);
            if st.newest.is_some() || st.closed || st.gone.is_some() || st.resend_stop {
                return;
            }
        }
        self.shared.wake.wait(timeout);
    }

    fn discard_wakeups(&mut self) {
        self.shared.wake.clear();
    }

    fn host_liveness(&mut self, check_process: bool) -> HostLiveness {
        let lost = lock(&self.shared.state).lost_since.is_some();
        if lost && check_process && Instant::now() >= self.next_probe {
            // Outside the lock: a try takes up to PROBE_TIMEOUT.
            let refused = every_address_refuses(&self.probe);
            self.next_probe = Instant::now() + PROBE_PERIOD;
            let mut st = lock(&self.shared.state);
            if let Some(addresses) = refused
                && st.lost_since.take().is_some()
            {
                st.gone = Some(format!(
                    "the host's zenoh liveliness token vanished without its close and its \
                     address refuses connections ({addresses}): its process ended"
                ));
            }
        }
        let mut st = lock(&self.shared.state);
        let window = self.shared.resume_window;
        if let Some(since) = st.lost_since
            && since.elapsed() >= window
        {
            st.lost_since = None;
            st.gone = Some(format!(
                "the host's zenoh liveliness token vanished without its close (the link was \
                 lost, or the host's process ended without closing) and did not come back \
                 within {} (sync.resume_window)",
                Rounded(window)
            ));
        }
        if st.closed {
            HostLiveness::Closed
        } else if let Some(reason) = &st.gone {
            HostLiveness::Gone {
                reason: reason.clone(),
            }
        } else {
            HostLiveness::Alive
        }
    }

    fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), AgentSendError> {
        let header = MotorHeader {
            command_count: commands.len() as u32,
            ..*header
        };
        self.out.clear();
        self.out.extend_from_slice(header.as_bytes());
        self.out.extend_from_slice(commands.as_bytes());
        if header.is_stop() {
            let mut st = lock(&self.shared.state);
            st.stop.clear();
            st.stop.extend_from_slice(&self.out);
            st.stop_cycle = Some(header.cycle);
        }
        // While the link is lost zenoh has no route for it: the put drops it, and the
        // stop goes again when the host, back, asks for its cycle again.
        let sent = self.publisher.put(self.out.as_slice()).wait();
        match sent {
            Ok(()) => Ok(()),
            Err(_) if lock(&self.shared.state).closed => Err(AgentSendError::HostClosed),
            Err(e) => Err(AgentSendError::Transport(format!(
                "cannot send the motor batch over zenoh: {e}"
            ))),
        }
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    fn begin_close(&mut self) {
        self.start_close();
    }
}
