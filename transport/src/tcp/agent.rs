//! The TCP transport's agent side: connect and hello, read the newest frame, send batches,
//! and come back after a lost link (`[sync] resume_window`).
//!
//! # A lost link
//! Frames are read piece by piece as their bytes arrive: a frame that arrives slowly (a
//! lossy link) is waited for as long as the connection lives. When the connection breaks
//! without the host's shutdown record (a reset, a timeout, a close), the agent connects
//! again with the same hello, every 250 ms or so, until the resume window has passed since
//! it saw the link go; meanwhile its waits see a live host. A host that refuses the
//! connection (nothing listens: its process is gone) ends the attempts at once. Back, the
//! host sends the frame of the cycle it waits for again if this agent's stop for it did not
//! arrive: the agent then sends that stop batch again (the whole batch: the host never
//! applied any of it, since it reads a record whole or not at all) instead of handing the
//! frame to the caller once more; a frame the caller has not stopped yet is handed on and
//! dropped as an old one by [`wait_for_newer_frame`](super::super::wait_for_newer_frame).

use super::*;
use crate::rounded::Rounded;
use vrsync_protocol::channel_layout::ChannelLayout;

// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

type Pool = std::rc::Rc<std::cell::RefCell<Vec<RecordBuf>>>;

/// The longest one attempt to connect again after a lost link may take before the wait
/// that made it goes on (the attempts repeat until the resume window has passed).
pub const RECONNECT_ATTEMPT: Duration = Duration::from_millis(250);

/// A received TCP frame. Its buffer goes back to the agent's pool when dropped, so
/// receiving allocates nothing in steady state. The header is read where it arrived
/// (the record's body starts 8-aligned), not copied: a frame is moved several times on
/// its way to the caller, and a copied header (1.3 KB) made each move a copy of it.
#[derive(Debug)]
pub struct TcpFrame {
    /// The record; its body starts with a whole header (checked by [`TcpFrame::new`]).
    buf: RecordBuf,
    pool: Pool,
}

/// What [`TcpFrame::header`] would give for a body without a header: never, as
/// [`TcpFrame::new`] checks that it has one.
static NO_HEADER: SensorHeader = zerocopy::transmute!([0u8; HEADER]);

impl TcpFrame {
    /// The frame of a received record, if its body starts with a whole, aligned header.
    fn new(buf: RecordBuf, pool: Pool) -> Result<Self, (RecordBuf, AgentReceiveError)> {
        if SensorHeader::ref_from_prefix(buf.body()).is_err() {
            return Err((buf, AgentReceiveError::Protocol("frame header".into())));
        }
        Ok(Self { buf, pool })
    }

    /// The header.
    pub fn header(&self) -> &SensorHeader {
        SensorHeader::ref_from_prefix(self.buf.body()).map_or(&NO_HEADER, |(h, _)| h)
    }

    /// The image bytes.
    pub fn payload(&self) -> &[u8] {
        self.buf.body().get(HEADER..).unwrap_or(&[])
    }
}

impl Drop for TcpFrame {
    fn drop(&mut self) {
        let buf = core::mem::take(&mut self.buf);
        if let Ok(mut pool) = self.pool.try_borrow_mut() {
            pool.push(buf);
        }
    }
}

/// What connecting (again) needs.
#[derive(Debug)]
struct Link {
    session: String,
    id: u32,
    addr: SocketAddr,
    hello: Vec<u8>,
    channels: ChannelLayout,
    resume_window: Duration,
}

/// A lost link: since when, and what was seen.
#[derive(Debug)]
struct Lost {
    since: Instant,
    reason: String,
}

/// Why a handshake did not connect.
enum HandshakeError {
    /// Nothing answered yet, or (when resuming) the host still holds the lost connection.
    NotYet(String),
    /// A final answer.
    Failed(AgentConnectError),
}

/// The agent side of the TCP transport. With a resume window it connects again by itself
/// after a lost link, until the window has passed (see the module's docs in
/// `tcp/agent.rs`).
#[derive(Debug)]
pub struct TcpAgent {
    stream: TcpStream,
    reader: RecordReader,
    max_frame_body: usize,
    write_timeout: Duration,
    pool: Pool,
    out: Vec<u8>,
    /// The latest stop batch sent (its whole record) and its cycle.
    stop_record: Vec<u8>,
    stop_cycle: Option<u64>,
    closed: bool,
    /// Why the connection broke without a shutdown, once the agent gave up on it.
    gone: Option<String>,
    /// The link is lost and the agent tries to connect again.
    lost: Option<Lost>,
    link: Link,
    signals: SignalHandling,
}

/// Whether a hello's write or the wait for its answer failed because the peer closed the
/// connection before answering (worth another connection), not because it is slow or
/// spoke nonsense.
fn closed_unanswered(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        ErrorKind::UnexpectedEof
            | ErrorKind::ConnectionReset
            | ErrorKind::ConnectionAborted
            | ErrorKind::BrokenPipe
    )
}

impl TcpAgent {
    /// A connection to `addr`, tried until `deadline` (or a termination request):
    /// `Err(Ok(last error))` if none was made. When `resuming`, a refused connection is
    /// final (`Err(Err(why))`): the host's machine answers and nothing listens, so its
    /// process is gone.
    fn open(
        addr: SocketAddr,
        deadline: Instant,
        signals: SignalHandling,
        resuming: bool,
    ) -> Result<TcpStream, Result<String, String>> {
        retry_until(
            deadline,
            || signals.termination_requested(),
            || {
                let left = deadline.saturating_duration_since(Instant::now());
                match TcpStream::connect_timeout(&addr, left.max(Duration::from_millis(1))) {
                    Ok(s) => Attempt::Done(s),
                    Err(e) if resuming && e.kind() == ErrorKind::ConnectionRefused => {
                        Attempt::Failed(format!("{addr} refuses connections ({e})"))
                    }
                    Err(e) => Attempt::NotYet(e.to_string()),
                }
            },
        )
    }

    /// Connects to `link.addr` and says hello, until `deadline`; returns the welcomed
    /// connection (non-blocking, its link watched with a resume window) and the largest
    /// frame body the host will send. The host's answer is waited for up to twice
    /// [`HELLO_TIMEOUT`] after the hello, and, when `resuming` is the moment the agent
    /// gives up, no later than that.
    fn handshake(
        link: &Link,
        deadline: Instant,
        signals: SignalHandling,
        resuming: Option<Instant>,
    ) -> Result<(TcpStream, usize), HandshakeError> {
        let answer_by = || {
            let by = Instant::now() + HELLO_TIMEOUT * 2;
            resuming.map_or(by, |give_up| by.min(give_up))
        };
        let (session, id, addr) = (&link.session, link.id, link.addr);
        let hs = |reason: String| {
            HandshakeError::Failed(AgentConnectError::Transport {
                session: session.clone(),
                agent: id,
                detail: format!("TCP handshake with {addr} failed: {reason}"),
            })
        };
        let mismatch = |host_protocol: u32, host_layout: u64| AgentConnectError::VersionMismatch {
            session: session.clone(),
            host_protocol: host_protocol.to_string(),
            host_layout: format!("{host_layout:016x}"),
            agent_protocol: PROTOCOL_VERSION,
            agent_layout: format!("{LAYOUT_HASH:016x}"),
        };
        // A connection closed before any answer to the hello (a relay or tunnel that
        // accepted it but cannot reach the host yet, a host restarting) is tried again
        // until the deadline, as a refused connection is.
        let mut backoff = Duration::from_millis(10);
        let (mut stream, prefix) = loop {
            let mut stream = match Self::open(addr, deadline, signals, resuming.is_some()) {
                Ok(stream) => stream,
                Err(Ok(missing)) => return Err(HandshakeError::NotYet(missing)),
                Err(Err(refused)) => return Err(hs(refused)),
            };
            set_nodelay(&stream).map_err(|e| hs(e.to_string()))?;
            let mut prefix = [0u8; PREFIX];
            let answered = write_record(&mut stream, kind::HELLO, &link.hello)
                .and_then(|()| read_exact_deadline(&mut stream, &mut prefix, answer_by()));
            match answered {
                Ok(()) => break (stream, prefix),
                Err(e)
                    if closed_unanswered(&e)
                        && Instant::now() + backoff < deadline
                        && !signals.termination_requested() =>
                {
                    debug!(%addr, "TCP hello closed unanswered ({e}); trying again");
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(Duration::from_millis(200));
                }
                Err(e) if resuming.is_some() && (closed_unanswered(&e) || link_lost(&e)) => {
                    return Err(HandshakeError::NotYet(e.to_string()));
                }
                Err(e) => return Err(hs(e.to_string())),
            }
        };
        let reply_deadline = answer_by();
        let (len, k) = decode_prefix(prefix, 4096).map_err(|e| hs(e.to_string()))?;
        let mut body = vec![0u8; len];
        read_exact_deadline(&mut stream, &mut body, reply_deadline)
            .map_err(|e| hs(e.to_string()))?;
        match k {
            kind::WELCOME => {
                let (Some(proto), Some(layout), Some(max)) =
                    (le_u32(&body, 0), le_u64(&body, 4), le_u32(&body, 12))
                else {
                    return Err(hs("malformed welcome".into()));
                };
                if proto != PROTOCOL_VERSION || layout != LAYOUT_HASH {
                    return Err(HandshakeError::Failed(mismatch(proto, layout)));
                }
                let watched = if link.resume_window.is_zero() {
                    Ok(())
                } else {
                    watch_link(&stream)
                };
                watched
                    .and_then(|()| stream.set_nonblocking(true))
                    .map_err(|e| hs(e.to_string()))?;
                Ok((stream, max as usize))
            }
            kind::REJECT => {
                let r = Reject::decode(&body).ok_or_else(|| hs("malformed reject".into()))?;
                if resuming.is_some() && r.code == reject::ID_IN_USE {
                    // The host has not seen the lost connection go yet.
                    return Err(HandshakeError::NotYet(r.message));
                }
                Err(HandshakeError::Failed(AgentConnectError::from_reject(
                    r,
                    session,
                    id,
                    &link.channels,
                    mismatch,
                )))
            }
            other => Err(hs(format!("unexpected reply kind {other}"))),
        }
    }

    /// Connects to `transport.tcp_listen`, retrying until `timeout`, and says hello.
    /// `signals` says whether SIGINT/SIGTERM handlers are installed (see
    /// [`SignalHandling`]).
    ///
    /// # Errors
    /// [`AgentConnectError`].
    fn connect_with_token(
        config: &Config,
        id: u32,
        timeout: Duration,
        token: Option<&[u8]>,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        signals.apply();
        let started = Instant::now();
        let channels = config.channel_layout_of(id);
        let link = Link {
            session: config.session.clone(),
            id,
            addr: config.transport.tcp_listen,
            hello: encode_hello(&Hello {
                protocol_version: PROTOCOL_VERSION,
                layout_hash: LAYOUT_HASH,
                agent_id: id,
                channels: channels.hash(),
                token: token.map(<[u8]>::to_vec).unwrap_or_default(),
            }),
            channels,
            resume_window: config.sync.resume_window,
        };
        let (stream, max_frame_body) = Self::handshake(&link, started + timeout, signals, None)
            .map_err(|e| match e {
                HandshakeError::NotYet(e) => AgentConnectError::HostNotFound {
                    session: link.session.clone(),
                    agent: id,
                    waited: started.elapsed(),
                    looked_for: format!("nothing accepts TCP connections at {} ({e})", link.addr),
                },
                HandshakeError::Failed(e) => e,
            })?;
        let pool: Pool = Default::default();
        pool.borrow_mut()
            .push(RecordBuf::with_capacity(max_frame_body));
        let batch = PREFIX
            + core::mem::size_of::<MotorHeader>()
            + config.transport.max_commands_per_cycle as usize
                * core::mem::size_of::<MotorCommand>();
        Ok(Self {
            stream,
            reader: RecordReader::new(max_frame_body),
            max_frame_body,
            write_timeout: config.sync.stop_timeout.max(Duration::from_secs(5)),
            pool,
            out: Vec::with_capacity(batch),
            stop_record: Vec::with_capacity(batch),
            stop_cycle: None,
            closed: false,
            gone: None,
            lost: None,
            link,
            signals,
        })
    }

    /// The connection broke without the host's shutdown: with a resume window the agent
    /// connects again (see the module's docs), else the host is gone.
    fn lose_link(&mut self, reason: String) {
        if self.lost.is_some() || self.gone.is_some() || self.closed {
            return;
        }
        if self.link.resume_window.is_zero() {
            self.gone = Some(reason);
            return;
        }
        warn!(
            agent = self.link.id,
            "TCP link to the host lost ({reason}): connecting again for up to {} \
             (sync.resume_window)",
            Rounded(self.link.resume_window)
        );
        self.lost = Some(Lost {
            since: Instant::now(),
            reason,
        });
    }

    /// One attempt to connect again after a lost link, of at most `budget` (at least
    /// [`RECONNECT_ATTEMPT`]) for the connection itself; gives up once the resume window
    /// has passed since the link was lost, or at once when the host is gone.
    fn try_resume(&mut self, budget: Duration) {
        let Some(lost) = &self.lost else {
            return;
        };
        let give_up = lost.since + self.link.resume_window;
        let now = Instant::now();
        if now >= give_up {
            self.give_up();
            return;
        }
        let deadline = (now + budget.max(RECONNECT_ATTEMPT)).min(give_up);
        match Self::handshake(&self.link, deadline, self.signals, Some(give_up)) {
            Ok((stream, max_frame_body)) => {
                info!(
                    agent = self.link.id,
                    down_s = lost.since.elapsed().as_secs_f64(),
                    "TCP link to the host back: resumed"
                );
                self.stream = stream;
                // What the old connection held of a record is gone with it.
                self.reader = RecordReader::new(max_frame_body);
                self.max_frame_body = max_frame_body;
                self.lost = None;
            }
            Err(HandshakeError::NotYet(e)) => {
                debug!(agent = self.link.id, "TCP link still lost: {e}");
            }
            Err(HandshakeError::Failed(e)) => {
                self.gone = Some(format!(
                    "the link was lost ({}) and connecting again failed: {e}",
                    lost.reason
                ));
                self.lost = None;
            }
        }
    }

    /// The resume window passed with the link still lost.
    fn give_up(&mut self) {
        if let Some(lost) = self.lost.take() {
            self.gone = Some(format!(
                "the link was lost ({}) and did not come back within {} (sync.resume_window)",
                lost.reason,
                Rounded(self.link.resume_window)
            ));
        }
    }

    /// Reads the records that arrived, without waiting for one; returns the newest frame
    /// among them. A shutdown record marks the session closed; a close or a broken
    /// connection marks the link lost (frames read before are still returned).
    fn read_arrived(&mut self) -> Result<Option<TcpFrame>, AgentReceiveError> {
        // Every frame the caller holds keeps a pool reference (the agent keeps one more).
        let held = std::rc::Rc::strong_count(&self.pool) - 1;
        if held >= AGENT_MAX_HELD_FRAMES {
            return Err(AgentReceiveError::TooManyFramesHeld {
                max: AGENT_MAX_HELD_FRAMES,
            });
        }
        let mut newest: Option<TcpFrame> = None;
        while !self.closed && self.gone.is_none() && self.lost.is_none() {
            match self.reader.read_from(&mut self.stream) {
                Ok(ReadProgress::Record(kind::FRAME)) => {
                    let len = self.reader.body().len();
                    if len < HEADER {
                        return Err(AgentReceiveError::Protocol(format!(
                            "frame of {len} bytes has no header"
                        )));
                    }
                    let mut buf = self.pool.borrow_mut().pop().unwrap_or_default();
                    self.reader.take_record(&mut buf);
                    let frame = match TcpFrame::new(buf, self.pool.clone()) {
                        Ok(frame) => frame,
                        Err((buf, e)) => {
                            self.pool.borrow_mut().push(buf);
                            return Err(e);
                        }
                    };
                    if self.stop_cycle == Some(frame.header().cycle) {
                        // The host, back after a lost link, did not get this cycle's stop
                        // (dropping the frame returns its buffer to the pool).
                        drop(frame);
                        self.resend_stop();
                        continue;
                    }
                    // Dropping an older frame returns its buffer to the pool.
                    newest = Some(frame);
                }
                Ok(ReadProgress::Record(kind::SHUTDOWN)) => self.closed = true,
                Ok(ReadProgress::Record(other)) => {
                    return Err(AgentReceiveError::Protocol(format!(
                        "unexpected record kind {other}"
                    )));
                }
                Ok(ReadProgress::Pending) => break,
                Ok(ReadProgress::Closed) => {
                    let why = match self.reader.buffered() {
                        0 => "connection closed without shutdown".to_owned(),
                        _ => format!(
                            "connection closed mid-record after {} of a frame",
                            self.reader.progress()
                        ),
                    };
                    self.lose_link(why);
                }
                Err(RecordReadError::Io(e)) => self.lose_link(e.to_string()),
                Err(e) => return Err(AgentReceiveError::Protocol(e.to_string())),
            }
        }
        Ok(newest)
    }

    /// Sends the latest stop batch again (the host, back after a lost link, asks for its
    /// cycle again: that batch never reached it).
    fn resend_stop(&mut self) {
        debug!(agent = self.link.id, cycle = ?self.stop_cycle, "stop sent again after a lost link");
        let deadline = Instant::now() + self.write_timeout;
        let sent = crate::wait::write_all_until(
            &mut self.stream,
            &self.stop_record,
            deadline,
            "the host does not read",
        );
        if let Err(e) = sent {
            self.lose_link(format!("cannot send the motor batch again: {e}"));
        }
    }

    /// Sends a motor batch (the stop flag in the header ends the agent's cycle). A stop
    /// batch is kept, to be sent again if the link is lost before the host got it.
    ///
    /// # Errors
    /// A string describing the I/O failure.
    fn send_record(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), String> {
        let header = MotorHeader {
            command_count: commands.len() as u32,
            ..*header
        };
        let body = core::mem::size_of::<MotorHeader>() + core::mem::size_of_val(commands);
        self.out.clear();
        self.out.extend_from_slice(&(body as u32).to_le_bytes());
        self.out.extend_from_slice(&kind::MOTOR.to_le_bytes());
        self.out.extend_from_slice(header.as_bytes());
        self.out.extend_from_slice(commands.as_bytes());
        if header.is_stop() {
            self.stop_record.clear();
            self.stop_record.extend_from_slice(&self.out);
            self.stop_cycle = Some(header.cycle);
        }
        if self.lost.is_some() {
            // Sent when the host, back, asks for this cycle again.
            return Ok(());
        }
        let deadline = Instant::now() + self.write_timeout;
        let sent = crate::wait::write_all_until(
            &mut self.stream,
            &self.out,
            deadline,
            "the host does not read",
        );
        match sent {
            Ok(()) => Ok(()),
            Err(e) if !self.link.resume_window.is_zero() => {
                self.lose_link(format!("cannot send the motor batch: {e}"));
                Ok(())
            }
            Err(e) => {
                // Did the host close the session cleanly? Its shutdown record would be
                // waiting behind any frames not read yet.
                self.look_for_shutdown();
                Err(format!("cannot send the motor batch to the host: {e}"))
            }
        }
    }

    /// Whether the host closed the session (its shutdown record was read).
    pub fn host_closed(&self) -> bool {
        self.closed
    }

    fn look_for_shutdown(&mut self) {
        let deadline = Instant::now() + Duration::from_millis(200);
        while !self.closed && Instant::now() < deadline {
            match self.reader.read_from(&mut self.stream) {
                Ok(ReadProgress::Record(kind::SHUTDOWN)) => self.closed = true,
                Ok(ReadProgress::Record(_)) => {}
                Ok(ReadProgress::Pending) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    let fd = self.stream.as_raw_fd();
                    let _ = crate::wait::poll_one(fd, libc::POLLIN, left);
                }
                Ok(ReadProgress::Closed) | Err(_) => return,
            }
        }
    }

    /// This agent's id.
    pub fn id(&self) -> u32 {
        self.link.id
    }
}

impl AgentFrame for TcpFrame {
    fn header(&self) -> &SensorHeader {
        TcpFrame::header(self)
    }

    fn payload(&self) -> &[u8] {
        TcpFrame::payload(self)
    }
}

impl AgentTransport for TcpAgent {
    type Frame = TcpFrame;

    fn connect(
        config: &Config,
        id: u32,
        timeout: Duration,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        let token = config.transport.tcp_token.as_deref().map(str::as_bytes);
        Self::connect_with_token(config, id, timeout, token, signals)
    }

    fn try_receive_newest(&mut self) -> Result<Option<TcpFrame>, AgentReceiveError> {
        self.read_arrived()
    }

    fn wait_readable(&mut self, timeout: Duration) {
        if self.lost.is_some() {
            self.try_resume(timeout);
            return;
        }
        if self.closed || self.gone.is_some() {
            return;
        }
        // A failed or interrupted poll ends the wait early; the next read reports what
        // broke.
        let _ = crate::wait::poll_one(self.stream.as_raw_fd(), libc::POLLIN, timeout);
    }

    fn discard_wakeups(&mut self) {}

    fn host_liveness(&mut self, _check_process: bool) -> HostLiveness {
        if let Some(lost) = &self.lost
            && lost.since.elapsed() >= self.link.resume_window
        {
            self.give_up();
        }
        // TCP sees the host's end directly: the shutdown record, or the close.
        if self.closed {
            HostLiveness::Closed
        } else if let Some(reason) = &self.gone {
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
        self.send_record(header, commands).map_err(|e| {
            if self.closed {
                AgentSendError::HostClosed
            } else {
                AgentSendError::Transport(e)
            }
        })
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }
}
