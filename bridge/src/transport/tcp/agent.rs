//! The TCP transport's agent side: connect and hello, read the newest frame, send batches.

use super::*;
// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

type Pool = std::rc::Rc<std::cell::RefCell<Vec<RecordBuf>>>;

/// A received TCP frame. Its buffer goes back to the agent's pool when dropped, so
/// receiving allocates nothing in steady state.
#[derive(Debug)]
pub struct TcpFrame {
    header: SensorHeader,
    buf: Option<RecordBuf>,
    pool: Pool,
}

impl TcpFrame {
    /// The header.
    pub fn header(&self) -> &SensorHeader {
        &self.header
    }

    /// The image bytes.
    pub fn payload(&self) -> &[u8] {
        self.buf
            .as_ref()
            .and_then(|b| b.body().get(HEADER..))
            .unwrap_or(&[])
    }
}

impl Drop for TcpFrame {
    fn drop(&mut self) {
        if let Some(buf) = self.buf.take()
            && let Ok(mut pool) = self.pool.try_borrow_mut()
        {
            pool.push(buf);
        }
    }
}

/// The agent side of the TCP transport.
#[derive(Debug)]
pub struct TcpAgent {
    id: u32,
    stream: TcpStream,
    max_frame_body: usize,
    stall_timeout: Duration,
    pool: Pool,
    out: Vec<u8>,
    closed: bool,
    /// Why the connection broke without a shutdown, once it did.
    gone: Option<String>,
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
    /// A connection to `addr`, tried until `deadline` (or a termination request); the last
    /// error if none was made.
    fn open(
        addr: SocketAddr,
        deadline: Instant,
        signals: SignalHandling,
    ) -> Result<TcpStream, String> {
        retry_until(
            deadline,
            || signals.termination_requested(),
            || {
                let left = deadline.saturating_duration_since(Instant::now());
                match TcpStream::connect_timeout(&addr, left.max(Duration::from_millis(1))) {
                    Ok(s) => Attempt::<_, ()>::Done(s),
                    Err(e) => Attempt::NotYet(e.to_string()),
                }
            },
        )
        .map_err(|e| e.unwrap_or_default())
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
        let session = &config.session;
        let addr = config.transport.tcp_listen;
        let started = Instant::now();
        let deadline = started + timeout;
        let hs = |reason: String| AgentConnectError::Transport {
            session: session.clone(),
            agent: id,
            detail: format!("TCP handshake with {addr} failed: {reason}"),
        };
        let mismatch = |host_protocol: u32, host_layout: u64| AgentConnectError::VersionMismatch {
            session: session.clone(),
            host_protocol: host_protocol.to_string(),
            host_layout: format!("{host_layout:016x}"),
            agent_protocol: PROTOCOL_VERSION,
            agent_layout: format!("{LAYOUT_HASH:016x}"),
        };
        let channels = config.channel_layout_of(id);
        let hello = encode_hello(&Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            channels: channels.hash(),
            token: token.map(<[u8]>::to_vec).unwrap_or_default(),
        });
        // A connection closed before any answer to the hello (a relay or tunnel that
        // accepted it but cannot reach the host yet, a host restarting) is tried again
        // until the deadline, as a refused connection is.
        let mut backoff = Duration::from_millis(10);
        let (mut stream, prefix) = loop {
            let mut stream = Self::open(addr, deadline, signals).map_err(|e| {
                AgentConnectError::HostNotFound {
                    session: session.clone(),
                    agent: id,
                    waited: started.elapsed(),
                    looked_for: format!("nothing accepts TCP connections at {addr} ({e})"),
                }
            })?;
            set_nodelay(&stream).map_err(|e| hs(e.to_string()))?;
            let mut prefix = [0u8; PREFIX];
            let answered = write_record(&mut stream, kind::HELLO, &hello).and_then(|()| {
                read_exact_deadline(&mut stream, &mut prefix, Instant::now() + HELLO_TIMEOUT * 2)
            });
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
                Err(e) => return Err(hs(e.to_string())),
            }
        };
        let reply_deadline = Instant::now() + HELLO_TIMEOUT * 2;
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
                    return Err(mismatch(proto, layout));
                }
                let max_frame_body = max as usize;
                let pool: Pool = Default::default();
                pool.borrow_mut()
                    .push(RecordBuf::with_capacity(max_frame_body));
                Ok(Self {
                    id,
                    stream,
                    max_frame_body,
                    stall_timeout: config.sync.stop_timeout.max(Duration::from_secs(5)),
                    pool,
                    out: Vec::with_capacity(
                        PREFIX
                            + core::mem::size_of::<MotorHeader>()
                            + config.transport.max_commands_per_cycle as usize
                                * core::mem::size_of::<MotorCommand>(),
                    ),
                    closed: false,
                    gone: None,
                    signals,
                })
            }
            kind::REJECT => {
                let r = Reject::decode(&body).ok_or_else(|| hs("malformed reject".into()))?;
                Err(AgentConnectError::from_reject(
                    r, session, id, &channels, mismatch,
                ))
            }
            other => Err(hs(format!("unexpected reply kind {other}"))),
        }
    }

    /// Reads the records that arrived, without waiting for one; returns the newest frame
    /// among them. A shutdown record marks the session closed; a close or a broken
    /// connection marks the host gone (frames read before are still returned).
    fn read_arrived(&mut self) -> Result<Option<TcpFrame>, AgentReceiveError> {
        // Every frame the caller holds keeps a pool reference (the agent keeps one more).
        let held = std::rc::Rc::strong_count(&self.pool) - 1;
        if held >= AGENT_MAX_HELD_FRAMES {
            return Err(AgentReceiveError::TooManyFramesHeld {
                max: AGENT_MAX_HELD_FRAMES,
            });
        }
        let mut newest: Option<TcpFrame> = None;
        while !self.closed && self.gone.is_none() && self.readable_now() {
            // A record has begun (or the connection ended): read it whole, bounded by the
            // stall timeout.
            let stall = Instant::now() + self.stall_timeout;
            let mut prefix = [0u8; PREFIX];
            match self.stream.read(&mut prefix[..1]) {
                Ok(0) => {
                    self.gone = Some("connection closed without shutdown".into());
                    break;
                }
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) =>
                {
                    continue;
                }
                Err(e) => {
                    self.gone = Some(e.to_string());
                    break;
                }
            }
            if let Err(e) = read_exact_deadline(&mut self.stream, &mut prefix[1..], stall) {
                self.gone = Some(e.to_string());
                break;
            }
            let (len, k) = decode_prefix(prefix, self.max_frame_body)
                .map_err(|e| AgentReceiveError::Protocol(e.to_string()))?;
            match k {
                kind::FRAME => {
                    if len < HEADER {
                        return Err(AgentReceiveError::Protocol(format!(
                            "frame of {len} bytes has no header"
                        )));
                    }
                    let mut buf = self.pool.borrow_mut().pop().unwrap_or_default();
                    buf.reserve_body(len);
                    let body = &mut buf.bytes_mut()[PREFIX..];
                    if let Err(e) = read_exact_deadline(&mut self.stream, body, stall) {
                        self.gone = Some(e.to_string());
                        break;
                    }
                    let header = SensorHeader::read_from_bytes(&buf.body()[..HEADER])
                        .map_err(|_| AgentReceiveError::Protocol("frame header".into()))?;
                    // Dropping an older frame returns its buffer to the pool.
                    newest = Some(TcpFrame {
                        header,
                        buf: Some(buf),
                        pool: self.pool.clone(),
                    });
                }
                kind::SHUTDOWN => self.closed = true,
                other => {
                    return Err(AgentReceiveError::Protocol(format!(
                        "unexpected record kind {other}"
                    )));
                }
            }
        }
        Ok(newest)
    }

    fn readable_now(&self) -> bool {
        crate::transport::wait::readable_now(self.stream.as_raw_fd())
    }

    /// Sends a motor batch (the stop flag in the header ends the agent's cycle).
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
        let sent = self
            .stream
            .set_write_timeout(Some(self.stall_timeout))
            .and_then(|()| self.stream.write_all(&self.out));
        if let Err(e) = sent {
            // Did the host close the session cleanly? Its shutdown record would be waiting
            // behind any frames not read yet.
            self.look_for_shutdown();
            return Err(format!("cannot send the motor batch to the host: {e}"));
        }
        Ok(())
    }

    /// Whether the host closed the session (its shutdown record was read).
    pub fn host_closed(&self) -> bool {
        self.closed
    }

    fn look_for_shutdown(&mut self) {
        let deadline = Instant::now() + Duration::from_millis(200);
        let mut prefix = [0u8; PREFIX];
        let mut scratch = [0u8; 64 * 1024];
        while read_exact_deadline(&mut self.stream, &mut prefix, deadline).is_ok() {
            let Ok((mut len, k)) = decode_prefix(prefix, self.max_frame_body) else {
                return;
            };
            if k == kind::SHUTDOWN {
                self.closed = true;
                return;
            }
            while len > 0 {
                let n = len.min(scratch.len());
                if read_exact_deadline(&mut self.stream, &mut scratch[..n], deadline).is_err() {
                    return;
                }
                len -= n;
            }
        }
    }

    /// This agent's id.
    pub fn id(&self) -> u32 {
        self.id
    }
}

impl AgentFrame for TcpFrame {
    fn header(&self) -> &SensorHeader {
        &self.header
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
        if self.closed || self.gone.is_some() {
            return;
        }
        // A failed or interrupted poll ends the wait early; the next read reports what
        // broke.
        let _ = crate::transport::wait::poll_one(self.stream.as_raw_fd(), libc::POLLIN, timeout);
    }

    fn discard_wakeups(&mut self) {}

    fn host_liveness(&mut self, _check_process: bool) -> HostLiveness {
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
