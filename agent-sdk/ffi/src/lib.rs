//! The C ABI of the agent SDK: what `include/vrsync.h` declares (generated from this file
//! by cbindgen; `tests::header_is_up_to_date` fails when the two drift apart).
//!
//! Conventions:
//! - Every name starts with `vrs_`; types end in `_t`; the agent is an opaque
//!   `vrs_agent_t*` handle.
//! - Every fallible function returns a [`vrs_status_t`]: `VRS_OK` (0), a positive
//!   non-error outcome (`VRS_TIMEOUT`, `VRS_SESSION_CLOSED`), or a negative error. The text
//!   of the last status of the calling thread is in [`vrs_last_error_message`].
//! - Each `extern "C"` function is a thin wrapper over a Rust `*_impl` function returning a
//!   `Result`; panics are caught at the boundary and reported as `VRS_ERROR_PANIC`.
//!
//! # Handles
//! A `vrs_agent_t*` is **not a pointer to memory**: it carries a number from a counter
//! that is never reused, and the agents live in a registry keyed by that number. The
//! library never dereferences a handle, so a null handle, a handle that was already
//! disconnected (double free) or a made-up value is a `VRS_ERROR_INVALID_HANDLE` with a
//! message, never a crash, and a stale handle can never alias a newer agent. (A magic /
//! tombstone scheme would have to read freed memory to detect a double free.)
//!
//! # Threads
//! The shared-memory ports behind an agent are not thread-safe (iceoryx2 `ipc` ports are
//! neither `Send` nor `Sync`), so an agent belongs to the thread that connected it: the
//! registry is per thread, and a call with the handle from another thread returns
//! `VRS_ERROR_WRONG_THREAD`. Different threads may each run their own agents. An agent
//! still connected when its thread exits is disconnected then.
//!
//! # Frames
//! [`vrs_agent_wait_start`] makes the received frame the agent's *current frame*. Its
//! scalar fields are copied into a [`vrs_frame_t`]; images are read with
//! [`vrs_agent_image`], whose `data` pointers point straight into shared memory (no copy).
//! They stay valid until the next [`vrs_agent_wait_start`] (whatever it returns),
//! [`vrs_agent_stop`] or [`vrs_agent_disconnect`] of that agent. The frame's vectors
//! ([`vrs_agent_vector`]) are views with the same lifetime.
//!
//! # Files
//! `types.rs` the constants, enums and `#[repr(C)]` structs; `state.rs` the error type of
//! the boundary and the registry of agents; `calls.rs` the `*_impl` functions behind the
//! exports; `exports.rs` the library, connection and frame functions; `send.rs` the
//! commands and the stop that sends them; `channels.rs` the vectors, the channel specs and
//! the actions (`[[agent.vector]]`, `[[agent.action]]`). The plumbing (handle registry, last error, panic
//! boundary, argument helpers) and the sensor structs are `vrsync_cabi`'s, shared with the
//! host C ABI.

#![allow(non_camel_case_types)]

mod calls;
mod channels;
mod exports;
mod send;
mod state;
mod types;

pub use channels::*;
pub use exports::*;
pub use send::*;
pub use types::*;

#[cfg(test)]
mod channel_tests;
#[cfg(test)]
mod tests;
