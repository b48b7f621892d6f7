//! What lives behind a `vrs_host_t`: the registry of hosts, each host's cycle state, the
//! error type of the boundary and the thread-local last-error message.

use std::cell::RefCell;
use std::collections::HashMap;
use std::ffi::c_char;
use std::thread::LocalKey;

use vrsync_bridge::ConfigLoadError;
use vrsync_bridge::{ActionConfig, ActionValue, AgentReport, ImageDesc, MAX_CAMERAS, MotorCommand};
use vrsync_bridge::{
    AgentOutcome, Host, HostCreateError, HostCycleError, HostWaitError, SensorFrameMut,
};
use vrsync_cabi::handles::LocalMap;
use vrsync_cabi::{
    AbiError, ArgError, HandleError, HandleKind, LastError, Registry, Removal, c_name,
};

use crate::types::{
    VRS_HOST_CHANNEL_NAME_SIZE, vrs_host_action_kind_t, vrs_host_cycle_t, vrs_host_outcome_t,
    vrs_host_status_t, vrs_host_t,
};

// ---------------------------------------------------------------------------------------
// Errors and the boundary
// ---------------------------------------------------------------------------------------

/// Everything a host C ABI call can fail with; each maps to one [`vrs_host_status_t`].
#[derive(Debug, thiserror::Error)]
pub(crate) enum FfiError {
    #[error(transparent)]
    Arg(#[from] ArgError),
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    #[error(transparent)]
    Handle(#[from] HandleError),
    #[error(transparent)]
    Config(#[from] ConfigLoadError),
    #[error("cannot create the host: {0}")]
    Create(#[from] HostCreateError),
    #[error("agents {missing:?} did not connect within {waited_ms} ms")]
    AgentsMissing { missing: Vec<u32>, waited_ms: u64 },
    #[error(transparent)]
    Wait(HostWaitError),
    #[error(transparent)]
    Cycle(#[from] HostCycleError),
    #[error("agent {0} is not part of this session")]
    UnknownAgent(u32),
    #[error("{call}: {why}")]
    WrongState { call: &'static str, why: String },
    #[error(
        "{call}: no frame is loaned for agent {agent} (call vrs_host_loan_frame first; a \
         frame ends when it is published or discarded)"
    )]
    NoFrame { call: &'static str, agent: u32 },
    #[error("{what} index {index} is out of range (there are {count})")]
    OutOfRange {
        what: &'static str,
        index: usize,
        count: usize,
    },
    #[error("agent {agent}'s frame has no camera named {name:?}")]
    NoSuchCamera { agent: u32, name: String },
    #[error("agent {agent} has no {what} {name:?} (its {what}s: {known})")]
    NoSuchChannel {
        agent: u32,
        what: &'static str,
        name: String,
        known: String,
    },
    #[error("logging is already initialised in this process")]
    LoggingAlreadySet,
    #[error("panic in the vrsync host library: {0}")]
    Panic(String),
}

impl AbiError for FfiError {
    type Status = vrs_host_status_t;
    const OK: vrs_host_status_t = vrs_host_status_t::VRS_HOST_OK;

    fn last_error() -> &'static LocalKey<LastError> {
        &LAST_ERROR
    }

    fn panicked(message: String) -> Self {
        Self::Panic(message)
    }

    // The wildcard arms keep new variants of the bridge's (non-exhaustive) error enums
    // from breaking the build; they map to VRS_HOST_ERROR_OTHER with their message.
    fn status(&self) -> vrs_host_status_t {
        use vrs_host_status_t::*;
        match self {
            Self::Arg(_)
            | Self::InvalidArgument(_)
            | Self::NoSuchCamera { .. }
            | Self::LoggingAlreadySet => VRS_HOST_ERROR_INVALID_ARGUMENT,
            Self::Handle(e) => match e {
                HandleError::WrongThread { .. } => VRS_HOST_ERROR_WRONG_THREAD,
                HandleError::Null(_)
                | HandleError::Unknown { .. }
                | HandleError::ThreadExiting(_) => VRS_HOST_ERROR_INVALID_HANDLE,
            },
            Self::Config(_) => VRS_HOST_ERROR_CONFIG,
            Self::Create(_) => VRS_HOST_ERROR_CREATE,
            Self::AgentsMissing { .. } => VRS_HOST_TIMEOUT,
            Self::Wait(e) => match e {
                HostWaitError::Terminated => VRS_HOST_ERROR_TERMINATED,
                HostWaitError::Transport(_) => VRS_HOST_ERROR_TRANSPORT,
                _ => VRS_HOST_ERROR_OTHER,
            },
            Self::Cycle(e) => match e {
                HostCycleError::UnknownAgent(_) => VRS_HOST_ERROR_UNKNOWN_AGENT,
                HostCycleError::StaleFrame { .. } => VRS_HOST_ERROR_WRONG_STATE,
                HostCycleError::Terminated => VRS_HOST_ERROR_TERMINATED,
                HostCycleError::Transport(_) => VRS_HOST_ERROR_TRANSPORT,
                HostCycleError::AgentLost { .. } | HostCycleError::AgentNotBack { .. } => {
                    VRS_HOST_ERROR_AGENT_LOST
                }
                _ => VRS_HOST_ERROR_OTHER,
            },
            Self::UnknownAgent(_) => VRS_HOST_ERROR_UNKNOWN_AGENT,
            Self::WrongState { .. } => VRS_HOST_ERROR_WRONG_STATE,
            Self::NoFrame { .. } => VRS_HOST_ERROR_NO_FRAME,
            Self::OutOfRange { .. } => VRS_HOST_ERROR_OUT_OF_RANGE,
            Self::NoSuchChannel { .. } => VRS_HOST_ERROR_UNKNOWN_CHANNEL,
            Self::Panic(_) => VRS_HOST_ERROR_PANIC,
        }
    }
}

impl From<HostWaitError> for FfiError {
    fn from(e: HostWaitError) -> Self {
        match e {
            HostWaitError::AgentsMissing {
                missing, waited, ..
            } => Self::AgentsMissing {
                missing,
                waited_ms: waited.as_millis() as u64,
            },
            other => Self::Wait(other),
        }
    }
}

thread_local! {
    static LAST_ERROR: LastError = LastError::default();
    static LOCAL_HOSTS: LocalMap<HostState> = RefCell::new(HashMap::new());
}

/// The last message of this thread as a C string (empty after a success).
pub(crate) fn last_error_ptr() -> *const c_char {
    vrsync_cabi::last_error_ptr(&LAST_ERROR)
}

/// The boundary: destroys hosts whose destruction other threads deferred to this one,
/// runs `f`, catches panics, records the message, returns the status.
pub(crate) fn boundary(f: impl FnOnce() -> Result<(), FfiError>) -> vrs_host_status_t {
    vrsync_cabi::boundary(|| {
        HOSTS.drop_deferred();
        f()
    })
}

/// Like [`boundary`] for calls whose success is itself a positive status
/// (`VRS_HOST_TIMEOUT`, `VRS_HOST_DEFERRED`) with a message.
pub(crate) fn boundary_status(
    f: impl FnOnce() -> Result<(vrs_host_status_t, String), FfiError>,
) -> vrs_host_status_t {
    vrsync_cabi::boundary_status(|| {
        HOSTS.drop_deferred();
        f()
    })
}

// ---------------------------------------------------------------------------------------
// One host and its cycle
// ---------------------------------------------------------------------------------------

/// Where the host is in its cycle. The calls of one cycle must come in this order:
/// `Frames` (loan, write, publish or discard each agent's frame) → `start` → `Started` →
/// `collect` → `Collected` (read the reports) → `end_cycle` → `Frames`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Phase {
    Frames,
    Started,
    Collected,
}

impl Phase {
    pub(crate) fn describe(self) -> &'static str {
        match self {
            Self::Frames => "the cycle is before vrs_host_start",
            Self::Started => "vrs_host_start was called and vrs_host_collect not yet",
            Self::Collected => {
                "the cycle was collected and not yet ended (call vrs_host_end_cycle)"
            }
        }
    }
}

/// One image of a loaned frame, located once at loan time.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ImageView {
    pub(crate) data: *mut u8,
    pub(crate) desc: ImageDesc,
}

/// One agent's frame slot in the current cycle.
#[derive(Debug, Default)]
pub(crate) struct FrameSlot {
    /// The loaned frame, until published or discarded.
    pub(crate) frame: Option<SensorFrameMut>,
    pub(crate) images: [Option<ImageView>; MAX_CAMERAS],
    /// Published this cycle (a second loan is refused).
    pub(crate) published: bool,
}

/// One agent's part of the last collected cycle, copied out of the host's report.
#[derive(Debug)]
pub(crate) struct ReportCopy {
    pub(crate) agent_id: u32,
    pub(crate) outcome: vrs_host_outcome_t,
    pub(crate) read_cycle: Option<u64>,
    pub(crate) evicted: bool,
    pub(crate) rejoined: bool,
    pub(crate) left: bool,
    pub(crate) slow: bool,
    pub(crate) commands: Vec<MotorCommand>,
    /// The agent's actions of the cycle, in config order (buffers sized from the config).
    pub(crate) actions: Vec<ActionCopy>,
    /// Action chunks of the agent refused in the cycle.
    pub(crate) actions_rejected: u32,
}

/// Everything behind one handle.
pub(crate) struct HostState {
    // Declared before `host`: loaned samples are released before the ports.
    pub(crate) slots: Vec<FrameSlot>,
    pub(crate) host: Host,
    pub(crate) ids: Vec<u32>,
    pub(crate) phase: Phase,
    pub(crate) cycle: vrs_host_cycle_t,
    pub(crate) reports: Vec<ReportCopy>,
}

impl HostState {
    pub(crate) fn new(host: Host) -> Self {
        let ids: Vec<u32> = host.agent_ids().collect();
        // Room for what the host hands over in one cycle, so that copying the report
        // does not allocate in steady state.
        let cap = host.config().transport.max_commands_per_cycle as usize * 2;
        let config = host.config();
        let reports = ids
            .iter()
            .map(|&agent_id| ReportCopy {
                agent_id,
                outcome: vrs_host_outcome_t::VRS_HOST_OUTCOME_NOT_AWAITED,
                read_cycle: None,
                evicted: false,
                rejoined: false,
                left: false,
                slow: false,
                commands: Vec::with_capacity(cap),
                actions: config.agent(agent_id).map_or_else(Vec::new, |a| {
                    a.actions.iter().map(ActionCopy::new).collect()
                }),
                actions_rejected: 0,
            })
            .collect();
        Self {
            slots: ids.iter().map(|_| FrameSlot::default()).collect(),
            host,
            ids,
            phase: Phase::Frames,
            cycle: vrs_host_cycle_t::default(),
            reports,
        }
    }

    /// The slot index of agent `id`.
    pub(crate) fn slot_of(&self, id: u32) -> Result<usize, FfiError> {
        self.ids
            .iter()
            .position(|&i| i == id)
            .ok_or(FfiError::UnknownAgent(id))
    }

    /// Fails unless the cycle is in `phase`.
    pub(crate) fn expect_phase(&self, call: &'static str, phase: Phase) -> Result<(), FfiError> {
        if self.phase == phase {
            return Ok(());
        }
        let hint = match phase {
            Phase::Frames => "it belongs before vrs_host_start",
            Phase::Started => "it belongs after vrs_host_start",
            Phase::Collected => "it belongs after vrs_host_collect",
        };
        Err(FfiError::WrongState {
            call,
            why: format!("{}; {hint}", self.phase.describe()),
        })
    }
}

/// Copies the host's report of the cycle that just ended into `reports` (whose command
/// buffers are reused) and returns the cycle's summary.
pub(crate) fn copy_report(
    reports: &mut [ReportCopy],
    report: &vrsync_bridge::CycleReport,
) -> vrs_host_cycle_t {
    let mut timed_out = 0u32;
    let mut commands = 0u32;
    let (mut evicted, mut rejoined, mut left, mut slow) = (0u32, 0u32, 0u32, 0u32);
    for (copy, agent) in reports.iter_mut().zip(report.agents()) {
        copy.agent_id = agent.agent_id;
        copy.outcome = outcome(agent.outcome);
        copy.read_cycle = agent.read_cycle;
        copy.evicted = agent.evicted;
        copy.rejoined = agent.rejoined;
        evicted += u32::from(agent.evicted);
        copy.left = agent.left;
        copy.slow = agent.slow;
        rejoined += u32::from(agent.rejoined);
        left += u32::from(agent.left);
        slow += u32::from(agent.slow);
        copy.commands.clear();
        copy.commands.extend_from_slice(agent.commands());
        copy_actions(&mut copy.actions, agent);
        copy.actions_rejected = agent.actions_rejected();
        commands = commands.saturating_add(copy.commands.len() as u32);
        if copy.outcome == vrs_host_outcome_t::VRS_HOST_OUTCOME_TIMED_OUT {
            timed_out += 1;
        }
    }
    vrs_host_cycle_t {
        cycle: report.cycle,
        sim_time_ns: report.sim_time_ns,
        agent_count: reports.len() as u32,
        timed_out_agents: timed_out,
        late_batches: report.late_batches,
        command_count: commands,
        evicted_agents: evicted,
        rejoined_agents: rejoined,
        left_agents: left,
        slow_agents: slow,
    }
}

/// The ABI code of an outcome. No wildcard arm: an outcome added to the bridge must fail
/// to compile here until it has its own code in the C header (and the C# binding).
pub(crate) fn outcome(o: AgentOutcome) -> vrs_host_outcome_t {
    use vrs_host_outcome_t::*;
    match o {
        AgentOutcome::Stopped => VRS_HOST_OUTCOME_STOPPED,
        AgentOutcome::TimedOut => VRS_HOST_OUTCOME_TIMED_OUT,
        AgentOutcome::NotAwaited => VRS_HOST_OUTCOME_NOT_AWAITED,
        AgentOutcome::Async => VRS_HOST_OUTCOME_ASYNC,
        AgentOutcome::Evicted => VRS_HOST_OUTCOME_EVICTED,
        AgentOutcome::Left => VRS_HOST_OUTCOME_LEFT,
    }
}

// ---------------------------------------------------------------------------------------
// The handle registry
// ---------------------------------------------------------------------------------------

static HOST_HANDLES: HandleKind = HandleKind {
    noun: "host",
    a_noun: "a host",
    released: "destroyed",
    made_by: "created it (Unity: the main thread)",
};

/// The hosts of every thread (each lives in its thread's map).
static HOSTS: Registry<HostState> = Registry::new(&HOST_HANDLES, &LOCAL_HOSTS);

/// Runs `f` on the host behind `handle`.
pub(crate) fn with_host<R>(
    handle: *const vrs_host_t,
    f: impl FnOnce(&mut HostState) -> Result<R, FfiError>,
) -> Result<R, FfiError> {
    HOSTS.with(handle, f)
}

/// Registers a new host on this thread and returns its handle value.
pub(crate) fn register(host: Host) -> Result<usize, FfiError> {
    Ok(HOSTS.insert(|_| HostState::new(host))?)
}

/// Destroys the host behind `handle`: at once on its own thread, deferred to the owner's
/// next call from any other thread (a .NET finalizer runs on its own thread).
pub(crate) fn destroy(handle: *mut vrs_host_t) -> Result<(vrs_host_status_t, String), FfiError> {
    Ok(match HOSTS.remove_or_defer(handle)? {
        Removal::Removed => (vrs_host_status_t::VRS_HOST_OK, String::new()),
        Removal::Deferred => (
            vrs_host_status_t::VRS_HOST_DEFERRED,
            format!(
                "host handle {:#x} belongs to another thread: it is destroyed at that \
                 thread's next vrs_host_ call",
                handle.addr()
            ),
        ),
    })
}

/// One action of one agent in the last collected cycle, copied out of the host's report
/// into buffers sized once from the config (no allocation per cycle).
#[derive(Debug)]
pub(crate) struct ActionCopy {
    pub(crate) name: [c_char; VRS_HOST_CHANNEL_NAME_SIZE],
    pub(crate) kind: vrs_host_action_kind_t,
    pub(crate) values: Vec<f32>,
    pub(crate) choice: u32,
}

impl ActionCopy {
    pub(crate) fn new(spec: &ActionConfig) -> Self {
        Self {
            name: c_name(&spec.name),
            kind: vrs_host_action_kind_t::VRS_HOST_ACTION_KIND_NONE,
            values: Vec::with_capacity(spec.len()),
            choice: 0,
        }
    }
}

/// Copies `agent`'s actions of the cycle (config order) into `copies`.
pub(crate) fn copy_actions(copies: &mut [ActionCopy], agent: &AgentReport) {
    use vrs_host_action_kind_t::*;
    for (copy, (_, value)) in copies.iter_mut().zip(agent.actions()) {
        copy.values.clear();
        copy.choice = 0;
        copy.kind = match value {
            None => VRS_HOST_ACTION_KIND_NONE,
            Some(ActionValue::Box(v)) => {
                copy.values.extend_from_slice(v);
                VRS_HOST_ACTION_KIND_BOX
            }
            Some(ActionValue::Discrete(c)) => {
                copy.choice = c;
                VRS_HOST_ACTION_KIND_DISCRETE
            }
        };
    }
}
