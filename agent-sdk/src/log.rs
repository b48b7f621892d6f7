//! Log and message output: ANSI colours only where a person reads them, durations as a
//! person writes them.

use std::ffi::OsStr;
use std::io::IsTerminal;

/// Displays a duration rounded to three significant digits (`30 s`, `2.5 s`, `250 ms`);
/// defined in the bridge, whose messages use it too.
pub use vrsync_bridge::Rounded;

/// Whether log lines written to stderr may carry ANSI colour codes: only when stderr is a
/// terminal and `NO_COLOR` is unset or empty (<https://no-color.org>). Redirected output (a
/// file, a pipe, Unity's `Editor.log`) gets plain text. What `vr-agent` and
/// [`vrs_init_logging`](crate::ffi::vrs_init_logging) use; pass it to your own subscriber's
/// `with_ansi`.
pub fn ansi_on_stderr() -> bool {
    ansi(
        std::io::stderr().is_terminal(),
        std::env::var_os("NO_COLOR").as_deref(),
    )
}

/// The rule of [`ansi_on_stderr`], given whether the stream is a terminal and `NO_COLOR`.
fn ansi(terminal: bool, no_color: Option<&OsStr>) -> bool {
    terminal && no_color.is_none_or(OsStr::is_empty)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        assert!(ansi(true, None));
        assert!(
            ansi(true, Some(OsStr::new(""))),
            "an empty NO_COLOR is unset"
        );
        assert!(!ansi(true, Some(OsStr::new("1"))));
        assert!(
            !ansi(true, Some(OsStr::new("0"))),
            "any non-empty value disables"
        );
        assert!(!ansi(false, None));
        assert!(!ansi(false, Some(OsStr::new(""))));
    }
}
