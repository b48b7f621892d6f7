//! Colour in log output: ANSI codes only where a person reads them.

use std::ffi::OsStr;
use std::io::IsTerminal;

/// Whether log lines written to stderr may carry ANSI colour codes: only when stderr is a
/// terminal and `NO_COLOR` is unset or empty (<https://no-color.org>). Redirected output (a
/// file, a pipe, Unity's `Editor.log`) gets plain text. What `vr-sim`, `vr-agent` and the
/// agent SDK's `vrs_init_logging` use; pass it to your own subscriber's `with_ansi`.
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
