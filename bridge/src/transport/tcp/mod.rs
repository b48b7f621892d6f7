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

/// Size of the sensor header at the start of a frame record.
const HEADER: usize = core::mem::size_of::<SensorHeader>();

mod agent;
mod host;

pub use agent::*;
pub use host::*;

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
            ack_cycle: 0,
        };
        let hl = core::mem::size_of::<MotorHeader>();
        let mut buf = RecordBuf::with_capacity(256);
        let body_len = hl + 64;
        buf.reserve_body(body_len);
        buf.bytes_mut()[PREFIX..PREFIX + hl].copy_from_slice(header.as_bytes());
        buf.bytes_mut()[PREFIX + hl..].copy_from_slice(cmds.as_bytes());
        let (h, c) = decode_motor(buf.body()).unwrap();
        assert_eq!(h, header);
        assert_eq!(c, &cmds);
        // A count that does not match the body is malformed, never an over-read.
        let mut bad = header;
        bad.command_count = 1000;
        buf.bytes_mut()[PREFIX..PREFIX + hl].copy_from_slice(bad.as_bytes());
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
            ack_cycle: 0,
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
        // Once it closed, a new one takes its place, even when the host does not drain
        // (it waits for agents, not for stops): after the hello timeout at the latest.
        drop(a0);
        let mut again = say_hello(&host, 0);
        let (k, _) = read_reply_pumping(&mut host, &mut again);
        assert_eq!(k, kind::WELCOME);
        assert!(host.is_connected(0));
    }

    #[test]
    fn a_closed_connections_last_batch_is_read_before_its_successor_is_admitted() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // The agent stops its cycle and closes; a new connection of its id says hello
        // before the host drained the old one (an agent that leaves and reconnects at once).
        a0.write_all(&motor_record(0)).unwrap();
        drop(a0);
        let again = say_hello(&host, 0);
        pump(&mut host, false, "the new hello", |h| {
            h.pending.first().is_some_and(|p| p.hello.is_some())
        });
        // It waits: the host has not seen the old connection go.
        assert!(host.slots[0].conn.is_some());
        // The drain delivers the old connection's stop and sees it closed...
        let got = std::cell::Cell::new(0);
        let deadline = Instant::now() + Duration::from_secs(20);
        while host.is_connected(0) {
            assert!(
                Instant::now() < deadline,
                "the old connection is never let go"
            );
            host.drain(&mut |slot, h, _| {
                assert_eq!((slot, h.cycle), (0, 0));
                got.set(got.get() + 1);
            })
            .unwrap();
        }
        assert_eq!(got.get(), 1, "the old connection's stop arrives");
        // ...and the next wait admits the new one at once.
        host.wait_activity(Duration::from_secs(20)).unwrap();
        assert!(host.is_connected(0));
        assert!(host.pending.is_empty());
        let mut again = again;
        assert_eq!(read_reply(&mut again).0, kind::WELCOME);
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
