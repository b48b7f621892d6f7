//! The config file being checked, and the checks every section uses: an error at a key's
//! line, a number of seconds.

use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use toml::Spanned;

use super::error::ConfigLoadError;

/// Highest agent id accepted (ids are also iceoryx2 event ids; the legacy transport's agent
/// ports follow its `local_port` up to it).
pub const MAX_AGENT_ID: u32 = 250;

/// The file being checked: its path (named in errors) and text (for line numbers).
pub(crate) struct Ctx<'a> {
    pub(crate) path: &'a Path,
    pub(crate) text: &'a str,
}

impl Ctx<'_> {
    pub(crate) fn line_of(&self, span: Range<usize>) -> usize {
        let end = span.start.min(self.text.len());
        self.text.as_bytes()[..end]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    pub(crate) fn invalid(
        &self,
        span: Range<usize>,
        key: &str,
        reason: impl Into<String>,
    ) -> ConfigLoadError {
        ConfigLoadError::Invalid {
            path: self.path.to_path_buf(),
            line: self.line_of(span),
            key: key.to_string(),
            reason: reason.into(),
        }
    }

    pub(crate) fn seconds(
        &self,
        value: Option<Spanned<f64>>,
        key: &str,
        default: f64,
    ) -> Result<Duration, ConfigLoadError> {
        let Some(v) = value else {
            return Ok(Duration::from_secs_f64(default));
        };
        let (span, secs) = (v.span(), *v.get_ref());
        if !secs.is_finite() || secs <= 0.0 {
            return Err(self.invalid(
                span,
                key,
                format!("must be a positive number of seconds, found {secs}"),
            ));
        }
        if secs > 86_400.0 {
            return Err(self.invalid(span, key, format!("{secs} s is more than a day")));
        }
        Ok(Duration::from_secs_f64(secs))
    }
}

/// `s` as a TOML string value. (Rust's `{:?}` is not TOML: it writes `\u{7f}`.)
pub(crate) fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}
