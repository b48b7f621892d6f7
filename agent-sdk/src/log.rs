//! Log and message output: ANSI colours only where a person reads them, the default log
//! filter, durations as a person writes them. All are defined in the bridge, whose messages
//! and programs use them too; re-exported here so that an agent needs no other crate for
//! them.

/// Displays a duration rounded to three significant digits (`30 s`, `2.5 s`, `250 ms`).
pub use vrsync_transport::Rounded;
/// Whether log lines written to stderr may carry ANSI colour codes: only when stderr is a
/// terminal and `NO_COLOR` is unset or empty (<https://no-color.org>). What `vr-agent` and
/// `vrs_init_logging` of the C ABI use; pass it to your own subscriber's
/// `with_ansi`.
pub use vrsync_transport::ansi_on_stderr;
/// The filter text of a program logging at a level by default: the level plus directives
/// that silence zenoh's notices meaningless to vrsync users ([`QUIET_ZENOH`]). What
/// `vr-agent` and the C ABI's `vrs_init_logging` use when `RUST_LOG`
/// is unset; give it to your own subscriber's `EnvFilter::new`.
pub use vrsync_transport::{QUIET_ZENOH, default_log_filter};
