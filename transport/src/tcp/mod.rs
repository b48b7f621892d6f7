//! The TCP transport: the same protocol for agents on other hosts, and the baseline the
//! shared-memory transport is measured against.
//!
//! Every record is `[len: u32 LE][kind: u32 LE][body: len bytes]`. Agents connect and send
//! [`kind::HELLO`] (magic, protocol version, layout hash, agent id, optional token); the host
//! answers [`kind::WELCOME`] (with the largest frame it will send) or [`kind::REJECT`] (a
//! reason) and closes. Then the host sends one [`kind::FRAME`] per cycle (sensor header +
//! images, which doubles as *start*), the agent answers [`kind::MOTOR`] batches (motor
//! header + commands; the stop flag ends its cycle), and [`kind::SHUTDOWN`] closes the
//! session.
//!
//! The host renders straight into a per-agent record buffer laid out exactly as it goes on
//! the wire, and sends it with one write: no per-frame allocation, no extra copy. Sockets
//! use `TCP_NODELAY`. Reads are bounded: a length beyond the peer's maximum is an error,
//! never an allocation. The host never blocks on reading: it waits for readiness on an
//! epoll set of all its sockets at once.
//!
//! # What a hostile or broken peer costs the host
//! Every record is read by a [`RecordReader`]: one buffer of the largest acceptable record,
//! allocated when the connection is accepted, never grown. Each misbehaviour drops that one
//! connection with a logged reason (`TCP peer dropped: …` before the hello, `TCP agent
//! dropped: …` after it); the host and the other agents go on.
//! - garbage, a wrong record kind, a length beyond the maximum ([`MAX_HELLO`] before the
//!   hello, the largest motor batch after it), a malformed hello or batch: dropped at once;
//! - a truncated record and a close: dropped when the close is read;
//! - wrong protocol version or layout, an agent id not in the session, an id already
//!   connected, a wrong or missing `tcp_token`: a [`kind::REJECT`] saying why (a version
//!   reject names both versions), then closed;
//! - a peer that connects and says nothing, or stalls in the middle of its hello: dropped
//!   [`HELLO_TIMEOUT`] after it connected; at most [`MAX_PENDING`] connections wait for
//!   their hello at once, more are closed at once;
//! - an admitted agent that stalls in the middle of a record: dropped once the record is
//!   not complete [`STALL_TIMEOUT`] (or the `stop_timeout`, if shorter) after its first
//!   bytes were seen; it is then no longer connected (with a resume window: once the
//!   window has passed, see below), so the barrier stops waiting for it;
//! - an agent that stops reading its frames: dropped when a frame cannot be written within
//!   the `stop_timeout` (at least 1 s);
//! - a flood of batches: each drain takes at most [`MAX_RECORDS_PER_DRAIN`] records per
//!   agent, so one agent cannot hold the host inside a drain.
//!
//! # A lost link (`[sync] resume_window`)
//! With a resume window (30 s by default), a connection that times out, stalls mid-record
//! or cannot take its frame is a lost link, not the agent's end: the host holds the
//! agent's place for the window (a reset connection for [`RESET_GRACE`]) and it counts as
//! connected (frames published to it meanwhile count as delivered and wait for it), so in
//! sync mode the cycle waits for its stop. A hello of that id within the window takes the
//! place again, and the frame published last goes out again unless its stop arrived. Past
//! the window the place is let go: the agent is no longer connected and the host evicts
//! it. A close (the agent's process ended) and a protocol violation end the connection at
//! once, as without a window. Both sides watch the link ([`LINK_TIMEOUT`]). The agent
//! connects again by itself and sends its stop again if the host asks for that cycle
//! again ([`TcpAgent`]).

use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant};

use tracing::{debug, info, warn};
use zerocopy::{FromBytes, IntoBytes};

pub use super::record::*;
use super::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, Attempt, BatchSink, FrameLoanMut, HostConnections, HostLiveness, HostReadiness,
    HostTransport, HostTransportError, retry_until,
};
use crate::config::Config;
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};

/// How long a new connection may take to say hello.
pub const HELLO_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a record may stay incomplete once its first bytes arrived from an admitted
/// agent (the host uses the `stop_timeout` instead when that is shorter). A working agent
/// writes each record in one go, so the rest follows within a network round trip.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(2);
/// Most connections that may wait for their hello at once; more are closed at once.
pub const MAX_PENDING: usize = 64;
/// Most records read from one agent in one [`HostTransport::drain`] call; the rest is read
/// by the next call.
pub const MAX_RECORDS_PER_DRAIN: usize = 256;

fn set_nodelay(s: &TcpStream) -> io::Result<()> {
    s.set_nodelay(true)
}

/// With a resume window (`[sync] resume_window`), how long either side of a connection
/// goes without an answer from the other before it declares the link lost: keep-alive
/// probes every second while idle, and `TCP_USER_TIMEOUT` for data not acknowledged.
/// (Without a window the connection lives as long as TCP keeps it: a long partition is
/// waited out, up to TCP's own retransmission limit of many minutes.)
pub const LINK_TIMEOUT: Duration = Duration::from_secs(10);

/// Makes the kernel declare `s`'s link lost after [`LINK_TIMEOUT`] without an answer
/// (the next read or write then fails with `TimedOut`).
fn watch_link(s: &TcpStream) -> io::Result<()> {
    let secs = LINK_TIMEOUT.as_secs() as libc::c_int;
    let options = [
        (libc::SOL_SOCKET, libc::SO_KEEPALIVE, 1),
        (libc::IPPROTO_TCP, libc::TCP_KEEPIDLE, 1),
        (libc::IPPROTO_TCP, libc::TCP_KEEPINTVL, 1),
        (libc::IPPROTO_TCP, libc::TCP_KEEPCNT, secs),
        (libc::IPPROTO_TCP, libc::TCP_USER_TIMEOUT, secs * 1000),
    ];
    for (level, name, value) in options {
        // SAFETY: setsockopt(2) on a socket we own, with a pointer to a c_int and its size.
        let rc = unsafe {
            libc::setsockopt(
                s.as_raw_fd(),
                level,
                name,
                (&raw const value).cast(),
                core::mem::size_of::<libc::c_int>() as libc::socklen_t,
            )
        };
        if rc != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    Ok(())
}

/// With a resume window, how long the host holds the place of an agent whose connection
/// was reset: not the whole window, since a process killed with a frame it had not read
/// resets its connection too, while an agent whose link was reset connects again at once.
pub const RESET_GRACE: Duration = Duration::from_secs(2);

/// How an admitted agent's connection ended, as the host sees it (and so how long it
/// holds the agent's place, with a resume window).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Loss {
    /// The agent's own end (a close: its process ended) or a protocol violation: not held.
    Ended,
    /// A reset: a process killed with a frame it had not read, or a link reset on the way
    /// (a middlebox, the agent's side of a link that timed out). The host cannot tell them
    /// apart; an agent whose link was reset connects again at once, so its place is held
    /// for [`RESET_GRACE`] (at most the window).
    Reset,
    /// The link timed out, was unreachable, or could not carry a record or a frame in
    /// time: held for the resume window.
    Lost,
}

/// What an I/O error on an agent's connection means.
fn loss_of(e: &io::Error) -> Loss {
    match e.kind() {
        ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted | ErrorKind::BrokenPipe => {
            Loss::Reset
        }
        ErrorKind::TimedOut
        | ErrorKind::HostUnreachable
        | ErrorKind::NetworkUnreachable
        | ErrorKind::NetworkDown => Loss::Lost,
        _ => Loss::Ended,
    }
}

/// Whether an I/O error means the link to the peer broke (reset, timed out, unreachable)
/// rather than that the peer spoke nonsense.
fn link_lost(e: &io::Error) -> bool {
    loss_of(e) != Loss::Ended
}

fn write_record(stream: &mut TcpStream, kind: u32, body: &[u8]) -> io::Result<()> {
    let mut prefix = [0u8; PREFIX];
    prefix[..4].copy_from_slice(&(body.len() as u32).to_le_bytes());
    prefix[4..].copy_from_slice(&kind.to_le_bytes());
    // One vectored write for prefix + body; fall back to write_all for the remainder.
    let bufs = [io::IoSlice::new(&prefix), io::IoSlice::new(body)];
    let mut written = stream.write_vectored(&bufs)?;
    if written < PREFIX {
        stream.write_all(&prefix[written..])?;
        written = PREFIX;
    }
    stream.write_all(&body[written - PREFIX..])
}

/// Reads exactly `buf.len()` bytes, with `deadline` for the whole read.
fn read_exact_deadline(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
) -> io::Result<()> {
    let mut done = 0;
    while done < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::Error::new(
                ErrorKind::TimedOut,
                "peer stalled mid-record",
            ));
        }
        stream.set_read_timeout(Some(left))?;
        match stream.read(&mut buf[done..]) {
            Ok(0) => {
                return Err(io::Error::new(
                    ErrorKind::UnexpectedEof,
                    "connection closed",
                ));
            }
            Ok(n) => done += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Size of the sensor header at the start of a frame record.
const HEADER: usize = core::mem::size_of::<SensorHeader>();

mod agent;
mod hellos;
mod host;
#[cfg(test)]
mod resume_tests;

pub use agent::*;
pub use host::*;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wait;
    use std::io::Read;

    // --- TcpHost against raw sockets (no simulator) ------------------------------------

    /// A TCP host of agents 0 and 1 without a resume window (a lost link ends the
    /// connection: what these tests look at).
    fn tcp_host(stop_timeout: f64) -> TcpHost {
        let text = format!(
            "[sync]\nstop_timeout = {stop_timeout}\nresume_window = 0\n[transport]\nkind = \"tcp\"\n\
             tcp_listen = \"127.0.0.1:0\"\n\
             [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n\
             [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n"
        );
        let config = Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap();
        TcpHost::create(&config, SignalHandling::Leave).unwrap()
    }

    fn say_hello(host: &TcpHost, id: u32) -> TcpStream {
        let mut s = TcpStream::connect(host.local_addr()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        let hello = Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            channels: crate::ChannelLayout::default().hash(),
            token: Vec::new(),
        };
        write_record(&mut s, kind::HELLO, &encode_hello(&hello)).unwrap();
        s
    }

    fn read_reply(s: &mut TcpStream) -> (u32, Vec<u8>) {
        let mut prefix = [0u8; PREFIX];
        s.read_exact(&mut prefix).unwrap();
        let (len, k) = decode_prefix(prefix, 4096).unwrap();
        let mut body = vec![0u8; len];
        s.read_exact(&mut body).unwrap();
        (k, body)
    }

    /// Runs the host's wait/drain loop until `done` holds; panics after 20 s.
    fn pump(host: &mut TcpHost, drain: bool, what: &str, done: impl Fn(&TcpHost) -> bool) {
        let deadline = Instant::now() + Duration::from_secs(20);
        while !done(host) {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            host.wait_activity(Duration::from_millis(50)).unwrap();
            if drain {
                host.drain(&mut |_, _, _| {}).unwrap();
            }
        }
    }

    fn motor_record(cycle: u64) -> Vec<u8> {
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: 0,
            cycle,
            flags: crate::wire::MOTOR_FLAG_STOP,
            command_count: 0,
            ack_cycle: 0,
        };
        let mut r = Vec::new();
        r.extend_from_slice(&(header.as_bytes().len() as u32).to_le_bytes());
        r.extend_from_slice(&kind::MOTOR.to_le_bytes());
        r.extend_from_slice(header.as_bytes());
        r
    }

    #[test]
    fn an_agent_stalling_mid_record_is_dropped_and_the_other_goes_on() {
        let mut host = tcp_host(0.2);
        let mut a0 = say_hello(&host, 0);
        let mut a1 = say_hello(&host, 1);
        pump(&mut host, false, "both agents", |h| {
            h.is_connected(0) && h.is_connected(1)
        });
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        assert_eq!(read_reply(&mut a1).0, kind::WELCOME);
        // Agent 0: a prefix and half a batch, then silence with the socket open.
        let rec = motor_record(0);
        a0.write_all(&rec[..PREFIX + 10]).unwrap();
        // Agent 1: a whole batch.
        a1.write_all(&motor_record(0)).unwrap();
        let got = std::cell::Cell::new(0);
        let deadline = Instant::now() + Duration::from_secs(20);
        while host.is_connected(0) {
            assert!(Instant::now() < deadline, "stalled agent never dropped");
            host.wait_activity(Duration::from_millis(500)).unwrap();
            host.drain(&mut |slot, h, _| {
                assert_eq!((slot, h.cycle), (1, 0));
                got.set(got.get() + 1);
            })
            .unwrap();
        }
        assert_eq!(got.get(), 1, "agent 1's batch arrives");
        assert!(host.is_connected(1));
        // The stalled agent's socket is closed by the host.
        let mut b = [0u8; 1];
        assert_eq!(a0.read(&mut b).unwrap_or(0), 0);
    }

    #[test]
    fn an_oversized_motor_prefix_drops_the_agent_without_reading_the_body() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        let mut prefix = [0u8; PREFIX];
        prefix[..4].copy_from_slice(&u32::MAX.to_le_bytes());
        prefix[4..].copy_from_slice(&kind::MOTOR.to_le_bytes());
        a0.write_all(&prefix).unwrap();
        pump(&mut host, true, "agent 0 dropped", |h| !h.is_connected(0));
    }

    #[test]
    fn silent_connections_are_bounded_and_time_out() {
        let mut host = tcp_host(5.0);
        let extra = 5;
        let mut silent: Vec<TcpStream> = (0..MAX_PENDING + extra)
            .map(|_| TcpStream::connect(host.local_addr()).unwrap())
            .collect();
        pump(&mut host, false, "the listen queue to empty", |h| {
            h.pending.len() == MAX_PENDING
        });
        // Exactly `extra` of them were closed at once; the rest wait for their hello.
        let closed = silent
            .iter_mut()
            .filter_map(|s| {
                s.set_nonblocking(true).unwrap();
                matches!(s.read(&mut [0u8; 1]), Ok(0)).then_some(())
            })
            .count();
        assert_eq!(closed, extra);
        pump(&mut host, false, "the hello timeout", |h| {
            h.pending.is_empty()
        });
        // A real agent still gets in.
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
    }

    /// Forwards bytes from `from` to `to` until either side ends, then shuts `to` down.
    fn forward(mut from: TcpStream, mut to: TcpStream) -> std::thread::JoinHandle<()> {
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut from, &mut to);
            let _ = to.shutdown(std::net::Shutdown::Both);
        })
    }

    /// A tunnel or relay that accepts the agent's connection before it can reach the host
    /// closes it unanswered: the agent tries again until its connect timeout, and the
    /// next connection, relayed, is welcomed.
    #[test]
    fn an_agent_whose_hello_is_closed_unanswered_tries_again() {
        let mut host = tcp_host(5.0);
        let host_addr = host.local_addr();
        let relay = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let relay_addr = relay.local_addr().unwrap();
        let relaying = std::thread::spawn(move || {
            drop(relay.accept().unwrap());
            let (agent, _) = relay.accept().unwrap();
            let host = TcpStream::connect(host_addr).unwrap();
            for s in [&agent, &host] {
                s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
            }
            let up = forward(agent.try_clone().unwrap(), host.try_clone().unwrap());
            let down = forward(host, agent);
            (up, down)
        });
        let text = format!(
            "[transport]\nkind = \"tcp\"\ntcp_listen = \"{relay_addr}\"\n\
             [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n\
             [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n"
        );
        let config = Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap();
        // The agent (not `Send`) lives in its thread until the host has seen it.
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let connecting = std::thread::spawn(move || {
            let agent =
                TcpAgent::connect(&config, 0, Duration::from_secs(20), SignalHandling::Leave)?;
            let _ = done_rx.recv_timeout(Duration::from_secs(20));
            Ok::<u32, AgentConnectError>(agent.id())
        });
        pump(&mut host, false, "agent 0 through the relay", |h| {
            h.is_connected(0)
        });
        done_tx.send(()).unwrap();
        assert_eq!(connecting.join().unwrap().unwrap(), 0);
        let (up, down) = relaying.join().unwrap();
        up.join().unwrap();
        down.join().unwrap();
    }

    #[test]
    fn an_agent_reconnecting_after_a_close_replaces_its_old_connection() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // A second connection while the first is alive is refused.
        let mut twin = say_hello(&host, 0);
        let (k, body) = read_reply_pumping(&mut host, &mut twin);
        assert_eq!(k, kind::REJECT);
        assert_eq!(Reject::decode(&body).unwrap().code, reject::ID_IN_USE);
        // Once it closed, a new one takes its place, even when the host does not drain
        // (it waits for agents, not for stops): after the hello timeout at the latest.
        drop(a0);
        let mut again = say_hello(&host, 0);
        let (k, _) = read_reply_pumping(&mut host, &mut again);
        assert_eq!(k, kind::WELCOME);
        assert!(host.is_connected(0));
    }

    #[test]
    fn a_closed_connections_last_batch_is_read_before_its_successor_is_admitted() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // The agent stops its cycle and closes; a new connection of its id says hello
        // before the host drained the old one (an agent that leaves and reconnects at once).
        a0.write_all(&motor_record(0)).unwrap();
        drop(a0);
        let again = say_hello(&host, 0);
        pump(&mut host, false, "the new hello", |h| {
            h.pending.first().is_some_and(|p| p.hello.is_some())
        });
        // It waits: the host has not seen the old connection go.
        assert!(host.slots[0].conn.is_some());
        // The drain delivers the old connection's stop and sees it closed...
        let got = std::cell::Cell::new(0);
        let deadline = Instant::now() + Duration::from_secs(20);
        while host.is_connected(0) {
            assert!(
                Instant::now() < deadline,
                "the old connection is never let go"
            );
            host.drain(&mut |slot, h, _| {
                assert_eq!((slot, h.cycle), (0, 0));
                got.set(got.get() + 1);
            })
            .unwrap();
        }
        assert_eq!(got.get(), 1, "the old connection's stop arrives");
        // ...and the next wait admits the new one at once.
        host.wait_activity(Duration::from_secs(20)).unwrap();
        assert!(host.is_connected(0));
        assert!(host.pending.is_empty());
        let mut again = again;
        assert_eq!(read_reply(&mut again).0, kind::WELCOME);
    }

    #[test]
    fn waiting_without_draining_does_not_spin_on_unread_agent_bytes() {
        let mut host = tcp_host(5.0);
        let mut a0 = say_hello(&host, 0);
        pump(&mut host, false, "agent 0", |h| h.is_connected(0));
        assert_eq!(read_reply(&mut a0).0, kind::WELCOME);
        // Bytes the host does not read while it waits for agent 1 to connect.
        a0.write_all(&motor_record(0)).unwrap();
        pump(&mut host, false, "agent 0's bytes", |h| h.unread);
        // The next wait returns at once (the bytes are still there) and mutes the agent
        // sockets: the one after it sleeps its whole timeout instead of spinning, while
        // the listener is still watched.
        host.wait_activity(Duration::from_millis(1)).unwrap();
        assert!(host.muted);
        assert!(!wait::readable_now(host.activity_fd()), "still ready");
        let mut a1 = say_hello(&host, 1);
        pump(&mut host, false, "agent 1", |h| h.is_connected(1));
        assert_eq!(read_reply(&mut a1).0, kind::WELCOME);
        // A drain reads the bytes and the sockets are watched again.
        let got = std::cell::Cell::new(0);
        host.drain(&mut |_, _, _| got.set(got.get() + 1)).unwrap();
        assert_eq!(got.get(), 1);
        assert!(!host.muted);
        a0.write_all(&motor_record(1)).unwrap();
        pump(&mut host, false, "agent 0's next bytes", |h| h.unread);
    }

    fn read_reply_pumping(host: &mut TcpHost, s: &mut TcpStream) -> (u32, Vec<u8>) {
        s.set_nonblocking(true).unwrap();
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            assert!(Instant::now() < deadline, "no reply");
            host.wait_activity(Duration::from_millis(20)).unwrap();
            if matches!(s.peek(&mut [0u8; 1]), Ok(1)) {
                break;
            }
        }
        s.set_nonblocking(false).unwrap();
        read_reply(s)
    }
}
