//! Durations as a person writes them, for messages and logs.

use std::fmt;
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
}
