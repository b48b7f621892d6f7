//! The stacked sample: the host writes each agent's payload into its block, the agents of
//! one reader find it there; what is refused, and why.

use super::*;
use crate::{AgentTransport, HostTransport};

/// A sync-mode config of agents `0..agents` on shared memory (one 8x4 rgb8 camera each,
/// 96 bytes), stacked or not, in a session of its own; agent `tcp_id`, if given, on TCP.
fn config(tag: &str, agents: u32, stacked: bool, tcp_id: Option<u32>) -> Config {
    let session = format!("stack-{tag}-{}", std::process::id());
    let mut text = format!(
        "session = {session:?}\n[sync]\nsync_mode = true\n[transport]\nkind = \"shm\"\n\
         tcp_listen = \"127.0.0.1:0\"\n[transport.shm]\nstacked_images = {stacked}\n"
    );
    for id in 0..agents {
        let transport = if Some(id) == tcp_id { "tcp" } else { "shm" };
        text += &format!(
            "[[agent]]\nid = {id}\ntransport = {transport:?}\n[[agent.camera]]\nname = \"c\"\n\
             width = 8\nheight = 4\n"
        );
    }
    Config::from_toml_str(&text, std::path::Path::new("<test>")).unwrap()
}

fn connect(config: &Config, id: u32) -> ShmAgent {
    ShmAgent::connect(config, id, Duration::from_secs(20), SignalHandling::Leave).unwrap()
}

/// A host of `config`, every agent connected and joined to one reader, and the reader.
fn joined(config: &Config) -> (ShmHost, Vec<ShmAgent>, SharedStack) {
    let mut host = ShmHost::create(config, SignalHandling::Leave).unwrap();
    let mut agents: Vec<ShmAgent> = config
        .agents
        .iter()
        .map(|a| connect(config, a.id))
        .collect();
    let stack: SharedStack = Rc::new(RefCell::new(ShmStack::open(config).unwrap()));
    for a in &mut agents {
        a.join_stack(&stack).unwrap();
    }
    host.update_connections().unwrap();
    (host, agents, stack)
}

/// One cycle: every slot's frame loaned, its payload filled with `fill(slot)` and its
/// cycle set, published, then *start*.
fn cycle(host: &mut ShmHost, slots: usize, cycle: u64, fill: impl Fn(usize) -> u8) {
    for slot in 0..slots {
        let mut loan = host.loan(slot).unwrap();
        let (header, payload) = loan.parts_mut();
        header.cycle = cycle;
        payload.fill(fill(slot));
        host.publish(slot, loan).unwrap();
    }
    host.signal_start().unwrap();
}

#[test]
fn each_agents_payload_is_its_block_of_one_stacked_sample() {
    let config = config("blocks", 3, true, None);
    let (mut host, mut agents, stack) = joined(&config);
    assert!(agents.iter().all(ShmAgent::is_stacked));
    let stride = stack_stride(8 * 4 * 3);
    assert_eq!(stride, 128);
    assert_eq!(stack.borrow().stride(), stride);
    for c in 1..=3u64 {
        cycle(&mut host, 3, c, |slot| 10 * c as u8 + slot as u8);
        let frames: Vec<ShmFrame> = agents
            .iter_mut()
            .map(|a| a.try_receive_newest().unwrap().expect("a frame"))
            .collect();
        let (first, _) = frames[0].stacked().unwrap();
        for (k, f) in frames.iter().enumerate() {
            assert_eq!(f.header().cycle, c);
            assert_eq!(f.payload().len(), 96);
            assert!(f.payload().iter().all(|&b| b == 10 * c as u8 + k as u8));
            let (sample, range) = f.stacked().unwrap();
            assert!(Rc::ptr_eq(sample, first), "one sample for every agent");
            assert_eq!(sample.cycle(), c);
            assert_eq!(range, k * stride..k * stride + 96);
        }
    }
    // Released samples are refilled: the reader allocated one or two, not one per cycle.
    assert!(
        stack.borrow().pool.len() <= 2,
        "{}",
        stack.borrow().pool.len()
    );
}

#[test]
fn a_held_frame_keeps_its_payload_while_later_cycles_come() {
    let config = config("held-frame", 1, true, None);
    let (mut host, mut agents, _stack) = joined(&config);
    let agent = &mut agents[0];
    cycle(&mut host, 1, 1, |_| 1);
    let held = agent.try_receive_newest().unwrap().unwrap();
    for c in 2..=6u64 {
        cycle(&mut host, 1, c, |_| c as u8);
        let f = agent.try_receive_newest().unwrap().unwrap();
        assert_eq!((f.header().cycle, f.payload()[0]), (c, c as u8));
    }
    assert_eq!((held.header().cycle, held.payload()[0]), (1, 1));
    assert!(held.payload().iter().all(|&b| b == 1), "never overwritten");
    // Two held and a third wanted: refused, and the header waits for the next look.
    let second = agent.try_receive_newest().unwrap();
    assert!(second.is_none(), "nothing new");
    cycle(&mut host, 1, 7, |_| 7);
    let seventh = agent.try_receive_newest().unwrap().unwrap();
    cycle(&mut host, 1, 8, |_| 8);
    assert!(matches!(
        agent.try_receive_newest(),
        Err(AgentReceiveError::TooManyFramesHeld { .. })
    ));
    drop(held);
    drop(seventh);
    let f = agent
        .try_receive_newest()
        .unwrap()
        .expect("the kept header, now paired");
    assert_eq!((f.header().cycle, f.payload()[0]), (8, 8));
}

#[test]
fn a_header_waits_for_its_stacked_sample_and_a_replaced_one_is_skipped() {
    let config = config("pairing", 1, true, None);
    let (mut host, mut agents, _stack) = joined(&config);
    let agent = &mut agents[0];
    // The header is published, the stacked sample not yet (it goes at start).
    let mut loan = host.loan(0).unwrap();
    loan.parts_mut().0.cycle = 1;
    loan.parts_mut().1.fill(7);
    host.publish(0, loan).unwrap();
    assert!(agent.try_receive_newest().unwrap().is_none());
    host.signal_start().unwrap();
    let f = agent
        .try_receive_newest()
        .unwrap()
        .expect("the kept header with its sample");
    assert_eq!((f.header().cycle, f.payload()[0]), (1, 7));
    drop(f);
    // Two cycles before the agent looks: it gets the newer one.
    cycle(&mut host, 1, 2, |_| 8);
    cycle(&mut host, 1, 3, |_| 9);
    let f = agent.try_receive_newest().unwrap().expect("cycle 3");
    assert_eq!((f.header().cycle, f.payload()[0]), (3, 9));
}

#[test]
fn a_stacked_agent_without_a_reader_and_a_second_reader_are_refused() {
    let config = config("refused", 2, true, None);
    let mut host = ShmHost::create(&config, SignalHandling::Leave).unwrap();
    let mut lone = connect(&config, 0);
    host.update_connections().unwrap();
    cycle(&mut host, 2, 1, |_| 1);
    let e = lone.try_receive_newest().unwrap_err().to_string();
    assert!(
        e.contains("stacked_images") && e.contains("join_stack"),
        "{e}"
    );
    let _reader = ShmStack::open(&config).unwrap();
    let e = ShmStack::open(&config).unwrap_err().to_string();
    assert!(e.contains("another"), "{e}");
}

#[test]
fn a_frame_still_loaned_at_start_is_an_error_not_a_race() {
    let config = config("held", 2, true, None);
    let mut host = ShmHost::create(&config, SignalHandling::Leave).unwrap();
    let published = host.loan(0).unwrap();
    host.publish(0, published).unwrap();
    let held = host.loan(1).unwrap();
    // The same agent's frame twice in one cycle: refused, the first is still written.
    assert!(host.loan(1).is_err());
    let e = host.signal_start().unwrap_err().to_string();
    assert!(e.contains("still loaned"), "{e}");
    // Once it is published, the cycle starts.
    host.publish(1, held).unwrap();
    host.signal_start().unwrap();
}

#[test]
fn host_and_agent_of_different_configs_are_told_so() {
    let stacked = config("mismatch", 2, true, None);
    let _host = ShmHost::create(&stacked, SignalHandling::Leave).unwrap();
    let mut plain = stacked.clone();
    plain.transport.shm.stacked_images = false;
    let e = ShmAgent::connect(&plain, 0, Duration::from_secs(20), SignalHandling::Leave)
        .unwrap_err()
        .to_string();
    assert!(e.contains("different configs"), "{e}");
}

#[test]
fn the_config_stacks_only_agents_of_one_layout_and_only_shared_memory_ones() {
    // A TCP agent is not stacked: the shared-memory ones are blocks 0 and 1.
    let mixed = config("mixed", 3, true, Some(1));
    assert_eq!(stack_index(&mixed, 0), Some(0));
    assert_eq!(stack_index(&mixed, 1), None);
    assert_eq!(stack_index(&mixed, 2), Some(1));
    assert_eq!(stack_shape(&mixed), Some((2, 96)));
    assert_eq!(stack_index(&config("off", 2, false, None), 0), None);
    // Other cameras on one shared-memory agent: refused, naming the key and both agents.
    let text = "session = \"s\"\n[transport.shm]\nstacked_images = true\n\
                [[agent]]\nid = 0\n[[agent.camera]]\nname = \"c\"\nwidth = 8\nheight = 4\n\
                [[agent]]\nid = 1\n[[agent.camera]]\nname = \"c\"\nwidth = 8\nheight = 8\n";
    let e = Config::from_toml_str(text, std::path::Path::new("x.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("transport.shm.stacked_images") && e.contains("agent 1") && e.contains(":3"),
        "{e}"
    );
}

const CHILD_ENV: &str = "VRSYNC_TEST_STACK_READER_SESSION";

/// A reader whose process was killed leaves its port behind; the next reader of the
/// session still gets the stacked sample (iceoryx2 cleans a dead node's ports when the
/// service is opened).
#[test]
fn a_killed_readers_place_goes_to_the_next_reader() {
    if let Ok(session) = std::env::var(CHILD_ENV) {
        // The child: open the reader of `session`, then die without cleaning up.
        let mut config = config("killed", 1, true, None);
        config.session = session;
        let _reader = ShmStack::open(&config).unwrap();
        // SAFETY: kills this (child) process on purpose.
        unsafe { libc::raise(libc::SIGKILL) };
        return;
    }
    let config = config("killed", 1, true, None);
    let _host = ShmHost::create(&config, SignalHandling::Leave).unwrap();
    let status = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "shm::stack::tests::a_killed_readers_place_goes_to_the_next_reader",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, &config.session)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(libc::SIGKILL)
    );
    ShmStack::open(&config).expect("the dead reader's place is free again");
}
