//! Feeds arbitrary bytes to the legacy transport's frame reader and decoder, exactly as
//! the host reads a legacy client: in arbitrary pieces, with `WouldBlock` between them,
//! each complete frame decoded in both dialects and tried as a version check.
//!
//! Checked on every input: no panic; no frame body beyond the reader's maximum; a
//! decoded command's arguments are finite or the command is refused by the catalogue's
//! own check (`MotorCommand::decode`), never applied unchecked.

#![no_main]

use std::io::{self, ErrorKind, Read};

use libfuzzer_sys::fuzz_target;
use vrsync_bridge::legacy::codec::{
    Dialect, FrameProgress, FrameReader, Incoming, MAX_INCOMING_FRAME, decode_frame,
    version_check_dialect,
};

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

fuzz_target!(|input: &[u8]| {
    // The first byte picks the reader's maximum and how the stream is split.
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
                    if let Ok(Incoming::Command { action_id, command }) = decode_frame(body, dialect)
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
});
