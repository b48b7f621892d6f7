//! The shared-memory transport's host side: creates every service of the session, loans
//! sensor samples, drains motor batches, waits on the stop event.

use super::*;
use iceoryx2::identifiers::{UniquePublisherId, UniqueSubscriberId};
use std::cell::Cell;
// ---------------------------------------------------------------------------------------
// Host side
// ---------------------------------------------------------------------------------------

/// A loaned sensor sample, initialised (see [`ShmHost::loan`]).
pub struct ShmFrameLoan {
    sample: SampleMut<Svc, [u8], SensorHeader>,
    /// A stacked agent's payload: its block of the cycle's stacked sample (its own
    /// sample then carries the header only).
    block: Option<StackBlock>,
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
        if let Some(block) = &mut self.block {
            return (self.sample.user_header_mut(), block.bytes_mut());
        }
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
    /// Its block of the stacked sample, if its payload goes there (see [`HostStack`]).
    stack_index: Option<usize>,
    sensor_pub: Publisher<Svc, [u8], SensorHeader>,
    motor_service: ps_factory::PortFactory<Svc, [MotorCommand], MotorHeader>,
    motor_sub: Subscriber<Svc, [MotorCommand], MotorHeader>,
    sensor_service: ps_factory::PortFactory<Svc, [u8], SensorHeader>,
    /// Addresses of pool chunks already written once: their bytes are initialised.
    initialised: Vec<usize>,
    /// The agent's sensor subscriber that got the last frame, until the host forgets it:
    /// once it is detached, another subscriber (the agent left and a new one connected
    /// before the host looked) is not this connection. `None` while the connection is not
    /// known by identity (none served yet, or several subscribers attached).
    served: Option<UniqueSubscriberId>,
    /// The subscriber of a connection the host stopped serving (it left, or was evicted),
    /// while it may still be attached: an agent that leaves tells the host before its
    /// ports are gone, so until they are, its subscriber is not a new connection of the
    /// id (taking it for one, the host would publish the next frame to it and then see
    /// that connection vanish: an eviction instead of a rejoin).
    departed: Option<UniqueSubscriberId>,
    /// When `served` was last found attached. Listing subscribers allocates (iceoryx2
    /// copies its container state), so the check runs at most every
    /// [`IDENTITY_CHECK_PERIOD`], not at every look of the host's wait loop.
    verified: Cell<Option<Instant>>,
    /// Whether the last check that listed the subscribers found `served` as the only
    /// one. While it holds, the count of subscribers is still 1 and no motor batch came
    /// from another publisher than before ([`Self::motor_from`]), the served connection is
    /// taken as still attached without listing again (see [`still_sole`]).
    sole: Cell<bool>,
    /// The publisher of the motor batches received last: the agent's connection. A batch
    /// from another one (a replaced connection) clears [`Self::sole`] and makes the next
    /// check list the subscribers.
    motor_from: Cell<Option<UniquePublisherId>>,
    /// The process of the served connection (iceoryx2 writes its creator's process id
    /// into a node's id), found with it: the agents of one process (a vector env) count
    /// as one waiting process for the host's poll (see [`ShmHost::count_processes`]).
    process: Option<i32>,
}

/// How often the host checks that the subscriber it serves is still the one attached:
/// a replaced connection (the agent left, its leave batch lost, and a new connection of the
/// id attached before the host looked) is seen within this when the count of subscribers
/// changed meanwhile, else at the new connection's first motor batch (see [`still_sole`]).
const IDENTITY_CHECK_PERIOD: Duration = Duration::from_millis(20);

/// The host side of the shared-memory transport.
pub struct ShmHost {
    _node: Node<Svc>,
    poll: super::PollLength,
    /// `[sync] spin_before_block_us`; the poll uses it when the processes of the
    /// connected agents and the host do not outnumber the cores.
    spin_before_block: Duration,
    signals: SignalHandling,
    agent_node_names: Vec<String>,
    spin: bool,
    spins: u32,
    _start_service: event_factory::PortFactory<Svc>,
    wake: WakeWord,
    _stop_service: event_factory::PortFactory<Svc>,
    stop: Listener<Svc>,
    agents: Vec<HostAgentPorts>,
    /// Per slot: its agent notified *stop* (or *leave*) since the last drain. A drain
    /// looks only at these queues unless [`Self::sweep`] is set: with many agents the
    /// host wakes up many times per cycle, and looking at every agent's queue on each
    /// wake-up (an iceoryx2 connection update and a lock per queue) was most of its time.
    notified: Vec<bool>,
    /// The next drain looks at every queue: batches may have come without a notification
    /// (while the host polled, agents leave it out; an agent of an older build sends its
    /// leave batch without one), or a wait ended without one (a timeout, a signal). Set by
    /// `signal_start`, so every cycle's first drain looks at all.
    sweep: Cell<bool>,
    /// Whether the page says the host polls ([`WakeWord::set_host_polling`]).
    polling: bool,
    /// The stacked sample's publisher (`[transport.shm] stacked_images`).
    stack: Option<HostStack>,
}

/// The builder of a service of frames from the host to one reader (an agent's sensor
/// service, the stacked sample): one publisher and one subscriber, the newest frame
/// queued (older ones replaced), [`AGENT_BORROWED_FRAMES`] held by the reader, payloads
/// aligned for images; user header `H`.
pub(super) fn frame_service<H: core::fmt::Debug + ZeroCopySend>(
    node: &Node<Svc>,
    name: &ServiceName,
) -> iceoryx2::service::builder::publish_subscribe::Builder<[u8], H, Svc> {
    let builder = node
        .service_builder(name)
        .publish_subscribe::<[u8]>()
        .user_header::<H>()
        .max_publishers(1)
        .max_subscribers(1)
        .max_nodes(4)
        .history_size(0)
        .subscriber_max_buffer_size(SENSOR_QUEUE)
        .subscriber_max_borrowed_samples(AGENT_BORROWED_FRAMES)
        .enable_safe_overflow(true);
    match Alignment::new(crate::wire::IMAGE_ALIGN) {
        Some(align) => builder.payload_alignment(align),
        None => builder,
    }
}

/// Marks the slot of agent `id` (a *stop* listener's event id) as notified; ids the host
/// does not serve are ignored.
fn mark_notified(agents: &[HostAgentPorts], notified: &mut [bool], id: usize) {
    if let Ok(slot) = agents.binary_search_by_key(&id, |p| p.id as usize)
        && let Some(n) = notified.get_mut(slot)
    {
        *n = true;
    }
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
    /// The session's wake word could not be created.
    #[error(transparent)]
    WakeWord(#[from] WakeWordError),
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
        let exists = |name: &str, e: &dyn IceError| {
            if e.already_exists() {
                ShmHostCreateError::SessionInUse {
                    session: session.clone(),
                    service: service_name(session, name),
                }
            } else {
                ShmHostCreateError::Iceoryx(format!(
                    "cannot create service {}: {e:?}",
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

        let stack = HostStack::create(&node, config)?;
        let mut agents = Vec::with_capacity(n);
        for a in &config.agents {
            let stack_index = stack.as_ref().and(stack_index(config, a.id));
            // A stacked agent's own sample carries the header only.
            let frame_bytes = if stack_index.is_some() {
                0
            } else {
                a.frame_bytes()
            };
            let sensors = format!("agent/{}/sensors", a.id);
            let builder =
                frame_service::<SensorHeader>(&node, &svc_name(session, &sensors).map_err(ice)?);
            let mut sensor_attrs = with_channels(&a.channel_layout()).map_err(ice)?;
            if stack_index.is_some() {
                let key =
                    AttributeKey::try_from(ATTR_STACKED).map_err(|e| ice(format!("{e:?}")))?;
                let val = AttributeValue::try_from("1").map_err(|e| ice(format!("{e:?}")))?;
                sensor_attrs = sensor_attrs
                    .define(&key, &val)
                    .map_err(|e| ice(format!("{e:?}")))?;
            }
            let sensor_service = builder
                .create_with_attributes(&sensor_attrs)
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
                stack_index,
                sensor_service,
                sensor_pub,
                motor_service,
                motor_sub,
                initialised: Vec::with_capacity(SENSOR_POOL_SAMPLES * 2),
                served: None,
                departed: None,
                verified: Cell::new(None),
                sole: Cell::new(false),
                motor_from: Cell::new(None),
                process: None,
            });
        }
        let wake = WakeWord::create(session)?;
        // `start` is created last: agents open it first, so once it exists every other
        // service of the session (and the wake word) does too. It has no ports: its
        // attributes are what agents read.
        let start_service = node
            .service_builder(&svc_name(session, "start").map_err(ice)?)
            .event()
            .max_listeners(1)
            .max_notifiers(1)
            .max_nodes(max_ports)
            .create_with_attributes(&attrs)
            .map_err(|e| exists("start", &e))?;
        Ok(Self {
            _node: node,
            // Until connections say otherwise, every agent counts as a process of its own.
            poll: super::PollLength::new(
                config.sync.effective_spin_before_block(config.agents.len()),
            ),
            spin_before_block: config.sync.spin_before_block,
            signals,
            agent_node_names: config
                .agents
                .iter()
                .map(|a| agent_node_name(session, a.id))
                .collect(),
            spin: config.sync.wait == crate::config::WaitMode::Spin,
            spins: 0,
            _start_service: start_service,
            wake,
            _stop_service: stop_service,
            stop,
            notified: vec![false; agents.len()],
            sweep: Cell::new(true),
            polling: false,
            agents,
            stack,
        })
    }

    /// Sets the poll for the processes the agents run in: the connections' processes,
    /// each agent without a known one counted as a process of its own. A vector env
    /// steps all of its agents in one process, so the host may poll while it waits for
    /// their stops (they then need no notification) without taking a core from an agent.
    /// Processes in different PID namespaces may share a number and are then counted as
    /// one (a poll yields between its looks, so such a count costs little).
    fn count_processes(&mut self) {
        let mut known: Vec<i32> = self.agents.iter().filter_map(|p| p.process).collect();
        known.sort_unstable();
        known.dedup();
        let unknown = self.agents.iter().filter(|p| p.process.is_none()).count();
        let processes = known.len() + unknown;
        let spin = crate::config::SyncConfig::spin_for_processes(self.spin_before_block, processes);
        self.poll.set_configured(spin);
        debug!(
            processes,
            ?spin,
            "agent processes counted for the host's poll"
        );
    }

    /// Says on the wake page whether the host polls (agents then leave out their stop
    /// notifications); writes the page only when that changes.
    fn set_polling(&mut self, polling: bool) {
        if self.polling != polling {
            self.wake.set_host_polling(polling);
            self.polling = polling;
        }
    }

    /// Waits on the stop listener for up to `timeout` (zero: takes only what is there),
    /// then takes the notifications already pending too (a pending one would end the
    /// next wait at once), marking the slot of each agent that notified. When none did (a
    /// timeout, a signal, a spurious wake-up), the next drain looks at every queue.
    fn take_notifications(
        &mut self,
        timeout: Duration,
    ) -> Result<(), iceoryx2::port::listener::ListenerWaitError> {
        let Self {
            stop,
            agents,
            notified,
            ..
        } = self;
        let mut woken = false;
        let mut on_event = |e: EventActivation| {
            woken = true;
            mark_notified(agents, notified, e.id.as_value());
        };
        // Under 1 µs (zero included) only a look: see `wait_events`.
        let waited = wait_events(stop, &mut on_event, timeout);
        let _ = stop.try_wait(&mut on_event);
        if !woken {
            self.sweep.set(true);
        }
        waited.map(|_| ())
    }

    /// Whether some agent's motor queue holds a batch (or cannot be read: look).
    fn any_batch_waiting(&self) -> bool {
        self.agents
            .iter()
            .any(|p| p.motor_sub.has_samples().unwrap_or(true))
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
        self.wake.close();
    }
}

fn is_dyn_connected(p: &HostAgentPorts) -> bool {
    use iceoryx2::service::port_factory::PortFactory as _;
    let attached =
        number_of_subscribers(p) > 0 && p.motor_service.dynamic_config().number_of_publishers() > 0;
    let Some(served) = p.served else {
        // Not known by identity: connected when a subscriber other than a departed
        // connection's is attached (listing allocates; only until that one is gone).
        return attached && not_only_departed(p);
    };
    if !attached {
        return false;
    }
    let now = Instant::now();
    if p.verified
        .get()
        .is_some_and(|t| now.saturating_duration_since(t) < IDENTITY_CHECK_PERIOD)
    {
        return true;
    }
    if still_sole(p) {
        p.verified.set(Some(now));
        return true;
    }
    let same = is_attached(p, served);
    if same {
        p.verified.set(Some(now));
    }
    p.sole.set(same && number_of_subscribers(p) == 1);
    same
}

fn number_of_subscribers(p: &HostAgentPorts) -> usize {
    use iceoryx2::service::port_factory::PortFactory as _;
    p.sensor_service.dynamic_config().number_of_subscribers()
}

/// Whether the served connection is still the one attached, told without listing the
/// subscribers (which allocates: in steady state, at 64 agents, a few listings per cycle):
/// the last listing found it alone, one subscriber is attached now, and every motor batch
/// since came from the same publisher. A connection replaced between two looks (the old
/// one's ports removed and a new one attached, so the count is 1 again) is seen at its
/// first batch, whose publisher differs; until then it gets the served connection's frames,
/// as it would during the listing's period.
fn still_sole(p: &HostAgentPorts) -> bool {
    p.sole.get() && number_of_subscribers(p) == 1
}

/// Whether a subscriber other than the departed connection's is (or may be) attached: the
/// rule by which a connection not known by identity counts, for `is_connected` and for a
/// frame's delivery alike.
fn not_only_departed(p: &HostAgentPorts) -> bool {
    p.departed.is_none_or(|d| has_other_subscriber(p, d))
}

/// Whether subscriber `id` is attached to the agent's sensor service.
fn is_attached(p: &HostAgentPorts, id: UniqueSubscriberId) -> bool {
    any_subscriber(p, |s| s == id)
}

/// Whether a subscriber other than `id` is attached to the agent's sensor service.
fn has_other_subscriber(p: &HostAgentPorts, id: UniqueSubscriberId) -> bool {
    any_subscriber(p, |s| s != id)
}

/// Whether an attached sensor subscriber satisfies `pred` (listing stops at the first).
fn any_subscriber(p: &HostAgentPorts, mut pred: impl FnMut(UniqueSubscriberId) -> bool) -> bool {
    use iceoryx2::service::port_factory::PortFactory as _;
    let mut found = false;
    p.sensor_service.dynamic_config().list_subscribers(|d| {
        found = pred(d.subscriber_id);
        if found {
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    found
}

/// The agent's sensor subscriber when exactly one is attached, and its process (the id
/// of the process that created its node). With more (a killed agent's port stays until
/// its dead node is cleaned up, next to its successor's) the connection is not told apart
/// by identity until one is left.
fn sole_subscriber(p: &HostAgentPorts) -> Option<(UniqueSubscriberId, Option<i32>)> {
    use iceoryx2::service::port_factory::PortFactory as _;
    let mut found = None;
    let mut count = 0usize;
    p.sensor_service.dynamic_config().list_subscribers(|d| {
        count += 1;
        let process = d.node_id.pid::<Svc>().ok().map(|pid| pid.value());
        found = Some((d.subscriber_id, process));
        if count > 1 {
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    if count == 1 { found } else { None }
}

impl HostTransport for ShmHost {
    type Loan = ShmFrameLoan;

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
        let block = match (p.stack_index, &mut self.stack) {
            (Some(index), Some(stack)) => Some(stack.block(index, id)?),
            _ => None,
        };
        Ok(ShmFrameLoan { sample, block })
    }

    fn publish(&mut self, slot: usize, frame: ShmFrameLoan) -> Result<bool, HostTransportError> {
        let id = self.agent(slot)?.id;
        let mut processes_changed = false;
        let mut delivered_to_departed = false;
        if frame.block.is_some()
            && let Some(stack) = &mut self.stack
        {
            stack.published(frame.sample.user_header().cycle);
        }
        let ShmFrameLoan { sample, block } = frame;
        // The block is written: its loan ends here (the stacked sample goes at start).
        drop(block);
        let delivered =
            sample
                .send()
                .map(|receivers| receivers > 0)
                .map_err(|e| HostTransportError::Send {
                    what: format!("the sensor frame of agent {id}"),
                    reason: format!("{e:?}"),
                })?;
        // The frame went to the subscriber attached now: it is the connection served (as
        // listing allocates, looked up again only when the identity check is due).
        if delivered && let Some(p) = self.agents.get_mut(slot) {
            let now = Instant::now();
            let due = p
                .verified
                .get()
                .is_none_or(|t| now.saturating_duration_since(t) >= IDENTITY_CHECK_PERIOD);
            if p.served.is_some() && due && still_sole(p) {
                p.verified.set(Some(now));
            } else if p.served.is_none() || due {
                let sole = sole_subscriber(p).filter(|&(s, _)| Some(s) != p.departed);
                let process = sole.and_then(|(_, process)| process);
                p.served = sole.map(|(s, _)| s);
                if p.served.is_some() {
                    p.departed = None;
                }
                if p.process != process {
                    p.process = process;
                    processes_changed = true;
                }
                p.sole.set(p.served.is_some());
                p.verified.set(Some(now));
            }
            // Only the ports of a connection that left got it, in the moment before they
            // close: not a new connection, so not delivered (as `is_connected` says).
            delivered_to_departed = p.served.is_none() && !not_only_departed(p);
        }
        if processes_changed {
            self.count_processes();
        }
        Ok(delivered && !delivered_to_departed)
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        // Before the wake-up: an agent woken finds its cycle's stacked sample there.
        if let Some(stack) = &mut self.stack {
            stack.send()?;
        }
        self.wake.bump();
        self.sweep.set(true);
        Ok(())
    }

    /// Over shared memory a batch has arrived once its agent's *stop* (or *leave*)
    /// notification has: agents notify after publishing. So a drain looks at the queues
    /// of the agents that notified since the last one, and at every queue when batches
    /// may have come without a notification: while the host polls (agents then leave
    /// the notification out), at each cycle's first drain, after a wait that ended
    /// without one, and after an agent was found disconnected.
    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        let sweep = self.sweep.replace(false) || self.polling;
        for ((slot, p), notified) in self.agents.iter().enumerate().zip(&mut self.notified) {
            if !core::mem::take(notified) && !sweep {
                continue;
            }
            loop {
                match p.motor_sub.receive() {
                    Ok(Some(sample)) => {
                        let from = sample.origin();
                        if p.motor_from.replace(Some(from)).is_some_and(|f| f != from) {
                            // Another connection's batch: list the subscribers again
                            // at the next check.
                            p.sole.set(false);
                            p.verified.set(None);
                        }
                        sink(slot, sample.user_header(), sample.payload());
                    }
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
}

impl HostReadiness for ShmHost {
    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        if self.spin {
            // Busy-poll: the caller drains the subscribers again right away. Check for a
            // termination request now and then only (it costs a syscall).
            let _ = timeout;
            // The host never sleeps on the stop listener: agents need not notify.
            self.set_polling(true);
            std::hint::spin_loop();
            self.spins = self.spins.wrapping_add(1);
            if self.spins.is_multiple_of(4096) && self.signals.termination_requested() {
                return Err(HostTransportError::Terminated);
            }
            return Ok(());
        }
        // Poll the subscribers briefly first: a quick answer is then seen without paying
        // for a sleep and a wake-up (see `spin_before_block_us`).
        // While it polls, agents leave out their *stop* notifications (the flag stays set
        // while the host works on what it found: it polls again before it sleeps).
        let window = self.poll.window(timeout);
        if !window.is_empty() {
            self.set_polling(true);
            loop {
                if self.any_batch_waiting() {
                    self.poll.record(window.elapsed());
                    return Ok(());
                }
                if !window.pause() {
                    break;
                }
            }
        }
        if self.polling {
            // About to sleep: agents notify again from here on. A batch published before
            // an agent saw the flag cleared is found by this last look (also when the
            // poll was just turned off: more processes than cores).
            self.set_polling(false);
            if self.any_batch_waiting() {
                self.sweep.set(true);
                self.poll.record(window.elapsed());
                return Ok(());
            }
        }
        match self.take_notifications(timeout) {
            Ok(()) => {}
            Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
            Err(e) => {
                return Err(HostTransportError::Wait {
                    reason: format!("stop listener: {e:?}"),
                });
            }
        }
        if !timeout.is_zero() {
            // A look without a wait (zero timeout) says nothing of how long answers take.
            self.poll.record(window.elapsed());
        }
        if self.signals.termination_requested() {
            return Err(HostTransportError::Terminated);
        }
        Ok(())
    }

    fn activity_fd(&self) -> std::os::fd::RawFd {
        // SAFETY: the descriptor stays owned by the listener; it is only polled.
        unsafe { self.stop.file_descriptor().native_handle() }
    }

    fn after_wait(&mut self) {
        let _ = self.take_notifications(Duration::ZERO);
    }
}

impl HostConnections for ShmHost {
    fn is_connected(&self, slot: usize) -> bool {
        let connected = self.agents.get(slot).is_some_and(is_dyn_connected);
        if !connected {
            // A connection that went away may have left a batch (its leave) that the
            // host was not notified of: the next drain looks at every queue.
            self.sweep.set(true);
        }
        connected
    }

    fn forget_connection(&mut self, slot: usize) {
        let mut left = false;
        if let Some(p) = self.agents.get_mut(slot) {
            p.departed = p
                .served
                .take()
                .or_else(|| sole_subscriber(p).map(|(s, _)| s));
            left = p.process.take().is_some();
            p.verified.set(None);
            p.sole.set(false);
        }
        if left {
            self.count_processes();
        }
    }

    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        let names = &self.agent_node_names;
        for_each_dead_node(|view, name| {
            if let Some(slot) = names.iter().position(|n| n == name) {
                // Removes its ports from our services: its sample loans come back and a
                // restarted agent with the same id can attach.
                let cleaned = view.try_remove_stale_resources().is_ok();
                debug!(slot, cleaned, "dead agent node found");
                dead.push(slot);
            }
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
}

#[cfg(test)]
mod tests;
