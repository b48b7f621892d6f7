//! Hostile and broken TCP peers against a real `vr-sim run` host.
//!
//! Every test runs one session with two agents: agent 0 is a real `vr-agent`, agent 1 is
//! a scripted agent written here (raw `TcpStream`, the wire format by hand), which lets
//! the test hold the host inside a chosen cycle. At cycle [`ATTACK_AT`] — agent 0 has
//! stopped, the host waits for agent 1 — the attack runs: either a stranger connects and
//! misbehaves, or agent 1 itself does. The test checks what the peer sees (the host's
//! REJECT with its reason, the connection closed) and, when agent 1 is dropped, the host's
//! `agent_evicted` event (`vr-sim run --events`), then lets the run finish and checks the
//! host and agent 0 were unaffected: exit 0, every cycle, no stop timeout, and that the
//! host refused exactly the expected strangers for the expected reasons (its
//! `peer_refused` events and the summary's `peers_refused` count).
//!
//! No sleeps: a peer that "stalls" keeps its socket open while the test waits for the host
//! to close it; every wait has a deadline.
//!
//! What decoding hostile bytes costs, in process: `hostile/decoding.rs`.

pub mod decoding;

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde_json::json;
use vrsync_bridge::tcp::{
    Hello, MAX_HELLO, MAX_PENDING, PREFIX, Reject, encode_hello, kind, reject,
};
use vrsync_bridge::{LAYOUT_HASH, MotorCommand, MotorHeader, PROTOCOL_VERSION, SensorHeader};

use crate::util::{
    EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, TestConfig, Transport, bin, cycle_log,
    make_certificates, spawn_host, summary,
};

/// Cycles per run.
const FRAMES: u64 = 50;
/// The cycle during which the attack happens.
const ATTACK_AT: u64 = 10;
/// Deadline for one host event or one record.
const LINE: Duration = Duration::from_secs(30);
/// Largest motor batch body with the default `max_commands_per_cycle = 64`.
const MAX_MOTOR_BODY: usize =
    std::mem::size_of::<MotorHeader>() + 64 * std::mem::size_of::<MotorCommand>();

/// A running session: host, agent 0 (real) and agent 1 (scripted).
struct Session {
    _dir: tempfile::TempDir,
    summary: PathBuf,
    log0: PathBuf,
    host: Proc,
    events: Events,
    agent0: Proc,
    addr: SocketAddr,
}

impl Session {
    /// Starts the host and agent 0; `token` becomes `tcp_token` when not empty.
    fn start(tag: &str, token: &str) -> (Self, Scripted) {
        Self::start_with(tag, token, "")
    }

    /// [`Session::start`] with `sync_extra` lines appended to the `[sync]` table.
    fn start_with(tag: &str, token: &str, sync_extra: &str) -> (Self, Scripted) {
        let dir = tempfile::tempdir().unwrap();
        let mut cfg = TestConfig::with_transport(tag, 2, Transport::Tcp);
        // Long enough that any stop timeout in these tests means a bug, not a slow machine.
        cfg.stop_timeout_s = 30.0;
        cfg.sync_extra = sync_extra.to_owned();
        let mut text = cfg.toml();
        if !token.is_empty() {
            text = text.replacen(
                "kind = \"tcp\"\n",
                &format!("kind = \"tcp\"\ntcp_token = {token:?}\n"),
                1,
            );
        }
        let config = dir.path().join("hostile.toml");
        std::fs::write(&config, &text).unwrap();
        let summary = dir.path().join("summary.json");
        let log0 = dir.path().join("agent0.log");
        let events = Events::in_dir(dir.path());
        let host = spawn_host(
            &config,
            &events,
            &[
                "--frames",
                &FRAMES.to_string(),
                "--summary-json",
                summary.to_str().unwrap(),
            ],
        );
        // The host binds port 0; agents learn the bound port from its `listening` event.
        let listening = events.wait_for("listening", LINE);
        let addr: SocketAddr = listening["address"].as_str().unwrap().parse().unwrap();
        let bound = format!("127.0.0.1:{}\"", addr.port());
        std::fs::write(&config, text.replacen("127.0.0.1:0\"", &bound, 1)).unwrap();
        let agent0 = Proc::spawn(
            &bin("vr-agent"),
            &[
                "--config",
                config.to_str().unwrap(),
                "--id",
                "0",
                "--log-cycles",
                log0.to_str().unwrap(),
            ],
        );
        let scripted = Scripted::connect(addr, 1, token.as_bytes());
        let session = Self {
            _dir: dir,
            summary,
            log0,
            host,
            events,
            agent0,
            addr,
        };
        (session, scripted)
    }

    /// Waits until the host evicted `agent`.
    fn host_evicts(&self, agent: u32) {
        self.events
            .wait_for_match("agent_evicted", |e| e["agent"] == agent, LINE);
    }

    /// Waits for the run to end and checks that the host and agent 0 were unaffected;
    /// `evicted` lists the agents the host must have evicted (checked in the summary and
    /// in the events), `refused` the kinds of the peers it refused (`peer_refused` events,
    /// and the summary's count).
    fn finish(self, evicted: &[u32], refused: &[&str]) {
        self.finish_counting(evicted, refused, 0);
    }

    /// [`Session::finish`], where `uncounted` more refusals are only counted (a flood).
    fn finish_counting(self, evicted: &[u32], refused: &[&str], uncounted: u64) {
        let out = self.host.wait(RUN_DEADLINE);
        assert_eq!(out.code(), Some(0), "host stderr:\n{}", out.stderr);
        let a0 = self.agent0.wait(LINE);
        assert_eq!(a0.code(), Some(0), "agent 0 stderr:\n{}", a0.stderr);
        let sum = summary(&self.summary);
        assert_eq!(sum["frames"], FRAMES, "{sum}");
        assert_eq!(sum["stop_timeouts"], 0, "{sum}\n{}", out.stderr);
        assert_eq!(sum["evicted_agents"], json!(evicted), "{sum}");
        let cycles: Vec<u64> = cycle_log(&self.log0).iter().map(|l| l.cycle).collect();
        assert_eq!(
            cycles,
            (0..FRAMES).collect::<Vec<_>>(),
            "agent 0 saw every cycle"
        );
        let evicted_events: Vec<u64> = self
            .events
            .of("agent_evicted")
            .iter()
            .map(|e| e["agent"].as_u64().unwrap())
            .collect();
        let evicted: Vec<u64> = evicted.iter().map(|&a| u64::from(a)).collect();
        assert_eq!(evicted_events, evicted);
        let mut refused_events: Vec<String> = self
            .events
            .of("peer_refused")
            .iter()
            .map(|e| e["kind"].as_str().unwrap().to_owned())
            .collect();
        refused_events.sort();
        let mut refused: Vec<&str> = refused.to_vec();
        refused.sort_unstable();
        assert_eq!(refused_events, refused, "peers refused");
        assert_eq!(
            sum["peers_refused"],
            refused.len() as u64 + uncounted,
            "{sum}"
        );
        assert_eq!(self.events.of("finished").len(), 1);
    }

    /// A raw connection to the host.
    fn stranger(&self) -> TcpStream {
        let s = TcpStream::connect(self.addr).unwrap();
        s.set_read_timeout(Some(LINE)).unwrap();
        s
    }
}

fn hello(agent_id: u32, token: &[u8]) -> Hello {
    Hello {
        protocol_version: PROTOCOL_VERSION,
        layout_hash: LAYOUT_HASH,
        agent_id,
        channels: vrsync_bridge::ChannelLayout::default().hash(),
        token: token.to_vec(),
    }
}

fn record(kind: u32, body: &[u8]) -> Vec<u8> {
    let mut r = Vec::with_capacity(PREFIX + body.len());
    r.extend_from_slice(&(body.len() as u32).to_le_bytes());
    r.extend_from_slice(&kind.to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// Reads one record (bounded: a test peer trusts the host no more than the host trusts it).
fn read_record(s: &mut TcpStream) -> (u32, Vec<u8>) {
    let mut prefix = [0u8; PREFIX];
    s.read_exact(&mut prefix)
        .unwrap_or_else(|e| panic!("no record from the host: {e}"));
    let len = u32::from_le_bytes(prefix[..4].try_into().unwrap()) as usize;
    let k = u32::from_le_bytes(prefix[4..].try_into().unwrap());
    assert!(len <= 64 << 20, "record of {len} bytes");
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).unwrap();
    (k, body)
}

/// Sends a hello and returns the host's REJECT as `(code, host protocol, host layout, message)`.
fn rejected(s: &mut TcpStream, hello: &Hello) -> (u32, u32, u64, String) {
    s.write_all(&record(kind::HELLO, &encode_hello(hello)))
        .unwrap();
    let (k, body) = read_record(s);
    assert_eq!(k, kind::REJECT, "expected a reject");
    let r = Reject::decode(&body).expect("a well-formed reject");
    assert_closed_by_host(s);
    (r.code, r.host_protocol, r.host_layout, r.message)
}

/// Reads until the host closes the connection (end of stream or reset); panics if it is
/// still open after the deadline.
fn assert_closed_by_host(s: &mut TcpStream) {
    let deadline = Instant::now() + LINE;
    let mut buf = [0u8; 4096];
    loop {
        assert!(
            Instant::now() < deadline,
            "the host kept the connection open"
        );
        match s.read(&mut buf) {
            Ok(0) => return,
            Ok(_) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                panic!("the host kept the connection open")
            }
            Err(_) => return, // reset: closed with unread bytes
        }
    }
}

/// Agent 1, scripted: answers each frame with an empty stop batch unless told otherwise.
struct Scripted {
    s: TcpStream,
    id: u32,
    next_cycle: u64,
    /// The cycle whose frame arrived and has not been answered.
    holding: Option<u64>,
}

impl Scripted {
    fn connect(addr: SocketAddr, id: u32, token: &[u8]) -> Self {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(LINE)).unwrap();
        s.set_nodelay(true).unwrap();
        s.write_all(&record(kind::HELLO, &encode_hello(&hello(id, token))))
            .unwrap();
        let (k, body) = read_record(&mut s);
        assert_eq!(
            k,
            kind::WELCOME,
            "scripted agent {id} refused: {:?}",
            Reject::decode(&body)
        );
        Self {
            s,
            id,
            next_cycle: 0,
            holding: None,
        }
    }

    /// Reads the next frame; `None` on SHUTDOWN.
    fn next_frame(&mut self) -> Option<u64> {
        let (k, body) = read_record(&mut self.s);
        match k {
            kind::FRAME => {
                let at = std::mem::offset_of!(SensorHeader, cycle);
                let cycle = u64::from_le_bytes(body[at..at + 8].try_into().unwrap());
                assert_eq!(cycle, self.next_cycle, "agent {} cycles in order", self.id);
                self.next_cycle += 1;
                Some(cycle)
            }
            kind::SHUTDOWN => None,
            other => panic!("unexpected record kind {other} from the host"),
        }
    }

    fn stop_batch(&self, cycle: u64) -> Vec<u8> {
        assert_eq!(std::mem::size_of::<MotorHeader>(), 32);
        let mut body = Vec::with_capacity(32);
        body.extend_from_slice(&PROTOCOL_VERSION.to_le_bytes());
        body.extend_from_slice(&self.id.to_le_bytes());
        body.extend_from_slice(&cycle.to_le_bytes());
        body.extend_from_slice(&vrsync_bridge::MOTOR_FLAG_STOP.to_le_bytes());
        body.extend_from_slice(&0u32.to_le_bytes()); // command count
        body.extend_from_slice(&0u64.to_le_bytes()); // ack_cycle (no MOTOR_FLAG_ACK)
        record(kind::MOTOR, &body)
    }

    /// Plays cycles until the frame of `cycle` arrived; holds it unanswered.
    fn hold_at(&mut self, cycle: u64) {
        loop {
            let c = self.next_frame().expect("the run ended early");
            if c == cycle {
                self.holding = Some(c);
                return;
            }
            let batch = self.stop_batch(c);
            self.s.write_all(&batch).unwrap();
        }
    }

    /// Answers the held frame and every later one until the host shuts the session down.
    fn play_to_the_end(mut self) {
        if let Some(c) = self.holding.take() {
            let batch = self.stop_batch(c);
            self.s.write_all(&batch).unwrap();
        }
        while let Some(c) = self.next_frame() {
            let batch = self.stop_batch(c);
            self.s.write_all(&batch).unwrap();
        }
        assert_eq!(self.next_cycle, FRAMES, "agent {} saw every cycle", self.id);
    }

    /// The held frame's stop batch (for breaking it up).
    fn held_batch(&self) -> Vec<u8> {
        self.stop_batch(self.holding.expect("holding a frame"))
    }
}

// --- strangers: dropped before their hello completes ------------------------------------

#[test]
fn garbage_bytes_from_a_stranger_are_dropped() {
    let (s, mut a1) = Session::start("garbage", "");
    a1.hold_at(ATTACK_AT);
    let mut peer = s.stranger();
    let garbage = b"GET / HTTP/1.1\r\nHost: vrsync\r\n\r\n";
    peer.write_all(garbage).unwrap();
    assert_closed_by_host(&mut peer);
    a1.play_to_the_end();
    s.finish(&[], &["malformed"]);
}

#[test]
fn a_truncated_hello_then_close_is_dropped() {
    let (s, mut a1) = Session::start("trunchello", "");
    a1.hold_at(ATTACK_AT);
    let mut peer = s.stranger();
    let rec = record(kind::HELLO, &encode_hello(&hello(1, b"")));
    peer.write_all(&rec[..PREFIX + 10]).unwrap();
    drop(peer);
    a1.play_to_the_end();
    s.finish(&[], &["silent"]);
}

#[test]
fn a_length_beyond_the_maximum_is_refused_before_any_body_byte() {
    let (s, mut a1) = Session::start("toolong", "");
    a1.hold_at(ATTACK_AT);
    let mut peer = s.stranger();
    let mut prefix = [0u8; PREFIX];
    prefix[..4].copy_from_slice(&u32::MAX.to_le_bytes());
    prefix[4..].copy_from_slice(&kind::HELLO.to_le_bytes());
    peer.write_all(&prefix).unwrap();
    let why = format!(
        "record of {} bytes exceeds the maximum of {MAX_HELLO}",
        u32::MAX
    );
    // It read the prefix and nothing else, so its reject reaches us intact.
    let (k, body) = read_record(&mut peer);
    assert_eq!(k, kind::REJECT);
    let Reject { code, message, .. } = Reject::decode(&body).unwrap();
    assert_eq!(code, reject::MALFORMED);
    assert!(message.contains(&why), "{message}");
    assert_closed_by_host(&mut peer);
    a1.play_to_the_end();
    s.finish(&[], &["malformed"]);
}

#[test]
fn a_wrong_protocol_version_gets_a_reject_naming_both_versions() {
    let (s, mut a1) = Session::start("version", "");
    a1.hold_at(ATTACK_AT);
    let theirs = PROTOCOL_VERSION + 1;
    let mut h = hello(1, b"");
    h.protocol_version = theirs;
    let (code, host_protocol, host_layout, message) = rejected(&mut s.stranger(), &h);
    assert_eq!(code, reject::VERSION);
    assert_eq!(
        (host_protocol, host_layout),
        (PROTOCOL_VERSION, LAYOUT_HASH)
    );
    assert!(
        message.contains(&format!("agent speaks protocol {theirs}"))
            && message.contains(&format!("host speaks protocol {PROTOCOL_VERSION}")),
        "{message}"
    );
    // Same version, other layout: refused the same way, both layouts named.
    let mut h = hello(1, b"");
    h.layout_hash = LAYOUT_HASH ^ 1;
    let (code, _, _, message) = rejected(&mut s.stranger(), &h);
    assert_eq!(code, reject::VERSION);
    assert!(
        message.contains(&format!("{:016x}", LAYOUT_HASH ^ 1))
            && message.contains(&format!("{LAYOUT_HASH:016x}")),
        "{message}"
    );
    a1.play_to_the_end();
    s.finish(&[], &["version", "version"]);
}

#[test]
fn an_agent_id_not_in_the_session_is_refused() {
    let (s, mut a1) = Session::start("unknownid", "");
    a1.hold_at(ATTACK_AT);
    let (code, _, _, message) = rejected(&mut s.stranger(), &hello(7, b""));
    assert_eq!(code, reject::UNKNOWN_AGENT);
    assert!(
        message.contains("agent 7 is not part of this session"),
        "{message}"
    );
    a1.play_to_the_end();
    s.finish(&[], &["unknown_agent"]);
}

#[test]
fn an_agent_id_already_connected_is_refused_and_the_owner_keeps_its_place() {
    let (s, mut a1) = Session::start("idinuse", "");
    a1.hold_at(ATTACK_AT);
    for id in [0, 1] {
        let (code, _, _, message) = rejected(&mut s.stranger(), &hello(id, b""));
        assert_eq!(code, reject::ID_IN_USE);
        assert!(
            message.contains(&format!("agent {id} is already connected")),
            "{message}"
        );
    }
    a1.play_to_the_end();
    s.finish(&[], &["id_in_use", "id_in_use"]);
}

#[test]
fn a_stranger_stalling_mid_hello_is_dropped_after_the_hello_timeout() {
    let (s, mut a1) = Session::start("stallhello", "");
    a1.hold_at(ATTACK_AT);
    let mut peer = s.stranger();
    let rec = record(kind::HELLO, &encode_hello(&hello(1, b"")));
    peer.write_all(&rec[..PREFIX + 12]).unwrap();
    // The peer now says nothing more and keeps its socket open.
    assert_closed_by_host(&mut peer);
    a1.play_to_the_end();
    s.finish(&[], &["silent"]);
}

#[test]
fn a_peer_that_connects_and_never_speaks_is_dropped_after_the_hello_timeout() {
    let (s, mut a1) = Session::start("silent", "");
    a1.hold_at(ATTACK_AT);
    let mut peer = s.stranger();
    assert_closed_by_host(&mut peer);
    a1.play_to_the_end();
    s.finish(&[], &["silent"]);
}

#[test]
fn a_flood_of_silent_connections_costs_a_bounded_number_of_slots() {
    let (s, mut a1) = Session::start("flood", "");
    a1.hold_at(ATTACK_AT);
    let extra = 8;
    let mut peers: Vec<TcpStream> = (0..MAX_PENDING + extra).map(|_| s.stranger()).collect();
    // Every one is closed (the ones beyond MAX_PENDING at once, the others after the
    // hello timeout), and the session goes on unaffected.
    for p in &mut peers {
        assert_closed_by_host(p);
    }
    a1.play_to_the_end();
    // The ones that waited are itemised; the ones turned away at once only counted.
    s.finish_counting(&[], &["silent"; MAX_PENDING], extra as u64);
}

// --- agent 1 itself misbehaves after its welcome -----------------------------------------

#[test]
fn garbage_from_an_admitted_agent_drops_only_that_agent() {
    let (s, mut a1) = Session::start("agentgarbage", "");
    a1.hold_at(ATTACK_AT);
    a1.s.write_all(&record(99, b"junk")).unwrap();
    assert_closed_by_host(&mut a1.s);
    s.host_evicts(1);
    s.finish(&[1], &[]);
}

#[test]
fn a_truncated_batch_then_close_drops_the_agent() {
    let (s, mut a1) = Session::start("truncbatch", "");
    a1.hold_at(ATTACK_AT);
    let batch = a1.held_batch();
    a1.s.write_all(&batch[..PREFIX + 10]).unwrap();
    drop(a1);
    s.host_evicts(1);
    s.finish(&[1], &[]);
}

#[test]
fn a_batch_longer_than_the_maximum_drops_the_agent() {
    let (s, mut a1) = Session::start("longbatch", "");
    a1.hold_at(ATTACK_AT);
    let mut prefix = [0u8; PREFIX];
    prefix[..4].copy_from_slice(&(MAX_MOTOR_BODY as u32 + 1).to_le_bytes());
    prefix[4..].copy_from_slice(&kind::MOTOR.to_le_bytes());
    a1.s.write_all(&prefix).unwrap();
    assert_closed_by_host(&mut a1.s);
    s.host_evicts(1);
    s.finish(&[1], &[]);
}

#[test]
fn an_agent_stalling_mid_batch_is_dropped_and_evicted_when_its_resume_window_ends() {
    // A record that stalls is a lost link to the host: the agent's place is held for the
    // resume window (here 2 s, not the default 30) in case it comes back.
    let (s, mut a1) = Session::start_with("stallbatch", "", "resume_window = 2.0\n");
    a1.hold_at(ATTACK_AT);
    let batch = a1.held_batch();
    a1.s.write_all(&batch[..PREFIX + 10]).unwrap();
    // Agent 1 now keeps its socket open and says nothing more. The host drops it after
    // the stall timeout (2 s), holds its place for the window and then evicts it (both
    // well inside the 30 s stop timeout), so the cycle ends without a stop timeout.
    s.host_evicts(1);
    assert_closed_by_host(&mut a1.s);
    s.finish(&[1], &[]);
}

// --- tcp_token -----------------------------------------------------------------------

#[test]
fn tcp_token_wrong_or_missing_is_refused_and_the_right_one_admitted() {
    // Agent 0 (vr-agent) and agent 1 (scripted) present the right token: admitted.
    let (s, mut a1) = Session::start("token", "s3cret-t0ken");
    a1.hold_at(ATTACK_AT);
    for token in [&b""[..], b"s3cret-t0ke", b"s3cret-t0ken!", b"S3CRET-T0KEN"] {
        // Claims a free id so only the token can be the reason.
        let (code, _, _, message) = rejected(&mut s.stranger(), &hello(5, token));
        assert_eq!(code, reject::TOKEN, "token {token:?}");
        assert!(message.contains("wrong tcp_token"), "{message}");
    }
    a1.play_to_the_end();
    s.finish(&[], &["token"; 4]);
}

#[test]
fn vr_agent_without_the_token_exits_with_a_clear_error() {
    let (s, a1) = Session::start("notoken", "s3cret-t0ken");
    // A config like the host's but without the token.
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("notoken-agent", 2, Transport::Tcp);
    cfg.tcp_port = s.addr.port();
    let config = cfg.write(dir.path());
    let out = Proc::spawn(
        &bin("vr-agent"),
        &["--config", config.to_str().unwrap(), "--id", "1"],
    )
    .wait(LINE);
    assert_eq!(out.code(), Some(1), "{}", out.stderr);
    assert!(out.stderr.contains("wrong tcp_token"), "{}", out.stderr);
    a1.play_to_the_end();
    s.finish(&[], &["token"]);
}

// --- strangers against a mutual-TLS zenoh host ------------------------------------------

/// A `vr-sim run` host over zenoh mutual TLS (`tls/127.0.0.1`): a plaintext TCP peer and
/// an agent whose certificate is of another CA never reach the hello and are counted as
/// refused (`peer_refused` events of kind `tls`, the summary's `peers_refused`); the
/// certified agent then runs every cycle.
#[test]
fn tls_strangers_are_counted_as_refused_and_a_certified_agent_runs() {
    let dir = tempfile::tempdir().unwrap();
    make_certificates(dir.path(), "127.0.0.1");
    let mut cfg = TestConfig::with_transport("tlsstranger", 1, Transport::Zenoh);
    cfg.connect_timeout_s = 60.0;
    let port = cfg.zenoh_port;
    let config_for = |name: &str, cert: &str, connect_timeout: &str| {
        let text = cfg
            .toml()
            .replace("\"tcp/127.0.0.1:", "\"tls/127.0.0.1:")
            .replace(
                "connect_timeout = 60\n",
                &format!("connect_timeout = {connect_timeout}\n"),
            )
            .replace(
                "[transport.zenoh]\n",
                &format!(
                    "[transport.zenoh]\ntls_ca = \"ca.pem\"\ntls_cert = \"{cert}.pem\"\n\
                     tls_key = \"{cert}.key\"\nmtls = true\n"
                ),
            );
        assert!(
            text.contains("tls/127.0.0.1:") && text.contains("mtls"),
            "{text}"
        );
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let host_config = config_for("host", "host", "60");
    let agent_config = config_for("agent", "agent", "60");
    let stranger_config = config_for("stranger", "stranger", "3");
    let events = Events::in_dir(dir.path());
    let sum_path = dir.path().join("summary.json");
    let host = spawn_host(
        &host_config,
        &events,
        &[
            "--frames",
            "20",
            "--summary-json",
            sum_path.to_str().unwrap(),
        ],
    );
    events.wait_for("listening", EVENT_DEADLINE);
    let is_tls = |e: &serde_json::Value| e["kind"] == "tls";

    // Plain TCP bytes: the TLS handshake fails, the connection is closed.
    let mut plain = TcpStream::connect(("127.0.0.1", port)).unwrap();
    plain.set_read_timeout(Some(LINE)).unwrap();
    plain.write_all(b"not TLS at all\r\n\r\n").unwrap();
    let mut rest = Vec::new();
    let _ = plain.read_to_end(&mut rest); // EOF or a reset: closed either way
    events.wait_for_match("peer_refused", is_tls, EVENT_DEADLINE);
    let after_plain = events.of("peer_refused").len();

    // A zenoh agent with a certificate of another CA: it never finds the host.
    let out = Proc::spawn(
        &bin("vr-agent"),
        &["--config", stranger_config.to_str().unwrap(), "--id", "0"],
    )
    .wait(LINE);
    assert_ne!(out.code(), Some(0), "{}", out.stderr);

    let (agent, log) = (
        Proc::spawn(
            &bin("vr-agent"),
            &[
                "--config",
                agent_config.to_str().unwrap(),
                "--id",
                "0",
                "--log-cycles",
                dir.path().join("a0.log").to_str().unwrap(),
            ],
        ),
        dir.path().join("a0.log"),
    );
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "host stderr:\n{}", out.stderr);
    let a = agent.wait(LINE);
    assert_eq!(a.code(), Some(0), "agent stderr:\n{}", a.stderr);
    let sum = summary(&sum_path);
    assert_eq!(sum["frames"], 20, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    let cycles: Vec<u64> = cycle_log(&log).iter().map(|l| l.cycle).collect();
    assert_eq!(cycles, (0..20).collect::<Vec<_>>());
    let refused = events.of("peer_refused");
    assert!(refused.iter().all(is_tls), "{refused:?}");
    assert!(
        refused.len() > after_plain,
        "the agent of another CA was not counted: {refused:?}"
    );
    assert_eq!(sum["peers_refused"], refused.len() as u64, "{sum}");
}
