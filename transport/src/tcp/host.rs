//! The TCP transport's host side: listening, hellos, one record buffer per agent, one
//! epoll set of every socket (its readiness descriptor).

use super::*;
use crate::rounded::Rounded;
use crate::wait::{self, EpollSet};
use crate::{PeerRefusal, Refusals};
use std::os::fd::RawFd;
use vrsync_protocol::channel_layout::ChannelLayout;

// ---------------------------------------------------------------------------------------
// Host side
// ---------------------------------------------------------------------------------------

/// A loaned TCP frame: the agent's record buffer, images written in place.
#[derive(Debug)]
pub struct TcpFrameLoan {
    // Boxed (and reused across cycles) to keep `FrameLoan` small.
    header: Box<SensorHeader>,
    buf: RecordBuf,
}

impl FrameLoanMut for TcpFrameLoan {
    /// Header and image bytes, both writable. The header is copied into the record when
    /// the frame is published (784 bytes); the images are written where they are sent from.
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        let payload = &mut self.buf.bytes_mut()[PREFIX + HEADER..];
        (&mut self.header, payload)
    }

    fn header(&self) -> &SensorHeader {
        &self.header
    }
}

#[derive(Debug)]
pub(super) struct Conn {
    pub(super) stream: TcpStream,
    pub(super) peer: SocketAddr,
    pub(super) reader: RecordReader,
    /// When the host first saw the current record incomplete.
    pub(super) partial_since: Option<Instant>,
}

#[derive(Debug)]
pub(super) struct Pending {
    pub(super) stream: TcpStream,
    pub(super) peer: SocketAddr,
    pub(super) since: Instant,
    pub(super) reader: RecordReader,
    /// Its hello, when it is in but the id's previous connection (closed by its peer)
    /// still has to be read to its end (see [`TcpHost::handle_pending`]).
    pub(super) hello: Option<Hello>,
}

#[derive(Debug)]
pub(super) struct TcpSlot {
    pub(super) id: u32,
    pub(super) conn: Option<Conn>,
    pub(super) buf: Option<RecordBuf>,
    pub(super) header: Option<Box<SensorHeader>>,
    pub(super) body_len: usize,
    /// Its link was lost (not the agent's own end): the slot is held for its return, and
    /// counts as connected meanwhile.
    pub(super) resuming: Option<Held>,
    /// The cycle of the frame in `buf` that was published last (none while it is loaned).
    pub(super) published: Option<u64>,
    /// The newest cycle whose stop batch arrived from this agent.
    pub(super) stopped: Option<u64>,
}

/// What `drain_conn` reports for a leave batch (not a failure: the connection ends).
const LEFT: &str = "left the session";

/// A slot held for its agent's return.
#[derive(Debug, Clone, Copy)]
pub(super) struct Held {
    /// When the link was lost.
    pub(super) since: Instant,
    /// When the slot is let go.
    pub(super) until: Instant,
}

/// The host side of the TCP transport.
#[derive(Debug)]
pub struct TcpHost {
    pub(super) listener: TcpListener,
    pub(super) local_addr: SocketAddr,
    pub(super) sync_mode: bool,
    pub(super) write_timeout: Duration,
    pub(super) slots: Vec<TcpSlot>,
    pub(super) pending: Vec<Pending>,
    pub(super) max_motor_body: usize,
    pub(super) max_frame_body: usize,
    pub(super) stall_timeout: Duration,
    pub(super) token: Option<Vec<u8>>,
    /// An agent socket was readable at the last wait and no drain has read it since.
    pub(super) unread: bool,
    /// Agent sockets are watched for errors and hang-ups only (see
    /// [`TcpHost::after_wait`]), until the next drain.
    pub(super) muted: bool,
    /// The listener, the connections waiting for their hello and the agents' sockets;
    /// each reported by its descriptor.
    pub(super) poll: EpollSet,
    /// Tokens of the last wait's ready sockets (reused).
    pub(super) ready: Vec<u64>,
    /// Peers refused since the host last took them.
    pub(super) refusals: Refusals,
    /// Each slot's channels, as the hellos must declare them.
    pub(super) layouts: Vec<ChannelLayout>,
    /// `[sync] resume_window` (zero: a lost link ends the connection).
    pub(super) resume_window: Duration,
    /// Agents back within the resume window since the host last took the count.
    pub(super) resumed: u64,
}

/// Why the TCP host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TcpHostCreateError {
    /// Binding the listen address failed.
    #[error("cannot listen on {addr}: {error} (set [transport] tcp_listen to a free address)")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The error (in the message, so not also a `source()`: printed once).
        error: io::Error,
    },
    /// The epoll set of the transport's sockets could not be created.
    #[error("cannot create the TCP transport's epoll set: {0}")]
    Poll(io::Error),
}

impl TcpHost {
    /// Binds `transport.tcp_listen` and prepares one record buffer per agent; `signals`
    /// says whether SIGINT/SIGTERM handlers are installed (see [`SignalHandling`]).
    ///
    /// # Errors
    /// [`TcpHostCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, TcpHostCreateError> {
        signals.apply();
        let addr = config.transport.tcp_listen;
        let bind = |error| TcpHostCreateError::Bind { addr, error };
        let listener = TcpListener::bind(addr).map_err(bind)?;
        listener.set_nonblocking(true).map_err(bind)?;
        let local_addr = listener.local_addr().map_err(bind)?;
        let poll = EpollSet::new(64).map_err(TcpHostCreateError::Poll)?;
        poll.add(listener.as_raw_fd(), listener.as_raw_fd() as u64)
            .map_err(TcpHostCreateError::Poll)?;
        if !local_addr.ip().is_loopback() {
            warn!(%local_addr, "TCP transport listens beyond loopback: any host that can reach it may connect");
        }
        let mut max_frame_body = 0;
        let slots = config
            .agents
            .iter()
            .map(|a| {
                let body_len = HEADER + a.frame_bytes();
                max_frame_body = max_frame_body.max(body_len);
                TcpSlot {
                    id: a.id,
                    conn: None,
                    buf: Some(RecordBuf::with_capacity(body_len)),
                    header: Some(Box::default()),
                    body_len,
                    resuming: None,
                    published: None,
                    stopped: None,
                }
            })
            .collect();
        let max_motor_body = core::mem::size_of::<MotorHeader>()
            + config.transport.max_commands_per_cycle as usize
                * core::mem::size_of::<MotorCommand>();
        info!(%local_addr, "TCP host listening");
        Ok(Self {
            listener,
            local_addr,
            sync_mode: config.sync.sync_mode,
            write_timeout: config.sync.stop_timeout.max(Duration::from_secs(1)),
            slots,
            pending: Vec::new(),
            max_motor_body,
            max_frame_body,
            stall_timeout: config.sync.stop_timeout.min(STALL_TIMEOUT),
            token: config.transport.tcp_token.clone().map(String::into_bytes),
            unread: false,
            muted: false,
            poll,
            ready: Vec::with_capacity(64),
            refusals: Refusals::default(),
            layouts: config
                .agents
                .iter()
                .map(crate::config::AgentConfig::channel_layout)
                .collect(),
            resume_window: config.sync.resume_window,
            resumed: 0,
        })
    }

    /// Services the sockets the last wait found ready (see [`HostReadiness::after_wait`]).
    fn service(&mut self) {
        self.ready.clear();
        // A failed look finds nothing ready: the next wait looks again.
        if let Ok(tokens) = self.poll.wait(Duration::ZERO) {
            self.ready.extend(tokens);
        }
        let listener = self.listener.as_raw_fd() as u64;
        let listener_ready = self.ready.contains(&listener);
        // An incomplete record past its deadline on a socket with nothing more to read is
        // a stall: drop it here too, so a caller that only waits makes progress as well.
        // (Not while agent sockets are muted: unread bytes may complete it.)
        let now = Instant::now();
        let mut agent_ready = false;
        for slot in 0..self.slots.len() {
            let Some(c) = &self.slots[slot].conn else {
                continue;
            };
            let readable = self.ready.contains(&(c.stream.as_raw_fd() as u64));
            agent_ready |= readable;
            if let Some(since) = c.partial_since
                && !self.muted
                && !readable
                && now.duration_since(since) >= self.stall_timeout
            {
                let why = stall_reason(&c.reader, self.stall_timeout);
                self.drop_conn(slot, &why, Loss::Lost);
            }
        }
        self.expire_resumes(now);
        if agent_ready {
            // Agent sockets whose data the caller has not drained since the last wait stay
            // readable: waiting on them again would return at once, and a caller that
            // waits without draining (for agents to connect, for a lost one to come back)
            // would spin. From the second such wait on they are only watched for errors
            // and hang-ups, until the next drain.
            if self.unread {
                self.set_agents_readable(false);
            }
            self.unread = true;
        }
        if listener_ready {
            self.accept_new();
        }
        if !self.pending.is_empty() {
            self.handle_pending();
        }
    }

    /// Watches every agent socket for input (`true`) or only for errors and hang-ups.
    fn set_agents_readable(&mut self, readable: bool) {
        if self.muted != readable {
            return;
        }
        self.muted = !readable;
        for c in self.slots.iter().filter_map(|s| s.conn.as_ref()) {
            let fd = c.stream.as_raw_fd();
            if let Err(e) = self.poll.set_readable(fd, fd as u64, readable) {
                warn!(peer = %c.peer, "TCP agent socket: epoll: {e}");
            }
        }
    }

    /// The address actually bound (resolves port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Drops slot `slot`'s connection; with a resume window, a lost link (see [`Loss`]) holds
    /// the slot for the agent's return.
    pub(super) fn drop_conn(&mut self, slot: usize, why: &str, loss: Loss) {
        // (A leave is not a failure: see `drain`.)
        let window = self.resume_window;
        let s = &mut self.slots[slot];
        let Some(c) = s.conn.take() else {
            return;
        };
        let hold = match loss {
            Loss::Ended => Duration::ZERO,
            Loss::Reset => window.min(RESET_GRACE),
            Loss::Lost => window,
        };
        if !hold.is_zero() {
            warn!(
                agent = s.id,
                peer = %c.peer,
                "TCP agent's link lost: {why}; its place is held for {} (sync.resume_window)",
                Rounded(hold)
            );
            let since = Instant::now();
            s.resuming = Some(Held {
                since,
                until: since + hold,
            });
        } else {
            warn!(agent = s.id, peer = %c.peer, "TCP agent dropped: {why}");
        }
    }

    /// Lets go of the slots whose agent was not back within the resume window: they are
    /// no longer connected, and the host evicts them.
    fn expire_resumes(&mut self, now: Instant) {
        for s in &mut self.slots {
            if let Some(held) = s.resuming
                && now >= held.until
            {
                warn!(
                    agent = s.id,
                    "TCP agent not back within {} of losing its link: lost",
                    Rounded(held.until - held.since)
                );
                s.resuming = None;
            }
        }
    }

    /// Writes a whole record to a non-blocking socket, waiting for writability with a
    /// deadline (a stalled agent cannot hold the host forever).
    pub(super) fn send_all(
        stream: &mut TcpStream,
        data: &[u8],
        deadline: Instant,
    ) -> io::Result<()> {
        wait::write_all_until(stream, data, deadline, "agent does not read")
    }

    /// Reads what has arrived from `c`, handing complete motor batches to `sink`.
    /// `Err((why, loss))` drops the connection, and so does a leave batch (`Err` with
    /// [`LEFT`]).
    fn drain_conn(
        c: &mut Conn,
        slot: usize,
        stall_timeout: Duration,
        sink: &mut BatchSink<'_>,
    ) -> Result<(), (String, Loss)> {
        let ended = |why: String| (why, Loss::Ended);
        for _ in 0..MAX_RECORDS_PER_DRAIN {
            match c.reader.read_from(&mut c.stream) {
                Ok(ReadProgress::Record(kind::MOTOR)) => {
                    c.partial_since = None;
                    let (header, commands) =
                        decode_motor(c.reader.body()).map_err(|e| ended(e.to_string()))?;
                    sink(slot, &header, commands);
                    if header.is_leave() {
                        // The agent is gone: free its id for a new connection now.
                        return Err(ended(LEFT.into()));
                    }
                }
                Ok(ReadProgress::Record(k)) => {
                    return Err(ended(format!(
                        "sent record kind {k}, expected motor batches"
                    )));
                }
                Ok(ReadProgress::Pending) => {
                    if let Some((_, k)) = c.reader.head()
                        && k != kind::MOTOR
                    {
                        return Err(ended(format!(
                            "sent record kind {k}, expected motor batches"
                        )));
                    }
                    if c.reader.buffered() == 0 {
                        c.partial_since = None;
                        return Ok(());
                    }
                    // Everything that has arrived is read and the record is still not
                    // complete: a working agent's rest follows within a round trip.
                    let now = Instant::now();
                    let since = *c.partial_since.get_or_insert(now);
                    if now.duration_since(since) >= stall_timeout {
                        return Err((stall_reason(&c.reader, stall_timeout), Loss::Lost));
                    }
                    return Ok(());
                }
                // A close is the agent's own end (its process ended): not a lost link.
                Ok(ReadProgress::Closed) if c.reader.buffered() == 0 => {
                    return Err(ended("connection closed".into()));
                }
                Ok(ReadProgress::Closed) => {
                    return Err(ended(format!(
                        "connection closed mid-record after {} of a motor batch",
                        c.reader.progress()
                    )));
                }
                Err(RecordReadError::Io(e)) => return Err((e.to_string(), loss_of(&e))),
                Err(e) => return Err(ended(e.to_string())),
            }
        }
        Ok(())
    }

    /// The earliest moment a pending hello or an incomplete record runs out of time.
    fn deadline(&self) -> Option<Instant> {
        let hellos = self.pending.iter().map(|p| p.since + HELLO_TIMEOUT);
        let stalls = self
            .slots
            .iter()
            .filter_map(|s| s.conn.as_ref()?.partial_since)
            .map(|t| t + self.stall_timeout);
        let resumes = self
            .slots
            .iter()
            .filter_map(|s| s.resuming)
            .map(|held| held.until);
        hellos.chain(stalls).chain(resumes).min()
    }

    fn writable_now(stream: &TcpStream) -> bool {
        wait::writable_now(stream.as_raw_fd())
    }

    /// Sets the shared secret agents must present.
    pub fn set_token(&mut self, token: Option<Vec<u8>>) {
        self.token = token;
    }

    /// Largest frame body any agent receives.
    pub fn max_frame_body(&self) -> usize {
        self.max_frame_body
    }
}

fn stall_reason(reader: &RecordReader, stall_timeout: Duration) -> String {
    format!(
        "stalled mid-record: {} of a motor batch, not complete within {}",
        reader.progress(),
        Rounded(stall_timeout)
    )
}

impl Drop for TcpHost {
    fn drop(&mut self) {
        for s in &mut self.slots {
            if let Some(c) = &mut s.conn {
                let deadline = Instant::now() + Duration::from_millis(200);
                let mut rec = [0u8; PREFIX];
                rec[4..].copy_from_slice(&kind::SHUTDOWN.to_le_bytes());
                let _ = Self::send_all(&mut c.stream, &rec, deadline);
            }
        }
    }
}

impl HostTransport for TcpHost {
    type Loan = TcpFrameLoan;

    fn loan(&mut self, slot: usize) -> Result<TcpFrameLoan, HostTransportError> {
        let s = self
            .slots
            .get_mut(slot)
            .ok_or(HostTransportError::NoSuchSlot { slot })?;
        // A loan dropped without publishing took its buffer with it: make a new one (rare;
        // steady state reuses the buffer every cycle).
        let mut buf = s
            .buf
            .take()
            .unwrap_or_else(|| RecordBuf::with_capacity(s.body_len));
        buf.reserve_body(s.body_len);
        let mut header = s.header.take().unwrap_or_default();
        *header = SensorHeader::default();
        s.published = None;
        Ok(TcpFrameLoan { header, buf })
    }

    fn publish(&mut self, slot: usize, frame: TcpFrameLoan) -> Result<bool, HostTransportError> {
        let TcpFrameLoan { header, mut buf } = frame;
        buf.bytes_mut()[PREFIX..PREFIX + HEADER].copy_from_slice(header.as_bytes());
        buf.set_prefix(kind::FRAME);
        let deadline = Instant::now() + self.write_timeout;
        let sync = self.sync_mode;
        let Some(s) = self.slots.get_mut(slot) else {
            return Ok(false);
        };
        s.published = Some(header.cycle);
        let result = match &mut s.conn {
            // Held for its agent's return: the frame goes out when it is back.
            None if s.resuming.is_some() => Ok(true),
            None => Ok(false),
            // Async mode: a slow agent whose socket is full misses this frame instead of
            // stalling the host (it reads the newest when it catches up).
            Some(c) if !sync && !Self::writable_now(&c.stream) => Ok(false),
            Some(c) => Self::send_all(&mut c.stream, buf.record(), deadline).map(|()| true),
        };
        s.buf = Some(buf);
        s.header = Some(header);
        match result {
            Ok(delivered) => Ok(delivered),
            Err(e) => {
                self.drop_conn(slot, &format!("cannot send its frame: {e}"), loss_of(&e));
                Ok(self.is_connected(slot))
            }
        }
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        // On TCP the frame record is the start: each agent begins as soon as its frame is in.
        Ok(())
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        self.unread = false;
        self.set_agents_readable(true);
        let stall_timeout = self.stall_timeout;
        for slot in 0..self.slots.len() {
            let s = &mut self.slots[slot];
            let failure = match &mut s.conn {
                Some(c) => {
                    let stopped = &mut s.stopped;
                    let mut note = |slot, header: &MotorHeader, commands: &[MotorCommand]| {
                        if header.is_stop() {
                            *stopped = Some(stopped.map_or(header.cycle, |c| c.max(header.cycle)));
                        }
                        sink(slot, header, commands);
                    };
                    Self::drain_conn(c, slot, stall_timeout, &mut note).err()
                }
                None => None,
            };
            match failure {
                Some((why, _)) if why == LEFT => {
                    if let Some(c) = self.slots[slot].conn.take() {
                        debug!(agent = self.slots[slot].id, peer = %c.peer, "TCP agent left");
                    }
                }
                Some((why, lost)) => self.drop_conn(slot, &why, lost),
                None => {}
            }
        }
        Ok(())
    }
}

impl HostReadiness for TcpHost {
    fn activity_fd(&self) -> RawFd {
        self.poll.raw()
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.deadline()
    }

    fn has_work(&self) -> bool {
        // A deferred hello whose id's old connection is gone is admitted by the next
        // `after_wait`.
        self.pending.iter().any(|p| {
            p.hello.as_ref().is_some_and(|h| {
                !self
                    .slots
                    .iter()
                    .any(|s| s.id == h.agent_id && s.conn.is_some())
            })
        })
    }

    fn after_wait(&mut self) {
        self.service();
    }
}

impl HostConnections for TcpHost {
    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        self.refusals.take(sink)
    }

    fn is_connected(&self, slot: usize) -> bool {
        // A slot held for its agent's return counts as connected: its frames go out when
        // the agent is back.
        self.slots
            .get(slot)
            .is_some_and(|s| s.conn.is_some() || s.resuming.is_some())
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn forget_connection(&mut self, slot: usize) {
        // Evicted (its resume window passed) or left: a new connection starts afresh.
        if let Some(s) = self.slots.get_mut(slot) {
            s.resuming = None;
        }
    }

    fn take_resumes(&mut self) -> u64 {
        std::mem::take(&mut self.resumed)
    }

    fn local_addr(&self) -> Option<SocketAddr> {
        Some(self.local_addr)
    }
}
