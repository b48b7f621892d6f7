//! Reading arguments and writing out-parameters.

use std::ffi::{CStr, c_char};
use std::str::Utf8Error;

use tracing_subscriber::EnvFilter;
use tracing_subscriber::filter::ParseError;

use crate::sensors::CAMERA_NAME_SIZE;

/// An argument a call cannot use.
#[derive(Debug, thiserror::Error)]
pub enum ArgError {
    /// A pointer that must not be null is.
    #[error("{0} must not be null")]
    Null(&'static str),
    /// A string argument is not UTF-8.
    #[error("invalid argument: {what} is not UTF-8: {source}")]
    NotUtf8 {
        /// The argument's name.
        what: &'static str,
        /// Where the bytes stop being UTF-8.
        source: Utf8Error,
    },
    /// A log filter that does not parse.
    #[error("invalid argument: bad log filter {text:?}: {source}")]
    BadLogFilter {
        /// The filter as given.
        text: String,
        /// Why it does not parse.
        source: ParseError,
    },
}

/// Writes `value` through `out` when `out` is not null.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
pub unsafe fn write_opt<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: non-null and, by the caller's contract, valid for writes.
        unsafe { out.write(value) }
    }
}

/// Writes `value` through `out`, which must not be null (`what` names it in the error).
///
/// # Errors
/// [`ArgError::Null`], converted to the caller's error type.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
pub unsafe fn write_required<T, E: From<ArgError>>(
    out: *mut T,
    what: &'static str,
    value: T,
) -> Result<(), E> {
    if out.is_null() {
        return Err(ArgError::Null(what).into());
    }
    // SAFETY: non-null and, by the caller's contract, valid for writes.
    unsafe { out.write(value) };
    Ok(())
}

/// Reads a C string argument as UTF-8 (`what` names it in the error).
///
/// # Errors
/// [`ArgError::Null`], [`ArgError::NotUtf8`].
///
/// # Safety
/// `s` is null or a valid NUL-terminated string that outlives `'a`.
pub unsafe fn str_arg<'a>(s: *const c_char, what: &'static str) -> Result<&'a str, ArgError> {
    if s.is_null() {
        return Err(ArgError::Null(what));
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract.
    let c = unsafe { CStr::from_ptr(s) };
    c.to_str()
        .map_err(|source| ArgError::NotUtf8 { what, source })
}

/// The log filter of an `init_logging` call: `filter`, a `RUST_LOG`-style filter such as
/// `"info"`; NULL takes the `RUST_LOG` environment variable, or `"warn"`.
///
/// # Errors
/// [`ArgError::NotUtf8`], [`ArgError::BadLogFilter`].
///
/// # Safety
/// `filter` is null or a valid NUL-terminated string.
pub unsafe fn log_filter(filter: *const c_char) -> Result<EnvFilter, ArgError> {
    if filter.is_null() {
        return Ok(EnvFilter::try_from_default_env()
            .unwrap_or_else(|_| EnvFilter::new(vrsync_transport::default_log_filter("warn"))));
    }
    // SAFETY: a C string by the caller's contract.
    let text = unsafe { str_arg(filter, "filter") }?;
    EnvFilter::try_new(text).map_err(|source| ArgError::BadLogFilter {
        text: text.to_owned(),
        source,
    })
}

/// A camera or channel name as a NUL-terminated C array (cut at the wire format's
/// [`CAMERA_NAME_LEN`](vrsync_transport::CAMERA_NAME_LEN) bytes, which is also
/// [`CHANNEL_NAME_LEN`](vrsync_transport::CHANNEL_NAME_LEN)).
pub fn c_name(name: &str) -> [c_char; CAMERA_NAME_SIZE] {
    let mut out = [0 as c_char; CAMERA_NAME_SIZE];
    for (dst, &src) in out.iter_mut().zip(
        name.as_bytes()
            .iter()
            .take(vrsync_transport::CAMERA_NAME_LEN),
    ) {
        *dst = src as c_char;
    }
    out
}

#[cfg(test)]
mod tests {
    use std::ffi::CStr;
    use std::ptr;

    use super::*;

    #[test]
    fn strings_and_out_parameters() {
        // SAFETY: null, or valid C strings and out pointers.
        unsafe {
            assert_eq!(str_arg(c"left".as_ptr(), "name").unwrap(), "left");
            let null = str_arg(ptr::null(), "name").unwrap_err().to_string();
            assert_eq!(null, "name must not be null");
            let bad = c"\xff\xfe";
            let bad = str_arg(bad.as_ptr(), "path").unwrap_err().to_string();
            assert!(
                bad.starts_with("invalid argument: path is not UTF-8"),
                "{bad}"
            );

            let mut v = 0u32;
            write_opt(&mut v, 3);
            write_opt(ptr::null_mut(), 4u32);
            assert_eq!(v, 3);
            write_required::<_, ArgError>(&mut v, "out", 5).unwrap();
            assert_eq!(v, 5);
            let e = write_required::<_, ArgError>(ptr::null_mut(), "out_id", 6u32);
            assert_eq!(e.unwrap_err().to_string(), "out_id must not be null");

            let bad = log_filter(c"[[[".as_ptr()).unwrap_err().to_string();
            assert!(
                bad.starts_with("invalid argument: bad log filter \"[[[\""),
                "{bad}"
            );
            assert!(log_filter(c"info,vrsync_agent=debug".as_ptr()).is_ok());

            let name = c_name("a-very-long-camera-name");
            assert_eq!(CStr::from_ptr(name.as_ptr()).to_bytes().len(), 16);
        }
    }
}
