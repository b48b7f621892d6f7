//! Hostile bytes, in process: what decoding them costs. The record reader and decoders the
//! host runs on a stranger's or an agent's bytes, under a global allocator that measures
//! (also used by the config loader's property tests, `config.rs`).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::{ErrorKind, Read};

use proptest::prelude::*;
use vrsync_bridge::tcp::{
    MAX_HELLO, MAX_TOKEN, ReadProgress, RecordReader, Reject, decode_hello, decode_motor,
};

use super::MAX_MOTOR_BODY;

/// The system allocator, remembering per thread how many allocations happened and the
/// largest one, so property tests can bound what a decoder or the config loader allocates
/// for hostile input. It only counts; the allocation itself is the system's.
struct MeasuringAlloc;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    // `try_with`: no panic while a thread is being torn down. Const thread-locals without
    // destructors never allocate, so this cannot recurse.
    let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for MeasuringAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: same contract as ours.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: same contract as ours.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: MeasuringAlloc = MeasuringAlloc;

/// What a closure allocated on this thread.
#[derive(Debug, Clone, Copy)]
pub struct Allocations {
    /// Allocations and reallocations.
    pub count: u64,
    /// Bytes of the largest one.
    pub largest: usize,
}

/// Runs `f` and reports its allocations on this thread.
pub fn allocations_in<R>(f: impl FnOnce() -> R) -> (R, Allocations) {
    let count = ALLOCATIONS.with(Cell::get);
    let largest = LARGEST.with(|l| l.replace(0));
    let r = f();
    let measured = Allocations {
        count: ALLOCATIONS.with(Cell::get) - count,
        largest: LARGEST.with(|l| l.replace(largest.max(l.get()))),
    };
    (r, measured)
}

/// Hands out bytes in chunks of the given sizes, with a `WouldBlock` before each chunk,
/// as a non-blocking socket does; then end of stream.
struct Chunked<'a> {
    data: &'a [u8],
    chunks: &'a [usize],
    next_chunk: usize,
    left_in_chunk: usize,
}

impl Read for Chunked<'_> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if self.data.is_empty() {
            return Ok(0);
        }
        if self.left_in_chunk == 0 {
            self.left_in_chunk = self.chunks.get(self.next_chunk).copied().unwrap_or(1 << 20);
            self.next_chunk += 1;
            return Err(ErrorKind::WouldBlock.into());
        }
        let n = out.len().min(self.left_in_chunk).min(self.data.len());
        out[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        self.left_in_chunk -= n;
        Ok(n)
    }
}

/// Hostile bytes: mostly random, sometimes starting with a prefix that announces any
/// length and kind (the interesting case for allocation).
fn hostile_stream() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..3000),
        (
            any::<u32>(),
            1u32..8,
            proptest::collection::vec(any::<u8>(), 0..600)
        )
            .prop_map(|(len, k, rest)| {
                let mut v = len.to_le_bytes().to_vec();
                v.extend_from_slice(&k.to_le_bytes());
                v.extend_from_slice(&rest);
                v
            }),
    ]
}

#[test]
fn the_allocation_meter_sees_allocations() {
    let (v, cost) = allocations_in(|| vec![0u8; 12345]);
    assert_eq!(v.len(), 12345);
    assert!(cost.count >= 1 && cost.largest >= 12345, "{cost:?}");
    let ((), cost) = allocations_in(|| {});
    assert_eq!((cost.count, cost.largest), (0, 0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Reading records, as the host does from a stranger (hello) or an agent (motor
    /// batches), allocates nothing at all once the reader exists, whatever the bytes and
    /// however they are split; decoding a record allocates at most its body's size.
    #[test]
    fn decoding_hostile_bytes_allocates_nothing_beyond_the_limit(
        data in hostile_stream(),
        chunks in proptest::collection::vec(1usize..200, 0..40),
        motor in any::<bool>(),
    ) {
        let max = if motor { MAX_MOTOR_BODY } else { MAX_HELLO };
        let mut reader = RecordReader::new(max);
        let capacity = reader.capacity();
        let mut src = Chunked { data: &data, chunks: &chunks, next_chunk: 0, left_in_chunk: 0 };
        loop {
            let (progress, read_cost) = allocations_in(|| reader.read_from(&mut src));
            prop_assert_eq!(read_cost.count, 0, "reading allocated");
            match progress {
                Ok(ReadProgress::Record(_)) => {
                    let body = reader.body();
                    prop_assert!(body.len() <= max);
                    let ((), cost) = allocations_in(|| {
                        let _ = decode_hello(body);
                        let _ = decode_motor(body);
                        let _ = Reject::decode(body);
                    });
                    // A hello's token (<= MAX_TOKEN), a reject's message (<= the body)
                    // or an error message: never more than the body plus a short text.
                    prop_assert!(
                        cost.largest <= max.max(MAX_TOKEN) + 256,
                        "decoding a {}-byte body allocated {} bytes", body.len(), cost.largest
                    );
                }
                Ok(ReadProgress::Pending) => {}
                Ok(ReadProgress::Closed) | Err(_) => break,
            }
        }
        prop_assert_eq!(reader.capacity(), capacity);
    }
}
