//! # vrsync-floor
//!
//! Benchmark-only support, kept out of the core library (`vrsync-bridge`):
//!
//! - the **transport floors**: the raw round trip each transport allows, measured by
//!   `vr-sim bench` with the same bytes and fan-out as a vrsync cycle and nothing else
//!   (host side [`ShmFloorHost`] / [`TcpFloorHost`] / [`ZenohFloorHost`], agent side
//!   [`shm_floor_agent`] / [`tcp_floor_agent`] / [`zenoh_floor_agent`], run by
//!   `vr-bench-agent --mode floor-shm|floor-tcp|floor-zenoh`), each reporting its
//!   allocations per cycle when the program installed `vrsync-alloc-count`'s counting
//!   allocator.

mod floor;
mod zenoh_floor;

pub use floor::{
    FloorAgentReport, FloorError, ShmFloorAgentOptions, ShmFloorHost, TcpFloorHost,
    shm_floor_agent, tcp_floor_agent, touch_rows,
};
pub use zenoh_floor::{ZenohFloorHost, zenoh_floor_agent};
