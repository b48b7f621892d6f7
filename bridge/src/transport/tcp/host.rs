//! The TCP transport's host side: listening, hellos, one record buffer per agent, one
//! epoll set of every socket (its readiness descriptor).

use super::*;
use crate::rounded::Rounded;
use crate::transport::wait::{self, EpollSet};
use crate::transport::{PeerRefusal, RefusalKind, Refusals};
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
}

/// What `drain_conn` reports for a leave batch (not a failure: the connection ends).
const LEFT: &str = "left the session";

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
    pub(super) signals: SignalHandling,
    /// Peers refused since the host last took them.
    pub(super) refusals: Refusals,
    /// Each slot's channels, as the hellos must declare them.
    pub(super) layouts: Vec<ChannelLayout>,
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
            signals,
            refusals: Refusals::default(),
            layouts: config
                .agents
                .iter()
                .map(crate::config::AgentConfig::channel_layout)
                .collect(),
        })
    }

    /// Services the sockets the last wait found ready (see [`HostTransport::after_wait`]).
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
                self.drop_conn(slot, &why);
            }
        }
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

    fn drop_conn(&mut self, slot: usize, why: &str) {
        // (A leave is not a failure: see `drain`.)
        if let Some(c) = self.slots[slot].conn.take() {
            warn!(agent = self.slots[slot].id, peer = %c.peer, "TCP agent dropped: {why}");
        }
    }

    fn accept_new(&mut self) {
        let mut turned_away = 0usize;
        loop {
            match self.listener.accept() {
                Ok((stream, peer)) => {
                    if self.pending.len() >= MAX_PENDING {
                        // Closed at once: a flood of silent connections costs a bounded
                        // number of descriptors and buffers.
                        debug!(%peer, "TCP peer dropped: too many connections waiting for their hello");
                        turned_away += 1;
                        continue;
                    }
                    if stream.set_nonblocking(true).is_err()
                        || set_nodelay(&stream).is_err()
                        || self
                            .poll
                            .add(stream.as_raw_fd(), stream.as_raw_fd() as u64)
                            .is_err()
                    {
                        continue;
                    }
                    debug!(%peer, "TCP connection");
                    self.pending.push(Pending {
                        stream,
                        peer,
                        since: Instant::now(),
                        reader: RecordReader::new(MAX_HELLO),
                        hello: None,
                    });
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    warn!("TCP accept failed: {e}");
                    break;
                }
            }
        }
        if turned_away > 0 {
            self.refusals.count(turned_away as u64);
            warn!(
                "TCP peer dropped: {turned_away} connection(s) closed at once, {MAX_PENDING} are already waiting for their hello"
            );
        }
    }

    /// Whether a complete hello must wait before it is admitted: its id's connection is
    /// closed by its peer (the agent left, died or reconnects) but not read to its end. Its
    /// last records (a stop, a leave batch) and its loss belong to the cycle the host
    /// waits for, and the host must see the old connection go before a new one of the
    /// same id counts as connected: else it would wait for a stop the new connection
    /// never got a frame for. The host's next drain reads the old connection to its end;
    /// the wait after it admits the new one. A host that does not drain within
    /// [`HELLO_TIMEOUT`] (it waits for agents, not for stops) gets the new connection
    /// anyway, the old one dropped with what it still held.
    fn must_defer(&self, hello: &Hello) -> bool {
        self.slots
            .iter()
            .find(|s| s.id == hello.agent_id)
            .and_then(|s| s.conn.as_ref())
            .is_some_and(|c| wait::peer_closed(c.stream.as_raw_fd()))
    }

    /// Admits the deferred hellos whose id's old connection is gone, or that waited
    /// [`HELLO_TIMEOUT`]. Returns whether one was admitted.
    fn admit_deferred(&mut self) -> bool {
        let mut admitted = false;
        let mut i = 0;
        while i < self.pending.len() {
            let Some(hello) = &self.pending[i].hello else {
                i += 1;
                continue;
            };
            let gone = !self
                .slots
                .iter()
                .any(|s| s.id == hello.agent_id && s.conn.is_some());
            if gone || self.pending[i].since.elapsed() >= HELLO_TIMEOUT {
                let mut p = self.pending.swap_remove(i);
                if let Some(hello) = p.hello.take() {
                    self.admit(p, hello);
                    admitted = true;
                }
            } else {
                i += 1;
            }
        }
        admitted
    }

    /// Reads pending hellos; admits, rejects or times out each connection.
    fn handle_pending(&mut self) {
        // A deferred hello whose predecessor the host has let go since is admitted now.
        self.admit_deferred();
        let mut i = 0;
        while i < self.pending.len() {
            if self.pending[i].hello.is_some() {
                i += 1;
                continue;
            }
            match self.progress_hello(i) {
                Ok(None) => {
                    let p = &self.pending[i];
                    if p.since.elapsed() >= HELLO_TIMEOUT {
                        let why = if p.reader.buffered() == 0 {
                            format!(
                                "sent nothing within {} of connecting (no hello)",
                                Rounded(HELLO_TIMEOUT)
                            )
                        } else {
                            format!(
                                "stalled mid-record: {} of its hello within {} of connecting",
                                p.reader.progress(),
                                Rounded(HELLO_TIMEOUT)
                            )
                        };
                        let p = self.pending.swap_remove(i);
                        self.refuse(RefusalKind::Silent, None, p.peer, why);
                    } else {
                        i += 1;
                    }
                }
                Ok(Some(hello)) if self.must_defer(&hello) => {
                    // It waits for the host's next drain, not for its socket.
                    let fd = self.pending[i].stream.as_raw_fd();
                    let _ = self.poll.set_readable(fd, fd as u64, false);
                    self.pending[i].hello = Some(hello);
                    i += 1;
                }
                Ok(Some(hello)) => {
                    let p = self.pending.swap_remove(i);
                    self.admit(p, hello);
                }
                Err((why, closed)) => {
                    let mut p = self.pending.swap_remove(i);
                    let kind = if closed {
                        RefusalKind::Silent
                    } else {
                        RefusalKind::Malformed
                    };
                    self.refuse(kind, None, p.peer, why.clone());
                    if !closed {
                        let _ = p.stream.set_nonblocking(false);
                        let _ = p.stream.set_write_timeout(Some(Duration::from_millis(200)));
                        let _ = write_record(
                            &mut p.stream,
                            kind::REJECT,
                            &Reject::new(reject::MALFORMED, why.as_str()).encode(),
                        );
                    }
                }
            }
        }
    }

    /// Reads what has arrived of connection `i`'s hello. `Err((why, closed))` drops it.
    fn progress_hello(&mut self, i: usize) -> Result<Option<Hello>, (String, bool)> {
        let p = &mut self.pending[i];
        match p.reader.read_from(&mut p.stream) {
            Ok(ReadProgress::Record(kind::HELLO)) => decode_hello(p.reader.body())
                .map(Some)
                .map_err(|e| (e.to_string(), false)),
            Ok(ReadProgress::Record(k)) => {
                Err((format!("expected a hello, got record kind {k}"), false))
            }
            Ok(ReadProgress::Pending) => match p.reader.head() {
                // Refuse a wrong kind as soon as its prefix is in.
                Some((_, k)) if k != kind::HELLO => {
                    Err((format!("expected a hello, got record kind {k}"), false))
                }
                _ => Ok(None),
            },
            Ok(ReadProgress::Closed) if p.reader.buffered() == 0 => {
                Err(("closed the connection without a hello".into(), true))
            }
            Ok(ReadProgress::Closed) => Err((
                format!(
                    "closed the connection mid-record after {} of its hello",
                    p.reader.progress()
                ),
                true,
            )),
            Err(e) => Err((e.to_string(), false)),
        }
    }

    /// Logs and records a refused peer.
    fn refuse(&mut self, kind: RefusalKind, agent: Option<u32>, peer: SocketAddr, why: String) {
        match agent {
            Some(agent) => warn!(%peer, agent, "TCP agent refused: {why}"),
            None => warn!(%peer, "TCP peer dropped: {why}"),
        }
        self.refusals.push(PeerRefusal {
            kind,
            agent,
            peer: peer.to_string(),
            reason: why,
        });
    }

    /// Tells a peer why its hello is refused (best effort), then logs and records it.
    fn refuse_hello(&mut self, stream: &mut TcpStream, peer: SocketAddr, agent: u32, r: Reject) {
        let _ = stream.set_nonblocking(false);
        let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
        let _ = write_record(stream, kind::REJECT, &r.encode());
        self.refuse(RefusalKind::of_reject(r.code), Some(agent), peer, r.message);
    }

    fn admit(&mut self, p: Pending, hello: Hello) {
        let mut stream = p.stream;
        let peer = p.peer;
        let agent = hello.agent_id;
        let served: Vec<u32> = self.slots.iter().map(|s| s.id).collect();
        let slot = match admit(
            &hello,
            self.token.as_deref(),
            "wrong tcp_token",
            &served,
            &self.layouts,
        ) {
            Ok(slot) => slot,
            Err(r) => return self.refuse_hello(&mut stream, peer, agent, r),
        };
        if let Some(old) = &self.slots[slot].conn
            && wait::peer_closed(old.stream.as_raw_fd())
        {
            // The agent died or reconnects; its old connection is gone already.
            self.drop_conn(slot, "connection closed (a new connection takes its place)");
        }
        if self.slots[slot].conn.is_some() {
            return self.refuse_hello(&mut stream, peer, agent, Reject::id_in_use(agent));
        }
        let mut welcome = [0u8; 16];
        welcome[..4].copy_from_slice(&PROTOCOL_VERSION.to_le_bytes());
        welcome[4..12].copy_from_slice(&LAYOUT_HASH.to_le_bytes());
        welcome[12..].copy_from_slice(&(self.slots[slot].body_len as u32).to_le_bytes());
        let sent = stream
            .set_nonblocking(false)
            .and_then(|()| stream.set_write_timeout(Some(Duration::from_secs(1))))
            .and_then(|()| write_record(&mut stream, kind::WELCOME, &welcome))
            .and_then(|()| stream.set_nonblocking(true));
        if let Err(e) = sent {
            warn!(peer = %p.peer, "TCP agent lost during welcome: {e}");
            return;
        }
        // Watched like the other agents' sockets (a deferred hello's socket was muted).
        let fd = stream.as_raw_fd();
        if let Err(e) = self.poll.set_readable(fd, fd as u64, !self.muted) {
            warn!(peer = %p.peer, "TCP agent lost during welcome: epoll: {e}");
            return;
        }
        info!(agent = hello.agent_id, peer = %p.peer, "TCP agent connected");
        self.slots[slot].conn = Some(Conn {
            stream,
            peer: p.peer,
            reader: RecordReader::new(self.max_motor_body),
            partial_since: None,
        });
    }

    /// Writes a whole record to a non-blocking socket, waiting for writability with a
    /// deadline (a stalled agent cannot hold the host forever).
    fn send_all(stream: &mut TcpStream, data: &[u8], deadline: Instant) -> io::Result<()> {
        wait::write_all_until(stream, data, deadline, "agent does not read")
    }

    /// Reads what has arrived from `c`, handing complete motor batches to `sink`.
    /// `Err(why)` drops the connection, and so does a leave batch (`Err` with
    /// [`LEFT`]).
    fn drain_conn(
        c: &mut Conn,
        slot: usize,
        stall_timeout: Duration,
        sink: &mut BatchSink<'_>,
    ) -> Result<(), String> {
        for _ in 0..MAX_RECORDS_PER_DRAIN {
            match c.reader.read_from(&mut c.stream) {
                Ok(ReadProgress::Record(kind::MOTOR)) => {
                    c.partial_since = None;
                    let (header, commands) =
                        decode_motor(c.reader.body()).map_err(|e| e.to_string())?;
                    sink(slot, &header, commands);
                    if header.is_leave() {
                        // The agent is gone: free its id for a new connection now.
                        return Err(LEFT.into());
                    }
                }
                Ok(ReadProgress::Record(k)) => {
                    return Err(format!("sent record kind {k}, expected motor batches"));
                }
                Ok(ReadProgress::Pending) => {
                    if let Some((_, k)) = c.reader.head()
                        && k != kind::MOTOR
                    {
                        return Err(format!("sent record kind {k}, expected motor batches"));
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
                        return Err(stall_reason(&c.reader, stall_timeout));
                    }
                    return Ok(());
                }
                Ok(ReadProgress::Closed) if c.reader.buffered() == 0 => {
                    return Err("connection closed".into());
                }
                Ok(ReadProgress::Closed) => {
                    return Err(format!(
                        "connection closed mid-record after {} of a motor batch",
                        c.reader.progress()
                    ));
                }
                Err(e) => return Err(e.to_string()),
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
        hellos.chain(stalls).min()
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

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        self.refusals.take(sink)
    }

    fn is_connected(&self, slot: usize) -> bool {
        self.slots.get(slot).is_some_and(|s| s.conn.is_some())
    }

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
        let result = match &mut s.conn {
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
                self.drop_conn(slot, &format!("cannot send its frame: {e}"));
                Ok(false)
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
            let failure = match &mut self.slots[slot].conn {
                Some(c) => Self::drain_conn(c, slot, stall_timeout, sink).err(),
                None => None,
            };
            match failure {
                Some(why) if why == LEFT => {
                    if let Some(c) = self.slots[slot].conn.take() {
                        debug!(agent = self.slots[slot].id, peer = %c.peer, "TCP agent left");
                    }
                }
                Some(why) => self.drop_conn(slot, &why),
                None => {}
            }
        }
        Ok(())
    }

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

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    fn local_addr(&self) -> Option<SocketAddr> {
        Some(self.local_addr)
    }
}
