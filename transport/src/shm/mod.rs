//! The shared-memory transport over iceoryx2.
//!
//! Services (all under `vrsync/<session>/`, see DESIGN §4):
//!
//! | service              | pattern                                 | writer → reader |
//! |----------------------|-----------------------------------------|-----------------|
//! | `agent/<id>/sensors` | pub-sub `[u8]` + [`SensorHeader`]       | host → agent    |
//! | `agent/<id>/motor`   | pub-sub `[MotorCommand]` + [`MotorHeader`] | agent → host |
//! | `start`              | event, no ports: its attributes         | host → agents   |
//! | `stop`               | event, id = agent id                    | agents → host   |
//!
//! *Start* (a frame is there) and *closed* reach every agent at once through the session's
//! [`WakeWord`], a futex word in shared memory: one system call wakes all the agents
//! (an iceoryx2 event would send a datagram to each). The same page says whether the host
//! polls the motor queues; while it does, an agent's *stop* is not notified on `stop`.
//!
//! The host `create`s every service; agents `open` them. Buffers are sized explicitly: the
//! sensor publisher of an agent holds at most [`SENSOR_POOL_SAMPLES`] frames (one loaned by
//! the host, one queued, two borrowed by the agent), so a 3×1080p rgb8 stream reserves
//! ~75 MB instead of the ~280 MB iceoryx2's defaults would.

use std::mem::MaybeUninit;
use std::time::{Duration, Instant};

use tracing::debug;

use iceoryx2::config::Config as Config2;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::attribute::{AttributeKey, AttributeSet, AttributeValue};
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe as ps_factory};

use super::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, Attempt, BatchSink, FrameLoanMut, HostConnections, HostLiveness, HostReadiness,
    HostTransport, HostTransportError, retry_until,
};
use crate::config::{Config, MAX_AGENT_ID};
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};
use vrsync_protocol::channel_layout::ChannelLayout;

type Svc = ipc::Service;

/// Frames an agent may hold at once (the current one and the one being received).
pub const AGENT_BORROWED_FRAMES: usize = AGENT_MAX_HELD_FRAMES;
/// Sensor frames queued per agent: only the newest is kept (safe overflow).
pub const SENSOR_QUEUE: usize = 1;
/// Size of each agent's sensor sample pool: queued + borrowed + one loaned by the host.
pub const SENSOR_POOL_SAMPLES: usize = SENSOR_QUEUE + AGENT_BORROWED_FRAMES + 1;
/// Motor batches queued per agent at the host.
pub const MOTOR_QUEUE: usize = 16;

/// Service attribute key holding [`PROTOCOL_VERSION`].
pub const ATTR_PROTOCOL: &str = "vrsync.protocol_version";
/// Service attribute key holding [`LAYOUT_HASH`] (hex).
pub const ATTR_LAYOUT: &str = "vrsync.layout_hash";
/// Prefix of the service attribute keys of an agent's sensor service that hold its channel
/// layout's canonical text ([`ChannelLayout::to_text`]): `vrsync.channels.0`, `.1`, … each
/// a piece of at most [`ATTR_VALUE_MAX`] bytes, in order (none without channels). One key
/// per piece, not one key with several values: iceoryx2 keeps a service's attributes sorted
/// by key and value, which would reorder the pieces.
pub const ATTR_CHANNELS: &str = "vrsync.channels";
/// Longest attribute value iceoryx2 stores (`MAX_ATTRIBUTE_VALUE_LENGTH`).
pub const ATTR_VALUE_MAX: usize = 256;

/// Name of service `suffix` of a session.
pub fn service_name(session: &str, suffix: &str) -> String {
    format!("vrsync/{session}/{suffix}")
}

/// iceoryx2 node name of the host of a session.
pub fn host_node_name(session: &str) -> String {
    format!("vrsync-host.{session}")
}

/// iceoryx2 node name of agent `id` of a session.
pub fn agent_node_name(session: &str, id: u32) -> String {
    format!("vrsync-agent.{session}.{id}")
}

/// Bytes of shared memory the host's services of `config` reserve for its agents on shared
/// memory (sensor pools dominate).
pub fn reserved_bytes(config: &Config) -> u64 {
    let header = core::mem::size_of::<SensorHeader>() as u64 + 64;
    config
        .agents
        .iter()
        .filter(|a| a.transport == crate::config::TransportKind::Shm)
        .map(|a| {
            // A stacked agent's own sample carries the header only; its payload is in the
            // stacked sample (added below).
            let payload = if stack_index(config, a.id).is_some() {
                1
            } else {
                a.frame_bytes().max(1)
            };
            let frame = payload as u64 + header;
            let motor = (u64::from(config.transport.max_commands_per_cycle)
                * core::mem::size_of::<MotorCommand>() as u64
                + 64)
                * (MOTOR_QUEUE as u64 + 2);
            frame * SENSOR_POOL_SAMPLES as u64 + motor
        })
        .sum::<u64>()
        + stack_shape(config).map_or(0, |(blocks, frame_bytes)| {
            (blocks as u64 * stack_stride(frame_bytes) as u64 + 64) * SENSOR_POOL_SAMPLES as u64
        })
}

/// Free bytes of the tmpfs behind `/dev/shm` (where iceoryx2 keeps its segments), if known.
pub fn shm_free_bytes() -> Option<u64> {
    let path = c"/dev/shm";
    let mut st = core::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is NUL-terminated and `st` is valid for writes of one statvfs.
    let rc = unsafe { libc::statvfs(path.as_ptr(), st.as_mut_ptr()) };
    if rc != 0 {
        return None;
    }
    // SAFETY: statvfs returned 0, so it initialised `st`.
    let st = unsafe { st.assume_init() };
    // The field types differ between platforms (u32 on some); the casts are for those.
    #[allow(clippy::unnecessary_cast)]
    Some(st.f_bavail as u64 * st.f_frsize as u64)
}

/// The shared memory a session needs does not fit into `/dev/shm`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
#[error(
    "{config}: agent.camera: the cameras of all agents need {needed_mb} MB of shared memory but \
     /dev/shm has {available_mb} MB free: {fix}",
    config = config.display(),
    needed_mb = needed / 1_000_000,
    available_mb = available / 1_000_000,
    fix = SHM_BUDGET_FIX
)]
pub struct ShmBudgetError {
    /// The config file whose cameras do not fit.
    pub config: std::path::PathBuf,
    /// Bytes the session's services reserve.
    pub needed: u64,
    /// Bytes free in `/dev/shm`.
    pub available: u64,
}

/// Checks that the shared memory of `config`'s session fits into `/dev/shm`. tmpfs is
/// filled lazily: an undersized one gives SIGBUS at write time, long after start, so the
/// host refuses up front ([`ShmHost::create`] runs this check); a program can run it
/// earlier as a pre-flight, e.g. to report it as a configuration error. A config is never
/// checked when it is merely parsed (an agent or a tool may parse it on another machine).
///
/// # Errors
/// [`ShmBudgetError`] with the bytes needed and free.
pub fn check_shm_budget(config: &Config) -> Result<(), ShmBudgetError> {
    let needed = reserved_bytes(config);
    match shm_free_bytes() {
        Some(available) if needed > available => Err(ShmBudgetError {
            config: config.source.clone(),
            needed,
            available,
        }),
        _ => Ok(()),
    }
}

/// The advice printed with a budget error.
pub const SHM_BUDGET_FIX: &str = "use fewer or smaller cameras or fewer agents, or give /dev/shm more room (`mount -o remount,size=16G /dev/shm`; in Docker `--shm-size=16g` or `--ipc=host`)";

fn svc_name(session: &str, suffix: &str) -> Result<ServiceName, String> {
    let name = service_name(session, suffix);
    ServiceName::new(&name).map_err(|e| format!("invalid service name {name:?}: {e:?}"))
}

fn attributes() -> Result<AttributeSpecifier, String> {
    with_channels(&ChannelLayout::default())
}

/// The attributes of a service: protocol and layout, and the channel layout `channels`
/// (an agent's sensor service carries its agent's; the others none).
fn with_channels(channels: &ChannelLayout) -> Result<AttributeSpecifier, String> {
    let key = |k: &str| AttributeKey::try_from(k).map_err(|e| format!("{e:?}"));
    let val = |v: &str| AttributeValue::try_from(v).map_err(|e| format!("{e:?}"));
    let (pk, pv) = (key(ATTR_PROTOCOL)?, val(&PROTOCOL_VERSION.to_string())?);
    let (lk, lv) = (key(ATTR_LAYOUT)?, val(&format!("{LAYOUT_HASH:016x}"))?);
    let mut attrs = AttributeSpecifier::new()
        .define(&pk, &pv)
        .and_then(|s| s.define(&lk, &lv))
        .map_err(|e| format!("{e:?}"))?;
    // The text is ASCII (`;`, `:`, names of `[A-Za-z0-9_.-]`, digits): any cut is a char
    // boundary. At most 3 pieces (`channel_layout::MAX_TEXT`), with the 2 above within
    // iceoryx2's 8 attributes.
    for (i, piece) in channels
        .to_text()
        .as_bytes()
        .chunks(ATTR_VALUE_MAX)
        .enumerate()
    {
        let piece = core::str::from_utf8(piece).map_err(|e| e.to_string())?;
        attrs = attrs
            .define(&key(&format!("{ATTR_CHANNELS}.{i}"))?, &val(piece)?)
            .map_err(|e| format!("{e:?}"))?;
    }
    Ok(attrs)
}

/// The channel layout an agent's sensor service carries (see [`ATTR_CHANNELS`]); `None`
/// if the pieces do not make one.
fn channels_of(attrs: &AttributeSet) -> Option<ChannelLayout> {
    let mut text = String::new();
    for i in 0.. {
        let key = AttributeKey::try_from(format!("{ATTR_CHANNELS}.{i}").as_str()).ok()?;
        match attrs.key_value(&key, 0) {
            Some(piece) => text.push_str(&piece.to_string()),
            None => break,
        }
    }
    ChannelLayout::parse(&text)
}

/// Quiets iceoryx2's own logging unless `IOX2_LOG_LEVEL` asks for more. iceoryx2 logs
/// through `tracing` (feature `tracing`), so what remains shows up in our logs.
pub fn init_iceoryx2_logging() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// iceoryx2 creates a process-wide signal handler (`iceoryx2_bb_posix::signal::
/// SignalHandler`) lazily, the first time it needs one — e.g. when it zeroes a new
/// shared-memory segment, which can happen in the middle of a wait once a peer's
/// connection appears — and that handler installs its own functions for SIGINT, SIGTERM
/// and ten other signals, whatever `SignalHandlingMode` the nodes have. A Python agent's
/// Ctrl-C then never reached Python. So before the first node, create that handler once
/// and put every signal's previous action back: iceoryx2 never installs anything later.
fn keep_process_signal_handlers() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        const SIGNALS: core::ops::RangeInclusive<libc::c_int> = 1..=31;
        let mut saved: Vec<(libc::c_int, libc::sigaction)> = Vec::new();
        for sig in SIGNALS {
            if sig == libc::SIGKILL || sig == libc::SIGSTOP {
                continue;
            }
            // SAFETY: querying (act = null) the current action of a valid signal number
            // into a zeroed, properly aligned sigaction.
            unsafe {
                let mut old: libc::sigaction = core::mem::zeroed();
                if libc::sigaction(sig, core::ptr::null(), &mut old) == 0 {
                    saved.push((sig, old));
                }
            }
        }
        // Creates the handler (and its registrations) now; reports no signal.
        let _ = iceoryx2_bb_posix::signal::SignalHandler::last_signal();
        for (sig, old) in &saved {
            // SAFETY: restoring an action sigaction(2) itself returned for this signal.
            unsafe {
                libc::sigaction(*sig, old, core::ptr::null_mut());
            }
        }
    });
}

/// The iceoryx2 config of every vrsync node: iceoryx2's own (`iceoryx2.toml` or its
/// defaults), except that creating or dropping a node does not clean up every dead node
/// of the machine. iceoryx2 does that by default (`cleanup-dead-nodes-on-creation` /
/// `-on-destruction`): it removed other sessions' (and other programs') leftovers, and
/// with a few hundred dead nodes in the registry each connect attempt and each `close()`
/// took a second or more, during which Ctrl-C was not seen. vrsync cleans the dead nodes
/// of its own session only ([`cleanup_dead_nodes`] when a host starts, and the host's
/// reaping of its agents); iceoryx2 still cleans a dead node's ports from a service when
/// the service is opened (`cleanup-dead-nodes-on-open`), i.e. within the session.
///
/// Public so that the benchmark's raw iceoryx2 floor (`vrsync-floor`) creates its nodes the
/// same way.
pub fn iceoryx2_config() -> &'static Config2 {
    static CONFIG: std::sync::OnceLock<Config2> = std::sync::OnceLock::new();
    CONFIG.get_or_init(|| {
        let mut config = Config2::global_config().clone();
        config.global.node.cleanup_dead_nodes_on_creation = false;
        config.global.node.cleanup_dead_nodes_on_destruction = false;
        config
    })
}

fn node(name: &str) -> Result<Node<Svc>, String> {
    keep_process_signal_handlers();
    let node_name =
        NodeName::new(name).map_err(|e| format!("invalid node name {name:?}: {e:?}"))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(iceoryx2_config())
        // Signals are handled by `crate::signal` (or left to the embedding process).
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| format!("cannot create iceoryx2 node {name:?}: {e:?}"))
}

/// Testing aid: creates `n` iceoryx2 nodes named `<prefix>.<k>` and never removes them,
/// so that they are dead nodes once this process exits (tests of Ctrl-C, connect and
/// close with a registry full of other programs' leftovers).
///
/// # Errors
/// The iceoryx2 failure, as text.
#[doc(hidden)]
pub fn leak_nodes_for_tests(prefix: &str, n: usize) -> Result<(), String> {
    for k in 0..n {
        std::mem::forget(node(&format!("{prefix}.{k}"))?);
    }
    Ok(())
}

/// Testing aid: counts the dead iceoryx2 nodes whose name starts with `prefix` (those of
/// [`leak_nodes_for_tests`]) and, with `remove`, removes them.
#[doc(hidden)]
pub fn dead_nodes_for_tests(prefix: &str, remove: bool) -> u64 {
    let mut n = 0;
    for_each_dead_node(|view, name| {
        if name.starts_with(prefix) {
            n += 1;
            if remove {
                let _ = view.try_remove_stale_resources();
            }
        }
    });
    n
}

/// What became of a session's host process, as iceoryx2's node registry tells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostState {
    /// The host's node exists and its process is alive.
    Alive,
    /// The host's process died without removing its node (crash, SIGKILL).
    Dead,
    /// No host node: it never existed or it closed the session cleanly.
    Absent,
}

/// What iceoryx2's node registry says of `session`'s host: its state, and its process id
/// while it is alive. Lists every node of the machine.
fn find_host(session: &str) -> (HostState, Option<i32>) {
    use iceoryx2::node::NodeView;
    let wanted = host_node_name(session);
    let mut found = (HostState::Absent, None);
    let _ = Node::<Svc>::list(iceoryx2_config(), |node| {
        let (state, details) = match &node {
            NodeState::Alive(view) => (HostState::Alive, view.details()),
            NodeState::Dead(view) => (HostState::Dead, view.details()),
            _ => return CallbackProgression::Continue,
        };
        let Some(d) = details.as_ref().filter(|d| d.name().as_str() == wanted) else {
            return CallbackProgression::Continue;
        };
        if state == HostState::Alive {
            found = (state, Some(d.process_id().value()));
            return CallbackProgression::Stop;
        }
        found = (state, None);
        CallbackProgression::Continue
    });
    found
}

/// The state of `session`'s host node.
pub fn host_state(session: &str) -> HostState {
    find_host(session).0
}

/// The process id of `session`'s live host, if there is one.
pub fn host_pid(session: &str) -> Option<i32> {
    find_host(session).1
}

/// Whether a live host node exists for `session`.
pub fn host_alive(session: &str) -> bool {
    host_state(session) == HostState::Alive
}

/// Whether iceoryx2 node `name` is the host, an agent or the stacked sample's reader of
/// `session` (a session name may contain dots: an agent's node name is
/// `vrsync-agent.<session>.<id>`, digits only after).
fn node_of_session(name: &str, session: &str) -> bool {
    name == host_node_name(session)
        || name == stack_node_name(session)
        || name
            .strip_prefix("vrsync-agent.")
            .and_then(|rest| rest.strip_prefix(session))
            .and_then(|rest| rest.strip_prefix('.'))
            .is_some_and(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
}

/// Removes the stale resources of the dead iceoryx2 nodes of `session` (its crashed host
/// or agents); other sessions' nodes, dead or alive, are left to their owners. Returns how
/// many nodes were cleaned.
pub fn cleanup_dead_nodes(session: &str) -> u64 {
    let mut cleaned = 0;
    let host = host_node_name(session);
    for_each_dead_node(|view, name| {
        if node_of_session(name, session) && view.try_remove_stale_resources().is_ok() {
            if name == host {
                remove_wake_word(session);
            }
            cleaned += 1;
        }
    });
    cleaned
}

/// Calls `f` with every dead iceoryx2 node of the machine that has a name (its view, to
/// clean it, and its name): the one registry walk behind session clean-up and the host's
/// reaping of dead agents.
fn for_each_dead_node(mut f: impl FnMut(iceoryx2::node::DeadNodeView<Svc>, &str)) {
    use iceoryx2::node::NodeView;
    let _ = Node::<Svc>::list(iceoryx2_config(), |state| {
        if let NodeState::Dead(view) = state
            && let Some(name) = view
                .details()
                .as_ref()
                .map(|d| d.name().as_str().to_owned())
        {
            // Owned name: cleaning consumes the view.
            f(view, &name);
        }
        CallbackProgression::Continue
    });
}

/// Waits on `listener` for up to `timeout`, calling `callback` for every event that came;
/// returns how many. iceoryx2's timed wait sets the socket's `SO_RCVTIMEO` from the timeout
/// cut to whole microseconds, and a zero `SO_RCVTIMEO` means *no* timeout: a wait of less
/// than 1 µs (zero included) blocked until the next notification, if one ever came (a host
/// between two cycles of an async run stalled until its agents gave up). Such a wait only
/// looks ([`Listener::try_wait`]).
///
/// # Errors
/// iceoryx2's.
pub fn wait_events<F: FnMut(EventActivation)>(
    listener: &Listener<Svc>,
    callback: F,
    timeout: Duration,
) -> Result<u64, iceoryx2::port::listener::ListenerWaitError> {
    if timeout < Duration::from_micros(1) {
        listener.try_wait(callback)
    } else {
        listener.timed_wait(callback, timeout)
    }
}

/// A poll-before-sleep window (`[sync] spin_before_block_us`, or longer: see
/// [`PollLength`]): busy-polls for its first [`POLL_SPIN_ONLY`], then gives the CPU away
/// between looks.
///
/// Polling pays off only when the peer runs on another CPU. A kernel may wake the peer on
/// the waker's own CPU (the host's *start* and an agent's *stop* wake a process that
/// sleeps): the peer then waits behind the poll, and a cycle pays the whole window twice
/// (measured on a 2-vCPU KVM guest, one agent, 3×320×240: 83–178 µs per cycle with host
/// and agent held on one CPU, 6 µs on two). After the busy head each look yields
/// (`sched_yield`), which lets a peer waiting on the same CPU run at once and returns at
/// once when nothing else is runnable.
#[derive(Debug, Clone, Copy)]
pub struct PollWindow {
    start: Instant,
    busy_until: Instant,
    until: Instant,
}

/// How long a [`PollWindow`] busy-polls before it yields between looks: an answer that
/// comes within it is seen without a system call.
pub const POLL_SPIN_ONLY: Duration = Duration::from_micros(5);

/// The longest [`PollWindow`] (`spin_before_block_us` is at most 10 ms).
pub const POLL_WINDOW_MAX: Duration = Duration::from_secs(1);

impl PollWindow {
    /// A window of `length` from now (at most [`POLL_WINDOW_MAX`]).
    pub fn new(length: Duration) -> Self {
        let start = Instant::now();
        Self {
            start,
            busy_until: start + POLL_SPIN_ONLY,
            until: start + length.min(POLL_WINDOW_MAX),
        }
    }

    /// Whether the window has no length (polling off, or a look without a wait).
    pub fn is_empty(&self) -> bool {
        self.until == self.start
    }

    /// The time since the window opened (the wait so far, for [`PollLength::record`]).
    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }

    /// Pauses between two looks: `false` (at once) once the window has passed.
    pub fn pause(&self) -> bool {
        let now = Instant::now();
        if now >= self.until {
            return false;
        }
        std::hint::spin_loop();
        if now >= self.busy_until {
            std::thread::yield_now();
        }
        true
    }
}

/// The length of one waiting side's poll-before-sleep windows: `[sync] spin_before_block_us`,
/// or twice the mean of the side's recent waits when that is longer and at most
/// [`POLL_FOLLOW_MAX`].
///
/// A fixed window misses a peer whose answer takes a little longer than it: the waiter then
/// sleeps and each cycle pays a wake-up (tens of microseconds), as with a Python agent that
/// reads a 3×1920×1080 frame in 35–55 µs against the 50 µs default. Following the recent
/// waits keeps such an answer inside the window; a peer that takes longer than half of
/// [`POLL_FOLLOW_MAX`] gets the configured window (a wake-up is then a small part of the
/// wait, and polling would only burn the core). A zero length (polling off) stays zero.
#[derive(Debug, Clone, Copy)]
pub struct PollLength {
    configured: Duration,
    /// Mean of the recent waits (an exponential average, weight 1/8), in nanoseconds.
    mean_ns: u64,
}

/// The longest window a [`PollLength`] grows to by following its waits.
pub const POLL_FOLLOW_MAX: Duration = Duration::from_micros(500);

impl PollLength {
    /// Windows of `configured` until waits have been recorded.
    pub fn new(configured: Duration) -> Self {
        Self {
            configured,
            mean_ns: 0,
        }
    }

    /// Changes the configured window (the followed mean stays).
    pub fn set_configured(&mut self, configured: Duration) {
        self.configured = configured;
    }

    /// The length of the next window.
    pub fn length(&self) -> Duration {
        if self.configured.is_zero() {
            return Duration::ZERO;
        }
        let follow = Duration::from_nanos(self.mean_ns.saturating_mul(2));
        if follow > self.configured && follow <= POLL_FOLLOW_MAX {
            follow
        } else {
            self.configured
        }
    }

    /// A window of the next length from now, at most `limit`.
    pub fn window(&self, limit: Duration) -> PollWindow {
        PollWindow::new(self.length().min(limit))
    }

    /// Counts one wait that took `waited` (until the answer, or until it gave up).
    pub fn record(&mut self, waited: Duration) {
        let waited = u64::try_from(waited.as_nanos()).unwrap_or(u64::MAX);
        // Never above the largest wait: no overflow.
        self.mean_ns = self.mean_ns - self.mean_ns / 8 + waited / 8;
    }
}

mod agent;
mod host;
mod ice_errors;
pub(crate) mod section;
mod stack;
mod wake;

pub use section::ShmConfig;
pub use stack::*;

use wake::remove_wake_word;
pub use wake::{WakeWord, WakeWordError, wake_word_name};

use ice_errors::IceError;

pub use agent::*;
pub use host::*;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_poll_window_pauses_until_it_has_passed() {
        let empty = PollWindow::new(Duration::ZERO);
        assert!(empty.is_empty());
        assert!(!empty.pause());
        // A length too long for an `Instant` is cut to the longest window.
        let window = PollWindow::new(Duration::MAX);
        assert!(!window.is_empty());
        // In the busy head and after it (where it yields), the window is still open.
        assert!(window.pause());
        let past_head = PollWindow {
            start: Instant::now(),
            busy_until: Instant::now(),
            until: Instant::now() + Duration::from_secs(3600),
        };
        assert!(past_head.pause());
        let ended = PollWindow {
            start: Instant::now(),
            busy_until: Instant::now(),
            until: Instant::now(),
        };
        assert!(!ended.pause());
    }

    #[test]
    fn a_poll_length_follows_short_waits_only() {
        let configured = Duration::from_micros(50);
        let mut length = PollLength::new(configured);
        assert_eq!(length.length(), configured);
        // Answers in 40 µs: the window grows to twice that.
        for _ in 0..100 {
            length.record(Duration::from_micros(40));
        }
        let grown = length.length();
        assert!(
            grown > Duration::from_micros(78) && grown <= Duration::from_micros(80),
            "{grown:?}"
        );
        // Quick answers: never below the configured window.
        for _ in 0..100 {
            length.record(Duration::from_micros(1));
        }
        assert_eq!(length.length(), configured);
        // Answers longer than half the cap: back to the configured window.
        for _ in 0..100 {
            length.record(Duration::from_millis(2));
        }
        assert_eq!(length.length(), configured);
        // An hour-long (or longer) wait neither overflows nor panics.
        length.record(Duration::MAX);
        assert_eq!(length.length(), configured);
        assert!(length.window(Duration::ZERO).is_empty());
        assert!(!length.window(Duration::from_secs(1)).is_empty());
        // Polling off stays off.
        let mut off = PollLength::new(Duration::ZERO);
        off.record(Duration::from_micros(40));
        assert_eq!(off.length(), Duration::ZERO);
    }

    /// A wait shorter than a microsecond returns at once: iceoryx2 would have turned it
    /// into a wait without end. A watchdog thread notifies after 10 s so that a wait that
    /// blocks ends (and fails the test) instead of hanging.
    #[test]
    fn a_wait_under_a_microsecond_only_looks() {
        let name = format!("vrsync/waittest{}/e", std::process::id());
        let service_name = ServiceName::new(&name).unwrap();
        let node_a = node(&format!("waittest{}.a", std::process::id())).unwrap();
        let service = node_a
            .service_builder(&service_name)
            .event()
            .create()
            .unwrap();
        let listener = service.listener_builder().create().unwrap();
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let watchdog = std::thread::spawn(move || {
            let node_b = node(&format!("waittest{}.b", std::process::id())).unwrap();
            let service = node_b
                .service_builder(&ServiceName::new(&name).unwrap())
                .event()
                .open()
                .unwrap();
            let notifier = service.notifier_builder().create().unwrap();
            if done_rx.recv_timeout(Duration::from_secs(10)).is_err() {
                let _ = notifier.notify();
            }
        });
        for timeout in [
            Duration::ZERO,
            Duration::from_nanos(1),
            Duration::from_nanos(999),
        ] {
            let started = Instant::now();
            assert_eq!(wait_events(&listener, |_| {}, timeout).unwrap(), 0);
            assert!(
                started.elapsed() < Duration::from_secs(5),
                "{timeout:?} blocked"
            );
        }
        // A real timeout still waits and ends.
        assert_eq!(
            wait_events(&listener, |_| {}, Duration::from_millis(2)).unwrap(),
            0
        );
        done_tx.send(()).unwrap();
        watchdog.join().unwrap();
    }

    #[test]
    fn only_the_sessions_own_nodes_belong_to_it() {
        assert!(node_of_session("vrsync-host.a", "a"));
        assert!(node_of_session("vrsync-agent.a.3", "a"));
        assert!(node_of_session("vrsync-agent.a.b.3", "a.b"));
        assert!(!node_of_session("vrsync-agent.a.b.3", "a"));
        assert!(!node_of_session("vrsync-host.ab", "a"));
        assert!(!node_of_session("vrsync-agent.ab.3", "a"));
        assert!(!node_of_session("vrsync-agent.a.", "a"));
        assert!(!node_of_session("floor-node", "a"));
        assert!(node_of_session("vrsync-stack.a", "a"));
        assert!(!node_of_session("vrsync-stack.ab", "a"));
    }

    const CHILD_ENV: &str = "VRSYNC_TEST_DEAD_NODE_SESSION";

    fn dead_nodes_of(session: &str) -> usize {
        let mut n = 0;
        for_each_dead_node(|_, name| {
            if node_of_session(name, session) {
                n += 1;
            }
        });
        n
    }

    /// A host process of one session is SIGKILLed; cleaning up for another session leaves
    /// its dead node alone, cleaning up for its own session removes it.
    #[test]
    fn cleanup_touches_only_the_dead_nodes_of_its_own_session() {
        if let Ok(session) = std::env::var(CHILD_ENV) {
            // The child: be a host of `session`, then die without cleaning up.
            let _node = node(&host_node_name(&session)).unwrap();
            // SAFETY: kills this (child) process on purpose.
            unsafe { libc::raise(libc::SIGKILL) };
            return;
        }
        let pid = std::process::id();
        let (dead, other) = (format!("deadnode{pid}"), format!("othernode{pid}"));
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "shm::tests::cleanup_touches_only_the_dead_nodes_of_its_own_session",
                "--test-threads=1",
            ])
            .env(CHILD_ENV, &dead)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .unwrap();
        assert_eq!(
            std::os::unix::process::ExitStatusExt::signal(&status),
            Some(libc::SIGKILL)
        );
        assert_eq!(dead_nodes_of(&dead), 1);
        assert_eq!(cleanup_dead_nodes(&other), 0);
        assert_eq!(
            dead_nodes_of(&dead),
            1,
            "another session's dead node was removed"
        );
        assert_eq!(cleanup_dead_nodes(&dead), 1);
        assert_eq!(dead_nodes_of(&dead), 0);
    }
}

#[cfg(test)]
mod signal_tests {
    extern "C" fn mine(_: libc::c_int) {}

    fn action(sig: libc::c_int) -> libc::sighandler_t {
        // SAFETY: querying the current action into a zeroed sigaction.
        unsafe {
            let mut old: libc::sigaction = core::mem::zeroed();
            assert_eq!(libc::sigaction(sig, core::ptr::null(), &mut old), 0);
            old.sa_sigaction
        }
    }

    /// The process's own handler survives a node and iceoryx2's lazy signal handler (which
    /// iceoryx2 creates e.g. when it zeroes a new segment during a wait).
    #[test]
    fn iceoryx2_never_replaces_the_process_signal_handlers() {
        // SAFETY: installing a handler that does nothing for SIGURG (ignored by default).
        unsafe {
            let mut act: libc::sigaction = core::mem::zeroed();
            act.sa_sigaction = mine as *const () as libc::sighandler_t;
            assert_eq!(
                libc::sigaction(libc::SIGURG, &act, core::ptr::null_mut()),
                0
            );
        }
        let _node = super::node(&format!("sigtest{}", std::process::id())).unwrap();
        let _ = iceoryx2_bb_posix::signal::SignalHandler::last_signal();
        assert_eq!(
            action(libc::SIGURG),
            mine as *const () as libc::sighandler_t
        );
    }
}
