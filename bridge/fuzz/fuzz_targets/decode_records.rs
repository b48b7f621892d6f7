//! Feeds arbitrary bytes to the TCP record reader and every body decoder, exactly as the
//! host reads a stranger's hello or an agent's motor batches: in arbitrary pieces, with
//! `WouldBlock` between them.
//!
//! Checked on every input: no panic; no body beyond the reader's maximum; the reader's
//! buffer never grows; a decoded hello's token is at most `MAX_TOKEN`; a decoded motor
//! batch holds exactly the commands its header announces. Run with `-malloc_limit_mb`
//! (see README.md) to also fail on any large allocation.

#![no_main]

use std::io::{self, ErrorKind, Read};

use libfuzzer_sys::fuzz_target;
use vrsync_bridge::tcp::{
    MAX_HELLO, MAX_TOKEN, PREFIX, ReadProgress, RecordReader, decode_hello, decode_motor,
    decode_prefix, kind, Reject,
};
use vrsync_bridge::{MotorCommand, MotorHeader};

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

fuzz_target!(|input: &[u8]| {
    // The first byte picks the reader's maximum and how the stream is split.
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
});
