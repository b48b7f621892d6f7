//! Unit tests of the zenoh transport's pieces; the transport end to end is in the
//! conformance suite (`agent-sdk/tests/conformance.rs`) and `tests/`.

use super::*;

#[test]
fn keys_parse_only_their_own_shape() {
    let k = Keys::new("s1");
    assert_eq!(k.parse_agent("vrsync/s1/agent/7/motor"), Some((7, None)));
    assert_eq!(
        k.parse_agent("vrsync/s1/agent/7/alive/42"),
        Some((7, Some(42)))
    );
    assert_eq!(k.parse_agent("vrsync/s2/agent/7/motor"), None);
    assert_eq!(k.parse_agent("vrsync/s1/agent/x/motor"), None);
    assert_eq!(k.parse_agent("vrsync/s1/agent/99999999999/motor"), None);
    assert_eq!(k.parse_agent("vrsync/s1/agent/7/alive/nonce"), None);
    assert_eq!(k.parse_agent("vrsync/s1/agent/+7/motor"), None);
}

#[test]
fn a_wake_fd_wakes_once_until_cleared() {
    let w = WakeFd::new().unwrap();
    assert!(!w.wait(Duration::ZERO));
    w.wake();
    w.wake();
    assert!(w.wait(Duration::ZERO));
    w.clear();
    assert!(!w.wait(Duration::ZERO));
}

// --- a host, real agents and hostile raw zenoh peers, in one process -------------------

use std::time::Instant;

use ::zenoh::Wait;
use zerocopy::IntoBytes;

use super::super::record::{Hello, Reject, encode_hello, reject};
use super::super::{
    AgentConnectError, AgentTransport, HostConnections, HostLiveness, HostReadiness, HostTransport,
};
use crate::signal::SignalHandling;
use crate::wire::{LAYOUT_HASH, MOTOR_FLAG_STOP, MotorCommand, MotorHeader, PROTOCOL_VERSION};

const WAIT: Duration = Duration::from_secs(20);

fn config(token: Option<&str>) -> Config {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let token = token.map_or(String::new(), |t| format!("token = {t:?}\n"));
    let text = format!(
        "session = \"zu{}-{}\"\n[sync]\nstop_timeout = 5.0\n[transport]\nkind = \"zenoh\"\n\
         [transport.zenoh]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n{token}\
         [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n\
         [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n",
        std::process::id(),
        N.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    );
    Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap()
}

fn agent(config: &Config, id: u32, token: Option<&str>) -> Result<ZenohAgent, AgentConnectError> {
    ZenohAgent::connect_with_token(
        config,
        id,
        WAIT,
        token.map(str::as_bytes),
        SignalHandling::Leave,
    )
}

/// Runs the host's wait until `done` holds; panics after 20 s naming `what`.
fn pump(host: &mut ZenohHost, what: &str, mut done: impl FnMut(&mut ZenohHost) -> bool) {
    let deadline = Instant::now() + WAIT;
    while !done(host) {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        host.wait_activity(Duration::from_millis(50)).unwrap();
    }
}

/// A raw zenoh peer connected to the host: it speaks zenoh, not necessarily vrsync.
fn raw_peer(config: &Config) -> ::zenoh::Session {
    let z = &config.transport.zenoh;
    let c = session_config(config, &[], &z.connect, None).unwrap();
    ::zenoh::open(c).wait().unwrap()
}

/// Sends `hello` as a raw query; returns the reply's code (WELCOME / REJECT) and body.
fn raw_hello(peer: &::zenoh::Session, keys: &Keys, payload: Vec<u8>) -> (u32, Vec<u8>) {
    let deadline = Instant::now() + WAIT;
    loop {
        let replies = peer
            .get(keys.hello())
            .payload(payload.clone())
            .timeout(Duration::from_secs(2))
            .wait()
            .unwrap();
        if let Ok(r) = replies.recv() {
            let Ok(sample) = r.result() else {
                // zenoh's own answer: nobody replied in time.
                return (0, Vec::new());
            };
            let body = sample.payload().to_bytes().into_owned();
            let code = u32::from_le_bytes(body[..4].try_into().unwrap());
            return (code, body[4..].to_vec());
        }
        // The peer's link to the host may still be opening.
        assert!(Instant::now() < deadline, "no answer to the hello");
    }
}

fn batch(id: u32, cycle: u64, action_id: u32) -> (MotorHeader, Vec<MotorCommand>) {
    let header = MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: id,
        cycle,
        flags: MOTOR_FLAG_STOP,
        command_count: 1,
        ack_cycle: 0,
    };
    let command = MotorCommand {
        action_id,
        ..MotorCommand::default()
    };
    (header, vec![command])
}

/// Drains until a batch with `action_id` from `slot` arrived; returns every batch seen.
fn drain_until(host: &mut ZenohHost, slot: usize, action_id: u32) -> Vec<(usize, u32)> {
    let mut seen = Vec::new();
    pump(host, "the batch", |h| {
        h.drain(&mut |s, _, c| seen.extend(c.iter().map(|c| (s, c.action_id))))
            .unwrap();
        seen.contains(&(slot, action_id))
    });
    seen
}

#[test]
fn an_agent_connects_and_batches_arrive_in_order() {
    let config = config(None);
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let mut a0 = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
    assert!(!host.is_connected(1));
    for i in 0..5 {
        let (h, c) = batch(0, i, 100 + i as u32);
        a0.send_batch(&h, &c).unwrap();
    }
    let seen = drain_until(&mut host, 0, 104);
    assert_eq!(seen, (100..105).map(|a| (0, a)).collect::<Vec<_>>());
    // A frame reaches the agent with its bytes intact.
    let mut loan = host.loan(0).unwrap();
    let (h, payload) = super::super::FrameLoanMut::parts_mut(&mut loan);
    h.cycle = 7;
    payload.fill(0xAB);
    assert!(host.publish(0, loan).unwrap());
    let deadline = Instant::now() + WAIT;
    let frame = loop {
        if let Some(f) = a0.try_receive_newest().unwrap() {
            break f;
        }
        assert!(Instant::now() < deadline, "no frame");
        a0.wait_readable(Duration::from_millis(50));
    };
    use super::super::AgentFrame;
    assert_eq!(frame.header().cycle, 7);
    assert!(frame.payload().iter().all(|&b| b == 0xAB));
    assert_eq!(frame.payload().len(), config.agents[0].frame_bytes());
    assert_eq!(
        host.stats(),
        ZenohHostStats {
            frames_sent: 1,
            ..Default::default()
        }
    );
}

#[test]
fn a_wrong_or_missing_token_is_refused_and_the_right_one_gets_in() {
    let config = config(Some("sesame"));
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let err = agent(&config, 0, Some("wrong")).unwrap_err();
    assert!(
        matches!(err, AgentConnectError::Refused { agent: 0, .. }),
        "{err}"
    );
    let err = agent(&config, 0, None).unwrap_err();
    assert!(matches!(err, AgentConnectError::Refused { .. }), "{err}");
    assert_eq!(host.stats().refused_token, 2);
    let _a0 = agent(&config, 0, Some("sesame")).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
}

#[test]
fn a_wrong_version_or_layout_is_refused_naming_both() {
    let config = config(None);
    let host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let peer = raw_peer(&config);
    for (version, layout) in [
        (PROTOCOL_VERSION + 1, LAYOUT_HASH),
        (PROTOCOL_VERSION, !LAYOUT_HASH),
    ] {
        let hello = Hello {
            protocol_version: version,
            layout_hash: layout,
            agent_id: 0,
            channels: crate::ChannelLayout::default().hash(),
            token: Vec::new(),
        };
        let (code, body) = raw_hello(&peer, host.keys(), encode_hello(&hello));
        assert_eq!(code, reply::REJECT);
        let r = Reject::decode(&body).unwrap();
        assert_eq!(
            (r.code, r.host_protocol, r.host_layout),
            (reject::VERSION, PROTOCOL_VERSION, LAYOUT_HASH)
        );
        assert!(
            r.message.contains(&format!("protocol {version}")),
            "{}",
            r.message
        );
    }
    assert_eq!(host.stats().refused_version, 2);
}

#[test]
fn garbage_and_oversized_hellos_are_refused() {
    let config = config(None);
    let host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let peer = raw_peer(&config);
    // Garbage, too short, longer than any hello.
    for payload in [
        b"GET / HTTP/1.1\r\n".to_vec(),
        vec![0u8; 3],
        vec![7u8; 8 * 1024],
    ] {
        let (code, body) = raw_hello(&peer, host.keys(), payload);
        assert_eq!(code, reply::REJECT);
        assert_eq!(Reject::decode(&body).unwrap().code, reject::MALFORMED);
    }
    assert_eq!(host.stats().refused_malformed, 3);
    let mut host = host;
    let mut refused = Vec::new();
    assert_eq!(host.take_refusals(&mut |r| refused.push(r.kind)), 0);
    assert_eq!(refused, [crate::RefusalKind::Malformed; 3]);
    // Beyond what zenoh reassembles for the host: dropped before it reaches us (no
    // answer); the host goes on and a real agent still gets in.
    let (code, _) = raw_hello(&peer, host.keys(), vec![7u8; 1 << 20]);
    assert_eq!(code, 0);
    let _a0 = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
}

/// A hello whose welcome did not reach its agent in time (a loaded machine) is asked
/// again: the id is not "in use" until a token exists, each hello gets a new welcome, and
/// the agent that declares its token with the last nonce is the connection.
#[test]
fn a_repeated_hello_before_the_token_is_welcomed_again() {
    let config = config(None);
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let peer = raw_peer(&config);
    let hello = Hello {
        protocol_version: PROTOCOL_VERSION,
        layout_hash: LAYOUT_HASH,
        agent_id: 1,
        channels: crate::ChannelLayout::default().hash(),
        token: Vec::new(),
    };
    let (first, body1) = raw_hello(&peer, host.keys(), encode_hello(&hello));
    let (second, body2) = raw_hello(&peer, host.keys(), encode_hello(&hello));
    assert_eq!((first, second), (reply::WELCOME, reply::WELCOME));
    assert_ne!(body1, body2, "each welcome has its own nonce");
    assert_eq!(host.stats().refused_id_in_use, 0);
    let _a1 = agent(&config, 1, None).unwrap();
    pump(&mut host, "agent 1", |h| h.is_connected(1));
    // Once its token exists the id is taken.
    let (third, _) = raw_hello(&peer, host.keys(), encode_hello(&hello));
    assert_eq!(third, reply::REJECT);
}

#[test]
fn an_id_in_use_is_refused_and_free_again_once_its_agent_left() {
    let config = config(None);
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let a0 = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
    let err = agent(&config, 0, None).unwrap_err();
    assert!(
        matches!(err, AgentConnectError::IdInUse { agent: 0, .. }),
        "{err}"
    );
    assert_eq!(host.stats().refused_id_in_use, 1);
    let err = agent(&config, 9, None).unwrap_err();
    match err {
        AgentConnectError::IdNotServed { served, .. } => assert_eq!(served, [0, 1]),
        other => panic!("{other}"),
    }
    assert!(host.is_connected(0), "the first agent is unaffected");
    drop(a0);
    pump(&mut host, "agent 0 gone", |h| !h.is_connected(0));
    let _again = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0 back", |h| h.is_connected(0));
}

/// The agent's view of its host once it is not alive any more (checked as its waits do,
/// the process check included); panics after 20 s.
fn until_not_alive(a: &mut ZenohAgent) -> HostLiveness {
    let deadline = Instant::now() + WAIT;
    loop {
        let seen = a.host_liveness(true);
        if !matches!(seen, HostLiveness::Alive) {
            return seen;
        }
        assert!(Instant::now() < deadline, "the host still looks alive");
        a.wait_readable(Duration::from_millis(50));
    }
}

/// One host and agent 0 connected, with a resume window of `window`.
fn connected_pair(window: Duration) -> (Config, ZenohHost, ZenohAgent) {
    let mut config = config(None);
    config.sync.resume_window = window;
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let a0 = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
    (config, host, a0)
}

#[test]
fn a_clean_close_is_confirmed_by_the_agent_and_seen_as_a_close() {
    let (_config, host, mut a0) = connected_pair(Duration::from_secs(30));
    // The host's drop waits (at most the lease) until the agent confirmed `host/closed`.
    drop(host);
    assert!(
        matches!(until_not_alive(&mut a0), HostLiveness::Closed),
        "a clean close is a close, not a lost link"
    );
}

#[test]
fn a_host_gone_without_its_close_is_gone_once_its_address_refuses() {
    // A window far longer than the test's deadline: the refusal, not the window, ends it.
    let (_config, host, mut a0) = connected_pair(Duration::from_secs(600));
    host.end_without_closing();
    let seen = until_not_alive(&mut a0);
    assert!(matches!(seen, HostLiveness::Gone { .. }), "{seen:?}");
}

#[test]
fn a_host_gone_without_its_close_whose_address_answers_is_waited_for_the_window() {
    let window = Duration::from_secs(2);
    let (config, host, mut a0) = connected_pair(window);
    let addr = config.transport.zenoh.listen[0]
        .strip_prefix("tcp/")
        .unwrap()
        .to_string();
    host.end_without_closing();
    // Something answers on the host's address (as a machine whose link is back before
    // its host is): not a refusal, so the agent waits for the window.
    let listener = std::net::TcpListener::bind(&addr).unwrap();
    let went = Instant::now();
    let seen = until_not_alive(&mut a0);
    assert!(matches!(seen, HostLiveness::Gone { .. }), "{seen:?}");
    assert!(went.elapsed() >= window / 2, "gone before the window");
    drop(listener);
}

#[test]
fn probe_addresses_are_the_tcp_and_tls_endpoints() {
    let connect = [
        "tcp/127.0.0.1:7447".to_string(),
        "tls/host.example:7448?x=1".into(),
        "udp/10.0.0.1:7449".into(),
        "tcp/[::1]:7450#iface=lo".into(),
    ];
    assert_eq!(
        super::agent::probe_addresses(&connect),
        ["127.0.0.1:7447", "host.example:7448", "[::1]:7450"]
    );
}

#[test]
fn garbage_oversized_and_foreign_batches_are_dropped_and_counted() {
    let config = config(None);
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let mut a0 = agent(&config, 0, None).unwrap();
    pump(&mut host, "agent 0", |h| h.is_connected(0));
    let peer = raw_peer(&config);
    let keys = host.keys().clone();
    let motor0 = keys.motor(0);
    // Garbage, too short, too long, a wrong command count, another agent's id: on agent
    // 0's key. A valid batch on agent 1's key (not connected), and on a key of no agent.
    let (h, c) = batch(0, 0, 1);
    let mut wrong_count = h;
    wrong_count.command_count = 2;
    let mut other = h;
    other.agent_id = 1;
    let with = |h: &MotorHeader| [h.as_bytes(), c.as_bytes()].concat();
    // One byte beyond the largest batch the config allows (64 commands).
    let too_long =
        core::mem::size_of::<MotorHeader>() + 64 * core::mem::size_of::<MotorCommand>() + 1;
    let bad: Vec<Vec<u8>> = vec![
        b"garbage".to_vec(),
        vec![0u8; 3],
        vec![0u8; too_long],
        with(&wrong_count),
        with(&other),
    ];
    for payload in &bad {
        peer.put(&motor0, payload.clone()).wait().unwrap();
    }
    peer.put(keys.motor(1), with(&h)).wait().unwrap();
    peer.put(keys.motor(77), with(&h)).wait().unwrap();
    // Far beyond what zenoh reassembles for the host: dropped before any callback.
    peer.put(&motor0, vec![0u8; 4 << 20]).wait().unwrap();
    // Then agent 0's own batch: everything sent before it has been handled by then.
    let (h0, c0) = batch(0, 0, 42);
    a0.send_batch(&h0, &c0).unwrap();
    let deadline = Instant::now() + WAIT;
    let mut seen = Vec::new();
    loop {
        host.drain(&mut |s, _, c| seen.extend(c.iter().map(|c| (s, c.action_id))))
            .unwrap();
        let st = host.stats();
        if st.dropped_malformed == 5 && st.dropped_not_connected == 2 && seen.contains(&(0, 42)) {
            break;
        }
        assert!(Instant::now() < deadline, "{st:?} {seen:?}");
        host.wait_activity(Duration::from_millis(50)).unwrap();
    }
    // Only agent 0's own batch came through; the host and agent 0 are unaffected.
    assert_eq!(seen, [(0, 42)]);
    assert!(host.is_connected(0));
}

#[test]
fn a_flood_of_batches_is_bounded() {
    let config = config(None);
    let mut host = ZenohHost::create(&config, SignalHandling::Leave).unwrap();
    let mut a0 = agent(&config, 0, None).unwrap();
    let _a1 = agent(&config, 1, None).unwrap();
    pump(&mut host, "agents", |h| {
        h.is_connected(0) && h.is_connected(1)
    });
    let n = MAX_QUEUED_BATCHES + 100;
    for i in 0..n {
        let (mut h, c) = batch(0, 0, i as u32);
        h.flags = 0;
        a0.send_batch(&h, &c).unwrap();
    }
    // Then the stop: it has room of its own.
    let (h, c) = batch(0, 0, 9999);
    a0.send_batch(&h, &c).unwrap();
    // Nothing drained meanwhile: the queue holds MAX_QUEUED_BATCHES, the rest is dropped.
    pump(&mut host, "the flood to arrive", |h| {
        h.stats().dropped_flood == 100
    });
    let mut got = Vec::new();
    pump(&mut host, "the stop", |h| {
        h.drain(&mut |_, _, c| got.extend(c.iter().map(|c| c.action_id)))
            .unwrap();
        got.contains(&9999)
    });
    let want: Vec<u32> = (0..MAX_QUEUED_BATCHES as u32).chain([9999]).collect();
    assert_eq!(got, want);
    assert!(host.is_connected(0) && host.is_connected(1));
}

// --- TLS: certificates made by the test, a host and agents over tls/ on loopback -------

/// A folder with `ca.pem`; `host.pem`/`.key` (names 127.0.0.1 and localhost) and
/// `agent.pem`/`.key` signed by it; `stranger.pem`/`.key` signed by another CA.
fn pki() -> tempfile::TempDir {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair,
    };
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: String| std::fs::write(dir.path().join(name), text).unwrap();
    let ca = |cn: &str| {
        let mut p = CertificateParams::new(Vec::<String>::new()).unwrap();
        p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        p.distinguished_name.push(DnType::CommonName, cn);
        CertifiedIssuer::self_signed(p, KeyPair::generate().unwrap()).unwrap()
    };
    let (ours, theirs) = (ca("vrsync test CA"), ca("another CA"));
    write("ca.pem", ours.pem());
    for (name, issuer) in [("host", &ours), ("agent", &ours), ("stranger", &theirs)] {
        let mut p = CertificateParams::new(vec!["127.0.0.1".into(), "localhost".into()]).unwrap();
        p.distinguished_name.push(DnType::CommonName, name);
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        let key = KeyPair::generate().unwrap();
        write(
            &format!("{name}.pem"),
            p.signed_by(&key, issuer).unwrap().pem(),
        );
        write(&format!("{name}.key"), key.serialize_pem());
    }
    dir
}

/// A session whose host listens (`side` "listen") or whose agents connect (`side`
/// "connect") on `endpoint`, with TLS settings `tls` (TOML lines of `[transport.zenoh]`),
/// its files in `dir`.
fn tls_config(
    dir: &std::path::Path,
    session: &str,
    side: &str,
    endpoint: &str,
    tls: &str,
) -> Config {
    let text = format!(
        "session = {session:?}\n[sync]\nstop_timeout = 5.0\n[transport]\nkind = \"zenoh\"\n\
         [transport.zenoh]\n{side} = [{endpoint:?}]\n{tls}\
         [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n\
         [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\n"
    );
    Config::from_toml_str(&text, &dir.join("c.toml")).unwrap()
}

/// A host config with mutual TLS on a loopback port free a moment ago, and its session.
fn mtls_host(dir: &std::path::Path) -> (Config, String) {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let session = format!(
        "zt{}-{}",
        std::process::id(),
        N.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    );
    let host = tls_config(
        dir,
        &session,
        "listen",
        &format!("tls/127.0.0.1:{port}"),
        "tls_ca = \"ca.pem\"\ntls_cert = \"host.pem\"\ntls_key = \"host.key\"\nmtls = true\n",
    );
    (host, session)
}

fn mtls_agent_lines(name: &str) -> String {
    format!(
        "tls_ca = \"ca.pem\"\ntls_cert = \"{name}.pem\"\ntls_key = \"{name}.key\"\nmtls = true\n"
    )
}

/// How long a refused agent tries before it gives up.
const REFUSED_AFTER: Duration = Duration::from_secs(3);

/// Connects agent 0 of `config`, expecting no host within REFUSED_AFTER: returns the
/// error's message; panics if it took far longer (a hang) or got in.
fn refused(config: &Config) -> String {
    let started = Instant::now();
    let err =
        match ZenohAgent::connect_with_token(config, 0, REFUSED_AFTER, None, SignalHandling::Leave)
        {
            Ok(_) => panic!("an agent with {:?} got in", config.transport.zenoh),
            Err(e) => e,
        };
    assert!(
        started.elapsed() < REFUSED_AFTER + Duration::from_secs(10),
        "gave up only after {:?}",
        started.elapsed()
    );
    assert!(
        matches!(err, AgentConnectError::HostNotFound { .. }),
        "{err}"
    );
    err.to_string()
}

#[test]
fn mutual_tls_agents_run_cycles_in_lock_step() {
    use super::super::AgentFrame;
    let dir = pki();
    let (host_config, session) = mtls_host(dir.path());
    let endpoint = &host_config.transport.zenoh.listen[0];
    let agent_config = tls_config(
        dir.path(),
        &session,
        "connect",
        endpoint,
        &mtls_agent_lines("agent"),
    );
    assert_eq!(
        agent_config.transport.zenoh.connect,
        std::slice::from_ref(endpoint)
    );
    let mut host = ZenohHost::create(&host_config, SignalHandling::Leave).unwrap();
    let mut agents = [
        agent(&agent_config, 0, None).unwrap(),
        agent(&agent_config, 1, None).unwrap(),
    ];
    pump(&mut host, "both agents over mutual TLS", |h| {
        h.is_connected(0) && h.is_connected(1)
    });
    for cycle in 0..40u64 {
        // Each agent's frame carries its cycle, and its payload a byte of it.
        for slot in 0..2 {
            let mut loan = host.loan(slot).unwrap();
            let (h, payload) = super::super::FrameLoanMut::parts_mut(&mut loan);
            h.cycle = cycle;
            payload.fill(cycle as u8 ^ slot as u8);
            assert!(host.publish(slot, loan).unwrap());
        }
        // Each agent sees this cycle's frame (not an older one) and stops it.
        for (slot, a) in agents.iter_mut().enumerate() {
            let deadline = Instant::now() + WAIT;
            let frame = loop {
                if let Some(f) = a.try_receive_newest().unwrap() {
                    break f;
                }
                assert!(Instant::now() < deadline, "agent {slot}: no frame {cycle}");
                a.wait_readable(Duration::from_millis(50));
            };
            assert_eq!(frame.header().cycle, cycle);
            assert!(
                frame
                    .payload()
                    .iter()
                    .all(|&b| b == cycle as u8 ^ slot as u8)
            );
            drop(frame);
            let (h, c) = batch(slot as u32, cycle, cycle as u32 * 10 + slot as u32);
            a.send_batch(&h, &c).unwrap();
        }
        // The host has both stops of this cycle before the next frame goes out.
        let mut seen = Vec::new();
        pump(&mut host, "both stops", |h| {
            h.drain(&mut |s, _, c| seen.extend(c.iter().map(|c| (s, c.action_id))))
                .unwrap();
            seen.len() == 2
        });
        seen.sort_unstable();
        let want = [(0, cycle as u32 * 10), (1, cycle as u32 * 10 + 1)];
        assert_eq!(seen, want, "cycle {cycle}");
    }
    assert_eq!(host.stats().frames_sent, 80);
}

#[test]
fn peers_without_a_certificate_of_the_ca_never_reach_the_hello() {
    let dir = pki();
    let (host_config, session) = mtls_host(dir.path());
    let endpoint = &host_config.transport.zenoh.listen[0];
    let mut host = ZenohHost::create(&host_config, SignalHandling::Leave).unwrap();
    // TLS without a client certificate; a client certificate from another CA.
    let no_cert = tls_config(
        dir.path(),
        &session,
        "connect",
        endpoint,
        "tls_ca = \"ca.pem\"\n",
    );
    assert!(no_cert.transport.zenoh.tls.cert.is_none());
    let stranger = tls_config(
        dir.path(),
        &session,
        "connect",
        endpoint,
        &mtls_agent_lines("stranger"),
    );
    for config in [&no_cert, &stranger] {
        let message = refused(config);
        assert!(message.contains(endpoint.as_str()), "{message}");
        assert!(message.contains("signed by tls_ca"), "{message}");
    }
    // Refused in the TLS handshake, below zenoh: no hello reached the host, none was
    // refused by it, nobody was admitted.
    host.wait_activity(Duration::ZERO).unwrap();
    assert_eq!(host.stats(), ZenohHostStats::default());
    assert_eq!(host.take_refusals(&mut |_| {}), 0);
    assert!(!host.is_connected(0));
    // The host is unharmed: an agent with a certificate of its CA gets in.
    let ok = tls_config(
        dir.path(),
        &session,
        "connect",
        endpoint,
        &mtls_agent_lines("agent"),
    );
    let _a0 = agent(&ok, 0, None).unwrap();
    pump(&mut host, "the certified agent", |h| h.is_connected(0));
}

#[test]
fn a_plaintext_agent_against_a_tls_host_is_refused_naming_the_endpoint() {
    let dir = pki();
    let (host_config, session) = mtls_host(dir.path());
    let mut host = ZenohHost::create(&host_config, SignalHandling::Leave).unwrap();
    let tls_endpoint = &host_config.transport.zenoh.listen[0];
    let plain_endpoint = tls_endpoint.replacen("tls/", "tcp/", 1);
    let plain = tls_config(dir.path(), &session, "connect", &plain_endpoint, "");
    let message = refused(&plain);
    assert!(message.contains(&plain_endpoint), "{message}");
    assert!(message.contains("host that listens on tls/"), "{message}");
    host.wait_activity(Duration::ZERO).unwrap();
    assert_eq!(host.stats(), ZenohHostStats::default());
    assert!(!host.is_connected(0));
    // And the other way round: a TLS agent against a plain host never gets in either.
    let (other, other_session) = mtls_host(dir.path());
    let other_tls = &other.transport.zenoh.listen[0];
    let other_plain = other_tls.replacen("tls/", "tcp/", 1);
    let plain_host_config = tls_config(dir.path(), &other_session, "listen", &other_plain, "");
    let _plain_host = ZenohHost::create(&plain_host_config, SignalHandling::Leave).unwrap();
    let lines = mtls_agent_lines("agent");
    let tls_agent = tls_config(dir.path(), &other_session, "connect", other_tls, &lines);
    let message = refused(&tls_agent);
    assert!(message.contains(other_tls.as_str()), "{message}");
}
