//! The record codec both network transports speak (TCP, zenoh): the hello, welcome and
//! reject bodies, the motor batch, and TCP's `[len: u32 LE][kind: u32 LE][body]` framing
//! with its bounded, non-allocating reader.
//!
//! zenoh carries the same bodies in its own messages (the hello as a query's payload, the
//! welcome or reject as its reply, a motor batch per put), so a hello, a refusal or a
//! malformed batch means the same thing whichever network transport brought it. Nothing
//! here does I/O beyond [`RecordReader::read_from`] on any [`Read`] source.

use std::io::{self, ErrorKind, Read};

use zerocopy::{FromBytes, IntoBytes};

use crate::wire::{MotorCommand, MotorHeader};

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
pub const MAX_HELLO: usize = 4 + 4 + 8 + 4 + 8 + 4 + MAX_TOKEN;

/// A decoded hello.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hello {
    /// The agent's protocol version.
    pub protocol_version: u32,
    /// The agent's layout hash.
    pub layout_hash: u64,
    /// The agent id it claims.
    pub agent_id: u32,
    /// The hash of the agent's channel layout as its config declares it
    /// ([`crate::channel_layout::ChannelLayout::hash`]).
    pub channels: u64,
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
    b.extend_from_slice(&hello.channels.to_le_bytes());
    b.extend_from_slice(&(token.len() as u32).to_le_bytes());
    b.extend_from_slice(token);
    b
}

/// The little-endian `u32` at byte `at` of `b` (`None` past the end).
pub fn le_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// The little-endian `u64` at byte `at` of `b` (`None` past the end).
pub fn le_u64(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// Decodes a hello body. Never panics, never allocates beyond [`MAX_TOKEN`].
///
/// A hello of another protocol version is decoded as far as the fields every version
/// shares (magic, version, layout, agent id), so that the host can refuse it naming both
/// versions; its other fields are zero and empty.
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
    if protocol_version != crate::wire::PROTOCOL_VERSION {
        return Ok(Hello {
            protocol_version,
            layout_hash,
            agent_id,
            channels: 0,
            token: Vec::new(),
        });
    }
    let channels = le_u64(body, 20).ok_or_else(|| bad("truncated"))?;
    let token_len = le_u32(body, 28).ok_or_else(|| bad("truncated"))? as usize;
    if token_len > MAX_TOKEN || body.len() != 32 + token_len {
        return Err(bad("token length does not match the record"));
    }
    Ok(Hello {
        protocol_version,
        layout_hash,
        agent_id,
        channels,
        token: body[32..].to_vec(),
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
    pub fn reserve_body(&mut self, body_len: usize) {
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

    /// The whole record, writable: prefix and body.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        let len = self.len;
        &mut self.words.as_mut_bytes()[..len]
    }

    /// Writes the prefix for a body of the current length.
    pub fn set_prefix(&mut self, kind: u32) {
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
    #[error(transparent)]
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

    /// Swaps the record the last [`RecordReader::read_from`] completed into `spare` and
    /// reads on into `spare`'s old buffer (grown to the largest acceptable record if it
    /// is smaller): a reader of large records (camera frames) hands them on without a
    /// copy. Returns `false`, and leaves `spare` alone, when no record is complete.
    pub fn take_record(&mut self, spare: &mut RecordBuf) -> bool {
        if !self.complete {
            return false;
        }
        spare.reserve_body(self.max_body);
        core::mem::swap(&mut self.buf, spare);
        self.buf.len = PREFIX;
        self.complete = false;
        self.fill = 0;
        self.head = None;
        true
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
    pub fn progress(&self) -> String {
        match self.head() {
            Some((len, _)) => format!("{} of {} bytes", self.buffered(), PREFIX + len),
            None => format!("{} of {PREFIX}+ bytes", self.buffered()),
        }
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
    /// The agent's channels (`[[agent.vector]]`, `[[agent.action]]`) differ from what the
    /// host's config declares for it; the reject carries the host's layout.
    pub const CHANNELS: u32 = 6;
}

pub use crate::admission::{Reject, admit};

/// Compares two byte strings in time independent of where they differ.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = (a.len() ^ b.len()) as u8 | u8::from(a.len() != b.len());
    for i in 0..a.len().max(b.len()) {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0);
    }
    diff == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::PROTOCOL_VERSION;
    use proptest::prelude::*;

    #[test]
    fn hello_round_trips() {
        let h = Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: 0xdead_beef,
            agent_id: 3,
            channels: 0x0123_4567_89ab_cdef,
            token: b"secret".to_vec(),
        };
        assert_eq!(decode_hello(&encode_hello(&h)), Ok(h.clone()));
        // Another version's hello: the fields every version shares, so that the host can
        // refuse it naming both versions (an agent of protocol 3 sent no channel hash).
        let mut v3 = encode_hello(&h);
        v3[4..8].copy_from_slice(&3u32.to_le_bytes());
        v3.drain(20..28);
        let old = decode_hello(&v3).unwrap();
        assert_eq!(
            (
                old.protocol_version,
                old.layout_hash,
                old.agent_id,
                old.channels
            ),
            (3, 0xdead_beef, 3, 0)
        );
        assert!(old.token.is_empty());
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
            let _ = Reject::decode(&body);
        }

        #[test]
        fn hellos_round_trip(
            layout_hash in any::<u64>(),
            agent_id in any::<u32>(),
            channels in any::<u64>(),
            token in proptest::collection::vec(any::<u8>(), 0..=MAX_TOKEN),
        ) {
            let h = Hello {
                protocol_version: PROTOCOL_VERSION,
                layout_hash,
                agent_id,
                channels,
                token,
            };
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

    /// Records taken out of the reader keep their bytes while the reader goes on into the
    /// spare buffer, split however the stream is.
    #[test]
    fn taken_records_keep_their_bytes_and_the_reader_goes_on() {
        let bodies: [&[u8]; 3] = [b"first body", b"", b"the third, longer body"];
        let mut data = Vec::new();
        for (k, body) in bodies.iter().enumerate() {
            data.extend_from_slice(&(body.len() as u32).to_le_bytes());
            data.extend_from_slice(&(k as u32).to_le_bytes());
            data.extend_from_slice(body);
        }
        let mut reader = RecordReader::new(32);
        let mut spare = RecordBuf::default();
        assert!(!reader.take_record(&mut spare), "nothing complete yet");
        let mut src = Chunked::new(&data, &[3, 5, 7, 1, 40]);
        let mut taken = Vec::new();
        loop {
            match reader.read_from(&mut src).unwrap() {
                ReadProgress::Record(k) => {
                    assert!(reader.take_record(&mut spare));
                    assert_eq!(reader.body(), b"", "handed on");
                    let record = core::mem::take(&mut spare);
                    taken.push((k, record));
                }
                ReadProgress::Pending => {}
                ReadProgress::Closed => break,
            }
        }
        assert_eq!(reader.buffered(), 0);
        let got: Vec<(u32, &[u8])> = taken.iter().map(|(k, r)| (*k, r.body())).collect();
        assert_eq!(got, [(0, bodies[0]), (1, bodies[1]), (2, bodies[2])]);
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
}
