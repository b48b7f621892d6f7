//! The agent: connect, wait for *start*, read the frame, send commands, stop.

use std::time::{Duration, Instant};

pub use vrsync_transport::HOST_LIVENESS_PERIOD;
pub use vrsync_transport::shm::{SharedStack, ShmStack, StackSample};
use vrsync_transport::{
    ActionState, ActionStatus, Collision, Command, ImageDesc, MOTOR_FLAG_ACK, MOTOR_FLAG_LEAVE,
    MOTOR_FLAG_STOP, MotorCommand, MotorHeader, PROTOCOL_VERSION, PixelFormat, Pose, SensorHeader,
};
pub use vrsync_transport::{AgentConnectError, SignalHandling};
use vrsync_transport::{
    AgentFrame, AgentReceiveError, AgentSendError, AgentTransport, AgentWaitError, HostLiveness,
    wait_for_newer_frame,
};
use vrsync_transport::{AnyAgent, AnyFrame};
use vrsync_transport::{Config, WaitForStop};

/// Why [`Agent::wait_start`] returned without a frame.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WaitStartError {
    /// No new frame before the timeout.
    #[error(
        "no start from the host within {} ({})",
        crate::log::Rounded(*.waited),
        match .last_cycle {
            Some(cycle) => format!("last cycle seen: {cycle}"),
            None => "no frame received yet".to_owned(),
        }
    )]
    Timeout {
        /// How long we waited.
        waited: Duration,
        /// The last cycle received, if any.
        last_cycle: Option<u64>,
    },
    /// The host closed the session (a clean end of the run).
    #[error("the host closed the session")]
    HostClosed,
    /// The host is gone without closing the session: its process crashed or was killed,
    /// or the link to it broke (`reason` says which the transport saw).
    #[error("the host is gone without closing session {session:?}: {reason}")]
    HostGone {
        /// The session.
        session: String,
        /// What the transport saw: "its process died", "connection closed without
        /// shutdown", "the host's zenoh liveliness token vanished (...)", ...
        reason: String,
    },
    /// The frame violates the protocol (corrupt image table, wrong agent, wrong version).
    #[error("invalid sensor frame for cycle {cycle}: {reason}")]
    BadFrame {
        /// The frame's cycle.
        cycle: u64,
        /// What is wrong.
        reason: String,
    },
    /// The caller still holds `max` frames of earlier cycles (or views into them), the
    /// most an agent may hold at once: no newer frame can be received.
    #[error(
        "cannot receive a new frame while {max} earlier frames are still held: drop the frames \
         (and any arrays or views into their images) you keep, or copy what you need from a \
         frame before waiting for the next one"
    )]
    TooManyFramesHeld {
        /// How many frames an agent may hold at once.
        max: usize,
    },
    /// Receiving failed.
    #[error("cannot receive the sensor frame: {0}")]
    Receive(String),
    /// SIGINT/SIGTERM arrived (only with [`SignalHandling::Install`]).
    #[error("termination requested")]
    Terminated,
}

/// Why a command could not be queued.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SendError {
    /// More than `max_commands_per_cycle` commands this cycle.
    #[error("more than {max} commands in one cycle")]
    QueueFull {
        /// The limit from the config.
        max: usize,
    },
}

/// Why [`Agent::stop`] failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StopError {
    /// No frame was received yet, so there is no cycle to stop.
    #[error("stop before the first frame: call wait_start first")]
    NoFrame,
    /// This cycle was already stopped.
    #[error("cycle {cycle} was already stopped")]
    AlreadyStopped {
        /// The cycle.
        cycle: u64,
    },
    /// The host closed the session before the stop could be sent (a normal end of a run).
    #[error("the host closed the session")]
    HostClosed,
    /// The transport failed.
    #[error("cannot send the stop: {0}")]
    Transport(String),
}

/// One image of a frame: a view straight into shared memory.
#[derive(Debug, Clone, Copy)]
pub struct Image<'a> {
    desc: ImageDesc,
    data: &'a [u8],
}

impl<'a> Image<'a> {
    /// The camera name (`left`, `right`, …).
    pub fn name(&self) -> &str {
        self.desc.name()
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.desc.width_px
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.desc.height_px
    }
    /// Bytes per row.
    pub fn stride(&self) -> usize {
        self.desc.stride_bytes as usize
    }
    /// Pixel format.
    pub fn format(&self) -> PixelFormat {
        // Validated when the frame was received.
        self.desc.pixel_format().unwrap_or_default()
    }
    /// All bytes, row-major, origin top-left.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
    /// Row `y` (`stride()` bytes), or `None` past the last row.
    pub fn row(&self, y: u32) -> Option<&'a [u8]> {
        let s = self.stride();
        self.data.get(y as usize * s..(y as usize + 1) * s)
    }
    /// The bytes of pixel (`x`, `y`), or `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<&'a [u8]> {
        if x >= self.width() {
            return None;
        }
        let bpp = self.format().bytes_per_pixel();
        self.row(y)?.get(x as usize * bpp..(x as usize + 1) * bpp)
    }
    /// The raw description from the header.
    pub fn desc(&self) -> &ImageDesc {
        &self.desc
    }
}

/// A sensor frame: the header and the images, in shared memory, read-only. Valid as long
/// as you hold it; the host never overwrites it. Drop it before the next
/// [`Agent::wait_start`] (an agent may hold at most two frames).
#[derive(Debug)]
pub struct Frame {
    inner: AnyFrame,
    /// Index of the first status (collision) of the header that this frame hands out.
    new_statuses: usize,
    new_collisions: usize,
}

impl Frame {
    /// The header with every scalar sensor.
    pub fn header(&self) -> &SensorHeader {
        self.inner.header()
    }
    /// Cycle number.
    pub fn cycle(&self) -> u64 {
        self.header().cycle
    }
    /// Simulated time at the start of this cycle.
    pub fn sim_time(&self) -> Duration {
        Duration::from_nanos(self.header().sim_time_ns)
    }
    /// Body pose.
    pub fn pose(&self) -> Pose {
        self.header().pose
    }
    /// The action statuses this frame brings, in the order the host reported them: each
    /// status reaches the agent's code exactly once, in the first frame the agent reads
    /// after the host reported it, even when the frames in between were skipped (the host
    /// repeats every status until the agent acknowledges a frame that carried it; the
    /// header's own table, [`SensorHeader::statuses`], holds the repeats too). The latest
    /// status of every action is also in [`Agent::action_state`].
    pub fn statuses(&self) -> &[ActionStatus] {
        self.header()
            .statuses()
            .get(self.new_statuses..)
            .unwrap_or(&[])
    }
    /// The collisions this frame brings, each exactly once (as [`Frame::statuses`]).
    pub fn collisions(&self) -> &[Collision] {
        self.header()
            .collisions()
            .get(self.new_collisions..)
            .unwrap_or(&[])
    }
    /// Number of images.
    pub fn image_count(&self) -> usize {
        self.header().image_descs().len()
    }
    /// Image `i`.
    pub fn image(&self, i: usize) -> Option<Image<'_>> {
        let desc = *self.header().image_descs().get(i)?;
        let data = self
            .inner
            .payload()
            .get(desc.offset as usize..(desc.offset + desc.len) as usize)?;
        Some(Image { desc, data })
    }
    /// The image of the camera called `name`.
    pub fn image_by_name(&self, name: &str) -> Option<Image<'_>> {
        (0..self.image_count())
            .filter_map(|i| self.image(i))
            .find(|img| img.name() == name)
    }
    /// All images in camera order.
    pub fn images(&self) -> impl Iterator<Item = Image<'_>> {
        (0..self.image_count()).filter_map(|i| self.image(i))
    }
}

fn validate(header: &SensorHeader, payload_len: usize, id: u32) -> Result<(), String> {
    if header.protocol_version != PROTOCOL_VERSION {
        return Err(format!(
            "protocol version {} (expected {PROTOCOL_VERSION})",
            header.protocol_version
        ));
    }
    if header.agent_id != id {
        return Err(format!(
            "frame is for agent {}, we are agent {id}",
            header.agent_id
        ));
    }
    fn ascending(seqs: impl Iterator<Item = u64>) -> bool {
        let mut last = 0;
        seqs.into_iter()
            .all(|seq| core::mem::replace(&mut last, seq) < seq)
    }
    if !ascending(header.statuses().iter().map(|s| s.seq))
        || !ascending(header.collisions().iter().map(|c| c.seq))
    {
        return Err("event sequence numbers are not ascending from 1".into());
    }
    if header.image_count as usize > header.images.len() {
        return Err(format!(
            "image_count {} exceeds the table",
            header.image_count
        ));
    }
    for d in header.image_descs() {
        let fmt = d
            .pixel_format()
            .ok_or_else(|| format!("image {}: unknown pixel format {}", d.camera, d.format))?;
        let min_stride = u64::from(d.width_px) * fmt.bytes_per_pixel() as u64;
        let end = d.offset.checked_add(d.len);
        if u64::from(d.stride_bytes) < min_stride
            || d.len < u64::from(d.stride_bytes) * u64::from(d.height_px)
            || end.is_none_or(|e| e > payload_len as u64)
        {
            return Err(format!(
                "image {} ({}x{} stride {} at {}+{}) does not fit the {payload_len}-byte payload",
                d.camera, d.width_px, d.height_px, d.stride_bytes, d.offset, d.len
            ));
        }
    }
    Ok(())
}

/// A receive failure as [`Agent::wait_start`] reports it (`last_cycle`: the newest cycle
/// received before).
fn receive_error(e: AgentReceiveError, last_cycle: Option<u64>) -> WaitStartError {
    match e {
        AgentReceiveError::TooManyFramesHeld { max } => WaitStartError::TooManyFramesHeld { max },
        AgentReceiveError::Protocol(reason) => WaitStartError::BadFrame {
            cycle: last_cycle.map_or(0, |c| c + 1),
            reason,
        },
        other => WaitStartError::Receive(other.to_string()),
    }
}

/// Builds an [`Agent`].
#[derive(Debug)]
pub struct AgentBuilder<'c> {
    config: &'c Config,
    id: u32,
    connect_timeout: Option<Duration>,
    signals: SignalHandling,
    stack: Option<SharedStack>,
}

impl<'c> AgentBuilder<'c> {
    /// An agent with id `id` in the session of `config`.
    pub fn new(config: &'c Config, id: u32) -> Self {
        Self {
            config,
            id,
            connect_timeout: None,
            signals: SignalHandling::default(),
            stack: None,
        }
    }

    /// The reader of the session's stacked sample this agent shares with the other
    /// agents of its group (`[transport.shm] stacked_images`; see [`Agent::stack`]). An
    /// agent whose payload is stacked and that is given none opens its own reader: the
    /// stacked sample has one reader, so that works for the one process that drives the
    /// stacked agents. Ignored for an agent whose payload is not stacked.
    pub fn stack(mut self, stack: &SharedStack) -> Self {
        self.stack = Some(SharedStack::clone(stack));
        self
    }

    /// Whether the agent installs SIGINT/SIGTERM handlers. Default:
    /// [`SignalHandling::Leave`]: the process keeps its own handlers (a Python
    /// interpreter's Ctrl-C, Unity's) and [`WaitStartError::Terminated`] is never
    /// returned. Programs that own their process choose [`SignalHandling::Install`]. No
    /// config key.
    pub fn signal_handling(mut self, signals: SignalHandling) -> Self {
        self.signals = signals;
        self
    }

    /// How long [`AgentBuilder::connect`] waits for the host to appear. Default: the
    /// config's `sync.connect_timeout` (30 s unless set).
    pub fn connect_timeout(mut self, timeout: Duration) -> Self {
        self.connect_timeout = Some(timeout);
        self
    }

    /// Connects, waiting for the host's services until the connect timeout. Right after
    /// an agent of the same id and session left in this process ([`Agent::close`]), an
    /// "id in use" answer is retried for up to [`REJOIN_GRACE`]: the host may not have
    /// read that leave yet.
    ///
    /// # Errors
    /// [`AgentConnectError`]: no host, protocol mismatch, id already in use.
    pub fn connect(self) -> Result<Agent, AgentConnectError> {
        let started = Instant::now();
        let timeout = self
            .connect_timeout
            .unwrap_or(self.config.sync.connect_timeout);
        let mut backoff = Duration::from_millis(2);
        loop {
            let left = timeout.saturating_sub(started.elapsed());
            match self.connect_once(left) {
                Err(AgentConnectError::IdInUse { session, agent })
                    if left_recently(&session, agent)
                        .is_some_and(|at| at.elapsed() < REJOIN_GRACE)
                        && started.elapsed() + backoff < timeout =>
                {
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(Duration::from_millis(50));
                }
                other => return other,
            }
        }
    }

    fn connect_once(&self, timeout: Duration) -> Result<Agent, AgentConnectError> {
        // The agent's own transport (`[[agent]] transport`), else `[transport] kind`.
        let mut backend = AnyAgent::connect(self.config, self.id, timeout, self.signals)?;
        if let AnyAgent::Shm(shm) = &mut backend
            && shm.is_stacked()
        {
            let stack = match &self.stack {
                Some(stack) => SharedStack::clone(stack),
                None => SharedStack::new(std::cell::RefCell::new(ShmStack::open(self.config)?)),
            };
            shm.join_stack(&stack)?;
        }
        let max = self.config.transport.max_commands_per_cycle as usize;
        Ok(Agent {
            id: self.id,
            session: self.config.session.clone(),
            wait_for_stop: self.config.wait_for_stop(self.id),
            sync_mode: self.config.sync.sync_mode,
            host_waits_without_limit: self.config.waits_for_live_agents(),
            backend,
            queue: Vec::with_capacity(max),
            max_commands: max,
            last_cycle: None,
            stopped_cycle: None,
            next_action_id: 1,
            frames_skipped: 0,
            next_liveness: Instant::now() + HOST_LIVENESS_PERIOD,
            last_event_seq: 0,
            action_states: ActionStates::with_capacity(ACTION_STATES_CAPACITY),
            closed: false,
            channels: Channels::new(self.config.agent(self.id)),
        })
    }
}

/// How long after an agent left ([`Agent::close`]) a new connection of the same id and
/// session in the same process retries when the host still calls the id in use (the host
/// reads the leave at its next wait).
pub const REJOIN_GRACE: Duration = Duration::from_secs(5);

/// (session, agent id, when it left) of agents that left in this process, newest last;
/// bounded (the oldest entries go).
static LEFT: std::sync::Mutex<Vec<(String, u32, Instant)>> = std::sync::Mutex::new(Vec::new());

/// How many entries [`LEFT`] keeps.
const LEFT_KEPT: usize = 64;

fn note_left(session: &str, agent: u32) {
    let mut left = LEFT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    left.retain(|(s, a, _)| !(s == session && *a == agent));
    if left.len() >= LEFT_KEPT {
        left.remove(0);
    }
    left.push((session.to_owned(), agent, Instant::now()));
}

fn left_recently(session: &str, agent: u32) -> Option<Instant> {
    let left = LEFT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    left.iter()
        .find(|(s, a, _)| s == session && *a == agent)
        .map(|e| e.2)
}

/// A connected agent.
#[derive(Debug)]
pub struct Agent {
    id: u32,
    session: String,
    wait_for_stop: WaitForStop,
    sync_mode: bool,
    host_waits_without_limit: bool,
    backend: AnyAgent,
    queue: Vec<MotorCommand>,
    max_commands: usize,
    last_cycle: Option<u64>,
    stopped_cycle: Option<u64>,
    next_action_id: u32,
    frames_skipped: u64,
    next_liveness: Instant,
    /// The highest event sequence number handed out.
    last_event_seq: u64,
    action_states: ActionStates,
    /// The leave was sent ([`Agent::close`]).
    closed: bool,
    /// Its vectors and actions, as its config declares them.
    channels: Channels,
}

/// How many actions [`Agent::action_state`] remembers; beyond, the one whose status came
/// earliest is forgotten (a finished or aborted one first).
pub const ACTION_STATES_CAPACITY: usize = 1024;

impl Agent {
    /// Connects agent `id` with the config's connect timeout (see [`AgentBuilder`]).
    ///
    /// # Errors
    /// [`AgentConnectError`].
    pub fn connect(config: &Config, id: u32) -> Result<Self, AgentConnectError> {
        AgentBuilder::new(config, id).connect()
    }

    /// This agent's id.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The reader of the session's stacked sample this agent's frames take their payload
    /// from (`[transport.shm] stacked_images`), to share with the other agents of a group
    /// ([`AgentBuilder::stack`]); `None` if its payload is not stacked.
    pub fn stack(&self) -> Option<&SharedStack> {
        match &self.backend {
            AnyAgent::Shm(shm) => shm.stack(),
            _ => None,
        }
    }

    /// The frame's stacked sample and its payload's place there (`[transport.shm]
    /// stacked_images`); `None` if its payload is its own.
    pub fn stacked_payload(
        frame: &Frame,
    ) -> Option<(&std::rc::Rc<StackSample>, core::ops::Range<usize>)> {
        match &frame.inner {
            AnyFrame::Shm(f) => f.stacked(),
            _ => None,
        }
    }

    /// How long the host waits for this agent's stop (its `[[agent]] wait_for_stop`, else
    /// `[sync] wait_for_stop`): with [`WaitForStop::Alive`] (the default) a busy agent never
    /// costs a stop timeout in sync mode, however long it computes between
    /// [`Agent::wait_start`] and [`Agent::stop`]; with [`WaitForStop::Timeout`] the cycle
    /// ends without it after `stop_timeout`.
    pub fn wait_for_stop(&self) -> WaitForStop {
        self.wait_for_stop
    }

    /// Whether the host never ends a cycle without this agent while it is alive (sync
    /// mode and [`WaitForStop::Alive`]): then its stop is never late and no frame is
    /// skipped, however long it computes.
    pub fn host_waits_for_me(&self) -> bool {
        self.sync_mode && self.wait_for_stop == WaitForStop::Alive
    }

    /// Whether the host may wait without limit for some agent of the session (sync mode and
    /// an agent with [`WaitForStop::Alive`]): a wait for the next frame should then not
    /// give up after a time derived from `stop_timeout` (pass `None` to
    /// [`Agent::wait_start`]; a dead host is detected anyway).
    pub fn host_may_wait_without_limit(&self) -> bool {
        self.host_waits_without_limit
    }

    /// The cycle of the newest frame received.
    pub fn last_cycle(&self) -> Option<u64> {
        self.last_cycle
    }

    /// Frames the host published that this agent never saw because a newer one arrived
    /// first (only in async mode or after a stop timeout). Their action statuses and
    /// collisions are not lost: the next frame read brings them ([`Frame::statuses`]).
    pub fn frames_skipped(&self) -> u64 {
        self.frames_skipped
    }

    /// The latest status of action `action_id` that a frame brought (`None`: none yet),
    /// like the original client's status map. Remembers the latest
    /// [`ACTION_STATES_CAPACITY`] actions.
    pub fn action_state(&self, action_id: u32) -> Option<ActionState> {
        self.action_states.get(action_id)
    }

    /// Every action's latest status, as [`Agent::action_state`], in no particular order.
    pub fn action_states(&self) -> impl Iterator<Item = (u32, ActionState)> + '_ {
        self.action_states.iter()
    }

    /// Blocks until the host signals *start* with a new frame, and returns that frame.
    /// `None` waits without limit (the host's liveness is still checked every 250 ms).
    ///
    /// # Errors
    /// [`WaitStartError`]: timeout, host closed or gone, invalid frame, termination.
    pub fn wait_start(&mut self, timeout: Option<Duration>) -> Result<Frame, WaitStartError> {
        let started = Instant::now();
        let deadline = timeout.map(|t| started + t);
        let (last, liveness) = (self.last_cycle, &mut self.next_liveness);
        let waited = wait_for_newer_frame(&mut self.backend, last, deadline, liveness);
        let inner = waited.map_err(|e| match e {
            AgentWaitError::Timeout => WaitStartError::Timeout {
                waited: started.elapsed(),
                last_cycle: self.last_cycle,
            },
            AgentWaitError::HostClosed => WaitStartError::HostClosed,
            AgentWaitError::HostGone { reason } => WaitStartError::HostGone {
                session: self.session.clone(),
                reason,
            },
            AgentWaitError::Receive(e) => receive_error(e, self.last_cycle),
            AgentWaitError::Terminated => WaitStartError::Terminated,
            other => WaitStartError::Receive(other.to_string()),
        })?;
        self.accept(inner)
    }

    /// The frame of a cycle newer than the last one received if the host published one,
    /// else `Ok(None)`, without waiting. Unlike [`Agent::wait_start`] with a zero
    /// timeout, it neither consumes the transport's pending wake-ups nor checks the
    /// host's liveness, so over shared memory it makes no system call. Meant for one
    /// thread serving many agents: it takes every frame that is there and waits (with
    /// [`Agent::wait_start`], which notices a host that closed or died) only for an agent
    /// whose frame has not come. A frame taken here is the same as one
    /// [`Agent::wait_start`] returns (its statuses and collisions handed out once).
    ///
    /// # Errors
    /// [`WaitStartError`]: invalid frame, too many frames held, receive failure,
    /// termination.
    pub fn try_next_frame(&mut self) -> Result<Option<Frame>, WaitStartError> {
        if self.backend.termination_requested() {
            return Err(WaitStartError::Terminated);
        }
        match self.backend.try_receive_newest() {
            Ok(Some(inner)) if self.last_cycle.is_none_or(|l| inner.header().cycle > l) => {
                self.accept(inner).map(Some)
            }
            Ok(_) => Ok(None),
            Err(e) => Err(receive_error(e, self.last_cycle)),
        }
    }

    /// Checks a received frame of a newer cycle and takes its events in.
    fn accept(&mut self, inner: AnyFrame) -> Result<Frame, WaitStartError> {
        let h = inner.header();
        let cycle = h.cycle;
        validate(h, inner.payload().len(), self.id)
            .and_then(|()| self.channels.check(h, inner.payload().len()))
            .map_err(|reason| WaitStartError::BadFrame { cycle, reason })?;
        if let Some(last) = self.last_cycle {
            self.frames_skipped += cycle - last - 1;
        }
        // The host repeats events until acknowledged: hand out the ones not seen yet (a
        // suffix of each table, whose sequence numbers ascend).
        let seen = self.last_event_seq;
        let new_statuses = h.statuses().partition_point(|s| s.seq <= seen);
        let new_collisions = h.collisions().partition_point(|c| c.seq <= seen);
        for status in &h.statuses()[new_statuses..] {
            self.action_states.update(status);
        }
        let newest = |a: Option<u64>, b: Option<u64>| a.max(b).unwrap_or(0);
        self.last_event_seq = seen.max(newest(
            h.statuses().last().map(|s| s.seq),
            h.collisions().last().map(|c| c.seq),
        ));
        self.last_cycle = Some(cycle);
        self.queue.clear();
        Ok(Frame {
            inner,
            new_statuses,
            new_collisions,
        })
    }

    /// Queues a command with a fresh action id (returned; statuses and collisions quote it).
    ///
    /// # Errors
    /// [`SendError::QueueFull`] beyond `max_commands_per_cycle`.
    pub fn send(&mut self, command: Command) -> Result<u32, SendError> {
        let id = self.next_action_id;
        self.send_with_id(id, command)?;
        self.next_action_id = self.next_action_id.wrapping_add(1).max(1);
        Ok(id)
    }

    /// Queues a command with an action id of your choice.
    ///
    /// # Errors
    /// [`SendError::QueueFull`] beyond `max_commands_per_cycle`.
    pub fn send_with_id(&mut self, action_id: u32, command: Command) -> Result<(), SendError> {
        self.send_wire(command.encode(action_id))
    }

    /// Queues a command in wire form as is, without any check: for tools and tests that
    /// must send what the typed API cannot express (the host validates everything).
    ///
    /// # Errors
    /// [`SendError::QueueFull`] beyond `max_commands_per_cycle`.
    pub fn send_wire(&mut self, command: MotorCommand) -> Result<(), SendError> {
        if self.queue.len() >= self.max_commands {
            return Err(SendError::QueueFull {
                max: self.max_commands,
            });
        }
        self.queue.push(command);
        Ok(())
    }

    /// Sends the queued commands with the *stop* flag for the cycle of the newest frame,
    /// and signals *stop*: this agent is done with the cycle. The batch also acknowledges
    /// that frame, so the host stops repeating the events it carried.
    ///
    /// # Errors
    /// [`StopError`].
    pub fn stop(&mut self) -> Result<(), StopError> {
        let cycle = self.last_cycle.ok_or(StopError::NoFrame)?;
        if self.stopped_cycle == Some(cycle) {
            return Err(StopError::AlreadyStopped { cycle });
        }
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: self.id,
            cycle,
            flags: MOTOR_FLAG_STOP | MOTOR_FLAG_ACK,
            command_count: self.queue.len() as u32,
            ack_cycle: cycle,
        };
        let sent = self.backend.send_batch(&header, &self.queue);
        match sent {
            Ok(()) => {}
            Err(AgentSendError::HostClosed) => return Err(StopError::HostClosed),
            Err(e) => return Err(StopError::Transport(e.to_string())),
        }
        self.queue.clear();
        self.stopped_cycle = Some(cycle);
        Ok(())
    }

    /// Leaves the session now, gracefully: tells the host (best effort) that this agent is
    /// gone, so it stops waiting for it at once — no stop timeout, no eviction — counts a
    /// leave, and frees the id: a new connection of the same id (in this process or
    /// another) takes part from the next cycle. Commands queued and not stopped are
    /// dropped. Dropping the agent does the same; `close` only makes it explicit.
    pub fn close(mut self) {
        self.leave();
    }

    /// Sends the leave batch once (errors ignored), unless the host closed the session or
    /// is gone: it needs no goodbye then (and a host closing its zenoh session would log
    /// the late batch as data for a key expression it no longer knows).
    fn leave(&mut self) {
        if core::mem::replace(&mut self.closed, true) {
            return;
        }
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: self.id,
            cycle: self.last_cycle.unwrap_or(0),
            flags: MOTOR_FLAG_LEAVE
                | if self.last_cycle.is_some() {
                    MOTOR_FLAG_ACK
                } else {
                    0
                },
            command_count: 0,
            ack_cycle: self.last_cycle.unwrap_or(0),
        };
        if matches!(self.backend.host_liveness(false), HostLiveness::Alive) {
            let _ = self.backend.send_batch(&header, &[]);
        }
        note_left(&self.session, self.id);
        self.backend.begin_close();
    }
}

/// Closes many agents at once: each leaves as with [`Agent::close`], and their
/// connections close together. A close that waits for the host (zenoh's, bounded by
/// about 1 s when the host does not answer: a frozen process, a lost link) is then waited
/// for once for all the agents, not once per agent.
pub fn close_all(agents: impl IntoIterator<Item = Agent>) {
    let mut agents: Vec<Agent> = agents.into_iter().collect();
    for agent in &mut agents {
        agent.leave();
    }
}

impl Drop for Agent {
    /// Leaves gracefully ([`Agent::close`]).
    fn drop(&mut self) {
        self.leave();
    }
}

mod action_states;
mod channels;
#[cfg(test)]
mod tests;

use action_states::ActionStates;

pub use channels::ActError;
use channels::Channels;
