//! Log and message output: ANSI colours only where a person reads them, durations as a
//! person writes them.

use std::ffi::OsStr;
use std::fmt;
use std::io::IsTerminal;
use std::time::Duration;

/// Displays a duration rounded to three significant digits in the largest fitting unit:
/// `30 s` (not `30.000000001s`), `2.5 s`, `250 ms`, `1.5 µs`, `0 s`. For messages and
/// logs a person reads; `Debug` of a [`Duration`] prints every nanosecond.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rounded(pub Duration);

impl fmt::Display for Rounded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ns = self.0.as_nanos() as f64;
        if ns == 0.0 {
            return f.write_str("0 s");
        }
        // Round to three significant digits first, so 999.9999 ms becomes 1 s, not 1000 ms.
        let scale = 10f64.powi(ns.log10().floor() as i32 - 2);
        let ns = if scale > 1.0 {
            (ns / scale).round() * scale
        } else {
            ns
        };
        let (value, unit) = match ns {
            n if n >= 1e9 => (n / 1e9, "s"),
            n if n >= 1e6 => (n / 1e6, "ms"),
            n if n >= 1e3 => (n / 1e3, "µs"),
            n => (n, "ns"),
        };
        // Three significant digits, without trailing zeros: 30, 2.5, 1.25, 123.
        let decimals = if value >= 100.0 {
            0
        } else if value >= 10.0 {
            1
        } else {
            2
        };
        let text = format!("{value:.decimals$}");
        let text = if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.')
        } else {
            &text
        };
        write!(f, "{text} {unit}")
    }
}

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
    fn durations_are_rounded_to_three_digits() {
        let r = |d: Duration| Rounded(d).to_string();
        assert_eq!(r(Duration::new(30, 1)), "30 s");
        assert_eq!(r(Duration::from_millis(2500)), "2.5 s");
        assert_eq!(r(Duration::from_millis(250)), "250 ms");
        assert_eq!(r(Duration::from_micros(1500)), "1.5 ms");
        assert_eq!(r(Duration::from_nanos(1_234_567)), "1.23 ms");
        assert_eq!(r(Duration::from_secs(3600)), "3600 s");
        assert_eq!(r(Duration::from_nanos(1500)), "1.5 µs");
        assert_eq!(r(Duration::from_nanos(7)), "7 ns");
        assert_eq!(r(Duration::ZERO), "0 s");
        assert_eq!(r(Duration::from_secs_f64(0.1)), "100 ms");
        assert_eq!(r(Duration::from_nanos(999_999_999)), "1 s");
        assert_eq!(r(Duration::from_nanos(2_499_999_999)), "2.5 s");
    }

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
