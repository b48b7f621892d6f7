//! The last-error message of a thread, the error chain it holds, and the boundary every
//! exported function runs its body in.

use std::cell::RefCell;
use std::ffi::{CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::thread::LocalKey;

/// The last-error message of one C ABI on one thread. Each ABI declares its own
/// `thread_local!` of this type, so that a call of one ABI never replaces (and frees) the
/// message the other one handed out.
#[derive(Debug, Default)]
pub struct LastError(RefCell<CString>);

/// The error type of one C ABI's boundary: its status codes and its last-error slot.
pub trait AbiError: std::error::Error + Sized {
    /// The ABI's status enum (`vrs_status_t`, `vrs_host_status_t`).
    type Status: Copy + PartialEq;
    /// The status of a success.
    const OK: Self::Status;
    /// The ABI's thread-local last-error slot.
    fn last_error() -> &'static LocalKey<LastError>;
    /// The status this error is reported as.
    fn status(&self) -> Self::Status;
    /// The error for a panic caught at the boundary, with the panic's message.
    fn panicked(message: String) -> Self;
}

/// The error and its sources, `: `-separated (what `{:#}` prints with anyhow).
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        let text = inner.to_string();
        // `#[error(transparent)]` repeats the source's text; say it once.
        if !s.ends_with(&text) {
            s.push_str(": ");
            s.push_str(&text);
        }
        source = inner.source();
    }
    s
}

/// Replaces this thread's message in `slot`.
pub fn set_last_error(slot: &'static LocalKey<LastError>, message: &str) {
    // A message cannot hold NUL bytes in C; cut at the first one.
    let message = message.split('\0').next().unwrap_or_default();
    let c = CString::new(message).unwrap_or_default();
    let _ = slot.try_with(|cell| {
        if let Ok(mut current) = cell.0.try_borrow_mut() {
            *current = c;
        }
    });
}

/// This thread's message in `slot` as a C string (empty after a success), never null. The
/// buffer stays where it is until the next call of the ABI replaces the message.
pub fn last_error_ptr(slot: &'static LocalKey<LastError>) -> *const c_char {
    slot.try_with(|cell| match cell.0.try_borrow() {
        Ok(s) => s.as_ptr(),
        Err(_) => c"".as_ptr(),
    })
    .unwrap_or(c"".as_ptr())
}

fn panic_message(payload: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic payload".to_owned()
    }
}

/// The boundary: runs `f`, catches panics, records the message (empty on success) and
/// returns the status.
pub fn boundary<E: AbiError>(f: impl FnOnce() -> Result<(), E>) -> E::Status {
    let result = catch_unwind(AssertUnwindSafe(f))
        .unwrap_or_else(|payload| Err(E::panicked(panic_message(payload))));
    match result {
        Ok(()) => {
            set_last_error(E::last_error(), "");
            E::OK
        }
        Err(e) => {
            set_last_error(E::last_error(), &chain(&e));
            e.status()
        }
    }
}

/// Like [`boundary`] for calls whose success may itself be a positive status with a
/// message (the host's `VRS_HOST_TIMEOUT`, `VRS_HOST_DEFERRED`).
pub fn boundary_status<E: AbiError>(
    f: impl FnOnce() -> Result<(E::Status, String), E>,
) -> E::Status {
    let mut outcome = None;
    let status = boundary::<E>(|| {
        outcome = Some(f()?);
        Ok(())
    });
    match outcome {
        Some((ok, message)) if status == E::OK && ok != E::OK => {
            set_last_error(E::last_error(), &message);
            ok
        }
        _ => status,
    }
}

#[cfg(test)]
mod tests {
    use std::ffi::CStr;

    use super::*;

    thread_local! {
        static LAST: LastError = LastError::default();
    }

    #[derive(Debug, thiserror::Error)]
    enum TestError {
        #[error("outer")]
        Outer(#[source] std::io::Error),
        #[error("panic: {0}")]
        Panic(String),
    }

    impl AbiError for TestError {
        type Status = i32;
        const OK: i32 = 0;
        fn last_error() -> &'static LocalKey<LastError> {
            &LAST
        }
        fn status(&self) -> i32 {
            match self {
                Self::Outer(_) => -1,
                Self::Panic(_) => -99,
            }
        }
        fn panicked(message: String) -> Self {
            Self::Panic(message)
        }
    }

    fn message() -> String {
        // SAFETY: never null, NUL-terminated.
        unsafe { CStr::from_ptr(last_error_ptr(&LAST)) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn errors_panics_and_positive_outcomes_become_statuses_and_messages() {
        let io = std::io::Error::other("inner\0cut here");
        assert_eq!(boundary(|| Err(TestError::Outer(io))), -1);
        assert_eq!(message(), "outer: inner");
        assert_eq!(boundary::<TestError>(|| panic!("boom")), -99);
        assert_eq!(message(), "panic: boom");
        assert_eq!(boundary::<TestError>(|| Ok(())), 0);
        assert_eq!(message(), "");
        assert_eq!(
            boundary_status::<TestError>(|| Ok((2, "later".to_owned()))),
            2
        );
        assert_eq!(message(), "later");
    }
}
