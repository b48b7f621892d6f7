//! The legacy transport's host side: listeners, version checks, one state machine per
//! agent that turns the original client's messages into motor batches, and the
//! per-cycle messages written at publish.

use std::io::{self, ErrorKind};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::os::fd::{AsRawFd, RawFd};
use std::time::{Duration, Instant};

use tracing::{debug, info, warn};

use crate::codec::{
    self, ActionStatus, Dialect, EyePosition, FrameProgress, FrameReader, GridPosition, HeadMotion,
    Incoming, MAX_INCOMING_FRAME, Reward, VERSION, VersionCheck, field,
};
use vrsync_protocol::wire::{
    ActionState, Command, ImageDesc, MOTOR_FLAG_ACK, MOTOR_FLAG_STOP, MotorCommand, MotorHeader,
    PROTOCOL_VERSION, PixelFormat, SensorHeader,
};
use vrsync_transport::Rounded;
use vrsync_transport::SignalHandling;
use vrsync_transport::internal::{EpollSet, write_all_until};
use vrsync_transport::{
    BatchSink, FrameLoanMut, HostConnections, HostReadiness, HostTransport, HostTransportError,
    PeerRefusal, RefusalKind, Refusals,
};
use vrsync_transport::{Config, LegacyDialect, PngCompression, TransportKind};

mod cycle;
mod env;
mod reading;
#[cfg(test)]
mod tests;

use cycle::push_status;

/// How long a new connection may take to send its version check.
pub const HELLO_TIMEOUT: Duration = Duration::from_secs(5);
/// After this long without a write, a connected agent gets a Debug keep-alive.
pub const KEEPALIVE_PERIOD: Duration = Duration::from_secs(1);
/// Connections per port waiting for their version check; more are closed at once.
const MAX_PENDING_PER_PORT: usize = 4;
/// Environment connections not paired with an agent connection (a client between its two
/// connects, or a stranger). A new connection beyond them closes the oldest unpaired one,
/// never the new one: a peer holding idle connections cannot lock a client out. Paired
/// connections (at most one per agent) do not count.
const MAX_ENV_CONNS: usize = 16;
/// Frames on the environment socket: it carries only resets (a dozen bytes); a longer
/// length closes the connection.
const MAX_ENV_FRAME: usize = 1024;
/// Frames read from one connection per pass; the rest waits for the next (the socket
/// stays readable), so one flooding client cannot hold the host.
const MAX_FRAMES_PER_PASS: usize = 256;
/// How long a frame may stay incomplete on a connection.
const STALL_TIMEOUT: Duration = Duration::from_secs(5);
/// Action id of resets that arrived on the environment socket (their status is not sent:
/// the clients expect none).
pub const RESET_ACTION_ID: u32 = u32::MAX;

/// A loaned legacy frame: header and raw images, encoded to PNG at publish.
#[derive(Debug)]
pub struct LegacyFrameLoan {
    header: Box<SensorHeader>,
    payload: Vec<u8>,
}

impl FrameLoanMut for LegacyFrameLoan {
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        (&mut self.header, &mut self.payload)
    }

    fn header(&self) -> &SensorHeader {
        &self.header
    }
}

/// Why the legacy host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LegacyHostCreateError {
    /// A port could not be bound.
    #[error(
        "cannot listen on {addr} for {what}: {error} (set [transport.legacy] local_port to a \
         free range: the environment socket and local_port + 1 + id for each legacy agent)"
    )]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Which socket.
        what: String,
        /// The error (in the message, so not also a `source()`: printed once).
        error: io::Error,
    },
    /// An agent's port would be beyond 65535.
    #[error("agent {agent}'s legacy port local_port + 1 + {agent} is beyond 65535")]
    PortRange {
        /// The agent.
        agent: u32,
    },
    /// A camera format the original protocol cannot carry.
    #[error(
        "agent {agent}'s camera {camera:?} is {format}: the original protocol carries PNG \
         images (rgb8, rgba8 or gray8)"
    )]
    Camera {
        /// The agent.
        agent: u32,
        /// The camera.
        camera: String,
        /// Its format.
        format: &'static str,
    },
    /// The epoll set could not be created.
    #[error("cannot create the legacy transport's epoll set: {0}")]
    Epoll(io::Error),
}

/// Counters of the legacy transport.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LegacyStats {
    /// Stops that arrived while no cycle of their agent was open: each ended the next.
    pub stops_without_cycle: u64,
    /// Stops beyond one while no cycle was open: ignored.
    pub stops_ignored: u64,
    /// Frames refused (undecodable, unknown or several fields, oversize).
    pub frames_refused: u64,
    /// Commands answered Aborted at once (non-finite, over the per-cycle limit).
    pub commands_refused: u64,
    /// Commands the simulator rejected, answered Aborted.
    pub commands_rejected: u64,
    /// Images encoded to PNG.
    pub png_images: u64,
    /// Time spent encoding them.
    pub png_time: Duration,
}

#[derive(Debug)]
struct Conn {
    stream: TcpStream,
    peer: SocketAddr,
    /// Accept order (see [`LegacyHost::pair_env`]).
    seq: u64,
    reader: FrameReader,
    dialect: Dialect,
    partial_since: Option<Instant>,
    last_write: Instant,
}

#[derive(Debug)]
struct Pending {
    stream: TcpStream,
    peer: SocketAddr,
    seq: u64,
    since: Instant,
    reader: FrameReader,
}

#[derive(Debug)]
struct Slot {
    id: u32,
    listener: TcpListener,
    conn: Option<Conn>,
    pending: Vec<Pending>,
    /// The last published cycle.
    cycle: Option<u64>,
    /// A published cycle waits for its stop.
    open: bool,
    /// Commands (and the stop) for `cycle`, handed over at the next drain.
    batch: Vec<MotorCommand>,
    batch_stop: bool,
    /// Commands taken for the open cycle so far (the per-cycle limit).
    in_cycle: usize,
    /// Commands received while no cycle was open, for the next one; `queued_stop` splits
    /// them: the first `n` end the next cycle with a stop.
    queued: Vec<MotorCommand>,
    queued_stop: Option<usize>,
    /// Action ids handed over for `applied_cycle` (to answer rejected ones Aborted).
    applied: Vec<u32>,
    applied_cycle: Option<u64>,
    /// The highest event sequence number written to the client: the host repeats events
    /// until acknowledged (see `SensorHeader::statuses`); the client gets each once.
    last_event_seq: u64,
    /// Reused buffers.
    header: Option<Box<SensorHeader>>,
    payload: Option<Vec<u8>>,
    payload_len: usize,
    out: Vec<u8>,
    png: [Vec<u8>; 3],
}

#[derive(Debug)]
struct EnvConn {
    stream: TcpStream,
    peer: SocketAddr,
    reader: FrameReader,
    /// Accept order, shared with the agent sockets (see [`LegacyHost::pair_env`]).
    seq: u64,
    /// The agent connection of the same client: (slot, that connection's `seq`). Valid
    /// while that slot's connection is still the one with this `seq`.
    agent: Option<(usize, u64)>,
    /// Since when it has no (valid) agent connection: closed after the hello timeout.
    unpaired_since: Instant,
    /// Since when a frame is incomplete.
    partial_since: Option<Instant>,
    /// Resets read before it was paired, handed over once it is.
    resets: Vec<MotorCommand>,
}

/// The host side of the legacy transport.
#[derive(Debug)]
pub struct LegacyHost {
    epoll: EpollSet,
    env_listener: TcpListener,
    env_conns: Vec<EnvConn>,
    slots: Vec<Slot>,
    sync_mode: bool,
    dialect: LegacyDialect,
    png: PngCompression,
    send_eye: bool,
    send_head: bool,
    max_commands: usize,
    write_timeout: Duration,
    stats: LegacyStats,
    /// The next accept's order number (environment and agent sockets alike).
    next_seq: u64,
    /// How long a new connection may take to send its version check.
    hello_timeout: Duration,
    /// How long a frame may stay incomplete ([`STALL_TIMEOUT`]; shorter in tests).
    stall_timeout: Duration,
    /// Peers refused before their version check passed.
    refusals: Refusals,
}

fn bind(addr: SocketAddr, what: String) -> Result<TcpListener, LegacyHostCreateError> {
    let err = |error| LegacyHostCreateError::Bind {
        addr,
        what: what.clone(),
        error,
    };
    let l = TcpListener::bind(addr).map_err(err)?;
    l.set_nonblocking(true).map_err(err)?;
    Ok(l)
}

impl LegacyHost {
    /// Binds the environment socket and one socket per legacy agent of `config`
    /// (`[transport.legacy]`); `signals` says whether SIGINT/SIGTERM handlers are installed.
    ///
    /// # Errors
    /// [`LegacyHostCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, LegacyHostCreateError> {
        signals.apply();
        let lc = &config.transport.legacy;
        let epoll = EpollSet::new(64).map_err(LegacyHostCreateError::Epoll)?;
        let ip: IpAddr = lc.bind;
        if !ip.is_loopback() {
            warn!(%ip, "legacy transport listens beyond loopback: any host that can reach it may connect");
        }
        let env_listener = bind(
            SocketAddr::new(ip, lc.local_port),
            "the environment socket".into(),
        )?;
        let mut slots = Vec::new();
        for a in config
            .agents
            .iter()
            .filter(|a| a.transport == TransportKind::Legacy)
        {
            for c in &a.cameras {
                if c.format == PixelFormat::Depth32f {
                    return Err(LegacyHostCreateError::Camera {
                        agent: a.id,
                        camera: c.name.clone(),
                        format: c.format.as_str(),
                    });
                }
            }
            let port = u32::from(lc.local_port) + 1 + a.id;
            let port = u16::try_from(port)
                .map_err(|_| LegacyHostCreateError::PortRange { agent: a.id })?;
            let listener = bind(SocketAddr::new(ip, port), format!("agent {}", a.id))?;
            let payload_len = a.frame_bytes();
            slots.push(Slot {
                id: a.id,
                listener,
                conn: None,
                pending: Vec::new(),
                cycle: None,
                open: false,
                batch: Vec::new(),
                batch_stop: false,
                in_cycle: 0,
                queued: Vec::new(),
                queued_stop: None,
                applied: Vec::new(),
                applied_cycle: None,
                last_event_seq: 0,
                header: Some(Box::default()),
                payload: Some(vec![0; payload_len]),
                payload_len,
                out: Vec::new(),
                png: Default::default(),
            });
        }
        let host = Self {
            epoll,
            env_listener,
            env_conns: Vec::new(),
            slots,
            sync_mode: config.sync.sync_mode,
            dialect: lc.dialect,
            png: lc.png_compression,
            send_eye: lc.send_eye_position,
            send_head: lc.send_head_motion,
            max_commands: config.transport.max_commands_per_cycle as usize,
            write_timeout: config.sync.stop_timeout.max(Duration::from_secs(1)),
            stats: LegacyStats::default(),
            next_seq: 0,
            hello_timeout: HELLO_TIMEOUT,
            stall_timeout: STALL_TIMEOUT,
            refusals: Refusals::default(),
        };
        host.watch(host.env_listener.as_raw_fd())
            .map_err(LegacyHostCreateError::Epoll)?;
        for i in 0..host.slots.len() {
            host.watch(host.slots[i].listener.as_raw_fd())
                .map_err(LegacyHostCreateError::Epoll)?;
        }
        info!(
            port = lc.local_port,
            %ip,
            agents = ?host.slots.iter().map(|s| (s.id, u32::from(lc.local_port) + 1 + s.id)).collect::<Vec<_>>(),
            "legacy host listening (environment socket, agent sockets)"
        );
        Ok(host)
    }

    /// Adds `fd` to the epoll set (level-triggered, readable). Closing the descriptor
    /// removes it again.
    fn watch(&self, fd: RawFd) -> io::Result<()> {
        self.epoll.add(fd, fd as u64)
    }

    /// The transport's counters.
    pub fn stats(&self) -> &LegacyStats {
        &self.stats
    }

    /// The environment socket's address (resolves the port actually bound).
    pub fn env_addr(&self) -> Option<SocketAddr> {
        self.env_listener.local_addr().ok()
    }

    /// The earliest moment something must be done without input: a version check or a
    /// stalled frame running out of time, a keep-alive due.
    pub fn next_deadline(&self) -> Option<Instant> {
        let mut next: Option<Instant> = None;
        let mut at = |t: Instant| next = Some(next.map_or(t, |n| n.min(t)));
        for s in &self.slots {
            for p in &s.pending {
                at(p.since + self.hello_timeout);
            }
            if let Some(c) = &s.conn {
                at(c.last_write + KEEPALIVE_PERIOD);
                if let Some(t) = c.partial_since {
                    at(t + self.stall_timeout);
                }
            }
        }
        for c in &self.env_conns {
            if c.agent.is_none() {
                at(c.unpaired_since + self.hello_timeout);
            }
            if let Some(t) = c.partial_since {
                at(t + self.stall_timeout);
            }
        }
        next
    }

    /// Does everything that needs no host: accepts connections, answers version checks,
    /// reads every socket (commands are acknowledged and queued for the next drain),
    /// writes keep-alives, drops stalled or broken connections. Never blocks for input.
    pub fn service(&mut self) {
        self.accept_env();
        self.read_env();
        // Before the agents' stops are read: a reset sent before its client's stop
        // belongs to the cycle that stop ends.
        self.route_resets();
        for i in 0..self.slots.len() {
            self.accept_agent(i);
            self.progress_pending(i);
            self.read_agent(i);
            self.keepalive(i);
        }
        // Resets of connections paired just now.
        self.route_resets();
        self.expire_env();
    }

    fn accept_agent(&mut self, i: usize) {
        loop {
            let s = &mut self.slots[i];
            match s.listener.accept() {
                Ok((stream, peer)) => {
                    if s.pending.len() >= MAX_PENDING_PER_PORT {
                        let reason = format!(
                            "closed at once: {MAX_PENDING_PER_PORT} connections are waiting for their version check"
                        );
                        warn!(agent = s.id, %peer, "legacy connection {reason}");
                        self.refusals.push(PeerRefusal::new(
                            RefusalKind::TooMany,
                            Some(s.id),
                            peer.to_string(),
                            reason,
                        ));
                        continue;
                    }
                    if stream.set_nonblocking(true).is_err() || stream.set_nodelay(true).is_err() {
                        continue;
                    }
                    // Environment connections made before this one are in their backlog
                    // now (a loopback or remote connect completes before the client's next
                    // one starts): accepted first, they get the lower `seq` that pairing
                    // relies on, however long this pass took.
                    self.accept_env();
                    let s = &mut self.slots[i];
                    let fd = stream.as_raw_fd();
                    s.pending.push(Pending {
                        stream,
                        peer,
                        seq: self.next_seq,
                        since: Instant::now(),
                        reader: FrameReader::new(MAX_INCOMING_FRAME),
                    });
                    self.next_seq += 1;
                    if let Err(e) = self.watch(fd) {
                        warn!("legacy connection dropped: epoll: {e}");
                        self.slots[i].pending.pop();
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    if e.kind() != ErrorKind::WouldBlock {
                        warn!(agent = s.id, "legacy accept failed: {e}");
                    }
                    break;
                }
            }
        }
    }

    fn progress_pending(&mut self, i: usize) {
        let mut k = 0;
        while k < self.slots[i].pending.len() {
            let s = &mut self.slots[i];
            let p = &mut s.pending[k];
            let result = match p.reader.read_from(&mut p.stream) {
                Ok(FrameProgress::Frame) => match codec::version_check_dialect(p.reader.body()) {
                    Some((d, v)) => match (self.dialect, d) {
                        (LegacyDialect::Vrnew, Dialect::Burkhardt)
                        | (LegacyDialect::Burkhardt, Dialect::Vrnew) => Err((
                            RefusalKind::Version,
                            format!(
                                "its version check is {} but dialect = {:?} is configured",
                                d.as_str(),
                                self.dialect.as_str()
                            ),
                        )),
                        _ => Ok(Some((d, v))),
                    },
                    None => Err((
                        RefusalKind::Malformed,
                        "its first frame is not a version check".into(),
                    )),
                },
                Ok(FrameProgress::Pending) => {
                    if p.since.elapsed() >= self.hello_timeout {
                        Err((
                            RefusalKind::Silent,
                            format!(
                                "sent no version check within {} of connecting",
                                Rounded(self.hello_timeout)
                            ),
                        ))
                    } else {
                        Ok(None)
                    }
                }
                Ok(FrameProgress::Skipped(n)) => Err((
                    RefusalKind::Malformed,
                    format!("sent a {n}-byte frame first"),
                )),
                Ok(FrameProgress::Closed) => Err((
                    RefusalKind::Silent,
                    "closed before its version check".into(),
                )),
                Err(e) => Err((RefusalKind::Malformed, e.to_string())),
            };
            match result {
                Ok(None) => k += 1,
                Err((kind, reason)) => {
                    let p = s.pending.swap_remove(k);
                    warn!(agent = s.id, peer = %p.peer, "legacy connection dropped: {reason}");
                    self.refusals.push(PeerRefusal::new(
                        kind,
                        Some(s.id),
                        p.peer.to_string(),
                        reason,
                    ));
                }
                Ok(Some((dialect, version))) => {
                    let p = s.pending.swap_remove(k);
                    if version != VERSION {
                        warn!(agent = s.id, peer = %p.peer, "legacy client speaks version {version:?}, this host {VERSION:?}: it will end itself");
                    }
                    let mut out = Vec::new();
                    codec::push_message(
                        &mut out,
                        dialect.version_check_field(),
                        &VersionCheck {
                            version: Some(VERSION.into()),
                        },
                    );
                    let mut stream = p.stream;
                    let deadline = Instant::now() + Duration::from_secs(1);
                    if let Err(e) = send_all(&mut stream, &out, deadline) {
                        warn!(agent = s.id, peer = %p.peer, "legacy connection lost while answering its version check: {e}");
                        continue;
                    }
                    if let Some(old) = s.conn.take() {
                        warn!(agent = s.id, old = %old.peer, new = %p.peer, "legacy agent connection replaced by a new one");
                    }
                    // Commands of a replaced connection are not the new client's.
                    s.batch.clear();
                    s.queued.clear();
                    s.queued_stop = None;
                    info!(agent = s.id, peer = %p.peer, dialect = dialect.as_str(), "legacy agent connected");
                    s.conn = Some(Conn {
                        stream,
                        peer: p.peer,
                        seq: p.seq,
                        reader: p.reader,
                        dialect,
                        partial_since: None,
                        last_write: Instant::now(),
                    });
                    self.pair_env(i);
                }
            }
        }
    }
}

/// Writes all of `data` to a non-blocking socket, waiting for writability until
/// `deadline` (whole frames only: the clients desynchronise on a partial one).
fn send_all(stream: &mut TcpStream, data: &[u8], deadline: Instant) -> io::Result<()> {
    write_all_until(stream, data, deadline, "the client does not read")
}

impl HostTransport for LegacyHost {
    type Loan = LegacyFrameLoan;

    fn loan(&mut self, slot: usize) -> Result<LegacyFrameLoan, HostTransportError> {
        let s = self
            .slots
            .get_mut(slot)
            .ok_or(HostTransportError::NoSuchSlot { slot })?;
        let mut header = s.header.take().unwrap_or_default();
        *header = SensorHeader::default();
        let payload = s.payload.take().unwrap_or_else(|| vec![0; s.payload_len]);
        Ok(LegacyFrameLoan { header, payload })
    }

    fn publish(&mut self, slot: usize, frame: LegacyFrameLoan) -> Result<bool, HostTransportError> {
        if slot >= self.slots.len() {
            return Err(HostTransportError::NoSuchSlot { slot });
        }
        let LegacyFrameLoan { header, payload } = frame;
        // Read what arrived first: a stop sent before this frame belongs to the last one.
        self.service();
        let delivered = if self.slots[slot].conn.is_some() {
            self.build_cycle(slot, &header, &payload);
            let deadline = Instant::now() + self.write_timeout;
            let s = &mut self.slots[slot];
            let r = match &mut s.conn {
                Some(c) => send_all(&mut c.stream, &s.out, deadline).map(|()| {
                    c.last_write = Instant::now();
                }),
                None => Ok(()),
            };
            match r {
                Ok(()) => true,
                Err(e) => {
                    Self::drop_conn(s, &format!("cannot send its frame: {e}"));
                    false
                }
            }
        } else {
            false
        };
        let s = &mut self.slots[slot];
        s.header = Some(header);
        s.payload = Some(payload);
        if !delivered {
            return Ok(false);
        }
        let cycle = s.header.as_ref().map_or(0, |h| h.cycle);
        s.cycle = Some(cycle);
        if self.sync_mode {
            // Commands that arrived while no cycle was open are this cycle's; a stop
            // among them ends it at once (the wire has no cycle number).
            match s.queued_stop.take() {
                Some(n) => {
                    s.in_cycle = n;
                    s.batch.extend(s.queued.drain(..n));
                    s.batch_stop = true;
                    s.open = false;
                }
                None => {
                    s.in_cycle = s.queued.len();
                    s.batch.append(&mut s.queued);
                    s.open = true;
                }
            }
        } else {
            s.in_cycle = 0;
            s.open = true;
        }
        Ok(true)
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        // StartSync is part of each agent's frame.
        Ok(())
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        self.service();
        for (slot, s) in self.slots.iter_mut().enumerate() {
            let Some(cycle) = s.cycle else { continue };
            if s.batch.is_empty() && !s.batch_stop {
                continue;
            }
            // Every frame goes down the client's stream, none is skipped: the batch
            // acknowledges the frame it answers, so the host stops repeating its events.
            let header = MotorHeader {
                protocol_version: PROTOCOL_VERSION,
                agent_id: s.id,
                cycle,
                flags: MOTOR_FLAG_ACK | if s.batch_stop { MOTOR_FLAG_STOP } else { 0 },
                command_count: s.batch.len() as u32,
                ack_cycle: cycle,
            };
            if s.applied_cycle != Some(cycle) {
                s.applied.clear();
                s.applied_cycle = Some(cycle);
            }
            s.applied.extend(
                s.batch
                    .iter()
                    .map(|c| c.action_id)
                    .filter(|&id| id != RESET_ACTION_ID),
            );
            sink(slot, &header, &s.batch);
            s.batch.clear();
            s.batch_stop = false;
        }
        Ok(())
    }
}

impl HostReadiness for LegacyHost {
    fn has_work(&self) -> bool {
        // Batches already read (at publish, or by a service of another transport's wait)
        // are activity too.
        self.slots
            .iter()
            .any(|s| s.cycle.is_some() && (!s.batch.is_empty() || s.batch_stop))
    }

    fn next_deadline(&self) -> Option<Instant> {
        LegacyHost::next_deadline(self)
    }

    fn activity_fd(&self) -> RawFd {
        self.epoll.raw()
    }

    fn after_wait(&mut self) {
        // Level-triggered: the set is readable while a socket has unread input. Reading
        // it is the clearing.
        self.service();
    }
}

impl HostConnections for LegacyHost {
    fn is_connected(&self, slot: usize) -> bool {
        self.slots.get(slot).is_some_and(|s| s.conn.is_some())
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        self.refusals.take(sink)
    }
}
