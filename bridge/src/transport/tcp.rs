//! The TCP transport: the same protocol for agents on other hosts, and the baseline the
//! shared-memory transport is measured against.
//!
//! Every record is `[len: u32 LE][kind: u32 LE][body: len bytes]`. Agents connect and send
//! [`kind::HELLO`] (magic, protocol version, layout hash, agent id, optional token); the host
//! answers [`kind::WELCOME`] (with the largest frame it will send) or [`kind::REJECT`] (a
//! reason) and closes. Then the host sends one [`kind::FRAME`] per cycle (sensor header +
//! images, which doubles as *start*), the agent answers [`kind::MOTOR`] batches (motor
//! header + commands; the stop flag ends its cycle), and [`kind::SHUTDOWN`] closes the
//! session.
//!
//! The host renders straight into a per-agent record buffer laid out exactly as it goes on
//! the wire, and sends it with one write: no per-frame allocation, no extra copy. Sockets
//! use `TCP_NODELAY`. Reads are bounded: a length beyond the peer's maximum is an error,
//! never an allocation. The host never blocks on reading: it waits for readiness with
//! `poll(2)` on all agent sockets at once.
//!
//! # What a hostile or broken peer costs the host
//! Every record is read by a [`RecordReader`]: one buffer of the largest acceptable record,
//! allocated when the connection is accepted, never grown. Each misbehaviour drops that one
//! connection with a logged reason (`TCP peer dropped: …` before the hello, `TCP agent
//! dropped: …` after it); the host and the other agents go on.
//! - garbage, a wrong record kind, a length beyond the maximum ([`MAX_HELLO`] before the
//!   hello, the largest motor batch after it), a malformed hello or batch: dropped at once;
//! - a truncated record and a close: dropped when the close is read;
//! - wrong protocol version or layout, an agent id not in the session, an id already
//!   connected, a wrong or missing `tcp_token`: a [`kind::REJECT`] saying why (a version
//!   reject names both versions), then closed;
//! - a peer that connects and says nothing, or stalls in the middle of its hello: dropped
//!   [`HELLO_TIMEOUT`] after it connected; at most [`MAX_PENDING`] connections wait for
//!   their hello at once, more are closed at once;
//! - an admitted agent that stalls in the middle of a record: dropped once the record is
//!   not complete [`STALL_TIMEOUT`] (or the `stop_timeout`, if shorter) after its first
//!   bytes were seen; it is then no longer connected, so the barrier stops waiting for it;
//! - an agent that stops reading its frames: dropped when a frame cannot be written within
//!   the `stop_timeout` (at least 1 s);
//! - a flood of batches: each drain takes at most [`MAX_RECORDS_PER_DRAIN`] records per
//!   agent, so one agent cannot hold the host inside a drain.

use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant};

use tracing::{debug, info, warn};
use zerocopy::{FromBytes, IntoBytes};

use super::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, Attempt, BatchSink, FrameLoanMut, HostLiveness, HostTransport,
    HostTransportError, retry_until,
};
use crate::config::Config;
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};

/// Record kinds.
pub mod kind {
    /// agent → host: magic, protocol version, layout hash, agent id, token.
    pub const HELLO: u32 = 1;
    /// host → agent: protocol version, layout hash, max frame record length.
    pub const WELCOME: u32 = 2;
    /// host → agent: why the hello was refused (UTF-8), then the host closes.
    pub const REJECT: u32 = 3;
    /// host → agent: sensor header + images; also the *start* of the cycle.
    pub const FRAME: u32 = 4;
    /// agent → host: motor header + commands.
    pub const MOTOR: u32 = 5;
    /// host → agent: the session is closed.
    pub const SHUTDOWN: u32 = 6;
}

/// Bytes of the record prefix (`len` + `kind`).
pub const PREFIX: usize = 8;
/// Magic at the start of a hello.
pub const HELLO_MAGIC: [u8; 4] = *b"VRSY";
pub use crate::wire::MAX_TOKEN;
/// Longest hello body.
pub const MAX_HELLO: usize = 4 + 4 + 8 + 4 + 4 + MAX_TOKEN;
/// How long a new connection may take to say hello.
pub const HELLO_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a record may stay incomplete once its first bytes arrived from an admitted
/// agent (the host uses the `stop_timeout` instead when that is shorter). A working agent
/// writes each record in one go, so the rest follows within a network round trip.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(2);
/// Most connections that may wait for their hello at once; more are closed at once.
pub const MAX_PENDING: usize = 64;
/// Most records read from one agent in one [`HostTransport::drain`] call; the rest is read
/// by the next call.
pub const MAX_RECORDS_PER_DRAIN: usize = 256;

/// A decoded hello.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hello {
    /// The agent's protocol version.
    pub protocol_version: u32,
    /// The agent's layout hash.
    pub layout_hash: u64,
    /// The agent id it claims.
    pub agent_id: u32,
    /// The shared secret it presents (empty if none).
    pub token: Vec<u8>,
}

/// A malformed record or hello.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The length field exceeds what this side accepts.
    #[error("record of {len} bytes exceeds the maximum of {max}")]
    TooLong {
        /// Announced length.
        len: usize,
        /// Maximum.
        max: usize,
    },
    /// A record of an unexpected kind.
    #[error("unexpected record kind {found} (expected {expected})")]
    UnexpectedKind {
        /// Found.
        found: u32,
        /// Expected.
        expected: &'static str,
    },
    /// The body does not have the expected shape.
    #[error("malformed {what}: {reason}")]
    Malformed {
        /// Record type.
        what: &'static str,
        /// Detail.
        reason: String,
    },
}

/// Encodes a hello body.
pub fn encode_hello(hello: &Hello) -> Vec<u8> {
    let token = &hello.token[..hello.token.len().min(MAX_TOKEN)];
    let mut b = Vec::with_capacity(MAX_HELLO);
    b.extend_from_slice(&HELLO_MAGIC);
    b.extend_from_slice(&hello.protocol_version.to_le_bytes());
    b.extend_from_slice(&hello.layout_hash.to_le_bytes());
    b.extend_from_slice(&hello.agent_id.to_le_bytes());
    b.extend_from_slice(&(token.len() as u32).to_le_bytes());
    b.extend_from_slice(token);
    b
}

fn le_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

fn le_u64(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// Decodes a hello body. Never panics, never allocates beyond [`MAX_TOKEN`].
///
/// # Errors
/// [`DecodeError::Malformed`].
pub fn decode_hello(body: &[u8]) -> Result<Hello, DecodeError> {
    let bad = |reason: &str| DecodeError::Malformed {
        what: "hello",
        reason: reason.to_string(),
    };
    if body.len() > MAX_HELLO {
        return Err(bad("too long"));
    }
    if body.get(..4) != Some(&HELLO_MAGIC[..]) {
        return Err(bad("not a vrsync hello (bad magic)"));
    }
    let protocol_version = le_u32(body, 4).ok_or_else(|| bad("truncated"))?;
    let layout_hash = le_u64(body, 8).ok_or_else(|| bad("truncated"))?;
    let agent_id = le_u32(body, 16).ok_or_else(|| bad("truncated"))?;
    let token_len = le_u32(body, 20).ok_or_else(|| bad("truncated"))? as usize;
    if token_len > MAX_TOKEN || body.len() != 24 + token_len {
        return Err(bad("token length does not match the record"));
    }
    Ok(Hello {
        protocol_version,
        layout_hash,
        agent_id,
        token: body[24..].to_vec(),
    })
}

/// Splits a record prefix into `(len, kind)`, checking `len <= max`.
///
/// # Errors
/// [`DecodeError::TooLong`].
pub fn decode_prefix(prefix: [u8; PREFIX], max: usize) -> Result<(usize, u32), DecodeError> {
    let len = u32::from_le_bytes([prefix[0], prefix[1], prefix[2], prefix[3]]) as usize;
    let kind = u32::from_le_bytes([prefix[4], prefix[5], prefix[6], prefix[7]]);
    if len > max {
        return Err(DecodeError::TooLong { len, max });
    }
    Ok((len, kind))
}

/// Decodes a motor record body into its header and commands (borrowed, no allocation).
///
/// # Errors
/// [`DecodeError::Malformed`] if the body is not a header plus `command_count` commands.
pub fn decode_motor(body: &[u8]) -> Result<(MotorHeader, &[MotorCommand]), DecodeError> {
    let bad = |reason: String| DecodeError::Malformed {
        what: "motor batch",
        reason,
    };
    let hsize = core::mem::size_of::<MotorHeader>();
    let (h, rest) = body
        .split_at_checked(hsize)
        .ok_or_else(|| bad(format!("{} bytes, shorter than the header", body.len())))?;
    let header = MotorHeader::read_from_bytes(h).map_err(|_| bad("header".into()))?;
    let n = header.command_count as usize;
    if rest.len() != n * core::mem::size_of::<MotorCommand>() {
        return Err(bad(format!(
            "header announces {n} commands, body holds {} bytes",
            rest.len()
        )));
    }
    // MotorCommand has alignment 4; the body may sit at any offset, so copy-free access
    // needs an aligned body: callers keep bodies 8-byte aligned (see `RecordBuf`).
    let commands = <[MotorCommand]>::ref_from_bytes(rest)
        .map_err(|_| bad("commands are misaligned".into()))?;
    Ok((header, commands))
}

/// An 8-byte aligned, reusable record buffer: `[prefix][body]`.
#[derive(Debug, Default)]
pub struct RecordBuf {
    words: Vec<u64>,
    len: usize,
}

impl RecordBuf {
    /// A buffer able to hold a body of `body_capacity` bytes without growing.
    pub fn with_capacity(body_capacity: usize) -> Self {
        Self {
            words: vec![0; (PREFIX + body_capacity).div_ceil(8)],
            len: 0,
        }
    }

    /// Makes room for a body of `body_len` bytes (grows only beyond the capacity).
    fn reserve_body(&mut self, body_len: usize) {
        let words = (PREFIX + body_len).div_ceil(8);
        if self.words.len() < words {
            self.words.resize(words, 0);
        }
        self.len = PREFIX + body_len;
    }

    /// The whole record: prefix and body.
    pub fn record(&self) -> &[u8] {
        &self.words.as_bytes()[..self.len]
    }

    /// The body.
    pub fn body(&self) -> &[u8] {
        &self.words.as_bytes()[PREFIX..self.len]
    }

    fn bytes_mut(&mut self) -> &mut [u8] {
        let len = self.len;
        &mut self.words.as_mut_bytes()[..len]
    }

    /// Writes the prefix for a body of the current length.
    fn set_prefix(&mut self, kind: u32) {
        let body = (self.len - PREFIX) as u32;
        let b = self.bytes_mut();
        b[..4].copy_from_slice(&body.to_le_bytes());
        b[4..8].copy_from_slice(&kind.to_le_bytes());
    }
}

/// What [`RecordReader::read_from`] got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadProgress {
    /// A whole record of this kind is in; its body is [`RecordReader::body`] until the
    /// next call.
    Record(u32),
    /// The source has nothing more for now; [`RecordReader::buffered`] bytes of an
    /// incomplete record are kept for the next call.
    Pending,
    /// The source closed; [`RecordReader::buffered`] tells whether it was mid-record.
    Closed,
}

/// Why [`RecordReader::read_from`] failed. The reader is then unusable: drop the
/// connection.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordReadError {
    /// The prefix announced a record longer than the maximum.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// Reading failed.
    #[error("{0}")]
    Io(#[from] io::Error),
}

/// Reads `[len][kind][body]` records from a byte source piece by piece, as the bytes
/// arrive, without blocking (a `WouldBlock` from the source ends the call) and without
/// allocating: its one buffer holds the largest acceptable record and is allocated in
/// [`RecordReader::new`]. A prefix announcing more than the maximum is an error before a
/// single body byte is read.
///
/// Bodies are 8-byte aligned, so [`decode_motor`] can view the commands in place.
#[derive(Debug)]
pub struct RecordReader {
    buf: RecordBuf,
    max_body: usize,
    fill: usize,
    /// `(body len, kind)` once the prefix of the current record is in.
    head: Option<(usize, u32)>,
    complete: bool,
}

impl RecordReader {
    /// A reader accepting bodies of at most `max_body` bytes.
    pub fn new(max_body: usize) -> Self {
        let mut buf = RecordBuf::with_capacity(max_body);
        buf.len = PREFIX;
        Self {
            buf,
            max_body,
            fill: 0,
            head: None,
            complete: false,
        }
    }

    /// Reads from `src` until one record is complete, `src` would block, or it closed.
    /// Reads never go past the end of the current record.
    ///
    /// # Errors
    /// [`RecordReadError::Decode`] for a length beyond the maximum,
    /// [`RecordReadError::Io`] for a read error other than `WouldBlock`/`Interrupted`.
    pub fn read_from(&mut self, src: &mut impl Read) -> Result<ReadProgress, RecordReadError> {
        if self.complete {
            self.complete = false;
            self.fill = 0;
            self.head = None;
        }
        loop {
            let need = match self.head {
                Some((len, _)) => PREFIX + len,
                None if self.fill < PREFIX => PREFIX,
                None => {
                    let b = self.buf.words.as_bytes();
                    let prefix = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
                    self.head = Some(decode_prefix(prefix, self.max_body)?);
                    continue;
                }
            };
            if let Some((len, kind)) = self.head
                && self.fill == need
            {
                self.complete = true;
                self.buf.len = PREFIX + len;
                return Ok(ReadProgress::Record(kind));
            }
            // `need <= PREFIX + max_body`, which the buffer holds: no growth.
            let Some(dst) = self.buf.words.as_mut_bytes().get_mut(self.fill..need) else {
                return Err(DecodeError::TooLong {
                    len: need - PREFIX,
                    max: self.max_body,
                }
                .into());
            };
            match src.read(dst) {
                Ok(0) => return Ok(ReadProgress::Closed),
                Ok(n) => self.fill += n,
                Err(e) if e.kind() == ErrorKind::WouldBlock => return Ok(ReadProgress::Pending),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// The body of the record the last [`RecordReader::read_from`] completed (empty
    /// otherwise).
    pub fn body(&self) -> &[u8] {
        if self.complete { self.buf.body() } else { &[] }
    }

    /// Bytes of an incomplete record read so far (0 between records).
    pub fn buffered(&self) -> usize {
        if self.complete { 0 } else { self.fill }
    }

    /// `(body len, kind)` of the incomplete record once its prefix is in.
    pub fn head(&self) -> Option<(usize, u32)> {
        if self.complete { None } else { self.head }
    }

    /// Largest accepted body, bytes.
    pub fn max_body(&self) -> usize {
        self.max_body
    }

    /// Bytes of the reader's buffer (constant: `PREFIX + max_body` rounded up to 8).
    pub fn capacity(&self) -> usize {
        self.buf.words.capacity() * 8
    }

    /// Describes the incomplete record for a log line: `"5 of 8+ bytes"` before the
    /// prefix is in, `"20 of 32 bytes"` after.
    fn progress(&self) -> String {
        match self.head() {
            Some((len, _)) => format!("{} of {} bytes", self.buffered(), PREFIX + len),
            None => format!("{} of {PREFIX}+ bytes", self.buffered()),
        }
    }
}

fn set_nodelay(s: &TcpStream) -> io::Result<()> {
    s.set_nodelay(true)
}

fn write_record(stream: &mut TcpStream, kind: u32, body: &[u8]) -> io::Result<()> {
    let mut prefix = [0u8; PREFIX];
    prefix[..4].copy_from_slice(&(body.len() as u32).to_le_bytes());
    prefix[4..].copy_from_slice(&kind.to_le_bytes());
    // One vectored write for prefix + body; fall back to write_all for the remainder.
    let bufs = [io::IoSlice::new(&prefix), io::IoSlice::new(body)];
    let mut written = stream.write_vectored(&bufs)?;
    if written < PREFIX {
        stream.write_all(&prefix[written..])?;
        written = PREFIX;
    }
    stream.write_all(&body[written - PREFIX..])
}

/// Reads exactly `buf.len()` bytes, with `deadline` for the whole read.
fn read_exact_deadline(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
) -> io::Result<()> {
    let mut done = 0;
    while done < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::Error::new(
                ErrorKind::TimedOut,
                "peer stalled mid-record",
            ));
        }
        stream.set_read_timeout(Some(left))?;
        match stream.read(&mut buf[done..]) {
            Ok(0) => {
                return Err(io::Error::new(
                    ErrorKind::UnexpectedEof,
                    "connection closed",
                ));
            }
            Ok(n) => done += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Waits until one of `fds` has one of its `(fd, events)` (or a hang-up or error) or
/// `timeout` passes; marks which are ready. `pfds` is scratch space reused across calls
/// (no allocation in steady state).
fn poll_readable(
    fds: &[(i32, i16)],
    timeout: Duration,
    pfds: &mut Vec<libc::pollfd>,
    ready: &mut Vec<bool>,
) -> io::Result<usize> {
    pfds.clear();
    pfds.extend(fds.iter().map(|&(fd, events)| libc::pollfd {
        fd,
        events,
        revents: 0,
    }));
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    // Round sub-millisecond timeouts up so a short wait does not spin.
    let ms = if ms == 0 && !timeout.is_zero() { 1 } else { ms };
    // SAFETY: `pfds` is a valid array of `pfds.len()` pollfd structs for the whole call.
    let n = unsafe { libc::poll(pfds.as_mut_ptr(), pfds.len() as libc::nfds_t, ms) };
    if n < 0 {
        let e = io::Error::last_os_error();
        if e.kind() == ErrorKind::Interrupted {
            ready.clear();
            ready.resize(fds.len(), false);
            return Ok(0);
        }
        return Err(e);
    }
    ready.clear();
    ready.extend(pfds.iter().map(|p| p.revents != 0));
    Ok(n as usize)
}

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

const HEADER: usize = core::mem::size_of::<SensorHeader>();

impl FrameLoanMut for TcpFrameLoan {
    /// Header and image bytes, both writable. The header is copied into the record when
    /// the frame is published (592 bytes); the images are written where they are sent from.
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        let payload = &mut self.buf.bytes_mut()[PREFIX + HEADER..];
        (&mut self.header, payload)
    }

    fn header(&self) -> &SensorHeader {
        &self.header
    }
}

/// REJECT reason codes.
pub mod reject {
    /// Protocol version or layout differ.
    pub const VERSION: u32 = 1;
    /// The agent id is not part of the session.
    pub const UNKNOWN_AGENT: u32 = 2;
    /// Another connection is this agent already.
    pub const ID_IN_USE: u32 = 3;
    /// The token does not match `tcp_token`.
    pub const TOKEN: u32 = 4;
    /// The hello could not be decoded.
    pub const MALFORMED: u32 = 5;
}

/// Encodes a REJECT body: code, host protocol, host layout, message.
pub fn encode_reject(code: u32, message: &str) -> Vec<u8> {
    let mut b = Vec::with_capacity(16 + message.len());
    b.extend_from_slice(&code.to_le_bytes());
    b.extend_from_slice(&PROTOCOL_VERSION.to_le_bytes());
    b.extend_from_slice(&LAYOUT_HASH.to_le_bytes());
    b.extend_from_slice(message.as_bytes());
    b
}

/// Decodes a REJECT body into `(code, host protocol, host layout, message)`.
pub fn decode_reject(body: &[u8]) -> Option<(u32, u32, u64, String)> {
    Some((
        le_u32(body, 0)?,
        le_u32(body, 4)?,
        le_u64(body, 8)?,
        String::from_utf8_lossy(body.get(16..)?).into_owned(),
    ))
}

#[derive(Debug)]
struct Conn {
    stream: TcpStream,
    peer: SocketAddr,
    reader: RecordReader,
    /// When the host first saw the current record incomplete.
    partial_since: Option<Instant>,
}

#[derive(Debug)]
struct Pending {
    stream: TcpStream,
    peer: SocketAddr,
    since: Instant,
    reader: RecordReader,
}

#[derive(Debug)]
struct TcpSlot {
    id: u32,
    conn: Option<Conn>,
    buf: Option<RecordBuf>,
    header: Option<Box<SensorHeader>>,
    body_len: usize,
}

/// The host side of the TCP transport.
#[derive(Debug)]
pub struct TcpHost {
    listener: TcpListener,
    local_addr: SocketAddr,
    sync_mode: bool,
    write_timeout: Duration,
    slots: Vec<TcpSlot>,
    pending: Vec<Pending>,
    max_motor_body: usize,
    max_frame_body: usize,
    stall_timeout: Duration,
    token: Option<Vec<u8>>,
    /// An agent socket was readable at the last wait and no drain has read it since.
    unread: bool,
    fds: Vec<(i32, i16)>,
    pfds: Vec<libc::pollfd>,
    ready: Vec<bool>,
    signals: SignalHandling,
}

/// Why the TCP host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TcpHostCreateError {
    /// Binding the listen address failed.
    #[error("cannot listen on {addr}: {source} (set [transport] tcp_listen to a free address)")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The error.
        source: io::Error,
    },
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
        let bind = |source| TcpHostCreateError::Bind { addr, source };
        let listener = TcpListener::bind(addr).map_err(bind)?;
        listener.set_nonblocking(true).map_err(bind)?;
        let local_addr = listener.local_addr().map_err(bind)?;
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
            fds: Vec::new(),
            pfds: Vec::new(),
            ready: Vec::new(),
            signals,
        })
    }

    /// [`HostTransport::wait_activity`] that also wakes when `extra` (another transport's
    /// [`HostTransport::activity_fd`]) becomes readable: one wait for a host that serves
    /// agents over several transports. Returns whether `extra` was readable.
    ///
    /// # Errors
    /// As [`HostTransport::wait_activity`].
    pub fn wait_activity_with(
        &mut self,
        timeout: Duration,
        extra: Option<std::os::fd::RawFd>,
    ) -> Result<bool, HostTransportError> {
        // Agent sockets whose data the caller has not drained since the last wait stay
        // readable: waiting on them again would return at once, and a caller that waits
        // without draining (for agents to connect, for a lost one to come back) would
        // spin. Until the next drain they are only watched for errors and hang-ups.
        let agent_events = if self.unread { 0 } else { libc::POLLIN };
        self.fds.clear();
        self.fds.push((self.listener.as_raw_fd(), libc::POLLIN));
        self.fds.extend(
            self.pending
                .iter()
                .map(|p| (p.stream.as_raw_fd(), libc::POLLIN)),
        );
        self.fds.extend(self.slots.iter().filter_map(|s| {
            s.conn
                .as_ref()
                .map(|c| (c.stream.as_raw_fd(), agent_events))
        }));
        let extra_index = self.fds.len();
        if let Some(fd) = extra {
            self.fds.push((fd, libc::POLLIN));
        }
        // Pending hellos and incomplete records have their own deadlines: wake for them
        // (the host's next drain drops a stalled agent).
        let timeout = match self.next_deadline() {
            Some(d) => timeout.min(d.saturating_duration_since(Instant::now())),
            None => timeout,
        };
        let mut ready = std::mem::take(&mut self.ready);
        let mut pfds = std::mem::take(&mut self.pfds);
        let result = poll_readable(&self.fds, timeout, &mut pfds, &mut ready);
        self.ready = ready;
        self.pfds = pfds;
        result.map_err(|e| HostTransportError::Wait {
            reason: format!("poll: {e}"),
        })?;
        // An incomplete record past its deadline on a socket with nothing more to read is
        // a stall: drop it here too, so a caller that only waits makes progress as well.
        // (Not when readability was not asked for: unread bytes may complete it.)
        let now = Instant::now();
        let watched_reads = agent_events != 0;
        let mut fd_index = 1 + self.pending.len();
        for slot in 0..self.slots.len() {
            let Some(c) = &self.slots[slot].conn else {
                continue;
            };
            let readable = self.ready.get(fd_index).copied().unwrap_or(true);
            fd_index += 1;
            self.unread |= readable;
            if let Some(since) = c.partial_since
                && watched_reads
                && !readable
                && now.duration_since(since) >= self.stall_timeout
            {
                let why = stall_reason(&c.reader, self.stall_timeout);
                self.drop_conn(slot, &why);
            }
        }
        if self.ready.first().copied().unwrap_or(false) {
            self.accept_new();
        }
        if !self.pending.is_empty() {
            self.handle_pending();
        }
        if self.signals.termination_requested() {
            return Err(HostTransportError::Terminated);
        }
        Ok(extra.is_some() && self.ready.get(extra_index).copied().unwrap_or(false))
    }

    /// The address actually bound (resolves port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    fn drop_conn(&mut self, slot: usize, why: &str) {
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
                    if stream.set_nonblocking(true).is_err() || set_nodelay(&stream).is_err() {
                        continue;
                    }
                    debug!(%peer, "TCP connection");
                    self.pending.push(Pending {
                        stream,
                        peer,
                        since: Instant::now(),
                        reader: RecordReader::new(MAX_HELLO),
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
            warn!(
                "TCP peer dropped: {turned_away} connection(s) closed at once, {MAX_PENDING} are already waiting for their hello"
            );
        }
    }

    /// Reads pending hellos; admits, rejects or times out each connection.
    fn handle_pending(&mut self) {
        let mut i = 0;
        while i < self.pending.len() {
            match self.progress_hello(i) {
                Ok(None) => {
                    let p = &self.pending[i];
                    if p.since.elapsed() >= HELLO_TIMEOUT {
                        let why = if p.reader.buffered() == 0 {
                            format!(
                                "sent nothing within {HELLO_TIMEOUT:?} of connecting (no hello)"
                            )
                        } else {
                            format!(
                                "stalled mid-record: {} of its hello within {HELLO_TIMEOUT:?} of connecting",
                                p.reader.progress()
                            )
                        };
                        let p = self.pending.swap_remove(i);
                        warn!(peer = %p.peer, "TCP peer dropped: {why}");
                    } else {
                        i += 1;
                    }
                }
                Ok(Some(hello)) => {
                    let p = self.pending.swap_remove(i);
                    self.admit(p, hello);
                }
                Err((why, closed)) => {
                    let mut p = self.pending.swap_remove(i);
                    warn!(peer = %p.peer, "TCP peer dropped: {why}");
                    if !closed {
                        let _ = p.stream.set_nonblocking(false);
                        let _ = p.stream.set_write_timeout(Some(Duration::from_millis(200)));
                        let _ = write_record(
                            &mut p.stream,
                            kind::REJECT,
                            &encode_reject(reject::MALFORMED, &why),
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

    fn admit(&mut self, p: Pending, hello: Hello) {
        let mut stream = p.stream;
        let refuse = |stream: &mut TcpStream, code: u32, why: String| {
            warn!(peer = %p.peer, agent = hello.agent_id, "TCP agent refused: {why}");
            let _ = stream.set_nonblocking(false);
            let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
            let _ = write_record(stream, kind::REJECT, &encode_reject(code, &why));
        };
        if hello.protocol_version != PROTOCOL_VERSION || hello.layout_hash != LAYOUT_HASH {
            return refuse(
                &mut stream,
                reject::VERSION,
                format!(
                    "agent speaks protocol {} (layout {:016x}), host speaks protocol {PROTOCOL_VERSION} (layout {LAYOUT_HASH:016x})",
                    hello.protocol_version, hello.layout_hash
                ),
            );
        }
        if let Some(token) = &self.token
            && !constant_time_eq(token, &hello.token)
        {
            return refuse(&mut stream, reject::TOKEN, "wrong tcp_token".into());
        }
        let Some(slot) = self.slots.iter().position(|s| s.id == hello.agent_id) else {
            return refuse(
                &mut stream,
                reject::UNKNOWN_AGENT,
                format!(
                    "agent {} is not part of this session (it serves agents {:?})",
                    hello.agent_id,
                    self.slots.iter().map(|s| s.id).collect::<Vec<_>>()
                ),
            );
        };
        if let Some(old) = &self.slots[slot].conn
            && peer_closed(&old.stream)
        {
            // The agent died or reconnects; its old connection is gone already.
            self.drop_conn(slot, "connection closed (a new connection takes its place)");
        }
        if self.slots[slot].conn.is_some() {
            return refuse(
                &mut stream,
                reject::ID_IN_USE,
                format!("agent {} is already connected", hello.agent_id),
            );
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
    fn send_all(stream: &mut TcpStream, mut data: &[u8], deadline: Instant) -> io::Result<()> {
        while !data.is_empty() {
            match stream.write(data) {
                Ok(0) => return Err(io::Error::new(ErrorKind::WriteZero, "connection closed")),
                Ok(n) => data = &data[n..],
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Err(io::Error::new(ErrorKind::TimedOut, "agent does not read"));
                    }
                    let mut pfd = libc::pollfd {
                        fd: stream.as_raw_fd(),
                        events: libc::POLLOUT,
                        revents: 0,
                    };
                    let ms = left.as_millis().clamp(1, i32::MAX as u128) as i32;
                    // SAFETY: one valid pollfd for the duration of the call.
                    unsafe { libc::poll(&mut pfd, 1, ms) };
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Reads what has arrived from `c`, handing complete motor batches to `sink`.
    /// `Err(why)` drops the connection.
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
    fn next_deadline(&self) -> Option<Instant> {
        let hellos = self.pending.iter().map(|p| p.since + HELLO_TIMEOUT);
        let stalls = self
            .slots
            .iter()
            .filter_map(|s| s.conn.as_ref()?.partial_since)
            .map(|t| t + self.stall_timeout);
        hellos.chain(stalls).min()
    }

    fn writable_now(stream: &TcpStream) -> bool {
        let mut pfd = libc::pollfd {
            fd: stream.as_raw_fd(),
            events: libc::POLLOUT,
            revents: 0,
        };
        // SAFETY: one valid pollfd for the duration of the call.
        unsafe { libc::poll(&mut pfd, 1, 0) == 1 && pfd.revents & libc::POLLOUT != 0 }
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
        "stalled mid-record: {} of a motor batch, not complete within {stall_timeout:?}",
        reader.progress()
    )
}

/// Whether the peer closed or reset the connection (without reading anything).
fn peer_closed(stream: &TcpStream) -> bool {
    let mut pfd = libc::pollfd {
        fd: stream.as_raw_fd(),
        events: libc::POLLRDHUP,
        revents: 0,
    };
    // SAFETY: one valid pollfd for the duration of the call.
    let n = unsafe { libc::poll(&mut pfd, 1, 0) };
    n == 1 && pfd.revents & (libc::POLLRDHUP | libc::POLLHUP | libc::POLLERR) != 0
}

/// Compares two byte strings in time independent of where they differ.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = (a.len() ^ b.len()) as u8 | u8::from(a.len() != b.len());
    for i in 0..a.len().max(b.len()) {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0);
    }
    diff == 0
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
        let stall_timeout = self.stall_timeout;
        for slot in 0..self.slots.len() {
            let failure = match &mut self.slots[slot].conn {
                Some(c) => Self::drain_conn(c, slot, stall_timeout, sink).err(),
                None => None,
            };
            if let Some(why) = failure {
                self.drop_conn(slot, &why);
            }
        }
        Ok(())
    }

    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        self.wait_activity_with(timeout, None).map(|_| ())
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

/// The ids in the `[…]` list at the end of an unknown-agent reject message.
fn served_ids_from_reject(message: &str) -> Vec<u32> {
    let list = message
        .rfind('[')
        .and_then(|start| Some(&message[start + 1..start + message[start..].find(']')?]));
    list.map(|l| {
        l.split(',')
            .filter_map(|id| id.trim().parse::<u32>().ok())
            .collect()
    })
    .unwrap_or_default()
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

impl TcpAgent {
    /// Connects to `transport.tcp_listen`, retrying until `timeout`, and says hello.
    /// `signals` says whether SIGINT/SIGTERM handlers are installed (see
    /// [`SignalHandling`]).
    ///
    /// # Errors
    /// [`AgentConnectError`].
    pub fn connect(
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
        let stream = retry_until(
            deadline,
            || signals.termination_requested(),
            || {
                let left = deadline.saturating_duration_since(Instant::now());
                match TcpStream::connect_timeout(&addr, left.max(Duration::from_millis(1))) {
                    Ok(s) => Attempt::<_, ()>::Done(s),
                    Err(e) => Attempt::NotYet(e.to_string()),
                }
            },
        );
        let mut stream = match stream {
            Ok(s) => s,
            Err(e) => {
                return Err(AgentConnectError::HostNotFound {
                    session: session.clone(),
                    agent: id,
                    waited: started.elapsed(),
                    looked_for: format!(
                        "nothing accepts TCP connections at {addr} ({})",
                        e.unwrap_or_default()
                    ),
                });
            }
        };
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
        set_nodelay(&stream).map_err(|e| hs(e.to_string()))?;
        let hello = Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            token: token.map(<[u8]>::to_vec).unwrap_or_default(),
        };
        write_record(&mut stream, kind::HELLO, &encode_hello(&hello))
            .map_err(|e| hs(e.to_string()))?;
        let reply_deadline = Instant::now() + HELLO_TIMEOUT * 2;
        let mut prefix = [0u8; PREFIX];
        read_exact_deadline(&mut stream, &mut prefix, reply_deadline)
            .map_err(|e| hs(e.to_string()))?;
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
                let (code, host_protocol, host_layout, reason) =
                    decode_reject(&body).ok_or_else(|| hs("malformed reject".into()))?;
                Err(match code {
                    reject::VERSION => mismatch(host_protocol, host_layout),
                    reject::UNKNOWN_AGENT => AgentConnectError::IdNotServed {
                        session: session.clone(),
                        agent: id,
                        served: served_ids_from_reject(&reason),
                    },
                    reject::ID_IN_USE => AgentConnectError::IdInUse {
                        session: session.clone(),
                        agent: id,
                    },
                    _ => AgentConnectError::Refused {
                        session: session.clone(),
                        agent: id,
                        reason,
                    },
                })
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
        let mut pfd = libc::pollfd {
            fd: self.stream.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd for the duration of the call.
        unsafe { libc::poll(&mut pfd, 1, 0) == 1 }
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

    fn try_receive_newest(&mut self) -> Result<Option<TcpFrame>, AgentReceiveError> {
        self.read_arrived()
    }

    fn wait_readable(&mut self, timeout: Duration) {
        if self.closed || self.gone.is_some() {
            return;
        }
        let mut pfd = libc::pollfd {
            fd: self.stream.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
        // Round sub-millisecond timeouts up so a short wait does not spin.
        let ms = if ms == 0 && !timeout.is_zero() { 1 } else { ms };
        // SAFETY: one valid pollfd for the duration of the call. A failed or interrupted
        // poll ends the wait early; the next read reports what broke.
        unsafe { libc::poll(&mut pfd, 1, ms) };
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn hello_round_trips() {
        let h = Hello {
            protocol_version: 1,
            layout_hash: 0xdead_beef,
            agent_id: 3,
            token: b"secret".to_vec(),
        };
        assert_eq!(decode_hello(&encode_hello(&h)), Ok(h));
    }

    #[test]
    fn constant_time_eq_compares() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"ab"));
        assert!(constant_time_eq(b"", b""));
    }

    #[test]
    fn motor_bodies_decode_without_copy() {
        let cmds = [
            crate::wire::Command::Turn { angle_deg: 5.0 }.encode(1),
            crate::wire::Command::CancelMove.encode(2),
        ];
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: 1,
            cycle: 9,
            flags: crate::wire::MOTOR_FLAG_STOP,
            command_count: 2,
        };
        let mut buf = RecordBuf::with_capacity(256);
        let body_len = 24 + 64;
        buf.reserve_body(body_len);
        buf.bytes_mut()[PREFIX..PREFIX + 24].copy_from_slice(header.as_bytes());
        buf.bytes_mut()[PREFIX + 24..].copy_from_slice(cmds.as_bytes());
        let (h, c) = decode_motor(buf.body()).unwrap();
        assert_eq!(h, header);
        assert_eq!(c, &cmds);
        // A count that does not match the body is malformed, never an over-read.
        let mut bad = header;
        bad.command_count = 1000;
        buf.bytes_mut()[PREFIX..PREFIX + 24].copy_from_slice(bad.as_bytes());
        assert!(decode_motor(buf.body()).is_err());
    }

    proptest! {
        #[test]
        fn hello_decoder_never_panics(body in proptest::collection::vec(any::<u8>(), 0..400)) {
            if let Ok(h) = decode_hello(&body) {
                prop_assert!(h.token.len() <= MAX_TOKEN);
            }
        }

        #[test]
        fn prefix_decoder_bounds_lengths(prefix in any::<[u8; 8]>(), max in 0usize..1_000_000) {
            match decode_prefix(prefix, max) {
                Ok((len, _)) => prop_assert!(len <= max),
                Err(DecodeError::TooLong { len, .. }) => prop_assert!(len > max),
                Err(_) => prop_assert!(false),
            }
        }

        #[test]
        fn motor_decoder_never_panics(body in proptest::collection::vec(any::<u8>(), 0..300)) {
            // Copy into an aligned buffer as the reader does.
            let mut buf = RecordBuf::with_capacity(body.len());
            buf.reserve_body(body.len());
            buf.bytes_mut()[PREFIX..].copy_from_slice(&body);
            if let Ok((h, c)) = decode_motor(buf.body()) {
                prop_assert_eq!(h.command_count as usize, c.len());
            }
        }

        #[test]
        fn reject_decoder_never_panics(body in proptest::collection::vec(any::<u8>(), 0..64)) {
            let _ = decode_reject(&body);
        }

        #[test]
        fn hellos_round_trip(
            protocol_version in any::<u32>(),
            layout_hash in any::<u64>(),
            agent_id in any::<u32>(),
            token in proptest::collection::vec(any::<u8>(), 0..=MAX_TOKEN),
        ) {
            let h = Hello { protocol_version, layout_hash, agent_id, token };
            let body = encode_hello(&h);
            prop_assert!(body.len() <= MAX_HELLO);
            prop_assert_eq!(decode_hello(&body), Ok(h));
        }

        /// Whatever the bytes and however they are split, the reader never panics, never
        /// hands out a body beyond its maximum, never grows its buffer, and reads no body
        /// byte of a record whose prefix is too long.
        #[test]
        fn record_reader_is_bounded_on_any_bytes(
            data in proptest::collection::vec(any::<u8>(), 0..700),
            chunks in proptest::collection::vec(1usize..40, 0..50),
            max in 0usize..300,
        ) {
            let mut reader = RecordReader::new(max);
            let capacity = reader.capacity();
            prop_assert!(capacity >= PREFIX + max && capacity < PREFIX + max + 8);
            let mut src = Chunked::new(&data, &chunks);
            let (records, end) = read_all(&mut reader, &mut src);
            let mut consumed = 0;
            for (_, body) in &records {
                prop_assert!(body.len() <= max);
                consumed += PREFIX + body.len();
            }
            match end {
                End::Closed { buffered } => prop_assert_eq!(consumed + buffered, data.len()),
                End::Failed(RecordReadError::Decode(DecodeError::TooLong { len, max: m })) => {
                    prop_assert!(len > max);
                    prop_assert_eq!(m, max);
                    // The prefix, and not a byte of the body.
                    prop_assert_eq!(src.pos, consumed + PREFIX);
                }
                End::Failed(other) => prop_assert!(false, "unexpected {other}"),
            }
            prop_assert_eq!(reader.capacity(), capacity);
        }

        /// Well-formed records come out exactly as they went in, however the stream is split.
        #[test]
        fn record_reader_round_trips_any_split(
            records in proptest::collection::vec(
                (any::<u32>(), proptest::collection::vec(any::<u8>(), 0..=64)), 0..8),
            chunks in proptest::collection::vec(1usize..30, 0..60),
        ) {
            let mut data = Vec::new();
            for (k, body) in &records {
                data.extend_from_slice(&(body.len() as u32).to_le_bytes());
                data.extend_from_slice(&k.to_le_bytes());
                data.extend_from_slice(body);
            }
            let mut reader = RecordReader::new(64);
            let mut src = Chunked::new(&data, &chunks);
            let (got, end) = read_all(&mut reader, &mut src);
            prop_assert_eq!(got, records);
            let clean = matches!(end, End::Closed { buffered: 0 });
            prop_assert!(clean, "stream did not end cleanly between records");
        }
    }

    /// Hands out `data` in chunks of the given sizes with a `WouldBlock` before each chunk
    /// (as a non-blocking socket does), then end of stream.
    struct Chunked<'a> {
        data: &'a [u8],
        pos: usize,
        chunks: &'a [usize],
        next_chunk: usize,
        left_in_chunk: usize,
    }

    impl<'a> Chunked<'a> {
        fn new(data: &'a [u8], chunks: &'a [usize]) -> Self {
            Self {
                data,
                pos: 0,
                chunks,
                next_chunk: 0,
                left_in_chunk: 0,
            }
        }
    }

    impl Read for Chunked<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            if self.pos == self.data.len() {
                return Ok(0);
            }
            if self.left_in_chunk == 0 {
                self.left_in_chunk = self
                    .chunks
                    .get(self.next_chunk)
                    .copied()
                    .unwrap_or(usize::MAX);
                self.next_chunk += 1;
                return Err(ErrorKind::WouldBlock.into());
            }
            let n = out
                .len()
                .min(self.left_in_chunk)
                .min(self.data.len() - self.pos);
            out[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
            self.pos += n;
            self.left_in_chunk -= n;
            Ok(n)
        }
    }

    enum End {
        Closed { buffered: usize },
        Failed(RecordReadError),
    }

    fn read_all(reader: &mut RecordReader, src: &mut Chunked<'_>) -> (Vec<(u32, Vec<u8>)>, End) {
        let mut records = Vec::new();
        loop {
            match reader.read_from(src) {
                Ok(ReadProgress::Record(k)) => records.push((k, reader.body().to_vec())),
                Ok(ReadProgress::Pending) => {}
                Ok(ReadProgress::Closed) => {
                    let buffered = reader.buffered();
                    return (records, End::Closed { buffered });
                }
                Err(e) => return (records, End::Failed(e)),
            }
        }
    }

    // --- TcpHost against raw sockets (no simulator) ------------------------------------

    fn tcp_host(stop_timeout: f64) -> TcpHost {
        let text = format!(
            "[sync]\nstop_timeout = {stop_timeout}\n[transport]\nkind = \"tcp\"\n\
             tcp_listen = \"127.0.0.1:0\"\n\
             [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n\
             [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n"
        );
        let config = Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap();
        TcpHost::create(&config, SignalHandling::Leave).unwrap()
    }

    fn say_hello(host: &TcpHost, id: u32) -> TcpStream {
        let mut s = TcpStream::connect(host.local_addr()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        let hello = Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            token: Vec::new(),
        };
        write_record(&mut s, kind::HELLO, &encode_hello(&hello)).unwrap();
        s
    }

    fn read_reply(s: &mut TcpStream) -> (u32, Vec<u8>) {
        let mut prefix = [0u8; PREFIX];
        s.read_exact(&mut prefix).unwrap();
        let (len, k) = decode_prefix(prefix, 4096).unwrap();
        let mut body = vec![0u8; len];
        s.read_exact(&mut body).unwrap();
        (k, body)
    }

    /// Runs the host's wait/drain loop until `done` holds; panics after 20 s.
    fn pump(host: &mut TcpHost, drain: bool, what: &str, done: impl Fn(&TcpHost) -> bool) {
        let deadline = Instant::now() + Duration::from_secs(20);
        while !done(host) {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            host.wait_activity(Duration::from_millis(50)).unwrap();
            if drain {
                host.drain(&mut |_, _, _| {}).unwrap();
            }
        }
    }

    fn motor_record(cycle: u64) -> Vec<u8> {
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: 0,
            cycle,
            flags: crate::wire::MOTOR_FLAG_STOP,
            command_count: 0,
        };
        let mut r = Vec::new();
        r.extend_from_slice(&(header.as_bytes().len() as u32).to_le_bytes());
        r.extend_from_slice(&kind::MOTOR.to_le_bytes());
        r.extend_from_slice(header.as_bytes());
        r
    }

    #[test]
    fn an_agent_stalling_mid_record_is_dropped_and_the_other_goes_on() {
        let mut host = tcp_host(0.2);
        let mut a0 = say_hello(&host, 0);
        let mut a1 = say_hello(&host, 1);
        pump(&mut host, false, "both agents", |h| {
            h.is_connected(0) && h.is_connected(1)
        });
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        assert_eq!(read_reply(&mut a1).0, kind::WELCOME);
        // Agent 0: a prefix and half a batch, then silence with the socket open.
        let rec = motor_record(0);
        a0.write_all(&rec[..PREFIX + 10]).unwrap();
        // Agent 1: a whole batch.
        a1.write_all(&motor_record(0)).unwrap();
        let got = std::cell::Cell::new(0);
        let deadline = Instant::now() + Duration::from_secs(20);
        while host.is_connected(0) {
            assert!(Instant::now() < deadline, "stalled agent never dropped");
            host.wait_activity(Duration::from_millis(500)).unwrap();
            host.drain(&mut |slot, h, _| {
                assert_eq!((slot, h.cycle), (1, 0));
                got.set(got.get() + 1);
            })
            .unwrap();
        }
        assert_eq!(got.get(), 1, "agent 1's batch arrives");
        assert!(host.is_connected(1));
        // The stalled agent's socket is closed by the host.
        let mut b = [0u8; 1];
        assert_eq!(a0.read(&mut b).unwrap_or(0), 0);
    }

    #[test]
    fn an_oversized_motor_prefix_drops_the_agent_without_reading_the_body() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        let mut prefix = [0u8; PREFIX];
        prefix[..4].copy_from_slice(&u32::MAX.to_le_bytes());
        prefix[4..].copy_from_slice(&kind::MOTOR.to_le_bytes());
        a0.write_all(&prefix).unwrap();
        pump(&mut host, true, "agent 0 dropped", |h| !h.is_connected(0));
    }

    #[test]
    fn silent_connections_are_bounded_and_time_out() {
        let mut host = tcp_host(5.0);
        let extra = 5;
        let mut silent: Vec<TcpStream> = (0..MAX_PENDING + extra)
            .map(|_| TcpStream::connect(host.local_addr()).unwrap())
            .collect();
        pump(&mut host, false, "the listen queue to empty", |h| {
            h.pending.len() == MAX_PENDING
        });
        // Exactly `extra` of them were closed at once; the rest wait for their hello.
        let closed = silent
            .iter_mut()
            .filter_map(|s| {
                s.set_nonblocking(true).unwrap();
                matches!(s.read(&mut [0u8; 1]), Ok(0)).then_some(())
            })
            .count();
        assert_eq!(closed, extra);
        pump(&mut host, false, "the hello timeout", |h| {
            h.pending.is_empty()
        });
        // A real agent still gets in.
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
    }

    #[test]
    fn an_agent_reconnecting_after_a_close_replaces_its_old_connection() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // A second connection while the first is alive is refused.
        let mut twin = say_hello(&host, 0);
        let (k, body) = read_reply_pumping(&mut host, &mut twin);
        assert_eq!(k, kind::REJECT);
        assert_eq!(decode_reject(&body).unwrap().0, reject::ID_IN_USE);
        // Once it closed (no drain has seen that yet), a new one takes its place.
        drop(a0);
        let mut again = say_hello(&host, 0);
        let (k, _) = read_reply_pumping(&mut host, &mut again);
        assert_eq!(k, kind::WELCOME);
        assert!(host.is_connected(0));
    }

    #[test]
    fn waiting_without_draining_does_not_spin_on_unread_agent_bytes() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // Bytes the host does not read while it waits for agent 1 to connect.
        a0.write_all(&motor_record(0)).unwrap();
        pump(&mut host, false, "agent 0's bytes", |h| h.unread);
        // The next wait no longer asks for agent 0's readability (it would return at
        // once, forever) but still for the listener's.
        host.wait_activity(Duration::from_millis(1)).unwrap();
        let a0_fd = a0_fd(&host);
        let events = host.pfds.iter().find(|p| p.fd == a0_fd).unwrap().events;
        assert_eq!(events, 0);
        assert_eq!(host.pfds[0].events, libc::POLLIN);
        // A drain reads the bytes and the socket is watched again.
        let got = std::cell::Cell::new(0);
        host.drain(&mut |_, _, _| got.set(got.get() + 1)).unwrap();
        assert_eq!(got.get(), 1);
        host.wait_activity(Duration::from_millis(1)).unwrap();
        let events = host.pfds.iter().find(|p| p.fd == a0_fd).unwrap().events;
        assert_eq!(events, libc::POLLIN);
    }

    fn a0_fd(host: &TcpHost) -> i32 {
        host.slots[0].conn.as_ref().unwrap().stream.as_raw_fd()
    }

    fn read_reply_pumping(host: &mut TcpHost, s: &mut TcpStream) -> (u32, Vec<u8>) {
        s.set_nonblocking(true).unwrap();
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            assert!(Instant::now() < deadline, "no reply");
            host.wait_activity(Duration::from_millis(20)).unwrap();
            if matches!(s.peek(&mut [0u8; 1]), Ok(1)) {
                break;
            }
        }
        s.set_nonblocking(false).unwrap();
        read_reply(s)
    }
}
