//! The agent: connect, wait for *start*, read the frame, send commands, stop.

use std::time::{Duration, Instant};

use tracing::debug;
use vrsync_bridge::config::{Config, TransportKind};
use vrsync_bridge::transport::shm::{HostState, ShmAgent, ShmAgentConnectError, ShmFrame};
use vrsync_bridge::transport::tcp::{TcpAgent, TcpAgentConnectError, TcpFrame, TcpWaitError};
use vrsync_bridge::wire::{
    Command, ImageDesc, MOTOR_FLAG_STOP, MotorCommand, MotorHeader, PROTOCOL_VERSION, PixelFormat,
    Pose, SensorHeader,
};

/// How often a waiting agent checks that the host process is still alive.
pub const HOST_LIVENESS_PERIOD: Duration = Duration::from_millis(250);

/// Why an agent could not connect.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AgentConnectError {
    /// The shared-memory transport refused (no host, version mismatch, id in use, …).
    #[error(transparent)]
    Shm(#[from] ShmAgentConnectError),
    /// The TCP transport refused (no host, version mismatch, id in use, wrong token, …).
    #[error(transparent)]
    Tcp(#[from] TcpAgentConnectError),
}

/// Why [`Agent::wait_start`] returned without a frame.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WaitStartError {
    /// No new frame before the timeout.
    #[error("no start from the host within {waited:?} (last cycle seen: {last_cycle:?})")]
    Timeout {
        /// How long we waited.
        waited: Duration,
        /// The last cycle received, if any.
        last_cycle: Option<u64>,
    },
    /// The host closed the session (a clean end of the run).
    #[error("the host closed the session")]
    HostClosed,
    /// The host process is gone without closing the session (crashed or killed).
    #[error("the host is gone: its process died without closing session {session:?}")]
    HostGone {
        /// The session.
        session: String,
    },
    /// The frame violates the protocol (corrupt image table, wrong agent, wrong version).
    #[error("invalid sensor frame for cycle {cycle}: {reason}")]
    BadFrame {
        /// The frame's cycle.
        cycle: u64,
        /// What is wrong.
        reason: String,
    },
    /// Receiving failed (e.g. too many frames still held by the caller).
    #[error("cannot receive the sensor frame: {0}")]
    Receive(String),
    /// SIGINT/SIGTERM arrived.
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
    inner: FrameInner,
}

// The TCP variant carries its 592-byte header by value (a frame is moved once, from the
// transport to the caller); boxing it would allocate every cycle.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum FrameInner {
    Shm(ShmFrame),
    Tcp(TcpFrame),
}

impl FrameInner {
    fn header(&self) -> &SensorHeader {
        match self {
            Self::Shm(f) => f.header(),
            Self::Tcp(f) => f.header(),
        }
    }

    fn payload(&self) -> &[u8] {
        match self {
            Self::Shm(f) => f.payload(),
            Self::Tcp(f) => f.payload(),
        }
    }
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

/// Builds an [`Agent`].
#[derive(Debug)]
pub struct AgentBuilder<'c> {
    config: &'c Config,
    id: u32,
    connect_timeout: Option<Duration>,
}

impl<'c> AgentBuilder<'c> {
    /// An agent with id `id` in the session of `config`.
    pub fn new(config: &'c Config, id: u32) -> Self {
        Self {
            config,
            id,
            connect_timeout: None,
        }
    }

    /// How long [`AgentBuilder::connect`] waits for the host to appear. Default: the
    /// config's `sync.connect_timeout` (30 s unless set).
    pub fn connect_timeout(mut self, timeout: Duration) -> Self {
        self.connect_timeout = Some(timeout);
        self
    }

    /// Connects, waiting for the host's services until the connect timeout.
    ///
    /// # Errors
    /// [`AgentConnectError`]: no host, protocol mismatch, id already in use.
    pub fn connect(self) -> Result<Agent, AgentConnectError> {
        let timeout = self
            .connect_timeout
            .unwrap_or(self.config.sync.connect_timeout);
        let backend = match self.config.transport.kind {
            TransportKind::Shm => {
                Backend::Shm(Box::new(ShmAgent::connect(self.config, self.id, timeout)?))
            }
            TransportKind::Tcp => Backend::Tcp(TcpAgent::connect(
                self.config,
                self.id,
                timeout,
                self.config
                    .transport
                    .tcp_token
                    .as_deref()
                    .map(str::as_bytes),
            )?),
        };
        let max = self.config.transport.max_commands_per_cycle as usize;
        Ok(Agent {
            id: self.id,
            session: self.config.session.clone(),
            backend,
            queue: Vec::with_capacity(max),
            max_commands: max,
            last_cycle: None,
            stopped_cycle: None,
            next_action_id: 1,
            frames_skipped: 0,
            next_liveness: Instant::now() + HOST_LIVENESS_PERIOD,
        })
    }
}

#[derive(Debug)]
enum Backend {
    Shm(Box<ShmAgent>),
    Tcp(TcpAgent),
}

/// A connected agent.
#[derive(Debug)]
pub struct Agent {
    id: u32,
    session: String,
    backend: Backend,
    queue: Vec<MotorCommand>,
    max_commands: usize,
    last_cycle: Option<u64>,
    stopped_cycle: Option<u64>,
    next_action_id: u32,
    frames_skipped: u64,
    next_liveness: Instant,
}

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

    /// The cycle of the newest frame received.
    pub fn last_cycle(&self) -> Option<u64> {
        self.last_cycle
    }

    /// Frames the host published that this agent never saw because a newer one arrived
    /// first (only in async mode or after a stop timeout).
    pub fn frames_skipped(&self) -> u64 {
        self.frames_skipped
    }

    /// Blocks until the host signals *start* with a new frame, and returns that frame.
    /// `None` waits without limit (the host's liveness is still checked every 250 ms).
    ///
    /// # Errors
    /// [`WaitStartError`]: timeout, host closed or gone, invalid frame, termination.
    pub fn wait_start(&mut self, timeout: Option<Duration>) -> Result<Frame, WaitStartError> {
        let started = Instant::now();
        let deadline = timeout.map(|t| started + t);
        let inner = match &mut self.backend {
            Backend::Shm(shm) => FrameInner::Shm(wait_shm(
                shm,
                deadline,
                self.last_cycle,
                &self.session,
                &mut self.next_liveness,
            )?),
            Backend::Tcp(tcp) => loop {
                let frame = tcp.wait_frame(deadline).map_err(|e| match e {
                    TcpWaitError::Timeout => WaitStartError::Timeout {
                        waited: started.elapsed(),
                        last_cycle: self.last_cycle,
                    },
                    TcpWaitError::HostClosed => WaitStartError::HostClosed,
                    TcpWaitError::HostGone(_) => WaitStartError::HostGone {
                        session: self.session.clone(),
                    },
                    TcpWaitError::Bad(reason) => WaitStartError::BadFrame {
                        cycle: self.last_cycle.map_or(0, |c| c + 1),
                        reason,
                    },
                    TcpWaitError::Terminated => WaitStartError::Terminated,
                    other => WaitStartError::Receive(other.to_string()),
                })?;
                if self
                    .last_cycle
                    .is_none_or(|last| frame.header().cycle > last)
                {
                    break FrameInner::Tcp(frame);
                }
                debug!(cycle = frame.header().cycle, "old frame ignored");
            },
        };
        let h = inner.header();
        let cycle = h.cycle;
        validate(h, inner.payload().len(), self.id)
            .map_err(|reason| WaitStartError::BadFrame { cycle, reason })?;
        if let Some(last) = self.last_cycle {
            self.frames_skipped += cycle - last - 1;
        }
        self.last_cycle = Some(cycle);
        self.queue.clear();
        Ok(Frame { inner })
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
    /// and signals *stop*: this agent is done with the cycle.
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
            flags: MOTOR_FLAG_STOP,
            command_count: self.queue.len() as u32,
        };
        let sent = match &mut self.backend {
            Backend::Shm(shm) => shm.send_batch(&header, &self.queue),
            Backend::Tcp(tcp) => tcp.send_batch(&header, &self.queue),
        };
        if let Err(e) = sent {
            return Err(match &self.backend {
                Backend::Tcp(tcp) if tcp.host_closed() => StopError::HostClosed,
                _ => StopError::Transport(e),
            });
        }
        self.queue.clear();
        self.stopped_cycle = Some(cycle);
        Ok(())
    }
}

/// Shared-memory wait: the newest frame newer than `last_cycle`. `next_liveness` persists
/// across calls so that zero-timeout polls also notice a dead host.
fn wait_shm(
    shm: &mut ShmAgent,
    deadline: Option<Instant>,
    last_cycle: Option<u64>,
    session: &str,
    next_liveness: &mut Instant,
) -> Result<ShmFrame, WaitStartError> {
    let started = Instant::now();
    // Pending notifications carry nothing we rely on: the frame itself tells whether it is
    // new. Clearing them first means a stale wake-up cannot return early, and a frame
    // published after this point always comes with a fresh notification. A shutdown seen
    // here is remembered by the transport even if a frame is returned first.
    shm.clear_start();
    loop {
        // Checked before taking a frame too: in a fast run a frame is always waiting.
        if shm.termination_requested() {
            return Err(WaitStartError::Terminated);
        }
        if let Some(frame) = shm.receive_newest().map_err(WaitStartError::Receive)? {
            let cycle = frame.header().cycle;
            if last_cycle.is_none_or(|last| cycle > last) {
                return Ok(frame);
            }
            debug!(cycle, "old frame ignored");
        }
        if shm.shutdown_seen() {
            debug!("host closed the session (shutdown event)");
            return Err(WaitStartError::HostClosed);
        }
        let now = Instant::now();
        if now >= *next_liveness {
            match shm.host_state() {
                HostState::Alive => {}
                HostState::Absent | HostState::Dead => {
                    // The shutdown event may have raced with the node's removal: look once
                    // more before calling the host gone.
                    shm.clear_start();
                    if shm.shutdown_seen() {
                        return Err(WaitStartError::HostClosed);
                    }
                    return Err(WaitStartError::HostGone {
                        session: session.to_string(),
                    });
                }
            }
            *next_liveness = now + HOST_LIVENESS_PERIOD;
        }
        let mut slice = next_liveness.saturating_duration_since(now);
        if let Some(d) = deadline {
            if now >= d {
                return Err(WaitStartError::Timeout {
                    waited: started.elapsed(),
                    last_cycle,
                });
            }
            slice = slice.min(d - now);
        }
        if shm.spins() {
            // Busy-poll the subscriber (checked at the top of the loop) until the slice ends.
            let until = Instant::now() + slice;
            while Instant::now() < until {
                if shm.has_frame() {
                    break;
                }
                std::hint::spin_loop();
            }
            shm.clear_start();
            continue;
        }
        shm.wait_start(slice);
    }
}
