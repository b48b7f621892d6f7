//! A lost link that comes back (`[sync] resume_window`): the host holds the agent's place
//! and sends its frame again, the agent connects again by itself and sends its stop again;
//! a host that is gone, or a link not back within the window, ends it.

use super::*;
use crate::{AgentWaitError, wait_for_newer_frame};
use std::io::Read;

fn config(addr: SocketAddr, resume_window: f64) -> Config {
    let text = format!(
        "[sync]\nstop_timeout = 5.0\nresume_window = {resume_window:?}\n[transport]\n\
         kind = \"tcp\"\ntcp_listen = \"{addr}\"\n\
         [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n"
    );
    Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap()
}

/// Closes `s` with a reset (as a link reset or a middlebox does), not a close.
fn reset(s: TcpStream) {
    let linger = libc::linger {
        l_onoff: 1,
        l_linger: 0,
    };
    // SAFETY: setsockopt(2) on a socket we own, with a pointer to a linger and its size.
    let rc = unsafe {
        libc::setsockopt(
            s.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_LINGER,
            (&raw const linger).cast(),
            core::mem::size_of::<libc::linger>() as libc::socklen_t,
        )
    };
    assert_eq!(rc, 0);
}

fn hello(id: u32) -> Vec<u8> {
    encode_hello(&Hello {
        protocol_version: PROTOCOL_VERSION,
        layout_hash: LAYOUT_HASH,
        agent_id: id,
        channels: crate::ChannelLayout::default().hash(),
        token: Vec::new(),
    })
}

fn read_record(s: &mut TcpStream) -> (u32, Vec<u8>) {
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut prefix = [0u8; PREFIX];
    s.read_exact(&mut prefix).unwrap();
    let (len, k) = decode_prefix(prefix, 1 << 20).unwrap();
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).unwrap();
    (k, body)
}

fn frame_cycle(body: &[u8]) -> u64 {
    SensorHeader::read_from_bytes(&body[..HEADER])
        .unwrap()
        .cycle
}

fn stop_record(cycle: u64, commands: u32) -> Vec<u8> {
    let header = MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: 0,
        cycle,
        flags: crate::wire::MOTOR_FLAG_STOP,
        command_count: commands,
        ack_cycle: 0,
    };
    let commands = vec![MotorCommand::default(); commands as usize];
    let body = [header.as_bytes(), commands.as_bytes()].concat();
    let mut r = (body.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(&kind::MOTOR.to_le_bytes());
    r.extend_from_slice(&body);
    r
}

// --- The host side, against raw sockets ------------------------------------------------

fn host(resume_window: f64) -> TcpHost {
    let addr = "127.0.0.1:0".parse().unwrap();
    TcpHost::create(&config(addr, resume_window), SignalHandling::Leave).unwrap()
}

/// Says hello as agent 0 and reads the welcome, running the host's wait meanwhile.
fn join(host: &mut TcpHost) -> TcpStream {
    let mut s = TcpStream::connect(host.local_addr()).unwrap();
    write_record(&mut s, kind::HELLO, &hello(0)).unwrap();
    s.set_nonblocking(true).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !matches!(s.peek(&mut [0u8; 1]), Ok(1)) {
        assert!(Instant::now() < deadline, "no welcome");
        host.wait_activity(Duration::from_millis(20)).unwrap();
    }
    s.set_nonblocking(false).unwrap();
    assert_eq!(read_record(&mut s).0, kind::WELCOME);
    s
}

fn publish(host: &mut TcpHost, cycle: u64) -> bool {
    let mut loan = host.loan(0).unwrap();
    loan.parts_mut().0.cycle = cycle;
    host.publish(0, loan).unwrap()
}

/// Runs the host's wait and drain until `done`; returns the stops drained meanwhile.
fn pump(host: &mut TcpHost, what: &str, done: impl Fn(&TcpHost) -> bool) -> Vec<u64> {
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut stops = Vec::new();
    while !done(host) {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        host.wait_activity(Duration::from_millis(20)).unwrap();
        host.drain(&mut |_, h, _| stops.push(h.cycle)).unwrap();
    }
    stops
}

#[test]
fn the_host_holds_a_lost_agents_place_and_sends_its_frame_again_unless_it_stopped() {
    let mut host = host(30.0);
    let mut a = join(&mut host);
    assert!(publish(&mut host, 7));
    assert_eq!(frame_cycle(&read_record(&mut a).1), 7);
    // The link resets before the agent's stop: its place is held, it counts as connected,
    // and a frame published meanwhile counts as delivered.
    reset(a);
    pump(&mut host, "the reset", |h| h.slots[0].conn.is_none());
    assert!(host.is_connected(0) && host.slots[0].resuming.is_some());
    // Back: the frame of the cycle whose stop did not arrive comes again.
    let mut a = join(&mut host);
    assert!(host.slots[0].resuming.is_none());
    assert_eq!(frame_cycle(&read_record(&mut a).1), 7);
    a.write_all(&stop_record(7, 2)).unwrap();
    assert_eq!(
        pump(&mut host, "the stop", |h| h.slots[0].stopped == Some(7)),
        [7]
    );
    // Lost after its stop, the next frame published while it is away: back, it gets
    // that one (once), not the one it stopped.
    reset(a);
    pump(&mut host, "the reset", |h| h.slots[0].conn.is_none());
    assert!(publish(&mut host, 8));
    let mut a = join(&mut host);
    assert_eq!(frame_cycle(&read_record(&mut a).1), 8);
    a.write_all(&stop_record(8, 0)).unwrap();
    assert_eq!(
        pump(&mut host, "the stop", |h| h.slots[0].stopped == Some(8)),
        [8]
    );
    // A second live connection of the same id is still refused.
    let mut twin = TcpStream::connect(host.local_addr()).unwrap();
    write_record(&mut twin, kind::HELLO, &hello(0)).unwrap();
    twin.set_nonblocking(true).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !matches!(twin.peek(&mut [0u8; 1]), Ok(1)) {
        assert!(Instant::now() < deadline, "no answer");
        host.wait_activity(Duration::from_millis(20)).unwrap();
    }
    twin.set_nonblocking(false).unwrap();
    let (k, body) = read_record(&mut twin);
    assert_eq!(k, kind::REJECT);
    assert_eq!(Reject::decode(&body).unwrap().code, reject::ID_IN_USE);
    drop(a);
}

#[test]
fn a_lost_agent_not_back_within_the_window_is_let_go_and_joins_afresh() {
    let window = Duration::from_millis(300);
    let mut host = host(window.as_secs_f64());
    let a = join(&mut host);
    assert!(publish(&mut host, 3));
    reset(a);
    pump(&mut host, "the reset", |h| h.slots[0].conn.is_none());
    let lost = Instant::now();
    assert!(host.is_connected(0));
    // The host's wait ends at the window's end by itself (its deadline), with nothing
    // else happening.
    pump(&mut host, "the window's end", |h| !h.is_connected(0));
    let held = lost.elapsed();
    assert!(held < window + Duration::from_secs(2), "{held:?}");
    assert!(!publish(&mut host, 4), "not delivered: the place is let go");
    // A connection now is a new agent: no frame comes again; the next one published does.
    let mut a = join(&mut host);
    assert!(publish(&mut host, 5));
    assert_eq!(frame_cycle(&read_record(&mut a).1), 5);
}

#[test]
fn a_close_is_not_held_a_reset_is_held_briefly_and_a_stalled_link_for_the_window() {
    let mut host = host(30.0);
    // A close is the agent's own end (its process ended): let go at once.
    drop(join(&mut host));
    pump(&mut host, "the close", |h| !h.is_connected(0));
    // A reset: a killed agent or a link reset on the way, held for the reset grace.
    reset(join(&mut host));
    pump(&mut host, "the reset", |h| h.slots[0].conn.is_none());
    let held = host.slots[0].resuming.unwrap();
    assert_eq!(held.until - held.since, RESET_GRACE);
    // A record that stops halfway (the link stalls): held for the whole window.
    let mut a = join(&mut host);
    a.write_all(&stop_record(0, 1)[..PREFIX + 4]).unwrap();
    pump(&mut host, "the stall", |h| h.slots[0].conn.is_none());
    let held = host.slots[0].resuming.unwrap();
    assert_eq!(held.until - held.since, Duration::from_secs(30));
    assert!(host.is_connected(0));
}

#[test]
fn without_a_window_a_reset_ends_the_connection() {
    let mut host = host(0.0);
    let a = join(&mut host);
    reset(a);
    pump(&mut host, "the reset", |h| !h.is_connected(0));
}

// --- The agent side, against a host written out by hand --------------------------------

/// Accepts one connection, reads its hello and welcomes it (frames of a header alone).
fn welcome(listener: &TcpListener) -> TcpStream {
    let (mut s, _) = listener.accept().unwrap();
    assert_eq!(read_record(&mut s).0, kind::HELLO);
    let mut welcome = [0u8; 16];
    welcome[..4].copy_from_slice(&PROTOCOL_VERSION.to_le_bytes());
    welcome[4..12].copy_from_slice(&LAYOUT_HASH.to_le_bytes());
    welcome[12..].copy_from_slice(&(HEADER as u32).to_le_bytes());
    write_record(&mut s, kind::WELCOME, &welcome).unwrap();
    s
}

fn send_frame(s: &mut TcpStream, cycle: u64) {
    let header = SensorHeader {
        cycle,
        ..SensorHeader::default()
    };
    write_record(s, kind::FRAME, header.as_bytes()).unwrap();
}

fn next_frame(agent: &mut TcpAgent, last: Option<u64>) -> Result<u64, AgentWaitError> {
    let mut liveness = Instant::now();
    let deadline = Instant::now() + Duration::from_secs(20);
    wait_for_newer_frame(agent, last, Some(deadline), &mut liveness).map(|f| f.header().cycle)
}

fn stop(agent: &mut TcpAgent, cycle: u64) {
    let header = MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: 0,
        cycle,
        flags: crate::wire::MOTOR_FLAG_STOP,
        command_count: 0,
        ack_cycle: 0,
    };
    let commands = [MotorCommand::default(), MotorCommand::default()];
    agent.send_batch(&header, &commands).unwrap();
}

#[test]
fn an_agent_whose_link_resets_connects_again_and_sends_its_stop_again() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let config = config(listener.local_addr().unwrap(), 30.0);
    let host = std::thread::spawn(move || {
        let mut s = welcome(&listener);
        send_frame(&mut s, 0);
        let (k, first) = read_record(&mut s);
        assert_eq!(k, kind::MOTOR);
        // The link resets after the stop left the agent, before the host read it.
        reset(s);
        let mut s = welcome(&listener);
        send_frame(&mut s, 0);
        let (k, again) = read_record(&mut s);
        assert_eq!((k, &again), (kind::MOTOR, &first), "the same batch again");
        send_frame(&mut s, 1);
        let (k, next) = read_record(&mut s);
        assert_eq!((k, frame_of(&next)), (kind::MOTOR, 1));
        write_record(&mut s, kind::SHUTDOWN, &[]).unwrap();
    });
    let mut agent =
        TcpAgent::connect(&config, 0, Duration::from_secs(20), SignalHandling::Leave).unwrap();
    assert_eq!(next_frame(&mut agent, None).unwrap(), 0);
    stop(&mut agent, 0);
    // The caller sees neither the lost link nor the frame of cycle 0 again.
    assert_eq!(next_frame(&mut agent, Some(0)).unwrap(), 1);
    stop(&mut agent, 1);
    assert_eq!(
        next_frame(&mut agent, Some(1)),
        Err(AgentWaitError::HostClosed)
    );
    host.join().unwrap();
}

fn frame_of(motor_body: &[u8]) -> u64 {
    decode_motor(motor_body).unwrap().0.cycle
}

#[test]
fn an_agent_whose_host_is_gone_gives_up_at_once_and_one_whose_link_stays_lost_at_the_window() {
    // The host's process is gone: its address refuses connections.
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let config = config(listener.local_addr().unwrap(), 30.0);
    let host = std::thread::spawn(move || {
        let s = welcome(&listener);
        drop(listener);
        reset(s);
    });
    let mut agent =
        TcpAgent::connect(&config, 0, Duration::from_secs(20), SignalHandling::Leave).unwrap();
    host.join().unwrap();
    let lost = Instant::now();
    assert!(matches!(
        next_frame(&mut agent, None),
        Err(AgentWaitError::HostGone { .. })
    ));
    assert!(
        lost.elapsed() < Duration::from_secs(5),
        "{:?}",
        lost.elapsed()
    );

    // The host's machine takes connections that are never answered (a link that is
    // still lost beyond it): the agent gives up once the window has passed.
    let window = Duration::from_millis(500);
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let config = self::config(listener.local_addr().unwrap(), window.as_secs_f64());
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    let host = std::thread::spawn(move || {
        let s = welcome(&listener);
        reset(s);
        // Holds the listener (its backlog takes the agent's new connections) until the
        // agent gave up.
        let _ = rx.recv_timeout(Duration::from_secs(20));
    });
    let mut agent =
        TcpAgent::connect(&config, 0, Duration::from_secs(20), SignalHandling::Leave).unwrap();
    let started = Instant::now();
    let gone = next_frame(&mut agent, None);
    let _ = tx.send(());
    host.join().unwrap();
    let Err(AgentWaitError::HostGone { reason }) = gone else {
        panic!("{gone:?}");
    };
    assert!(reason.contains("resume_window"), "{reason}");
    let waited = started.elapsed();
    assert!(
        waited >= window && waited < window + Duration::from_secs(3),
        "{waited:?}"
    );
}
