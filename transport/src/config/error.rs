//! Why a configuration could not be loaded.

use std::path::PathBuf;

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigLoadError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, so not also a `source()`: printed once).
        error: std::io::Error,
    },
    /// TOML syntax error, unknown key or wrong type.
    #[error("{path}:{line}:{column}: {message} (at key `{key}`)")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Dotted key at that line (table header + key), `?` if none.
        key: String,
        /// What the TOML parser said (names the key).
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{path}:{line}: invalid `{key}`: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the value.
        line: usize,
        /// Dotted key, e.g. `sync.stop_timeout`.
        key: String,
        /// Why it is invalid.
        reason: String,
    },
}
