//! vrsync integration tests: real `vr-sim` and `vr-agent` processes, one binary
//! (`autotests = false`), a module per area, fixtures in `util.rs`.

// Test code: panicking on a broken fixture is the right failure.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[macro_use]
mod util;

mod config;
mod cpp;
mod events;
mod examples;
mod faults;
mod fuzz;
mod hostile;
mod legacy;
mod liveness;
mod logs;
mod netfaults;
mod netns;
mod packages;
mod replay;
mod sync;
mod world;
