//! The shared-memory transport over iceoryx2.
//!
//! Services (all under `vrsync/<session>/`, see DESIGN §4):
//!
//! | service              | pattern                                 | writer → reader |
//! |----------------------|-----------------------------------------|-----------------|
//! | `agent/<id>/sensors` | pub-sub `[u8]` + [`SensorHeader`]       | host → agent    |
//! | `agent/<id>/motor`   | pub-sub `[MotorCommand]` + [`MotorHeader`] | agent → host |
//! | `start`              | event, id [`START_EVENT`]               | host → agents   |
//! | `stop`               | event, id = agent id                    | agents → host   |
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
use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe as ps_factory};

use super::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, Attempt, BatchSink, FrameLoanMut, HostLiveness, HostTransport,
    HostTransportError, retry_until,
};
use crate::config::{Config, MAX_AGENT_ID};
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};

type Svc = ipc::Service;

/// Event id of *start* on the `start` service.
pub const START_EVENT: usize = 0;
/// Event id on the `start` service telling agents the host closed the session cleanly.
pub const SHUTDOWN_EVENT: usize = 1;
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
            let frame = a.frame_bytes().max(1) as u64 + header;
            let motor = (u64::from(config.transport.max_commands_per_cycle)
                * core::mem::size_of::<MotorCommand>() as u64
                + 64)
                * (MOTOR_QUEUE as u64 + 2);
            frame * SENSOR_POOL_SAMPLES as u64 + motor
        })
        .sum()
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
    let key = |k: &str| AttributeKey::try_from(k).map_err(|e| format!("{e:?}"));
    let val = |v: &str| AttributeValue::try_from(v).map_err(|e| format!("{e:?}"));
    let (pk, pv) = (key(ATTR_PROTOCOL)?, val(&PROTOCOL_VERSION.to_string())?);
    let (lk, lv) = (key(ATTR_LAYOUT)?, val(&format!("{LAYOUT_HASH:016x}"))?);
    AttributeSpecifier::new()
        .define(&pk, &pv)
        .and_then(|s| s.define(&lk, &lv))
        .map_err(|e| format!("{e:?}"))
}

/// Quiets iceoryx2's own logging unless `IOX2_LOG_LEVEL` asks for more. iceoryx2 logs
/// through `tracing` (feature `tracing`), so what remains shows up in our logs.
pub fn init_iceoryx2_logging() {
    set_log_level_from_env_or(LogLevel::Error);
}

fn node(name: &str) -> Result<Node<Svc>, String> {
    let node_name =
        NodeName::new(name).map_err(|e| format!("invalid node name {name:?}: {e:?}"))?;
    NodeBuilder::new()
        .name(&node_name)
        // Signals are handled by `crate::signal` (or left to the embedding process).
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| format!("cannot create iceoryx2 node {name:?}: {e:?}"))
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
    let _ = Node::<Svc>::list(Config2::global_config(), |node| {
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

/// Whether iceoryx2 node `name` is the host or an agent of `session` (a session name may
/// contain dots: an agent's node name is `vrsync-agent.<session>.<id>`, digits only after).
fn node_of_session(name: &str, session: &str) -> bool {
    name == host_node_name(session)
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
    use iceoryx2::node::NodeView;
    let mut cleaned = 0;
    let _ = Node::<Svc>::list(Config2::global_config(), |state| {
        if let NodeState::Dead(view) = state
            && view
                .details()
                .as_ref()
                .is_some_and(|d| node_of_session(d.name().as_str(), session))
            && view.try_remove_stale_resources().is_ok()
        {
            cleaned += 1;
        }
        CallbackProgression::Continue
    });
    cleaned
}

// ---------------------------------------------------------------------------------------
// Host side
// ---------------------------------------------------------------------------------------

/// A loaned sensor sample, initialised (see [`ShmHost::loan`]).
pub struct ShmFrameLoan {
    sample: SampleMut<Svc, [u8], SensorHeader>,
}

impl core::fmt::Debug for ShmFrameLoan {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmFrameLoan")
            .field("header", self.sample.user_header())
            .field("payload_len", &self.sample.payload().len())
            .finish()
    }
}

impl FrameLoanMut for ShmFrameLoan {
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        let payload = self.sample.payload_mut();
        let (ptr, len) = (payload.as_mut_ptr(), payload.len());
        let header = self.sample.user_header_mut();
        // SAFETY: the user header and the payload are disjoint regions of the sample's chunk
        // (iceoryx2 lays out header, user header and payload one after the other), so the two
        // mutable borrows do not alias; both live as long as `&mut self`.
        let payload = unsafe { core::slice::from_raw_parts_mut(ptr, len) };
        (header, payload)
    }

    fn header(&self) -> &SensorHeader {
        self.sample.user_header()
    }
}

struct HostAgentPorts {
    id: u32,
    frame_bytes: usize,
    sensor_pub: Publisher<Svc, [u8], SensorHeader>,
    motor_service: ps_factory::PortFactory<Svc, [MotorCommand], MotorHeader>,
    motor_sub: Subscriber<Svc, [MotorCommand], MotorHeader>,
    sensor_service: ps_factory::PortFactory<Svc, [u8], SensorHeader>,
    /// Addresses of pool chunks already written once: their bytes are initialised.
    initialised: Vec<usize>,
}

/// The host side of the shared-memory transport.
pub struct ShmHost {
    _node: Node<Svc>,
    spin_before_block: Duration,
    signals: SignalHandling,
    agent_node_names: Vec<String>,
    spin: bool,
    spins: u32,
    _start_service: event_factory::PortFactory<Svc>,
    start: Notifier<Svc>,
    _stop_service: event_factory::PortFactory<Svc>,
    stop: Listener<Svc>,
    agents: Vec<HostAgentPorts>,
}

impl core::fmt::Debug for ShmHost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmHost")
            .field(
                "agents",
                &self.agents.iter().map(|a| a.id).collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// Why the shared-memory host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShmHostCreateError {
    /// Another live host owns this session.
    #[error(
        "session {session:?} is already hosted by a running process (service {service} exists); \
         stop it or choose another `session`"
    )]
    SessionInUse {
        /// The session.
        session: String,
        /// The service that exists.
        service: String,
    },
    /// The services would not fit into `/dev/shm`.
    #[error(transparent)]
    ShmBudget(#[from] ShmBudgetError),
    /// iceoryx2 refused to create a node, service or port.
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
}

impl ShmHost {
    /// Creates every service of the session and the host's ports; `signals` says whether
    /// SIGINT/SIGTERM handlers are installed (see [`SignalHandling`]).
    ///
    /// # Errors
    /// [`ShmHostCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, ShmHostCreateError> {
        init_iceoryx2_logging();
        signals.apply();
        let ice = ShmHostCreateError::Iceoryx;
        let session = &config.session;
        check_shm_budget(config)?;
        cleanup_dead_nodes(session);
        if host_alive(session) {
            return Err(ShmHostCreateError::SessionInUse {
                session: session.clone(),
                service: host_node_name(session),
            });
        }
        let node = node(&host_node_name(session)).map_err(ice)?;
        let attrs = attributes().map_err(ice)?;
        let n = config.agents.len();
        let max_ports = n + 4;
        let exists = |name: &str, e: &dyn core::fmt::Debug| {
            let s = format!("{e:?}");
            if s.contains("AlreadyExists") {
                ShmHostCreateError::SessionInUse {
                    session: session.clone(),
                    service: service_name(session, name),
                }
            } else {
                ShmHostCreateError::Iceoryx(format!(
                    "cannot create service {}: {s}",
                    service_name(session, name)
                ))
            }
        };

        let stop_service = node
            .service_builder(&svc_name(session, "stop").map_err(ice)?)
            .event()
            .max_listeners(2)
            .max_notifiers(max_ports)
            .max_nodes(max_ports)
            .event_id_max_value(MAX_AGENT_ID as usize + 1)
            .create_with_attributes(&attrs)
            .map_err(|e| exists("stop", &e))?;
        let stop = stop_service
            .listener_builder()
            .create()
            .map_err(|e| ice(format!("cannot create the stop listener: {e:?}")))?;

        let mut agents = Vec::with_capacity(n);
        for a in &config.agents {
            let frame_bytes = a.frame_bytes();
            let sensors = format!("agent/{}/sensors", a.id);
            let mut builder = node
                .service_builder(&svc_name(session, &sensors).map_err(ice)?)
                .publish_subscribe::<[u8]>()
                .user_header::<SensorHeader>()
                .max_publishers(1)
                .max_subscribers(1)
                .max_nodes(4)
                .history_size(0)
                .subscriber_max_buffer_size(SENSOR_QUEUE)
                .subscriber_max_borrowed_samples(AGENT_BORROWED_FRAMES)
                .enable_safe_overflow(true);
            if let Some(align) = Alignment::new(crate::wire::IMAGE_ALIGN) {
                builder = builder.payload_alignment(align);
            }
            let sensor_service = builder
                .create_with_attributes(&attrs)
                .map_err(|e| exists(&sensors, &e))?;
            let sensor_pub = sensor_service
                .publisher_builder()
                .initial_max_slice_len(frame_bytes.max(1))
                .allocation_strategy(AllocationStrategy::Static)
                .max_loaned_samples(1)
                .create()
                .map_err(|e| {
                    ice(format!(
                        "cannot create the sensor publisher of agent {}: {e:?}",
                        a.id
                    ))
                })?;
            let motor = format!("agent/{}/motor", a.id);
            let motor_service = node
                .service_builder(&svc_name(session, &motor).map_err(ice)?)
                .publish_subscribe::<[MotorCommand]>()
                .user_header::<MotorHeader>()
                .max_publishers(1)
                .max_subscribers(1)
                .max_nodes(4)
                .history_size(0)
                .subscriber_max_buffer_size(MOTOR_QUEUE)
                .subscriber_max_borrowed_samples(1)
                .enable_safe_overflow(true)
                .create_with_attributes(&attrs)
                .map_err(|e| exists(&motor, &e))?;
            let motor_sub = motor_service
                .subscriber_builder()
                .buffer_size(MOTOR_QUEUE)
                .create()
                .map_err(|e| {
                    ice(format!(
                        "cannot create the motor subscriber of agent {}: {e:?}",
                        a.id
                    ))
                })?;
            agents.push(HostAgentPorts {
                id: a.id,
                frame_bytes,
                sensor_service,
                sensor_pub,
                motor_service,
                motor_sub,
                initialised: Vec::with_capacity(SENSOR_POOL_SAMPLES * 2),
            });
        }
        // `start` is created last: agents open it first, so once it exists every other
        // service of the session does too.
        let start_service = node
            .service_builder(&svc_name(session, "start").map_err(ice)?)
            .event()
            .max_listeners(max_ports)
            .max_notifiers(2)
            .max_nodes(max_ports)
            .event_id_max_value(SHUTDOWN_EVENT + 1)
            .create_with_attributes(&attrs)
            .map_err(|e| exists("start", &e))?;
        let start = start_service
            .notifier_builder()
            .default_event_id(EventId::new(START_EVENT))
            .create()
            .map_err(|e| ice(format!("cannot create the start notifier: {e:?}")))?;
        Ok(Self {
            _node: node,
            spin_before_block: config.sync.effective_spin_before_block(config.agents.len()),
            signals,
            agent_node_names: config
                .agents
                .iter()
                .map(|a| agent_node_name(session, a.id))
                .collect(),
            spin: config.sync.wait == crate::config::WaitMode::Spin,
            spins: 0,
            _start_service: start_service,
            start,
            _stop_service: stop_service,
            stop,
            agents,
        })
    }

    fn agent(&self, slot: usize) -> Result<&HostAgentPorts, HostTransportError> {
        self.agents
            .get(slot)
            .ok_or(HostTransportError::NoSuchSlot { slot })
    }
}

impl Drop for ShmHost {
    fn drop(&mut self) {
        // Wake every agent at once with "session closed" instead of letting each find out
        // by its liveness check.
        let _ = self
            .start
            .notify_with_custom_event_id(EventId::new(SHUTDOWN_EVENT));
    }
}

fn is_dyn_connected(p: &HostAgentPorts) -> bool {
    use iceoryx2::service::port_factory::PortFactory as _;
    p.sensor_service.dynamic_config().number_of_subscribers() > 0
        && p.motor_service.dynamic_config().number_of_publishers() > 0
}

impl HostTransport for ShmHost {
    type Loan = ShmFrameLoan;

    fn is_connected(&self, slot: usize) -> bool {
        self.agents.get(slot).is_some_and(is_dyn_connected)
    }

    fn loan(&mut self, slot: usize) -> Result<ShmFrameLoan, HostTransportError> {
        let id = self.agent(slot)?.id;
        let Some(p) = self.agents.get_mut(slot) else {
            return Err(HostTransportError::Loan {
                agent: id,
                reason: "no such agent slot".into(),
            });
        };
        let mut sample = p.sensor_pub.loan_slice_uninit(p.frame_bytes).map_err(|e| {
            HostTransportError::Loan {
                agent: id,
                reason: format!("{e:?}"),
            }
        })?;
        let addr = sample.payload().as_ptr() as usize;
        if !p.initialised.contains(&addr) {
            // First use of this pool chunk: give every byte a defined value once. Later
            // loans of the same chunk find the bytes of an earlier frame, so steady state
            // costs no memset (zero copy, no per-cycle work proportional to image size).
            sample.payload_mut().fill(MaybeUninit::new(0));
            if p.initialised.len() < p.initialised.capacity() {
                p.initialised.push(addr);
            }
        }
        // SAFETY: every byte of this chunk was written (above, now or in an earlier loan of
        // the same chunk); shared memory is never de-initialised by anyone afterwards.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = SensorHeader::default();
        Ok(ShmFrameLoan { sample })
    }

    fn publish(&mut self, slot: usize, frame: ShmFrameLoan) -> Result<bool, HostTransportError> {
        let id = self.agent(slot)?.id;
        frame
            .sample
            .send()
            .map(|receivers| receivers > 0)
            .map_err(|e| HostTransportError::Send {
                what: format!("the sensor frame of agent {id}"),
                reason: format!("{e:?}"),
            })
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        self.start
            .notify()
            .map(|_| ())
            .map_err(|e| HostTransportError::Send {
                what: "start".into(),
                reason: format!("{e:?}"),
            })
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        for (slot, p) in self.agents.iter().enumerate() {
            loop {
                match p.motor_sub.receive() {
                    Ok(Some(sample)) => sink(slot, sample.user_header(), sample.payload()),
                    Ok(None) => break,
                    Err(e) => {
                        return Err(HostTransportError::Receive {
                            agent: p.id,
                            reason: format!("{e:?}"),
                        });
                    }
                }
            }
        }
        Ok(())
    }

    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        if self.spin {
            // Busy-poll: the caller drains the subscribers again right away. Check for a
            // termination request now and then only (it costs a syscall).
            let _ = timeout;
            std::hint::spin_loop();
            self.spins = self.spins.wrapping_add(1);
            if self.spins.is_multiple_of(4096) && self.termination_requested() {
                return Err(HostTransportError::Terminated);
            }
            return Ok(());
        }
        // Poll the subscribers briefly first: a quick answer is then seen without paying
        // for a sleep and a wake-up (see `spin_before_block_us`).
        if !self.spin_before_block.is_zero() {
            let until = Instant::now() + self.spin_before_block.min(timeout);
            loop {
                if self
                    .agents
                    .iter()
                    .any(|p| p.motor_sub.has_samples().unwrap_or(true))
                {
                    return Ok(());
                }
                if Instant::now() >= until {
                    break;
                }
                std::hint::spin_loop();
            }
        }
        match self.stop.timed_wait(|_| {}, timeout) {
            Ok(_) => {}
            Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
            Err(e) => {
                return Err(HostTransportError::Wait {
                    reason: format!("stop listener: {e:?}"),
                });
            }
        }
        // Drain every id that is already pending: counts merge and carry no information
        // we rely on, and a pending id would make the next wait return at once.
        let _ = self.stop.try_wait(|_| {});
        if self.termination_requested() {
            return Err(HostTransportError::Terminated);
        }
        Ok(())
    }

    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        use iceoryx2::node::NodeView;
        let names = &self.agent_node_names;
        let _ = Node::<Svc>::list(Config2::global_config(), |state| {
            if let NodeState::Dead(view) = state {
                let slot = view
                    .details()
                    .as_ref()
                    .and_then(|d| names.iter().position(|n| n == d.name().as_str()));
                if let Some(slot) = slot {
                    // Removes its ports from our services: its sample loans come back and
                    // a restarted agent with the same id can attach.
                    let cleaned = view.try_remove_stale_resources().is_ok();
                    debug!(slot, cleaned, "dead agent node found");
                    dead.push(slot);
                }
            }
            CallbackProgression::Continue
        });
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        for p in &self.agents {
            let connect = |what: &str, e: &dyn core::fmt::Debug| HostTransportError::Connect {
                agent: p.id,
                reason: format!("{what}: {e:?}"),
            };
            p.sensor_pub
                .update_connections()
                .map_err(|e| connect("sensor publisher", &e))?;
            p.motor_sub
                .update_connections()
                .map_err(|e| connect("motor subscriber", &e))?;
        }
        Ok(())
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    fn activity_fd(&self) -> Option<std::os::fd::RawFd> {
        // SAFETY: the descriptor stays owned by the listener; it is only polled.
        Some(unsafe { self.stop.file_descriptor().native_handle() })
    }

    fn clear_activity(&mut self) {
        let _ = self.stop.try_wait(|_| {});
    }
}

// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

/// What [`ShmAgent::wait_start`] saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StartSignal {
    /// *start* was signalled.
    pub start: bool,
    /// The host closed the session.
    pub shutdown: bool,
}

impl StartSignal {
    fn record(&mut self, e: EventActivation) {
        if e.id.as_value() == SHUTDOWN_EVENT {
            self.shutdown = true;
        } else {
            self.start = true;
        }
    }
}

/// A received sensor frame in shared memory, owned by the agent until dropped.
pub struct ShmFrame {
    sample: Sample<Svc, [u8], SensorHeader>,
}

impl core::fmt::Debug for ShmFrame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmFrame")
            .field("cycle", &self.sample.user_header().cycle)
            .finish()
    }
}

impl ShmFrame {
    /// The header.
    pub fn header(&self) -> &SensorHeader {
        self.sample.user_header()
    }
    /// The image bytes, straight from shared memory.
    pub fn payload(&self) -> &[u8] {
        self.sample.payload()
    }
}

/// The agent side of the shared-memory transport.
pub struct ShmAgent {
    id: u32,
    session: String,
    host_pid: Option<i32>,
    _node: Node<Svc>,
    signals: SignalHandling,
    _start_service: event_factory::PortFactory<Svc>,
    start: Listener<Svc>,
    _stop_service: event_factory::PortFactory<Svc>,
    stop: Notifier<Svc>,
    _sensor_service: ps_factory::PortFactory<Svc, [u8], SensorHeader>,
    sensor_sub: Subscriber<Svc, [u8], SensorHeader>,
    _motor_service: ps_factory::PortFactory<Svc, [MotorCommand], MotorHeader>,
    motor_pub: Publisher<Svc, [MotorCommand], MotorHeader>,
    max_commands: usize,
    spin: bool,
    spin_before_block: Duration,
    shutdown_seen: bool,
}

impl core::fmt::Debug for ShmAgent {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmAgent")
            .field("id", &self.id)
            .field("session", &self.session)
            .finish()
    }
}

fn attr(attrs: &AttributeSet, key: &str) -> String {
    AttributeKey::try_from(key)
        .ok()
        .and_then(|k| attrs.key_value(&k, 0).map(|v| v.to_string()))
        .unwrap_or_else(|| "unknown".into())
}

/// The agent ids whose sensor service exists in `session` (the ids its host serves),
/// ascending.
fn served_agent_ids(session: &str) -> Vec<u32> {
    let prefix = service_name(session, "agent/");
    let mut ids = Vec::new();
    let _ = Svc::list(Config2::global_config(), |info| {
        let name = info.static_details.name().as_str();
        if let Some(id) = name
            .strip_prefix(prefix.as_str())
            .and_then(|rest| rest.strip_suffix("/sensors"))
            .and_then(|id| id.parse::<u32>().ok())
        {
            ids.push(id);
        }
        CallbackProgression::Continue
    });
    ids.sort_unstable();
    ids.dedup();
    ids
}

impl ShmAgent {
    /// Opens the session's services as agent `id`, retrying until the host created them or
    /// `timeout` passed. Checks the protocol version and layout first. `signals` says
    /// whether SIGINT/SIGTERM handlers are installed (see [`SignalHandling`]).
    ///
    /// # Errors
    /// [`AgentConnectError`].
    pub fn connect(
        config: &Config,
        id: u32,
        timeout: Duration,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        use iceoryx2::service::port_factory::PortFactory as _;
        init_iceoryx2_logging();
        signals.apply();
        let session = &config.session;
        let ice = |detail: String| AgentConnectError::Transport {
            session: session.clone(),
            agent: id,
            detail: format!("iceoryx2: {detail}"),
        };
        let deadline = Instant::now() + timeout;
        let started = Instant::now();
        let node = node(&agent_node_name(session, id)).map_err(ice)?;
        let not_found = |what: &str| AgentConnectError::HostNotFound {
            session: session.clone(),
            agent: id,
            waited: started.elapsed(),
            looked_for: format!(
                "shared-memory service {} does not exist",
                service_name(session, what)
            ),
        };

        // Opening does not block in iceoryx2: retry until the host created the services.
        let start_name = svc_name(session, "start").map_err(ice)?;
        let start_service = retry_until(
            deadline,
            || signals.termination_requested(),
            || {
                use iceoryx2::service::builder::event::EventOpenError as E;
                match node.service_builder(&start_name).event().open() {
                    Ok(s) => Attempt::Done(s),
                    Err(E::DoesNotExist | E::InsufficientPermissions | E::HangsInCreation) => {
                        Attempt::NotYet(String::new())
                    }
                    Err(e) => Attempt::Failed(ice(format!("cannot open the start service: {e:?}"))),
                }
            },
        )
        .map_err(|e| match e {
            Ok(_) => not_found("start"),
            Err(e) => e,
        })?;
        let host_protocol = attr(start_service.attributes(), ATTR_PROTOCOL);
        let host_layout = attr(start_service.attributes(), ATTR_LAYOUT);
        let agent_layout = format!("{LAYOUT_HASH:016x}");
        if host_protocol != PROTOCOL_VERSION.to_string() || host_layout != agent_layout {
            return Err(AgentConnectError::VersionMismatch {
                session: session.clone(),
                host_protocol,
                host_layout,
                agent_protocol: PROTOCOL_VERSION,
                agent_layout,
            });
        }

        let sensors = format!("agent/{id}/sensors");
        let motor = format!("agent/{id}/motor");
        // `start` is created last by the host: once it exists, a missing service of this
        // agent means the host does not serve this id.
        let open_err = |what: &str, e: &dyn core::fmt::Debug| {
            let s = format!("{e:?}");
            if s.contains("DoesNotExist") {
                if what == "stop" {
                    not_found(what)
                } else {
                    AgentConnectError::IdNotServed {
                        session: session.clone(),
                        agent: id,
                        served: served_agent_ids(session),
                    }
                }
            } else {
                ice(format!("cannot open {}: {s}", service_name(session, what)))
            }
        };
        let sensor_service = node
            .service_builder(&svc_name(session, &sensors).map_err(ice)?)
            .publish_subscribe::<[u8]>()
            .user_header::<SensorHeader>()
            .open()
            .map_err(|e| open_err(&sensors, &e))?;
        let motor_service = node
            .service_builder(&svc_name(session, &motor).map_err(ice)?)
            .publish_subscribe::<[MotorCommand]>()
            .user_header::<MotorHeader>()
            .open()
            .map_err(|e| open_err(&motor, &e))?;
        let stop_service = node
            .service_builder(&svc_name(session, "stop").map_err(ice)?)
            .event()
            .open()
            .map_err(|e| open_err("stop", &e))?;

        let in_use = |e: &dyn core::fmt::Debug| {
            let s = format!("{e:?}");
            if s.contains("ExceedsMax") {
                AgentConnectError::IdInUse {
                    session: session.clone(),
                    agent: id,
                }
            } else {
                ice(s)
            }
        };
        let max_commands = config.transport.max_commands_per_cycle as usize;
        // Order matters: the host treats the agent as connected once the sensor subscriber
        // exists, so everything else (stop notifier, motor publisher, start listener) is
        // created first.
        let stop = stop_service
            .notifier_builder()
            .default_event_id(EventId::new(id as usize))
            .create()
            .map_err(|e| in_use(&e))?;
        let motor_pub = motor_service
            .publisher_builder()
            .initial_max_slice_len(max_commands)
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(1)
            .create()
            .map_err(|e| in_use(&e))?;
        let start = start_service
            .listener_builder()
            .create()
            .map_err(|e| in_use(&e))?;
        let sensor_sub = sensor_service
            .subscriber_builder()
            .buffer_size(SENSOR_QUEUE)
            .create()
            .map_err(|e| in_use(&e))?;
        // Tell the host we are here (it waits on the stop event while agents join).
        let _ = stop.notify();
        Ok(Self {
            id,
            session: session.clone(),
            host_pid: host_pid(session),
            _node: node,
            signals,
            _start_service: start_service,
            start,
            _stop_service: stop_service,
            stop,
            _sensor_service: sensor_service,
            sensor_sub,
            _motor_service: motor_service,
            motor_pub,
            max_commands,
            spin: config.sync.wait == crate::config::WaitMode::Spin,
            spin_before_block: config.sync.effective_spin_before_block(config.agents.len()),
            shutdown_seen: false,
        })
    }

    /// The newest frame not yet received; older queued frames are dropped.
    ///
    /// # Errors
    /// [`AgentReceiveError::TooManyFramesHeld`] when the caller still holds
    /// [`AGENT_BORROWED_FRAMES`] frames.
    pub fn receive_newest(&mut self) -> Result<Option<ShmFrame>, AgentReceiveError> {
        let mut newest = None;
        loop {
            match self.sensor_sub.receive() {
                Ok(Some(sample)) => newest = Some(ShmFrame { sample }),
                Ok(None) => return Ok(newest),
                Err(e) => {
                    if newest.is_some() {
                        return Ok(newest);
                    }
                    return Err(match e {
                        iceoryx2::port::ReceiveError::ExceedsMaxBorrows => {
                            AgentReceiveError::TooManyFramesHeld {
                                max: AGENT_BORROWED_FRAMES,
                            }
                        }
                        other => AgentReceiveError::Transport(format!("iceoryx2: {other:?}")),
                    });
                }
            }
        }
    }

    /// Blocks until *start* may have been signalled, or `timeout` passed. Polls for a
    /// frame for up to `spin_before_block_us` first.
    pub fn wait_start(&mut self, timeout: Duration) -> StartSignal {
        if !self.spin_before_block.is_zero() {
            let until = Instant::now() + self.spin_before_block.min(timeout);
            while Instant::now() < until {
                if self.has_frame() {
                    return StartSignal {
                        start: true,
                        shutdown: false,
                    };
                }
                std::hint::spin_loop();
            }
        }
        let mut signal = StartSignal::default();
        let mut record = |e: EventActivation| signal.record(e);
        if let Ok(n) = self.start.timed_wait(&mut record, timeout)
            && n > 0
        {
            let _ = self.start.try_wait(&mut record);
        }
        self.shutdown_seen |= signal.shutdown;
        signal
    }

    /// Whether the host's "session closed" event was ever seen (sticky: a call that
    /// returned a frame may have consumed it).
    pub fn shutdown_seen(&self) -> bool {
        self.shutdown_seen
    }

    /// Whether a frame is waiting (cheap, non-blocking).
    pub fn has_frame(&self) -> bool {
        self.sensor_sub.has_samples().unwrap_or(true)
    }

    /// Whether this agent busy-polls (`[sync] wait = "spin"`).
    pub fn spins(&self) -> bool {
        self.spin
    }

    /// Discards pending *start* notifications; reports a pending shutdown.
    pub fn clear_start(&mut self) -> StartSignal {
        let mut signal = StartSignal::default();
        let _ = self.start.try_wait(|e: EventActivation| signal.record(e));
        self.shutdown_seen |= signal.shutdown;
        signal
    }

    /// The state of the host's node.
    pub fn host_state(&self) -> HostState {
        // Cheap and allocation-free: is the host's process still there? Only when it is
        // gone, ask iceoryx2's registry (which lists every node of the machine) what
        // became of it.
        if let Some(pid) = self.host_pid {
            // SAFETY: kill with signal 0 only checks that the process exists.
            let rc = unsafe { libc::kill(pid, 0) };
            let gone =
                rc != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
            if !gone {
                return HostState::Alive;
            }
            return match host_state(&self.session) {
                HostState::Alive => HostState::Dead, // another host took over the session
                other => other,
            };
        }
        host_state(&self.session)
    }

    /// Whether SIGINT/SIGTERM was received (never, with [`SignalHandling::Leave`]).
    pub fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    /// Publishes a motor batch and, if it carries the stop flag, notifies *stop*.
    ///
    /// # Errors
    /// A string describing the iceoryx2 failure.
    pub fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), String> {
        let n = commands.len().min(self.max_commands);
        let mut sample = self
            .motor_pub
            .loan_slice_uninit(n)
            .map_err(|e| format!("cannot loan a motor batch: {e:?}"))?;
        *sample.user_header_mut() = MotorHeader {
            command_count: n as u32,
            ..*header
        };
        let sample = sample.write_from_slice(&commands[..n]);
        sample
            .send()
            .map_err(|e| format!("cannot send the motor batch: {e:?}"))?;
        if header.is_stop() {
            self.stop
                .notify()
                .map_err(|e| format!("cannot notify stop: {e:?}"))?;
        }
        Ok(())
    }
}

impl AgentFrame for ShmFrame {
    fn header(&self) -> &SensorHeader {
        self.sample.user_header()
    }

    fn payload(&self) -> &[u8] {
        self.sample.payload()
    }
}

impl AgentTransport for ShmAgent {
    type Frame = ShmFrame;

    fn try_receive_newest(&mut self) -> Result<Option<ShmFrame>, AgentReceiveError> {
        self.receive_newest()
    }

    fn wait_readable(&mut self, timeout: Duration) {
        if self.spin {
            // Busy-poll the subscriber until the slice ends (`[sync] wait = "spin"`).
            let until = Instant::now() + timeout;
            while Instant::now() < until {
                if self.has_frame() {
                    break;
                }
                std::hint::spin_loop();
            }
            self.clear_start();
            return;
        }
        self.wait_start(timeout);
    }

    fn discard_wakeups(&mut self) {
        self.clear_start();
    }

    fn host_liveness(&mut self, check_process: bool) -> HostLiveness {
        if self.shutdown_seen {
            return HostLiveness::Closed;
        }
        if !check_process {
            return HostLiveness::Alive;
        }
        match self.host_state() {
            HostState::Alive => HostLiveness::Alive,
            state => {
                // The shutdown event may have raced with the node's removal: look once
                // more before calling the host gone.
                self.clear_start();
                if self.shutdown_seen {
                    HostLiveness::Closed
                } else {
                    HostLiveness::Gone {
                        reason: match state {
                            HostState::Dead => "its process died".into(),
                            _ => "its node is gone".into(),
                        },
                    }
                }
            }
        }
    }

    fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), AgentSendError> {
        ShmAgent::send_batch(self, header, commands).map_err(AgentSendError::Transport)
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }

    const CHILD_ENV: &str = "VRSYNC_TEST_DEAD_NODE_SESSION";

    fn dead_nodes_of(session: &str) -> usize {
        use iceoryx2::node::NodeView;
        let mut n = 0;
        let _ = Node::<Svc>::list(Config2::global_config(), |state| {
            if let NodeState::Dead(view) = state
                && view
                    .details()
                    .as_ref()
                    .is_some_and(|d| node_of_session(d.name().as_str(), session))
            {
                n += 1;
            }
            CallbackProgression::Continue
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
                "transport::shm::tests::cleanup_touches_only_the_dead_nodes_of_its_own_session",
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
