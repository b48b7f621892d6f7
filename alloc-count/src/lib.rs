//! # vrsync-alloc-count
//!
//! A counting global allocator ([`CountingAlloc`]): the system allocator, counting every
//! allocation and reallocation, so that a benchmark can report allocations per cycle
//! ([`allocations`]). The programs (`vr-sim`, `vr-bench-agent`) and the Python extension
//! install it; the benchmark's transport floors (`vrsync-floor`) read the count. A crate
//! of its own, without dependencies, so that what installs it links nothing else of the
//! benchmark.
//!
//! ```
//! #[global_allocator]
//! static ALLOC: vrsync_alloc_count::CountingAlloc = vrsync_alloc_count::CountingAlloc;
//!
//! fn main() {
//!     let before = vrsync_alloc_count::allocations();
//!     let v = std::hint::black_box(vec![1u8; 16]);
//!     assert!(vrsync_alloc_count::allocations() > before);
//!     drop(v);
//! }
//! ```

mod counting;

pub use counting::{CountingAlloc, allocations};
