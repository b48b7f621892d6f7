//! # vrsync-agent-bin
//!
//! vrsync's agent programs, built on the agent SDK (`vrsync-agent`): the example agent
//! `vr-agent` and the benchmark agent `vr-bench-agent` that `vr-sim bench` spawns. The
//! library holds what the programs share with the tests: the example [`policy`] of
//! `vr-agent`. A Rust agent depends on `vrsync-agent`, not on this package.

pub mod policy;
