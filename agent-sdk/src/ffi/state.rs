//! What lives behind a `vrs_agent_t`: the error type of the boundary, the thread-local
//! last-error message and the registry of agents.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::ffi::CString;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::thread::ThreadId;

use vrsync_bridge::ConfigLoadError;

use super::types::{vrs_agent_t, vrs_status_t};
use crate::agent::{Agent, AgentConnectError, Frame, SendError, StopError, WaitStartError};

// ---------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------

/// Everything a C ABI call can fail with; each maps to one [`vrs_status_t`].
#[derive(Debug, thiserror::Error)]
pub(super) enum FfiError {
    #[error("{0} must not be null")]
    Null(&'static str),
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    #[error("invalid agent handle: null")]
    NullHandle,
    #[error("invalid agent handle {0:#x}: not an agent, or already disconnected (double free?)")]
    UnknownHandle(usize),
    #[error(
        "agent handle {0:#x} belongs to another thread: use an agent only on the thread that \
         connected it"
    )]
    WrongThread(usize),
    #[error("the calling thread is exiting; its agents are already disconnected")]
    ThreadExiting,
    #[error(transparent)]
    Config(#[from] ConfigLoadError),
    #[error(transparent)]
    Connect(#[from] AgentConnectError),
    #[error(transparent)]
    Wait(#[from] WaitStartError),
    #[error(transparent)]
    Send(#[from] SendError),
    #[error(transparent)]
    Stop(#[from] StopError),
    #[error(
        "no current frame: call vrs_agent_wait_start first (a frame ends at the next wait, \
         at stop and at disconnect)"
    )]
    NoFrame,
    #[error("{what} index {index} is out of range (the frame has {count})")]
    OutOfRange {
        what: &'static str,
        index: usize,
        count: usize,
    },
    #[error("the current frame has no camera named {0:?}")]
    NoSuchCamera(String),
    #[error("logging is already initialised in this process")]
    LoggingAlreadySet,
    #[error("panic in the vrsync library: {0}")]
    Panic(String),
}

impl FfiError {
    // The wildcard arms keep new variants of the SDK's (non-exhaustive) error enums from
    // breaking the build; they map to VRS_ERROR_OTHER with their message.
    #[allow(unreachable_patterns)]
    fn status(&self) -> vrs_status_t {
        use vrs_status_t::*;
        match self {
            Self::Null(_)
            | Self::InvalidArgument(_)
            | Self::NoSuchCamera(_)
            | Self::LoggingAlreadySet => VRS_ERROR_INVALID_ARGUMENT,
            Self::NullHandle | Self::UnknownHandle(_) | Self::ThreadExiting => {
                VRS_ERROR_INVALID_HANDLE
            }
            Self::WrongThread(_) => VRS_ERROR_WRONG_THREAD,
            Self::Config(_) => VRS_ERROR_CONFIG,
            Self::Connect(_) => VRS_ERROR_CONNECT,
            Self::Wait(e) => match e {
                WaitStartError::Timeout { .. } => VRS_TIMEOUT,
                WaitStartError::HostClosed => VRS_SESSION_CLOSED,
                WaitStartError::HostGone { .. } => VRS_ERROR_HOST_GONE,
                WaitStartError::BadFrame { .. } => VRS_ERROR_PROTOCOL,
                WaitStartError::Receive(_) | WaitStartError::TooManyFramesHeld { .. } => {
                    VRS_ERROR_TRANSPORT
                }
                WaitStartError::Terminated => VRS_ERROR_TERMINATED,
                _ => VRS_ERROR_OTHER,
            },
            Self::Send(e) => match e {
                SendError::QueueFull { .. } => VRS_ERROR_QUEUE_FULL,
                _ => VRS_ERROR_OTHER,
            },
            Self::Stop(e) => match e {
                StopError::NoFrame => VRS_ERROR_NO_FRAME,
                StopError::AlreadyStopped { .. } => VRS_ERROR_ALREADY_STOPPED,
                StopError::HostClosed => VRS_SESSION_CLOSED,
                StopError::Transport(_) => VRS_ERROR_TRANSPORT,
                _ => VRS_ERROR_OTHER,
            },
            Self::NoFrame => VRS_ERROR_NO_FRAME,
            Self::OutOfRange { .. } => VRS_ERROR_OUT_OF_RANGE,
            Self::Panic(_) => VRS_ERROR_PANIC,
        }
    }
}

/// The error and its sources, `: `-separated (what `{:#}` prints with anyhow).
fn chain(e: &dyn std::error::Error) -> String {
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

thread_local! {
    pub(super) static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    // A message cannot hold NUL bytes in C; cut at the first one.
    let message = message.split('\0').next().unwrap_or_default();
    let c = CString::new(message).unwrap_or_default();
    let _ = LAST_ERROR.try_with(|cell| {
        if let Ok(mut slot) = cell.try_borrow_mut() {
            *slot = c;
        }
    });
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

/// The boundary: runs `f`, catches panics, records the message, returns the status.
pub(super) fn boundary(f: impl FnOnce() -> Result<(), FfiError>) -> vrs_status_t {
    let result = catch_unwind(AssertUnwindSafe(f))
        .unwrap_or_else(|payload| Err(FfiError::Panic(panic_message(payload))));
    match result {
        Ok(()) => {
            set_last_error("");
            vrs_status_t::VRS_OK
        }
        Err(e) => {
            set_last_error(&chain(&e));
            e.status()
        }
    }
}

// ---------------------------------------------------------------------------------------
// The handle registry
// ---------------------------------------------------------------------------------------

/// One connected agent and its current frame.
pub(super) struct AgentState {
    pub(super) handle: usize,
    // Declared before `agent`: the frame's sample is released before the ports.
    pub(super) frame: Option<Frame>,
    pub(super) agent: Agent,
}

impl Drop for AgentState {
    fn drop(&mut self) {
        owners().remove(&self.handle);
    }
}

/// The next handle value; never reused, never 0.
static NEXT_HANDLE: AtomicUsize = AtomicUsize::new(1);

/// Which thread owns each live handle (the agents themselves live in `AGENTS`).
static OWNERS: Mutex<BTreeMap<usize, ThreadId>> = Mutex::new(BTreeMap::new());

fn owners() -> std::sync::MutexGuard<'static, BTreeMap<usize, ThreadId>> {
    // The map stays consistent even if a holder panicked: every operation is one call.
    OWNERS
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

thread_local! {
    pub(super) static AGENTS: RefCell<HashMap<usize, AgentState>> = RefCell::new(HashMap::new());
}

pub(super) fn handle_key(handle: *const vrs_agent_t) -> usize {
    handle.addr()
}

pub(super) fn unknown_handle(key: usize) -> FfiError {
    match owners().get(&key) {
        Some(owner) if *owner != std::thread::current().id() => FfiError::WrongThread(key),
        _ => FfiError::UnknownHandle(key),
    }
}

/// Runs `f` on the agent behind `handle`.
pub(super) fn with_agent<R>(
    handle: *const vrs_agent_t,
    f: impl FnOnce(&mut AgentState) -> Result<R, FfiError>,
) -> Result<R, FfiError> {
    let key = handle_key(handle);
    if key == 0 {
        return Err(FfiError::NullHandle);
    }
    AGENTS
        .try_with(|agents| {
            let mut agents = agents.borrow_mut();
            match agents.get_mut(&key) {
                Some(state) => f(state),
                None => Err(unknown_handle(key)),
            }
        })
        .unwrap_or(Err(FfiError::ThreadExiting))
}

pub(super) fn register(state_of: impl FnOnce(usize) -> AgentState) -> Result<usize, FfiError> {
    let key = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed);
    let state = state_of(key);
    owners().insert(key, std::thread::current().id());
    AGENTS
        .try_with(|agents| {
            agents.borrow_mut().insert(key, state);
        })
        .map_err(|_| FfiError::ThreadExiting)?;
    Ok(key)
}
