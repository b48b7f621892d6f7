//! The legacy host against raw sockets speaking the original protocol.

//! The legacy host over real loopback sockets, driven through the host contract; the
//! "clients" are raw byte streams. Bad input of every kind (issue 14 item 5).

use std::io::{Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};

use prost::Message;

use super::*;
use crate::codec::{AgentMovement, Images, Reset, single_field};

/// Creates a host for legacy agents `ids`, on a port range found by trying: a base
/// port derived from the process id and a counter, and on any bind conflict (another
/// test or program holds one of the ports) the next candidate. The host binds the
/// ports itself, so there is no window between choosing and binding.
fn host(ids: &[u32], extra: &str) -> (LegacyHost, u16) {
    static N: AtomicU32 = AtomicU32::new(0);
    for _ in 0..50 {
        let n = N.fetch_add(1, Ordering::Relaxed);
        let base = 20_000 + (std::process::id().wrapping_mul(7919).wrapping_add(n * 263)) % 40_000;
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
    let (descs, _) = vrsync_protocol::wire::image_layout([
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
