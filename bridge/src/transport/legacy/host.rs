//! The legacy transport's host side: listeners, version checks, one state machine per
//! agent that turns the original client's messages into motor batches, and the
//! per-cycle messages written at publish.

use std::io::{self, ErrorKind};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::os::fd::{AsRawFd, RawFd};
use std::time::{Duration, Instant};

use tracing::{debug, info, warn};

use super::codec::{
    self, ActionStatus, Dialect, EyePosition, FrameProgress, FrameReader, GridPosition, HeadMotion,
    Incoming, MAX_INCOMING_FRAME, Reward, VERSION, VersionCheck, field,
};
use crate::config::{Config, LegacyDialect, PngCompression, TransportKind};
use crate::rounded::Rounded;
use crate::signal::SignalHandling;
use crate::transport::wait::{EpollSet, write_all_until};
use crate::transport::{
    BatchSink, FrameLoanMut, HostTransport, HostTransportError, PeerRefusal, RefusalKind, Refusals,
};
use crate::wire::{
    ActionState, Command, ImageDesc, MOTOR_FLAG_ACK, MOTOR_FLAG_STOP, MotorCommand, MotorHeader,
    PROTOCOL_VERSION, PixelFormat, SensorHeader,
};

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
    signals: SignalHandling,
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
            signals,
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

    /// Whether environment connection `c`'s agent connection is still the one it was
    /// paired with.
    fn env_paired(&self, c: &EnvConn) -> bool {
        c.agent.is_some_and(|(slot, seq)| {
            self.slots
                .get(slot)
                .and_then(|s| s.conn.as_ref())
                .is_some_and(|a| a.seq == seq)
        })
    }

    /// Closes environment connection `k` with a warning naming its peer and `why`, and
    /// reports it as a refused peer of `kind`.
    fn close_env(&mut self, k: usize, kind: RefusalKind, why: String) {
        let c = self.env_conns.remove(k);
        let agent = c
            .agent
            .and_then(|(slot, _)| self.slots.get(slot))
            .map(|s| s.id);
        let lost = if c.resets.is_empty() {
            String::new()
        } else {
            format!(
                " ({} resets sent before it was paired dropped)",
                c.resets.len()
            )
        };
        warn!(peer = %c.peer, ?agent, "legacy environment connection closed: {why}{lost}");
        self.refusals.push(PeerRefusal {
            kind,
            agent,
            peer: c.peer.to_string(),
            reason: format!("environment socket: {why}"),
        });
    }

    fn accept_env(&mut self) {
        loop {
            match self.env_listener.accept() {
                Ok((stream, peer)) => {
                    if stream.set_nonblocking(true).is_err()
                        || self.watch(stream.as_raw_fd()).is_err()
                    {
                        continue;
                    }
                    // A full cap closes the oldest unpaired connection, not the new one: a
                    // peer holding idle connections cannot lock a client out (issue 22).
                    let unpaired: Vec<usize> = (0..self.env_conns.len())
                        .filter(|&k| !self.env_paired(&self.env_conns[k]))
                        .collect();
                    if unpaired.len() >= MAX_ENV_CONNS {
                        // `env_conns` is in accept order: the first is the oldest.
                        self.close_env(
                            unpaired[0],
                            RefusalKind::TooMany,
                            format!(
                                "{MAX_ENV_CONNS} connections without an agent connection are \
                                 open; the oldest makes room for {peer}"
                            ),
                        );
                    }
                    debug!(%peer, "legacy environment connection");
                    self.env_conns.push(EnvConn {
                        stream,
                        peer,
                        reader: FrameReader::new(MAX_ENV_FRAME),
                        seq: self.next_seq,
                        agent: None,
                        unpaired_since: Instant::now(),
                        partial_since: None,
                        resets: Vec::new(),
                    });
                    self.next_seq += 1;
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    if e.kind() != ErrorKind::WouldBlock {
                        warn!("legacy accept on the environment socket failed: {e}");
                    }
                    break;
                }
            }
        }
    }

    fn read_env(&mut self) {
        let mut i = 0;
        while i < self.env_conns.len() {
            let (max_commands, stall_timeout) = (self.max_commands, self.stall_timeout);
            let c = &mut self.env_conns[i];
            let mut drop_why = None;
            for _ in 0..MAX_FRAMES_PER_PASS {
                let r = c.reader.read_from(&mut c.stream);
                if let Some(n) = c.reader.oversize() {
                    drop_why = Some((
                        Some(RefusalKind::Malformed),
                        format!(
                            "it announced a frame of {n} bytes; the environment socket carries \
                             only resets (at most {MAX_ENV_FRAME} bytes)"
                        ),
                    ));
                    break;
                }
                match r {
                    Ok(FrameProgress::Frame) => {
                        c.partial_since = None;
                        // Fields 11 and 12 are the same in both dialects.
                        match codec::decode_frame(c.reader.body(), Dialect::Burkhardt) {
                            Ok(Incoming::Reset(cmd)) => {
                                if c.resets.len() < max_commands {
                                    c.resets.push(cmd.encode(RESET_ACTION_ID));
                                } else {
                                    warn!(peer = %c.peer, "legacy reset dropped: {} are waiting already", c.resets.len());
                                }
                            }
                            Ok(other) => {
                                debug!(peer = %c.peer, ?other, "legacy environment socket: message ignored (only resets are read there)");
                            }
                            Err(e) => {
                                self.stats.frames_refused += 1;
                                warn!(peer = %c.peer, "legacy environment frame refused: {e}");
                            }
                        }
                    }
                    Ok(FrameProgress::Skipped(n)) => {
                        drop_why = Some((
                            Some(RefusalKind::Malformed),
                            format!("it sent a frame of {n} bytes (at most {MAX_ENV_FRAME})"),
                        ));
                        break;
                    }
                    Ok(FrameProgress::Pending) => {
                        if c.reader.mid_frame() {
                            let now = Instant::now();
                            let since = *c.partial_since.get_or_insert(now);
                            if now.duration_since(since) >= stall_timeout {
                                drop_why = Some((
                                    Some(RefusalKind::Malformed),
                                    format!(
                                        "stalled mid-frame: {} within {}",
                                        c.reader.progress(),
                                        Rounded(stall_timeout)
                                    ),
                                ));
                            }
                        }
                        break;
                    }
                    Ok(FrameProgress::Closed) => {
                        if c.reader.mid_frame() {
                            drop_why = Some((
                                Some(RefusalKind::Malformed),
                                format!(
                                    "closed mid-frame after {} (truncated frame not applied)",
                                    c.reader.progress()
                                ),
                            ));
                        } else {
                            drop_why = Some((None, String::new()));
                        }
                        break;
                    }
                    Err(e) => {
                        drop_why = Some((Some(RefusalKind::Malformed), e.to_string()));
                        break;
                    }
                }
            }
            let Some((kind, why)) = drop_why else {
                i += 1;
                continue;
            };
            // Resets it sent before it went still go to its agent.
            self.route_env(i);
            match kind {
                Some(kind) => self.close_env(i, kind, why),
                None => {
                    let c = self.env_conns.remove(i);
                    if c.resets.is_empty() {
                        debug!(peer = %c.peer, "legacy environment connection closed by its client");
                    } else {
                        warn!(peer = %c.peer, "legacy environment connection closed by its client before it was paired with an agent connection: its {} resets are dropped", c.resets.len());
                    }
                }
            }
        }
    }

    /// Ends the life of unpaired environment connections: one whose client's agent
    /// connection did not pass its version check within the hello timeout of it (or whose
    /// agent connection went away that long ago) is closed.
    fn expire_env(&mut self) {
        let now = Instant::now();
        let mut k = 0;
        while k < self.env_conns.len() {
            let paired = self.env_paired(&self.env_conns[k]);
            let c = &mut self.env_conns[k];
            if !paired && c.agent.take().is_some() {
                c.unpaired_since = now;
            }
            if !paired && now.duration_since(c.unpaired_since) >= self.hello_timeout {
                let why = format!(
                    "no agent connection of the same client passed its version check within {} \
                     (resets go to the agent whose client sent them)",
                    Rounded(self.hello_timeout)
                );
                self.close_env(k, RefusalKind::Silent, why);
            } else {
                k += 1;
            }
        }
    }

    /// Hands the resets read on environment connection `k` to its paired agent, in whose
    /// batch they are applied; unpaired, they wait (see [`LegacyHost::pair_env`]).
    fn route_env(&mut self, k: usize) {
        if !self.env_paired(&self.env_conns[k]) || self.env_conns[k].resets.is_empty() {
            return;
        }
        let Some((slot, _)) = self.env_conns[k].agent else {
            return;
        };
        let mut resets = std::mem::take(&mut self.env_conns[k].resets);
        for cmd in resets.drain(..) {
            Self::queue_command(&mut self.slots[slot], cmd, self.sync_mode);
        }
        // Keep the buffer.
        self.env_conns[k].resets = resets;
    }

    fn route_resets(&mut self) {
        for k in 0..self.env_conns.len() {
            self.route_env(k);
        }
    }

    /// Pairs the agent connection of slot `i` (which has just passed its version check)
    /// with the environment connection of the same client, whose resets then go to this
    /// agent. The wire carries no identity; the original clients connect the environment
    /// socket first and their agent socket right after, from one process. So the rule:
    /// among the environment connections not paired yet, from the same IP address and
    /// accepted before this agent connection, the newest one; where the host can see
    /// which process owns the client sockets (a peer on this machine, run by the same
    /// user: `/proc/net/tcp` and `/proc/<pid>/fd`), one of the agent's own process, else
    /// one whose process is unknown. A client that connects no environment socket
    /// (`agentOnly`) gets none.
    fn pair_env(&mut self, i: usize) {
        let Some(a) = &self.slots[i].conn else {
            return;
        };
        let (a_seq, a_peer) = (a.seq, a.peer);
        let mut candidates: Vec<usize> = (0..self.env_conns.len())
            .filter(|&k| {
                let c = &self.env_conns[k];
                c.seq < a_seq && c.peer.ip() == a_peer.ip() && !self.env_paired(c)
            })
            .collect();
        if candidates.is_empty() {
            debug!(agent = self.slots[i].id, peer = %a_peer, "legacy agent connection without an environment connection");
            return;
        }
        // Newest first.
        candidates.sort_by_key(|&k| std::cmp::Reverse(self.env_conns[k].seq));
        let mut sockets = vec![(a_peer, a.stream.local_addr().ok())];
        sockets.extend(candidates.iter().map(|&k| {
            let c = &self.env_conns[k];
            (c.peer, c.stream.local_addr().ok())
        }));
        let owners = socket_owners(&sockets);
        let theirs = || candidates.iter().zip(owners.iter().skip(1));
        let pick = match owners.first().copied().flatten() {
            Some(pid) => theirs()
                .find(|(_, o)| **o == Some(pid))
                .or_else(|| theirs().find(|(_, o)| o.is_none()))
                .map(|(&k, _)| k),
            None => candidates.first().copied(),
        };
        let Some(k) = pick else {
            debug!(agent = self.slots[i].id, peer = %a_peer, "legacy agent connection: no environment connection of its process");
            return;
        };
        let c = &mut self.env_conns[k];
        c.agent = Some((i, a_seq));
        info!(agent = self.slots[i].id, agent_peer = %a_peer, env_peer = %c.peer, "legacy environment connection paired: its resets go to this agent");
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
                        self.refusals.push(PeerRefusal {
                            kind: RefusalKind::TooMany,
                            agent: Some(s.id),
                            peer: peer.to_string(),
                            reason,
                        });
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
                    self.refusals.push(PeerRefusal {
                        kind,
                        agent: Some(s.id),
                        peer: p.peer.to_string(),
                        reason,
                    });
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

    fn drop_conn(s: &mut Slot, why: &str) {
        if let Some(c) = s.conn.take() {
            warn!(agent = s.id, peer = %c.peer, "legacy agent dropped: {why}");
        }
        s.open = false;
        s.batch.clear();
        s.batch_stop = false;
        s.queued.clear();
        s.queued_stop = None;
    }

    /// Queues a command for the agent's open cycle, or the next one.
    fn queue_command(s: &mut Slot, cmd: MotorCommand, sync: bool) {
        if s.open || !sync {
            s.batch.push(cmd);
            s.in_cycle += 1;
        } else {
            s.queued.push(cmd);
        }
    }

    fn read_agent(&mut self, i: usize) {
        let sync = self.sync_mode;
        let max_commands = self.max_commands;
        let stall_timeout = self.stall_timeout;
        let s = &mut self.slots[i];
        // Taken out while its frames are applied to the slot; put back unless dropped.
        let Some(mut conn) = s.conn.take() else {
            return;
        };
        let c = &mut conn;
        let mut acks = std::mem::take(&mut s.out);
        acks.clear();
        let mut drop_why = None;
        for _ in 0..MAX_FRAMES_PER_PASS {
            match c.reader.read_from(&mut c.stream) {
                Ok(FrameProgress::Frame) => {
                    c.partial_since = None;
                    match codec::decode_frame(c.reader.body(), c.dialect) {
                        Ok(Incoming::Stop) => {
                            if !sync {
                                // Async mode: stops are accepted and ignored.
                            } else if s.open {
                                s.batch_stop = true;
                                s.open = false;
                            } else if s.queued_stop.is_none() {
                                s.queued_stop = Some(s.queued.len());
                                self.stats.stops_without_cycle += 1;
                                debug!(
                                    agent = s.id,
                                    "legacy stop while no cycle is open: it ends the next one"
                                );
                            } else {
                                self.stats.stops_ignored += 1;
                                debug!(
                                    agent = s.id,
                                    "legacy stop ignored: one is waiting for the next cycle already"
                                );
                            }
                        }
                        Ok(Incoming::Command { action_id, command }) => {
                            let ack = match command {
                                Command::Turn { .. } => ActionState::Rotating,
                                Command::Move { .. } | Command::MoveTo { .. } => {
                                    ActionState::Walking
                                }
                                _ => ActionState::InExecution,
                            };
                            let wire = command.encode(action_id);
                            let in_cycle = if s.open || !sync {
                                s.in_cycle
                            } else {
                                s.queued.len() - s.queued_stop.unwrap_or(0)
                            };
                            let refused = if let Err(e) = wire.decode() {
                                Some(e.to_string())
                            } else if in_cycle >= max_commands {
                                Some(format!(
                                    "more than max_commands_per_cycle = {max_commands} in one cycle"
                                ))
                            } else {
                                None
                            };
                            if let Some(why) = refused {
                                self.stats.commands_refused += 1;
                                if self.stats.commands_refused.is_power_of_two() {
                                    warn!(
                                        agent = s.id,
                                        action_id,
                                        total = self.stats.commands_refused,
                                        "legacy command answered Aborted: {why}"
                                    );
                                }
                                push_status(&mut acks, action_id, ActionState::Aborted);
                            } else {
                                push_status(&mut acks, action_id, ack);
                                Self::queue_command(s, wire, sync);
                            }
                        }
                        Ok(Incoming::Reset(cmd)) => {
                            Self::queue_command(s, cmd.encode(RESET_ACTION_ID), sync);
                        }
                        Ok(Incoming::VersionCheck(_)) => {
                            codec::push_message(
                                &mut acks,
                                c.dialect.version_check_field(),
                                &VersionCheck {
                                    version: Some(VERSION.into()),
                                },
                            );
                        }
                        Ok(Incoming::Ignored(what)) => {
                            debug!(agent = s.id, "legacy {what} ignored");
                        }
                        Err(e) => {
                            self.stats.frames_refused += 1;
                            warn!(agent = s.id, peer = %c.peer, "legacy frame refused, nothing of it applied: {e}");
                        }
                    }
                }
                Ok(FrameProgress::Skipped(n)) => {
                    self.stats.frames_refused += 1;
                    warn!(agent = s.id, peer = %c.peer, "legacy frame of {n} bytes skipped unread: longer than {MAX_INCOMING_FRAME}");
                }
                Ok(FrameProgress::Pending) => {
                    if c.reader.mid_frame() {
                        let now = Instant::now();
                        let since = *c.partial_since.get_or_insert(now);
                        if now.duration_since(since) >= stall_timeout {
                            drop_why = Some(format!(
                                "stalled mid-frame: {} within {}",
                                c.reader.progress(),
                                Rounded(stall_timeout)
                            ));
                        }
                    }
                    break;
                }
                Ok(FrameProgress::Closed) if c.reader.mid_frame() => {
                    drop_why = Some(format!(
                        "connection closed mid-frame after {} (truncated frame not applied)",
                        c.reader.progress()
                    ));
                    break;
                }
                Ok(FrameProgress::Closed) => {
                    drop_why = Some("connection closed".into());
                    break;
                }
                Err(e) => {
                    drop_why = Some(e.to_string());
                    break;
                }
            }
        }
        if drop_why.is_none() && !acks.is_empty() {
            let deadline = Instant::now() + self.write_timeout;
            match send_all(&mut c.stream, &acks, deadline) {
                Ok(()) => c.last_write = Instant::now(),
                Err(e) => drop_why = Some(format!("cannot send statuses: {e}")),
            }
        }
        s.out = acks;
        s.conn = Some(conn);
        if let Some(why) = drop_why {
            Self::drop_conn(s, &why);
        }
    }

    fn keepalive(&mut self, i: usize) {
        let s = &mut self.slots[i];
        let Some(c) = &mut s.conn else {
            return;
        };
        if c.last_write.elapsed() < KEEPALIVE_PERIOD {
            return;
        }
        let mut out = std::mem::take(&mut s.out);
        out.clear();
        codec::push_debug(&mut out, "vrsync keep-alive");
        let r = send_all(&mut c.stream, &out, Instant::now() + self.write_timeout);
        s.out = out;
        match r {
            Ok(()) => c.last_write = Instant::now(),
            Err(e) => Self::drop_conn(s, &format!("cannot send a keep-alive: {e}")),
        }
    }

    fn encode_png(&mut self, slot: usize, which: usize, desc: &ImageDesc, payload: &[u8]) {
        let started = Instant::now();
        let out = &mut self.slots[slot].png[which];
        out.clear();
        let start = desc.offset as usize;
        let data = payload.get(start..start + desc.len as usize).unwrap_or(&[]);
        let color = match desc.pixel_format() {
            Some(PixelFormat::Rgba8) => png::ColorType::Rgba,
            Some(PixelFormat::Gray8) => png::ColorType::Grayscale,
            _ => png::ColorType::Rgb,
        };
        let mut enc = png::Encoder::new(&mut *out, desc.width_px, desc.height_px);
        enc.set_color(color);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(match self.png {
            PngCompression::Fastest => png::Compression::Fastest,
            PngCompression::Fast => png::Compression::Fast,
            PngCompression::Balanced => png::Compression::Balanced,
            PngCompression::High => png::Compression::High,
        });
        let r = enc
            .write_header()
            .and_then(|mut w| w.write_image_data(data).and_then(|()| w.finish()));
        if let Err(e) = r {
            // Only a table/size mismatch can get here, a bug: an empty image tells the
            // client nothing is there rather than nothing at all.
            warn!(agent = self.slots[slot].id, "PNG encoding failed: {e}");
            self.slots[slot].png[which].clear();
        }
        self.stats.png_images += 1;
        self.stats.png_time += started.elapsed();
    }

    /// Writes one cycle's messages for slot `slot` into its `out` buffer.
    fn build_cycle(&mut self, slot: usize, header: &SensorHeader, payload: &[u8]) {
        let dialect = match &self.slots[slot].conn {
            Some(c) => c.dialect,
            None => return,
        };
        let mut out = std::mem::take(&mut self.slots[slot].out);
        out.clear();
        // 1. Statuses and collisions of the last cycle's commands.
        let s = &mut self.slots[slot];
        if header.previous_rejected > 0 && s.applied_cycle.is_some_and(|c| c + 1 == header.cycle) {
            // The simulator rejected some of the commands handed over last cycle and
            // reports no status for them: those without one end Aborted.
            for &id in &s.applied {
                if !header.statuses().iter().any(|st| st.action_id == id) {
                    push_status(&mut out, id, ActionState::Aborted);
                    self.stats.commands_rejected += 1;
                }
            }
        }
        // Events the host repeats (not acknowledged yet) went to the client already.
        let seen = s.last_event_seq;
        s.last_event_seq = header
            .statuses()
            .iter()
            .map(|st| st.seq)
            .chain(header.collisions().iter().map(|c| c.seq))
            .fold(seen, u64::max);
        for c in header.collisions().iter().filter(|c| c.seq > seen) {
            codec::push_message(
                &mut out,
                field::COLLISION,
                &codec::Collision {
                    action_id: Some(c.action_id as i32),
                    collider_id: Some(c.collider_id as i32),
                },
            );
        }
        for st in header.statuses().iter().filter(|st| st.seq > seen) {
            if st.action_id != RESET_ACTION_ID {
                codec::push_message(
                    &mut out,
                    field::ACTION_STATUS,
                    &ActionStatus {
                        action_id: Some(st.action_id as i32),
                        status: Some(st.state as i32),
                    },
                );
            }
        }
        // 2. Images.
        let descs = header.image_descs();
        let pick = |name: &str, index: usize| {
            descs
                .iter()
                .position(|d| d.name() == name)
                .or_else(|| (index < descs.len()).then_some(index))
        };
        let left = pick("left", 0);
        let right = pick("right", 1).or(left);
        let main = match dialect {
            Dialect::Burkhardt => pick("main", 2).or(left),
            Dialect::Vrnew => None,
        };
        let mut which_of = [usize::MAX; 3];
        for (k, cam) in [left, right, main].into_iter().enumerate() {
            let Some(cam) = cam else { continue };
            // An image used twice is encoded once.
            if let Some(j) = (0..k).find(|&j| [left, right, main][j] == Some(cam)) {
                which_of[k] = which_of[j];
                continue;
            }
            which_of[k] = k;
            let desc = descs[cam];
            self.encode_png(slot, k, &desc, payload);
        }
        let s = &mut self.slots[slot];
        let png = |k: usize| -> &[u8] { s.png.get(which_of[k]).map_or(&[], Vec::as_slice) };
        codec::push_images(&mut out, png(0), png(1), main.is_some().then(|| png(2)));
        // 3. Grid position; 4. optional sensors.
        let g = &header.grid;
        codec::push_message(
            &mut out,
            field::GRID_POSITION,
            &GridPosition {
                x: Some(g.position[0]),
                y: Some(g.position[1]),
                z: Some(g.position[2]),
                rotation_x: Some(g.rotation_deg[0]),
                rotation_y: Some(g.rotation_deg[1]),
                rotation_z: Some(g.rotation_deg[2]),
            },
        );
        if header.reward != 0.0 {
            codec::push_message(
                &mut out,
                field::REWARD,
                &Reward {
                    reward: Some(header.reward),
                },
            );
        }
        if self.send_eye {
            let e = &header.eye;
            codec::push_message(
                &mut out,
                field::EYE_POSITION,
                &EyePosition {
                    x: Some(e.rotation_deg[0]),
                    y: Some(e.rotation_deg[1]),
                    z: Some(e.rotation_deg[2]),
                    vx: Some(e.rotation_velocity_deg[0]),
                    vy: Some(e.rotation_velocity_deg[1]),
                    vz: Some(e.rotation_velocity_deg[2]),
                },
            );
        }
        if self.send_head {
            let h = &header.head_motion;
            codec::push_message(
                &mut out,
                dialect.head_motion_field(),
                &HeadMotion {
                    vx: Some(h.velocity[0]),
                    vy: Some(h.velocity[1]),
                    vz: Some(h.velocity[2]),
                    ax: Some(h.acceleration[0]),
                    ay: Some(h.acceleration[1]),
                    az: Some(h.acceleration[2]),
                    rvx: Some(h.angular_velocity_deg[0]),
                    rvy: Some(h.angular_velocity_deg[1]),
                    rvz: Some(h.angular_velocity_deg[2]),
                    rax: Some(h.angular_acceleration_deg[0]),
                    ray: Some(h.angular_acceleration_deg[1]),
                    raz: Some(h.angular_acceleration_deg[2]),
                },
            );
        }
        // 5. StartSync (sync mode); 6. a Debug trailer naming the cycle.
        if self.sync_mode {
            codec::push_message(&mut out, field::START_SYNC, &codec::Empty {});
        }
        codec::push_debug(&mut out, &format!("vrsync cycle {}", header.cycle));
        self.slots[slot].out = out;
    }
}

/// The processes owning the client ends of accepted connections `(peer, local)` (the
/// host's accepted socket has local address `local` and peer `peer`; the client's socket
/// is the one bound to `peer` and connected to `local`), where the host can see them: a
/// client on this machine, in this network namespace, run by the same user (or the host
/// is privileged). `None` where it cannot. Reads `/proc/net/tcp{,6}` once and walks
/// `/proc/<pid>/fd` once; called only when an agent connection passes its version check.
fn socket_owners(conns: &[(SocketAddr, Option<SocketAddr>)]) -> Vec<Option<u32>> {
    let mut inodes: Vec<Option<u64>> = vec![None; conns.len()];
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let Ok(text) = std::fs::read_to_string(table) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let (Some(local), Some(remote), Some(inode)) = (
                f.get(1).and_then(|a| proc_addr(a)),
                f.get(2).and_then(|a| proc_addr(a)),
                f.get(9).and_then(|i| i.parse::<u64>().ok()),
            ) else {
                continue;
            };
            for (k, (peer, host)) in conns.iter().enumerate() {
                let host = host.map(canonical);
                if inode != 0 && local == canonical(*peer) && Some(remote) == host {
                    inodes[k] = Some(inode);
                }
            }
        }
    }
    let mut owners: Vec<Option<u32>> = vec![None; conns.len()];
    let mut left = inodes.iter().filter(|i| i.is_some()).count();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return owners;
    };
    for entry in procs.flatten() {
        if left == 0 {
            break;
        }
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let Ok(fds) = std::fs::read_dir(entry.path().join("fd")) else {
            continue;
        };
        for fd in fds.flatten() {
            let Ok(target) = std::fs::read_link(fd.path()) else {
                continue;
            };
            let Some(inode) = target
                .to_str()
                .and_then(|t| t.strip_prefix("socket:["))
                .and_then(|t| t.strip_suffix(']'))
                .and_then(|t| t.parse::<u64>().ok())
            else {
                continue;
            };
            for (k, want) in inodes.iter().enumerate() {
                if *want == Some(inode) && owners[k].is_none() {
                    owners[k] = Some(pid);
                    left -= 1;
                }
            }
        }
    }
    owners
}

/// `addr` with a v4-mapped IPv6 address (a v4 peer of a dual-stack socket) as IPv4.
fn canonical(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V6(v6) => v6
            .to_ipv4_mapped()
            .map_or(addr, |v4| SocketAddr::new(v4.into(), addr.port())),
        IpAddr::V4(_) => addr,
    }
}

/// An address of `/proc/net/tcp{,6}`: the IP's 32-bit words in hex as stored (native
/// byte order), a colon, the port in hex.
fn proc_addr(text: &str) -> Option<SocketAddr> {
    let (ip, port) = text.split_once(':')?;
    let port = u16::from_str_radix(port, 16).ok()?;
    let word = |k: usize| -> Option<[u8; 4]> {
        let w = u32::from_str_radix(ip.get(8 * k..8 * k + 8)?, 16).ok()?;
        Some(w.to_ne_bytes())
    };
    let ip: IpAddr = match ip.len() {
        8 => std::net::Ipv4Addr::from(word(0)?).into(),
        32 => {
            let mut b = [0u8; 16];
            for k in 0..4 {
                b[4 * k..4 * k + 4].copy_from_slice(&word(k)?);
            }
            std::net::Ipv6Addr::from(b).into()
        }
        _ => return None,
    };
    Some(canonical(SocketAddr::new(ip, port)))
}

/// Appends an ActionExecutationStatus frame.
fn push_status(out: &mut Vec<u8>, action_id: u32, state: ActionState) {
    codec::push_message(
        out,
        field::ACTION_STATUS,
        &ActionStatus {
            action_id: Some(action_id as i32),
            status: Some(state as i32),
        },
    );
}

/// Writes all of `data` to a non-blocking socket, waiting for writability until
/// `deadline` (whole frames only: the clients desynchronise on a partial one).
fn send_all(stream: &mut TcpStream, data: &[u8], deadline: Instant) -> io::Result<()> {
    write_all_until(stream, data, deadline, "the client does not read")
}

impl HostTransport for LegacyHost {
    type Loan = LegacyFrameLoan;

    fn is_connected(&self, slot: usize) -> bool {
        self.slots.get(slot).is_some_and(|s| s.conn.is_some())
    }

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

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    fn activity_fd(&self) -> RawFd {
        self.epoll.raw()
    }

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        self.refusals.take(sink)
    }

    fn after_wait(&mut self) {
        // Level-triggered: the set is readable while a socket has unread input. Reading
        // it is the clearing.
        self.service();
    }
}

#[cfg(test)]
mod tests {
    //! The legacy host over real loopback sockets, driven through the host contract; the
    //! "clients" are raw byte streams. Bad input of every kind (issue 14 item 5).

    use std::io::{Read, Write};
    use std::path::Path;
    use std::sync::atomic::{AtomicU32, Ordering};

    use prost::Message;

    use super::*;
    use crate::transport::legacy::codec::{AgentMovement, Images, Reset, single_field};

    /// Creates a host for legacy agents `ids`, on a port range found by trying: a base
    /// port derived from the process id and a counter, and on any bind conflict (another
    /// test or program holds one of the ports) the next candidate. The host binds the
    /// ports itself, so there is no window between choosing and binding.
    fn host(ids: &[u32], extra: &str) -> (LegacyHost, u16) {
        static N: AtomicU32 = AtomicU32::new(0);
        for _ in 0..50 {
            let n = N.fetch_add(1, Ordering::Relaxed);
            let base =
                20_000 + (std::process::id().wrapping_mul(7919).wrapping_add(n * 263)) % 40_000;
            let base = base as u16;
            let mut text = format!(
                "session = \"legacy-unit\"\n[sync]\nstop_timeout = 5\n[transport]\nmax_commands_per_cycle = 8\n[transport.legacy]\nlocal_port = {base}\n{extra}\n"
            );
            for id in ids {
                text += &format!(
                    "[[agent]]\nid = {id}\ntransport = \"legacy\"\n[[agent.camera]]\nname = \"left\"\nwidth = 4\nheight = 3\n[[agent.camera]]\nname = \"right\"\nwidth = 4\nheight = 3\n"
                );
            }
            let config = Config::from_toml_str(&text, Path::new("unit.toml")).unwrap();
            match LegacyHost::create(&config, SignalHandling::Leave) {
                Ok(h) => return (h, base),
                Err(LegacyHostCreateError::Bind { .. }) => continue,
                Err(e) => panic!("{e}"),
            }
        }
        panic!("no free legacy port range found in 50 attempts");
    }

    struct Client {
        s: TcpStream,
    }

    impl Client {
        fn connect(port: u16) -> Self {
            let s = TcpStream::connect(("127.0.0.1", port)).unwrap();
            s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            Self { s }
        }

        fn raw(&mut self, bytes: &[u8]) {
            self.s.write_all(bytes).unwrap();
        }

        fn frame(&mut self, body: &[u8]) {
            self.raw(&(body.len() as i32).to_le_bytes());
            self.raw(body);
        }

        fn message(&mut self, field: u32, msg: &impl Message) {
            let mut out = Vec::new();
            codec::push_message(&mut out, field, msg);
            self.raw(&out);
        }

        fn version(&mut self, dialect: Dialect) {
            self.message(
                dialect.version_check_field(),
                &VersionCheck {
                    version: Some("1.0".into()),
                },
            );
        }

        fn movement(&mut self, id: i32) {
            self.message(
                field::AGENT_MOVEMENT,
                &AgentMovement {
                    action_id: Some(id),
                    degree: Some(0.0),
                    distance: Some(1.0),
                },
            );
        }

        /// Reads one frame body (blocking, with the read timeout).
        fn read(&mut self) -> Vec<u8> {
            let mut len = [0u8; 4];
            self.s.read_exact(&mut len).unwrap();
            let mut body = vec![0; i32::from_le_bytes(len) as usize];
            self.s.read_exact(&mut body).unwrap();
            body
        }

        /// Reads frames up to and including the Debug trailer of a cycle; returns the
        /// field numbers in order and the statuses seen.
        fn cycle(&mut self) -> (Vec<u32>, Vec<(i32, i32)>) {
            let (mut fields, mut statuses) = (Vec::new(), Vec::new());
            loop {
                let body = self.read();
                let (f, p) = single_field(&body, Dialect::Burkhardt).unwrap();
                if f == field::ACTION_STATUS {
                    let st = ActionStatus::decode(p).unwrap();
                    statuses.push((st.action_id.unwrap(), st.status.unwrap()));
                }
                if f == field::IMAGES {
                    let im = Images::decode(p).unwrap();
                    let png = im.left.unwrap();
                    assert_eq!(&png[1..4], b"PNG");
                }
                fields.push(f);
                if f == field::DEBUG && fields.contains(&field::START_SYNC) {
                    return (fields, statuses);
                }
            }
        }

        /// Reads one ActionExecutationStatus.
        fn status(&mut self) -> (i32, i32) {
            let body = self.read();
            let (f, p) = single_field(&body, Dialect::Burkhardt).unwrap();
            assert_eq!(f, field::ACTION_STATUS);
            let st = ActionStatus::decode(p).unwrap();
            (st.action_id.unwrap(), st.status.unwrap())
        }

        /// Whether the host closed the connection (reads until EOF or an error).
        fn closed(&mut self) -> bool {
            let mut buf = [0u8; 4096];
            loop {
                match self.s.read(&mut buf) {
                    Ok(0) => return true,
                    Ok(_) => {}
                    Err(e) if e.kind() == ErrorKind::ConnectionReset => return true,
                    Err(_) => return false,
                }
            }
        }
    }

    /// Services the host until `done` holds (deadline 10 s).
    fn pump(h: &mut LegacyHost, mut done: impl FnMut(&mut LegacyHost) -> bool) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !done(h) {
            assert!(
                Instant::now() < deadline,
                "condition not reached within 10 s"
            );
            h.wait_activity(Duration::from_millis(20)).unwrap();
        }
    }

    fn publish(h: &mut LegacyHost, slot: usize, cycle: u64, previous_rejected: u32) -> bool {
        let mut loan = h.loan(slot).unwrap();
        let (header, payload) = loan.parts_mut();
        let (descs, _) = crate::wire::image_layout([
            ("left", 4, 3, PixelFormat::Rgb8),
            ("right", 4, 3, PixelFormat::Rgb8),
        ]);
        header.cycle = cycle;
        header.images = descs;
        header.image_count = 2;
        header.previous_rejected = previous_rejected;
        payload.fill(7);
        h.publish(slot, loan).unwrap()
    }

    type Batch = (usize, u64, bool, Vec<MotorCommand>);

    fn drain(h: &mut LegacyHost) -> Vec<Batch> {
        let mut got = Vec::new();
        h.drain(&mut |slot, header, commands| {
            got.push((slot, header.cycle, header.is_stop(), commands.to_vec()));
        })
        .unwrap();
        got
    }

    /// Connects agent `slot` (port base + 1 + id) and passes the version check.
    fn join(h: &mut LegacyHost, base: u16, id: u32, slot: usize, dialect: Dialect) -> Client {
        let mut c = Client::connect(base + 1 + id as u16);
        c.version(dialect);
        let me = c.s.local_addr().unwrap();
        pump(h, |h| {
            h.slots[slot].conn.as_ref().is_some_and(|x| x.peer == me)
        });
        let reply = c.read();
        assert_eq!(
            codec::version_check_dialect(&reply),
            Some((dialect, "1.0".into()))
        );
        c
    }

    #[test]
    fn a_cycle_in_order_with_commands_acknowledged_and_the_zero_length_stop() {
        for dialect in [Dialect::Vrnew, Dialect::Burkhardt] {
            let (mut h, base) = host(&[0], "");
            let mut c = join(&mut h, base, 0, 0, dialect);
            assert!(publish(&mut h, 0, 0, 0));
            let (fields, _) = c.cycle();
            let images = fields.iter().position(|&f| f == field::IMAGES).unwrap();
            let grid = fields
                .iter()
                .position(|&f| f == field::GRID_POSITION)
                .unwrap();
            let start = fields.iter().position(|&f| f == field::START_SYNC).unwrap();
            assert!(images < grid && grid < start, "{fields:?}");
            c.movement(41);
            c.frame(&[]);
            let mut got = Vec::new();
            pump(&mut h, |h| {
                got.extend(drain(h));
                got.iter().any(|b| b.2)
            });
            let commands: Vec<_> = got
                .iter()
                .flat_map(|b| b.3.iter().map(|c| c.action_id))
                .collect();
            assert_eq!(commands, [41]);
            assert!(got.iter().all(|b| b.1 == 0));
            // Acknowledged on receipt: Walking for a movement.
            assert_eq!(c.status(), (41, ActionState::Walking as i32));
        }
    }

    #[test]
    fn a_stop_while_no_cycle_is_open_ends_the_next_and_is_counted() {
        let (mut h, base) = host(&[0], "");
        let mut c = join(&mut h, base, 0, 0, Dialect::Vrnew);
        assert!(publish(&mut h, 0, 0, 0));
        c.cycle();
        c.frame(&[0xAA, 0x01, 0x00]); // a real StopSync
        pump(&mut h, |h| drain(h).iter().any(|b| b.2 && b.1 == 0));
        c.frame(&[]); // no cycle open
        pump(&mut h, |h| h.stats().stops_without_cycle == 1);
        assert!(publish(&mut h, 0, 1, 0));
        let got = drain(&mut h);
        assert_eq!(got.len(), 1);
        assert_eq!((got[0].1, got[0].2), (1, true));
    }

    #[test]
    fn bad_frames_are_refused_and_the_connection_and_other_agents_go_on() {
        let (mut h, base) = host(&[0, 1], "");
        let mut a = join(&mut h, base, 0, 0, Dialect::Burkhardt);
        let mut b = join(&mut h, base, 1, 1, Dialect::Vrnew);
        assert!(publish(&mut h, 0, 0, 0));
        assert!(publish(&mut h, 1, 0, 0));
        a.cycle();
        b.cycle();
        // Garbage, an unknown field, two messages, an oversize frame: each refused.
        a.frame(&[0xFF; 9]);
        a.frame(&[0x8A, 0x02, 0x00]);
        a.frame(&[0x0A, 0x00, 0xAA, 0x01, 0x00]);
        a.raw(&(MAX_INCOMING_FRAME as i32 + 1).to_le_bytes());
        a.raw(&vec![0x0A; MAX_INCOMING_FRAME + 1]);
        // A command with a non-finite argument: answered Aborted, not applied.
        a.message(
            field::AGENT_MOVEMENT,
            &AgentMovement {
                action_id: Some(5),
                degree: Some(f32::NAN),
                distance: Some(1.0),
            },
        );
        a.frame(&[]);
        let mut got = Vec::new();
        pump(&mut h, |h| {
            got.extend(drain(h));
            got.iter().any(|b| b.0 == 0 && b.2)
        });
        assert!(
            got.iter().all(|b| b.3.is_empty()),
            "nothing applied: {got:?}"
        );
        assert_eq!(h.stats().frames_refused, 4);
        assert_eq!(a.status(), (5, ActionState::Aborted as i32));
        // A negative length ends that connection, not the other agent's.
        a.raw(&(-1i32).to_le_bytes());
        pump(&mut h, |h| !h.is_connected(0));
        assert!(a.closed());
        b.frame(&[]);
        pump(&mut h, |h| drain(h).iter().any(|x| x.0 == 1 && x.2));
        assert!(h.is_connected(1));
    }

    #[test]
    fn a_truncated_frame_is_not_applied() {
        let (mut h, base) = host(&[0], "");
        let mut c = join(&mut h, base, 0, 0, Dialect::Vrnew);
        assert!(publish(&mut h, 0, 0, 0));
        c.cycle();
        let mut out = Vec::new();
        codec::push_message(
            &mut out,
            field::AGENT_MOVEMENT,
            &AgentMovement {
                action_id: Some(9),
                degree: Some(1.0),
                distance: Some(1.0),
            },
        );
        c.raw(&out[..out.len() - 2]);
        drop(c);
        pump(&mut h, |h| !h.is_connected(0));
        assert!(drain(&mut h).is_empty());
    }

    #[test]
    fn a_second_connection_replaces_the_first_and_a_silent_one_replaces_nothing() {
        let (mut h, base) = host(&[0], "");
        h.hello_timeout = Duration::from_millis(200);
        let mut first = join(&mut h, base, 0, 0, Dialect::Vrnew);
        // Connects and says nothing: dropped after the version-check timeout; the first
        // connection stays.
        let mut silent = Client::connect(base + 1);
        pump(&mut h, |h| h.slots[0].pending.len() == 1);
        pump(&mut h, |h| h.slots[0].pending.is_empty());
        assert!(silent.closed());
        let mut refused = Vec::new();
        assert_eq!(h.take_refusals(&mut |r| refused.push(r.kind)), 0);
        assert_eq!(refused, [RefusalKind::Silent]);
        assert!(h.is_connected(0));
        // A real second client replaces the first.
        let mut second = join(&mut h, base, 0, 0, Dialect::Burkhardt);
        assert!(first.closed());
        assert!(publish(&mut h, 0, 0, 0));
        second.cycle();
    }

    #[test]
    fn a_flood_of_commands_is_bounded_per_cycle_and_the_rest_aborted() {
        let (mut h, base) = host(&[0], "");
        let mut c = join(&mut h, base, 0, 0, Dialect::Vrnew);
        assert!(publish(&mut h, 0, 0, 0));
        c.cycle();
        for id in 0..20 {
            c.movement(id);
        }
        c.frame(&[]);
        let mut got = Vec::new();
        pump(&mut h, |h| {
            got.extend(drain(h));
            got.iter().any(|b| b.2)
        });
        let applied: Vec<u32> = got
            .iter()
            .flat_map(|b| b.3.iter().map(|c| c.action_id))
            .collect();
        assert_eq!(applied, (0..8).collect::<Vec<_>>());
        let statuses: Vec<_> = (0..20).map(|_| c.status()).collect();
        for (id, st) in statuses {
            let want = if id < 8 {
                ActionState::Walking
            } else {
                ActionState::Aborted
            };
            assert_eq!(st, want as i32, "action {id}");
        }
        assert_eq!(h.stats().commands_refused, 12);
    }

    #[test]
    fn environment_resets_ride_with_their_clients_agent_and_rejected_commands_end_aborted() {
        let (mut h, base) = host(&[2, 5], "");
        let mut env = Client::connect(base);
        let mut a = join(&mut h, base, 2, 0, Dialect::Vrnew);
        let _b = join(&mut h, base, 5, 1, Dialect::Vrnew);
        assert!(publish(&mut h, 0, 0, 0));
        a.cycle();
        env.message(
            field::TRIAL_RESET,
            &Reset {
                reset_type: Some(3),
            },
        );
        a.movement(77);
        a.frame(&[]);
        let mut got = Vec::new();
        pump(&mut h, |h| {
            got.extend(drain(h));
            got.iter().any(|b| b.2) && got.iter().map(|b| b.3.len()).sum::<usize>() == 2
        });
        let reset = got
            .iter()
            .flat_map(|b| b.3.iter())
            .find(|c| c.action_id == RESET_ACTION_ID)
            .unwrap();
        assert_eq!(reset.decode(), Ok(Command::TrialReset { reset_type: 3 }));
        assert!(got.iter().all(|b| b.0 == 0));
        assert_eq!(a.status(), (77, ActionState::Walking as i32));
        // The simulator rejected one command of cycle 0 and reported no status for it.
        assert!(publish(&mut h, 0, 1, 1));
        let (_, statuses) = a.cycle();
        assert_eq!(statuses, [(77, ActionState::Aborted as i32)]);
        assert_eq!(h.stats().commands_rejected, 1);
    }

    fn reset_frame(reset_type: i32) -> Vec<u8> {
        let mut out = Vec::new();
        codec::push_message(
            &mut out,
            field::TRIAL_RESET,
            &Reset {
                reset_type: Some(reset_type),
            },
        );
        out
    }

    /// The resets (by type) handed over for each slot until `want` have come.
    fn resets_until(h: &mut LegacyHost, want: usize) -> Vec<(usize, Command)> {
        let mut got = Vec::new();
        pump(h, |h| {
            for (slot, _, _, commands) in drain(h) {
                for c in commands {
                    if c.action_id == RESET_ACTION_ID {
                        got.push((slot, c.decode().unwrap()));
                    }
                }
            }
            got.len() >= want
        });
        got
    }

    /// Issue 22: a peer holding 16 silent environment connections no longer locks a client
    /// out; the oldest unpaired one makes room, and the client's first reset reaches its
    /// agent.
    #[test]
    fn sixteen_silent_environment_connections_do_not_lock_a_client_out() {
        let (mut h, base) = host(&[0], "");
        let mut silent: Vec<Client> = (0..MAX_ENV_CONNS).map(|_| Client::connect(base)).collect();
        pump(&mut h, |h| h.env_conns.len() == MAX_ENV_CONNS);
        let mut env = Client::connect(base);
        let mut c = join(&mut h, base, 0, 0, Dialect::Burkhardt);
        // The oldest silent one was closed to make room; the client's is paired.
        assert!(silent[0].closed());
        assert_eq!(h.env_conns.len(), MAX_ENV_CONNS + 1 - 1);
        let me = env.s.local_addr().unwrap();
        assert!(
            h.env_conns
                .iter()
                .any(|e| e.peer == me && h.env_paired(e) && e.agent.map(|a| a.0) == Some(0))
        );
        let mut refused = Vec::new();
        h.take_refusals(&mut |r| refused.push(r.kind));
        assert_eq!(refused, [RefusalKind::TooMany]);
        assert!(publish(&mut h, 0, 0, 0));
        c.cycle();
        env.raw(&reset_frame(4));
        c.frame(&[]);
        assert_eq!(
            resets_until(&mut h, 1),
            [(0, Command::TrialReset { reset_type: 4 })]
        );
        // More strangers push out strangers, never the paired connection.
        let more: Vec<Client> = (0..MAX_ENV_CONNS).map(|_| Client::connect(base)).collect();
        // 15 strangers were unpaired: the first new one fits, each further one closes
        // the oldest unpaired.
        let mut refused = 0;
        pump(&mut h, |h| {
            h.take_refusals(&mut |r| {
                assert_eq!(r.kind, RefusalKind::TooMany);
                refused += 1;
            });
            refused == MAX_ENV_CONNS - 1
        });
        assert_eq!(h.env_conns.len(), MAX_ENV_CONNS + 1);
        env.raw(&reset_frame(5));
        assert!(publish(&mut h, 0, 1, 0));
        assert_eq!(
            resets_until(&mut h, 1),
            [(0, Command::TrialReset { reset_type: 5 })]
        );
        drop((more, silent));
    }

    /// Environment connections get the agent sockets' timeouts: a half frame stalled past
    /// the stall timeout, a huge length, and a connection no agent connection of its
    /// client follows within the hello timeout are closed (reported as refused peers); a
    /// paired, silent connection stays.
    #[test]
    fn stalled_huge_and_unpaired_environment_connections_are_closed() {
        let (mut h, base) = host(&[0], "");
        h.stall_timeout = Duration::from_millis(300);
        h.hello_timeout = Duration::from_millis(600);
        let mut env = Client::connect(base);
        let _c = join(&mut h, base, 0, 0, Dialect::Vrnew);
        let mut half = Client::connect(base);
        half.raw(&[9, 0]);
        let mut huge = Client::connect(base);
        huge.raw(&(1i32 << 30).to_le_bytes());
        let mut unpaired = Client::connect(base);
        let started = Instant::now();
        let mut kinds = Vec::new();
        pump(&mut h, |h| {
            h.take_refusals(&mut |r| kinds.push((r.kind, r.peer.clone())));
            kinds.len() == 3
        });
        let took = started.elapsed();
        assert!(half.closed() && huge.closed() && unpaired.closed());
        let of = |c: &Client| c.s.local_addr().unwrap().to_string();
        let kind_of = |c: &Client| kinds.iter().find(|k| k.1 == of(c)).map(|k| k.0);
        assert_eq!(kind_of(&half), Some(RefusalKind::Malformed));
        assert_eq!(kind_of(&huge), Some(RefusalKind::Malformed));
        assert_eq!(kind_of(&unpaired), Some(RefusalKind::Silent));
        assert!(took >= Duration::from_millis(600), "{took:?}");
        // The paired connection, silent all along, still carries a reset.
        assert_eq!(h.env_conns.len(), 1);
        env.raw(&reset_frame(1));
        pump(&mut h, |h| h.slots[0].queued.len() == 1);
    }

    /// A client process run by `bash` (its `/dev/tcp`): it opens its environment
    /// connection, then its agent connection (with a version check), and sends resets on
    /// the first, as told on its stdin. The host pairs by owner process, so two such
    /// clients connecting interleaved are told apart.
    struct BashClient {
        child: std::process::Child,
        stdin: std::process::ChildStdin,
    }

    impl BashClient {
        fn spawn() -> Self {
            let script = r#"while read -r cmd arg; do
                case $cmd in
                  env) exec 3<>/dev/tcp/127.0.0.1/$arg ;;
                  agent) exec 4<>/dev/tcp/127.0.0.1/${arg%% *}; printf "${arg#* }" >&4 ;;
                  send) printf "$arg" >&3 ;;
                esac
              done"#;
            let mut child = std::process::Command::new("bash")
                .args(["-c", script])
                .stdin(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            let stdin = child.stdin.take().unwrap();
            Self { child, stdin }
        }

        fn tell(&mut self, line: &str) {
            writeln!(self.stdin, "{line}").unwrap();
        }
    }

    impl Drop for BashClient {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    fn escaped(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("\\x{b:02x}")).collect()
    }

    /// Issue 22: each client's resets reach its own agent, also when two client
    /// processes connect interleaved (A's environment connection, B's, A's agent, B's
    /// agent: by connect order alone, A's agent would take B's).
    #[test]
    fn resets_reach_the_agent_whose_client_process_sent_them() {
        let (mut h, base) = host(&[0, 1], "");
        let mut version = Vec::new();
        codec::push_message(
            &mut version,
            Dialect::Vrnew.version_check_field(),
            &VersionCheck {
                version: Some("1.0".into()),
            },
        );
        let (mut a, mut b) = (BashClient::spawn(), BashClient::spawn());
        a.tell(&format!("env {base}"));
        pump(&mut h, |h| h.env_conns.len() == 1);
        b.tell(&format!("env {base}"));
        pump(&mut h, |h| h.env_conns.len() == 2);
        a.tell(&format!("agent {} {}", base + 1, escaped(&version)));
        pump(&mut h, |h| h.is_connected(0));
        b.tell(&format!("agent {} {}", base + 2, escaped(&version)));
        pump(&mut h, |h| h.is_connected(1));
        assert!(publish(&mut h, 0, 0, 0) && publish(&mut h, 1, 0, 0));
        a.tell(&format!("send {}", escaped(&reset_frame(10))));
        b.tell(&format!("send {}", escaped(&reset_frame(20))));
        let mut got = Vec::new();
        pump(&mut h, |h| {
            got.extend(
                h.slots
                    .iter_mut()
                    .flat_map(|s| s.batch.drain(..).map(|c| (s.id, c.decode()))),
            );
            got.len() == 2
        });
        got.sort_by_key(|g| g.0);
        assert_eq!(
            got,
            [
                (0, Ok(Command::TrialReset { reset_type: 10 })),
                (1, Ok(Command::TrialReset { reset_type: 20 })),
            ]
        );
    }
}
