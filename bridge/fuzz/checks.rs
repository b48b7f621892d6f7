//! What every fuzz input is checked against: one definition, used by the cargo-fuzz
//! targets (`fuzz_targets/*.rs`, libFuzzer on nightly) and by the workspace's test that
//! replays the committed corpus and mutates it on stable in CI (`tests/fuzz.rs` of
//! vrsync-tests). Each check feeds its bytes to the code a host runs on what a stranger
//! sends, exactly as the host does, and panics when a rule below is broken.

use std::io::{self, ErrorKind, Read};
use std::path::Path;

use vrsync_bridge::legacy::codec::{
    Dialect, FrameProgress, FrameReader, Incoming, MAX_INCOMING_FRAME, decode_frame,
    version_check_dialect,
};
use vrsync_bridge::tcp::{
    MAX_HELLO, MAX_TOKEN, PREFIX, ReadProgress, RecordReader, Reject, decode_hello, decode_motor,
    decode_prefix, kind,
};
use vrsync_bridge::{Config, MotorCommand, MotorHeader};

/// A check: panics when `input` breaks one of its rules.
pub type Check = fn(&[u8]);

/// The fuzz targets, by name: the folder of each one's corpus under `bridge/fuzz/corpus/`.
pub const TARGETS: [(&str, Check); 3] = [
    ("decode_records", records),
    ("decode_legacy", legacy),
    ("decode_config", config),
];

/// Largest motor batch body with the default `max_commands_per_cycle = 64`.
const MAX_MOTOR_BODY: usize =
    core::mem::size_of::<MotorHeader>() + 64 * core::mem::size_of::<MotorCommand>();

/// Hands out `data` in pieces of `chunk` bytes with a `WouldBlock` before each piece.
struct Chunked<'a> {
    data: &'a [u8],
    chunk: usize,
    left: usize,
}

impl Read for Chunked<'_> {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.data.is_empty() {
            return Ok(0);
        }
        if self.left == 0 {
            self.left = self.chunk;
            return Err(ErrorKind::WouldBlock.into());
        }
        let n = out.len().min(self.left).min(self.data.len());
        out[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        self.left -= n;
        Ok(n)
    }
}

/// The TCP record reader and every body decoder, as the host reads a stranger's hello or
/// an agent's motor batches: in arbitrary pieces, with `WouldBlock` between them. The
/// first byte picks the reader's maximum and how the stream is split.
///
/// Checked: no panic; no body beyond the reader's maximum; the reader's buffer never
/// grows; a decoded hello's token is at most `MAX_TOKEN`; a decoded motor batch holds
/// exactly the commands its header announces.
pub fn records(input: &[u8]) {
    let Some((&select, data)) = input.split_first() else {
        return;
    };
    let max = match select & 3 {
        0 => MAX_HELLO,
        1 => MAX_MOTOR_BODY,
        2 => usize::from(select),
        _ => 0,
    };
    let chunk = 1 + usize::from(select >> 2);

    if let Some(prefix) = data.get(..PREFIX) {
        let mut p = [0u8; PREFIX];
        p.copy_from_slice(prefix);
        if let Ok((len, _)) = decode_prefix(p, max) {
            assert!(len <= max);
        }
    }

    let mut reader = RecordReader::new(max);
    let capacity = reader.capacity();
    let mut src = Chunked {
        data,
        chunk,
        left: 0,
    };
    loop {
        match reader.read_from(&mut src) {
            Ok(ReadProgress::Record(k)) => {
                let body = reader.body();
                assert!(body.len() <= max);
                match k {
                    kind::HELLO => {
                        if let Ok(h) = decode_hello(body) {
                            assert!(h.token.len() <= MAX_TOKEN);
                        }
                    }
                    kind::MOTOR => {
                        if let Ok((h, commands)) = decode_motor(body) {
                            assert_eq!(h.command_count as usize, commands.len());
                        }
                    }
                    _ => {
                        let _ = Reject::decode(body);
                    }
                }
            }
            Ok(ReadProgress::Pending) => {}
            Ok(ReadProgress::Closed) | Err(_) => break,
        }
        assert!(reader.buffered() <= PREFIX + max);
    }
    assert_eq!(reader.capacity(), capacity);
}

/// The original protocol's frame reader and decoder, as the host reads a client of the
/// original system: in arbitrary pieces, each complete frame decoded in both dialects and
/// tried as a version check. The first byte picks the reader's maximum and the split.
///
/// Checked: no panic; no frame body beyond the reader's maximum (longer frames are
/// skipped, never buffered); a decoded command's arguments pass the catalogue's own
/// check (`MotorCommand::decode`) or the command is refused, never applied unchecked.
pub fn legacy(input: &[u8]) {
    let Some((&select, data)) = input.split_first() else {
        return;
    };
    let max = if select & 1 == 0 {
        MAX_INCOMING_FRAME
    } else {
        usize::from(select)
    };
    let chunk = 1 + usize::from(select >> 1);
    let mut reader = FrameReader::new(max);
    let mut src = Chunked {
        data,
        chunk,
        left: 0,
    };
    loop {
        match reader.read_from(&mut src) {
            Ok(FrameProgress::Frame) => {
                let body = reader.body();
                assert!(body.len() <= max);
                let _ = version_check_dialect(body);
                for dialect in [Dialect::Vrnew, Dialect::Burkhardt] {
                    if let Ok(Incoming::Command { action_id, command }) =
                        decode_frame(body, dialect)
                    {
                        // What the host hands on is what the catalogue accepts.
                        let wire = command.encode(action_id);
                        if let Ok(back) = wire.decode() {
                            assert_eq!(back, command);
                        }
                    }
                }
            }
            Ok(FrameProgress::Skipped(n)) => assert!(n > max),
            Ok(FrameProgress::Pending) => {}
            Ok(FrameProgress::Closed) | Err(_) => break,
        }
    }
}

/// The config loader on any text (a config file is the user's input, often edited by
/// hand): bytes that are not UTF-8 are not a config.
///
/// Checked: no panic; a config that loads writes itself back out
/// (`Config::to_toml_string`) as text that loads to the same config.
pub fn config(input: &[u8]) {
    let Ok(text) = std::str::from_utf8(input) else {
        return;
    };
    let path = Path::new("<fuzz>");
    if let Ok(config) = Config::from_toml_str(text, path) {
        let written = config.to_toml_string();
        match Config::from_toml_str(&written, path) {
            Ok(again) => assert_eq!(again, config, "written out as:\n{written}"),
            Err(e) => panic!(
                "a loaded config wrote itself out as text that does not load: {e}\n{written}"
            ),
        }
    }
}
