//! # vrsync-cabi
//!
//! The plumbing that both vrsync C ABIs need, written once: the agent SDK's
//! (`vrsync-agent-ffi`, header `agent-sdk/include/vrsync.h`) and the host's
//! (`vrsync-host-ffi`, header `bridge/ffi/include/vrsync_host.h`). Internal: its items
//! serve those two crates and may change with them; nothing here is exported to C (no
//! `extern "C"` function), so linking both libraries into one program clashes nowhere.
//!
//! - [`handles`]: opaque handles that are registry keys, never pointers: a null, stale
//!   (double free) or made-up handle is an error, never a crash; a handle belongs to the
//!   thread that made it, and another thread can only ask for its destruction.
//! - [`error`]: the per-thread last-error message of each ABI, the error chain it holds,
//!   and the boundary that catches panics and turns a `Result` into a status code.
//! - [`args`]: reading C string and log filter arguments, writing out-parameters.
//! - [`sensors`]: the `#[repr(C)]` sensor structs both headers declare. One Rust type
//!   each; the host's cbindgen settings rename them (`vrs_pose_t` → `vrs_host_pose_t`, …)
//!   so each header keeps its names and both can be included together.

pub mod args;
pub mod error;
pub mod handles;
pub mod sensors;

pub use args::{ArgError, c_name, log_filter, str_arg, write_opt, write_required};
pub use error::{AbiError, LastError, boundary, boundary_status, chain, last_error_ptr};
pub use handles::{HandleError, HandleKind, Registry, Removal};
pub use sensors::{
    CAMERA_NAME_SIZE, CHANNEL_NAME_SIZE, vrs_action_status_t, vrs_collision_t, vrs_eye_position_t,
    vrs_grid_position_t, vrs_head_motion_t, vrs_pose_t,
};
