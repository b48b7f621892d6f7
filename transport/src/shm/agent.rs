//! The shared-memory transport's agent side: opens the session's services, receives the
//! newest sample, publishes batches and notifies stop.

use super::*;
// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

/// A received sensor frame in shared memory, owned by the agent until dropped.
pub struct ShmFrame {
    sample: Sample<Svc, [u8], SensorHeader>,
    /// A stacked agent's payload: its block of the cycle's stacked sample.
    block: Option<(std::rc::Rc<StackSample>, core::ops::Range<usize>)>,
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
        match &self.block {
            Some((stack, range)) => stack.payload().get(range.clone()).unwrap_or(&[]),
            None => self.sample.payload(),
        }
    }

    /// The stacked sample this frame's payload is in, and the payload's place in it
    /// (`[transport.shm] stacked_images`); `None` for a payload of its own.
    pub fn stacked(&self) -> Option<(&std::rc::Rc<StackSample>, core::ops::Range<usize>)> {
        self.block.as_ref().map(|(s, r)| (s, r.clone()))
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
    wake: WakeWord,
    /// The wake word's value at the last `discard_wakeups` or wake.
    seen: u32,
    _stop_service: event_factory::PortFactory<Svc>,
    stop: Notifier<Svc>,
    _sensor_service: ps_factory::PortFactory<Svc, [u8], SensorHeader>,
    sensor_sub: Subscriber<Svc, [u8], SensorHeader>,
    _motor_service: ps_factory::PortFactory<Svc, [MotorCommand], MotorHeader>,
    motor_pub: Publisher<Svc, [MotorCommand], MotorHeader>,
    /// This agent's block of the stacked sample, if the host puts its payload there (see
    /// [`ShmStack`]).
    stack_index: Option<usize>,
    /// The stacked sample's reader and this agent's block in it, once joined.
    stack: Option<(SharedStack, usize)>,
    /// A stacked agent's header whose stacked sample had not come yet.
    pending: Option<Sample<Svc, [u8], SensorHeader>>,
    max_commands: usize,
    spin: bool,
    poll: super::PollLength,
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

pub(super) fn attr(attrs: &AttributeSet, key: &str) -> String {
    AttributeKey::try_from(key)
        .ok()
        .and_then(|k| attrs.key_value(&k, 0).map(|v| v.to_string()))
        .unwrap_or_else(|| "unknown".into())
}

/// The host's protocol version and layout hash, as the start service's attributes carry
/// them, against this agent's.
fn check_host_version(attrs: &AttributeSet, session: &str) -> Result<(), AgentConnectError> {
    let host_protocol = attr(attrs, ATTR_PROTOCOL);
    let host_layout = attr(attrs, ATTR_LAYOUT);
    let agent_layout = format!("{LAYOUT_HASH:016x}");
    if host_protocol != PROTOCOL_VERSION.to_string() || host_layout != agent_layout {
        return Err(AgentConnectError::VersionMismatch {
            session: session.to_owned(),
            host_protocol,
            host_layout,
            agent_protocol: PROTOCOL_VERSION,
            agent_layout,
        });
    }
    Ok(())
}

/// The host's channels for this agent, as its sensor service's attributes carry them,
/// against this agent's config.
fn check_channels(
    attrs: &AttributeSet,
    config: &Config,
    session: &str,
    agent: u32,
) -> Result<(), AgentConnectError> {
    let ours = config.channel_layout_of(agent);
    let Some(host) = channels_of(attrs) else {
        return Err(AgentConnectError::Transport {
            session: session.to_owned(),
            agent,
            detail: "the host's sensor service carries no readable channel layout".into(),
        });
    };
    match AgentConnectError::channel_mismatch(session, agent, &host, &ours) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The agent ids whose sensor service exists in `session` (the ids its host serves),
/// ascending.
fn served_agent_ids(session: &str) -> Vec<u32> {
    let prefix = service_name(session, "agent/");
    let mut ids = Vec::new();
    let _ = Svc::list(iceoryx2_config(), |info| {
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
    /// Makes this stacked agent's frames take their payload from `stack`'s samples
    /// (`[transport.shm] stacked_images`): the agents of one group share one reader.
    ///
    /// # Errors
    /// [`AgentConnectError::Transport`] if the host does not stack this agent, or
    /// `stack` is another session's.
    pub fn join_stack(&mut self, stack: &SharedStack) -> Result<(), AgentConnectError> {
        let fail = |detail: String| AgentConnectError::Transport {
            session: self.session.clone(),
            agent: self.id,
            detail,
        };
        let Some(index) = self.stack_index else {
            return Err(fail("the host does not stack this agent's payload".into()));
        };
        if stack.borrow().session() != self.session {
            return Err(fail(format!(
                "the stacked sample's reader is session {:?}'s",
                stack.borrow().session()
            )));
        }
        self.stack = Some((std::rc::Rc::clone(stack), index));
        Ok(())
    }

    /// The stacked sample's reader this agent joined ([`Self::join_stack`]).
    pub fn stack(&self) -> Option<&SharedStack> {
        self.stack.as_ref().map(|(s, _)| s)
    }

    /// Whether this agent's payload comes in the session's stacked sample.
    pub fn is_stacked(&self) -> bool {
        self.stack_index.is_some()
    }

    /// The newest sample of the subscriber, if one is there.
    fn receive_sample(
        &mut self,
    ) -> Result<Option<Sample<Svc, [u8], SensorHeader>>, AgentReceiveError> {
        // The subscriber's queue holds one frame (`SENSOR_QUEUE`; a newer one replaces
        // it): what it holds is the newest, and one look is enough.
        const _: () = assert!(SENSOR_QUEUE == 1);
        match self.sensor_sub.receive() {
            Ok(sample) => Ok(sample),
            Err(iceoryx2::port::ReceiveError::ExceedsMaxBorrows) => {
                Err(AgentReceiveError::TooManyFramesHeld {
                    max: AGENT_BORROWED_FRAMES,
                })
            }
            Err(other) => Err(AgentReceiveError::Transport(format!("iceoryx2: {other:?}"))),
        }
    }

    /// A stacked agent's newest frame: its header, with its block of the stacked sample
    /// of the same cycle. The host publishes the headers first and sends the stacked
    /// sample at *start*: a header whose stacked sample has not come is kept until it
    /// has; one whose stacked sample was replaced by a newer cycle's (the agent read too
    /// late) is skipped.
    fn receive_stacked(&mut self) -> Result<Option<ShmFrame>, AgentReceiveError> {
        let Some((stack, index)) = self.stack.clone() else {
            return Err(AgentReceiveError::Transport(format!(
                "agent {}'s images come in the session's stacked sample ([transport.shm] \
                 stacked_images): read it through a group that drives every stacked agent \
                 (vrsync.AgentGroup, VrsyncVectorEnv; in Rust `ShmAgent::join_stack`)",
                self.id
            )));
        };
        // A newer header replaces a kept one (released first: the kept one counts
        // against the agent's borrowed frames).
        if self.pending.is_some() && self.has_header() {
            self.pending = None;
        }
        for _ in 0..2 {
            let header = match self.pending.take() {
                Some(h) => h,
                None => match self.receive_sample()? {
                    Some(h) => h,
                    None => return Ok(None),
                },
            };
            let mut s = stack.borrow_mut();
            let looked = match s.lookup(header.user_header().cycle) {
                Ok(looked) => looked,
                Err(e) => {
                    // Too many stacked samples held: the header waits for the next try.
                    self.pending = Some(header);
                    return Err(e);
                }
            };
            match looked {
                StackLookup::Found(sample) => {
                    let range = s.block_range(index);
                    return Ok(Some(ShmFrame {
                        sample: header,
                        block: Some((sample, range)),
                    }));
                }
                StackLookup::NotYet => {
                    self.pending = Some(header);
                    return Ok(None);
                }
                // The newer cycle's header came before its stacked sample: look again.
                StackLookup::Gone => {}
            }
        }
        Ok(None)
    }

    /// Whether the host's "session closed" event was ever seen (sticky: a call that
    /// returned a frame may have consumed it).
    pub fn shutdown_seen(&self) -> bool {
        self.shutdown_seen
    }

    /// Whether a frame is waiting (cheap, non-blocking): a new header, or for a kept
    /// header of a stacked agent, a new stacked sample.
    pub fn has_frame(&self) -> bool {
        self.has_header()
            || (self.pending.is_some()
                && self
                    .stack
                    .as_ref()
                    .is_some_and(|(s, _)| s.borrow().has_sample()))
    }

    /// Whether a new header (a frame's sample) is waiting.
    fn has_header(&self) -> bool {
        self.sensor_sub.has_samples().unwrap_or(true)
    }

    /// Whether this agent busy-polls (`[sync] wait = "spin"`).
    pub fn spins(&self) -> bool {
        self.spin
    }

    /// The state of the host's node.
    fn host_node_state(&self) -> HostState {
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
}

impl AgentFrame for ShmFrame {
    fn header(&self) -> &SensorHeader {
        self.sample.user_header()
    }

    fn payload(&self) -> &[u8] {
        ShmFrame::payload(self)
    }
}

impl AgentTransport for ShmAgent {
    type Frame = ShmFrame;

    fn connect(
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
        check_host_version(start_service.attributes(), session)?;
        let wake = WakeWord::open(session).map_err(|e| ice(e.to_string()))?;

        let sensors = format!("agent/{id}/sensors");
        let motor = format!("agent/{id}/motor");
        // `start` is created last by the host: once it exists, a missing service of this
        // agent means the host does not serve this id.
        let open_err = |what: &str, e: &dyn IceError| {
            if e.does_not_exist() {
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
                ice(format!(
                    "cannot open {}: {e:?}",
                    service_name(session, what)
                ))
            }
        };
        let sensor_service = node
            .service_builder(&svc_name(session, &sensors).map_err(ice)?)
            .publish_subscribe::<[u8]>()
            .user_header::<SensorHeader>()
            .open()
            .map_err(|e| open_err(&sensors, &e))?;
        check_channels(sensor_service.attributes(), config, session, id)?;
        let stacked = attr(sensor_service.attributes(), ATTR_STACKED) == "1";
        let stack_index = stack_index(config, id);
        if stacked != stack_index.is_some() {
            return Err(ice(format!(
                "the host {} this agent's payload ([transport.shm] stacked_images), this \
                 config {}: host and agent read different configs",
                if stacked { "stacks" } else { "does not stack" },
                if stacked { "does not" } else { "does" },
            )));
        }
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

        let in_use = |e: &dyn IceError| {
            if e.port_limit_reached() {
                AgentConnectError::IdInUse {
                    session: session.clone(),
                    agent: id,
                }
            } else {
                ice(format!("{e:?}"))
            }
        };
        let max_commands = config.transport.max_commands_per_cycle as usize;
        // Order matters: the host treats the agent as connected once the sensor subscriber
        // exists, so everything else (stop notifier, motor publisher) is created first.
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
            seen: wake.value(),
            wake,
            _stop_service: stop_service,
            stop,
            _sensor_service: sensor_service,
            sensor_sub,
            _motor_service: motor_service,
            motor_pub,
            stack_index,
            stack: None,
            pending: None,
            max_commands,
            spin: config.sync.wait == crate::config::WaitMode::Spin,
            poll: super::PollLength::new(
                config.sync.effective_spin_before_block(config.agents.len()),
            ),
            shutdown_seen: false,
        })
    }

    fn try_receive_newest(&mut self) -> Result<Option<ShmFrame>, AgentReceiveError> {
        if self.stack_index.is_some() {
            return self.receive_stacked();
        }
        Ok(self.receive_sample()?.map(|sample| ShmFrame {
            sample,
            block: None,
        }))
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
            self.shutdown_seen |= self.wake.closed();
            return;
        }
        // Poll for a frame first (`spin_before_block_us`, or longer: see `PollLength`).
        let window = self.poll.window(timeout);
        if !window.is_empty() {
            loop {
                if self.has_frame() {
                    self.poll.record(window.elapsed());
                    return;
                }
                if !window.pause() {
                    break;
                }
            }
        }
        // A frame published since the last `discard_wakeups` (or wake) has bumped the word
        // past `seen`: the sleep then ends at once.
        self.seen = self.wake.wait_change(self.seen, timeout);
        self.poll.record(window.elapsed());
        self.shutdown_seen |= self.wake.closed();
    }

    fn discard_wakeups(&mut self) {
        self.seen = self.wake.value();
        self.shutdown_seen |= self.wake.closed();
    }

    fn host_liveness(&mut self, check_process: bool) -> HostLiveness {
        if self.shutdown_seen {
            return HostLiveness::Closed;
        }
        if !check_process {
            return HostLiveness::Alive;
        }
        match self.host_node_state() {
            HostState::Alive => HostLiveness::Alive,
            state => {
                // The close may have raced with the node's removal: look once more before
                // calling the host gone.
                self.shutdown_seen |= self.wake.closed();
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

    /// Publishes the batch and, if it carries the stop or the leave flag, notifies *stop*
    /// (unless the host polls the motor queues: see [`WakeWord::host_polling`]): the host
    /// drains the queues of the agents that notified.
    fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), AgentSendError> {
        let fail = AgentSendError::Transport;
        let n = commands.len().min(self.max_commands);
        let mut sample = self
            .motor_pub
            .loan_slice_uninit(n)
            .map_err(|e| fail(format!("cannot loan a motor batch: {e:?}")))?;
        *sample.user_header_mut() = MotorHeader {
            command_count: n as u32,
            ..*header
        };
        let sample = sample.write_from_slice(&commands[..n]);
        sample
            .send()
            .map_err(|e| fail(format!("cannot send the motor batch: {e:?}")))?;
        // No notification while the host polls the motor queues itself: it finds the batch
        // (one system call less per agent and cycle; see `WakeWord::set_host_polling`).
        if (header.is_stop() || header.is_leave()) && !self.wake.host_polling() {
            self.stop
                .notify()
                .map_err(|e| fail(format!("cannot notify stop: {e:?}")))?;
        }
        Ok(())
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }
}
