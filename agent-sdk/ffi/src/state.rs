//! What lives behind a `vrs_agent_t`: the error type of the boundary, the thread-local
//! last-error message and the registry of agents (their plumbing is `vrsync_cabi`'s,
//! shared with the host C ABI).

use std::cell::RefCell;
use std::collections::HashMap;
use std::ffi::c_char;
use std::thread::LocalKey;

use vrsync_cabi::handles::LocalMap;
use vrsync_cabi::{AbiError, ArgError, HandleError, HandleKind, LastError, Registry};
use vrsync_transport::{ConfigLoadError, VectorConfig};

use super::types::{vrs_agent_t, vrs_status_t};
use sdk::{ActError, Agent, AgentConnectError, Frame, SendError, StopError, WaitStartError};

// ---------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------

/// Everything a C ABI call can fail with; each maps to one [`vrs_status_t`].
#[derive(Debug, thiserror::Error)]
pub(super) enum FfiError {
    #[error(transparent)]
    Arg(#[from] ArgError),
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    #[error(transparent)]
    Handle(#[from] HandleError),
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
    #[error("protocol error: {0}")]
    Protocol(String),
    #[error("agent {agent} has no vector {name:?} (its vectors: {known})")]
    NoSuchVector {
        agent: u32,
        name: String,
        known: String,
    },
    /// An action refused by the SDK; its message names the action.
    #[error(transparent)]
    Act(ActError),
    /// An action that does not fit the queue (the SDK's message does not name it).
    #[error(
        "action {action:?} does not fit this cycle's queue (a continuous action takes one \
         entry per 4 values)"
    )]
    ActQueue {
        action: String,
        #[source]
        source: SendError,
    },
    #[error("logging is already initialised in this process")]
    LoggingAlreadySet,
    #[error("panic in the vrsync library: {0}")]
    Panic(String),
}

impl AbiError for FfiError {
    type Status = vrs_status_t;
    const OK: vrs_status_t = vrs_status_t::VRS_OK;

    fn last_error() -> &'static LocalKey<LastError> {
        &LAST_ERROR
    }

    fn panicked(message: String) -> Self {
        Self::Panic(message)
    }

    // The wildcard arms keep new variants of the SDK's (non-exhaustive) error enums from
    // breaking the build; they map to VRS_ERROR_OTHER with their message.
    #[allow(unreachable_patterns)]
    fn status(&self) -> vrs_status_t {
        use vrs_status_t::*;
        match self {
            Self::Arg(_)
            | Self::InvalidArgument(_)
            | Self::NoSuchCamera(_)
            | Self::LoggingAlreadySet => VRS_ERROR_INVALID_ARGUMENT,
            Self::Handle(e) => match e {
                HandleError::WrongThread { .. } => VRS_ERROR_WRONG_THREAD,
                HandleError::Null(_)
                | HandleError::Unknown { .. }
                | HandleError::ThreadExiting(_) => VRS_ERROR_INVALID_HANDLE,
            },
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
            Self::Protocol(_) => VRS_ERROR_PROTOCOL,
            Self::NoSuchVector { .. } => VRS_ERROR_UNKNOWN_CHANNEL,
            Self::Act(e) => match e {
                ActError::UnknownAction { .. } => VRS_ERROR_UNKNOWN_CHANNEL,
                ActError::WrongLength { .. } => VRS_ERROR_WRONG_LENGTH,
                ActError::OutOfBounds { .. } => VRS_ERROR_OUT_OF_BOUNDS,
                ActError::ChoiceOutOfRange { .. } => VRS_ERROR_CHOICE_OUT_OF_RANGE,
                ActError::WrongKind { .. } => VRS_ERROR_WRONG_ACTION_KIND,
                ActError::Queue(SendError::QueueFull { .. }) => VRS_ERROR_QUEUE_FULL,
                _ => VRS_ERROR_OTHER,
            },
            Self::ActQueue { source, .. } => match source {
                SendError::QueueFull { .. } => VRS_ERROR_QUEUE_FULL,
                _ => VRS_ERROR_OTHER,
            },
            Self::NoFrame => VRS_ERROR_NO_FRAME,
            Self::OutOfRange { .. } => VRS_ERROR_OUT_OF_RANGE,
            Self::Panic(_) => VRS_ERROR_PANIC,
        }
    }
}

thread_local! {
    static LAST_ERROR: LastError = LastError::default();
    static LOCAL_AGENTS: LocalMap<AgentState> = RefCell::new(HashMap::new());
}

/// The message of the last call on this thread (empty after a success), never null.
pub(super) fn last_error_ptr() -> *const c_char {
    vrsync_cabi::last_error_ptr(&LAST_ERROR)
}

/// The boundary: runs `f`, catches panics, records the message, returns the status.
pub(super) fn boundary(f: impl FnOnce() -> Result<(), FfiError>) -> vrs_status_t {
    vrsync_cabi::boundary(f)
}

// ---------------------------------------------------------------------------------------
// The handle registry
// ---------------------------------------------------------------------------------------

/// One connected agent and its current frame.
pub(super) struct AgentState {
    // Declared before `agent`: the frame's sample is released before the ports.
    pub(super) frame: Option<Frame>,
    pub(super) agent: Agent,
    /// Its vectors as its config declares them (their bounds are handed out by pointer,
    /// so they stay here, unchanged, until the disconnect).
    pub(super) vectors: Vec<VectorConfig>,
}

static AGENT_HANDLES: HandleKind = HandleKind {
    noun: "agent",
    a_noun: "an agent",
    released: "disconnected",
    made_by: "connected it",
};

/// The agents of every thread (each lives in its thread's map).
pub(super) static AGENTS: Registry<AgentState> = Registry::new(&AGENT_HANDLES, &LOCAL_AGENTS);

/// Runs `f` on the agent behind `handle`.
pub(super) fn with_agent<R>(
    handle: *const vrs_agent_t,
    f: impl FnOnce(&mut AgentState) -> Result<R, FfiError>,
) -> Result<R, FfiError> {
    AGENTS.with(handle, f)
}
