//! The host against a fake transport: barrier, leaves, evictions, slow agents.

//! The host's logic over a fake transport: no processes, no shared memory, no sockets.
//! The fake's "agents" answer at the host's waits, as real ones would while it blocks.

use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;

use super::*;
use crate::transport::{BatchSink, HostConnections, HostReadiness};
use crate::wire::{ActionState, Command, MOTOR_FLAG_ACK, MOTOR_FLAG_STOP, MotorHeader};

/// What the fake's agents do; shared between the test and the host's transport.
#[derive(Default)]
struct Agents {
    connected: Vec<bool>,
    /// Slots whose process "died" (reported by `reap_dead_agents`).
    dead: Vec<usize>,
    /// Whether a slot answers each frame it gets with one command and a stop.
    answers: Vec<bool>,
    /// Slots that reconnect at the next wait.
    reconnect: Vec<usize>,
    /// Slots that answer only from this instant on (a busy agent), if any.
    busy_until: Vec<Option<Instant>>,
    /// Frames delivered and not answered yet: (slot, cycle).
    delivered: Vec<(usize, u64)>,
    /// Batches waiting for the host's next drain.
    inbox: Vec<(usize, MotorHeader, Vec<MotorCommand>)>,
    /// Every header published: (slot, header).
    published: Vec<(usize, SensorHeader)>,
}

impl Agents {
    fn batch(&mut self, slot: usize, cycle: u64, stop: bool, commands: Vec<MotorCommand>) {
        let header = MotorHeader {
            protocol_version: PROTOCOL_VERSION,
            agent_id: 0,
            cycle,
            flags: if stop { MOTOR_FLAG_STOP } else { 0 },
            command_count: commands.len() as u32,
            ack_cycle: 0,
        };
        self.inbox.push((slot, header, commands));
    }
}

#[derive(Debug)]
struct FakeLoan {
    header: SensorHeader,
    payload: Vec<u8>,
}

impl FrameLoanMut for FakeLoan {
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        (&mut self.header, &mut self.payload)
    }
    fn header(&self) -> &SensorHeader {
        &self.header
    }
}

struct Fake(Rc<RefCell<Agents>>);

impl HostTransport for Fake {
    type Loan = FakeLoan;

    fn loan(&mut self, _slot: usize) -> Result<FakeLoan, HostTransportError> {
        Ok(FakeLoan {
            header: SensorHeader::default(),
            payload: vec![0; 64],
        })
    }

    fn publish(&mut self, slot: usize, frame: FakeLoan) -> Result<bool, HostTransportError> {
        let mut a = self.0.borrow_mut();
        if !a.connected[slot] {
            return Ok(false);
        }
        a.delivered.push((slot, frame.header.cycle));
        a.published.push((slot, frame.header));
        Ok(true)
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        let inbox = std::mem::take(&mut self.0.borrow_mut().inbox);
        for (slot, header, commands) in &inbox {
            sink(*slot, header, commands);
        }
        Ok(())
    }
}

impl HostReadiness for Fake {
    fn activity_fd(&self) -> std::os::fd::RawFd {
        // Never polled: the fake's wait is its own (below).
        -1
    }

    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        let mut a = self.0.borrow_mut();
        for slot in std::mem::take(&mut a.reconnect) {
            a.connected[slot] = true;
        }
        let delivered = std::mem::take(&mut a.delivered);
        for (slot, cycle) in delivered {
            let busy = a
                .busy_until
                .get(slot)
                .copied()
                .flatten()
                .is_some_and(|t| Instant::now() < t);
            if busy {
                a.delivered.push((slot, cycle));
                continue;
            }
            if a.answers[slot] && a.connected[slot] {
                let command = Command::Turn { angle_deg: 1.0 }.encode(cycle as u32);
                a.batch(slot, cycle, true, vec![command]);
                // An answer acknowledges the frame it answers, as the SDK's stop does.
                if let Some((_, header, _)) = a.inbox.last_mut() {
                    header.flags |= MOTOR_FLAG_ACK;
                    header.ack_cycle = cycle;
                }
            }
        }
        if a.inbox.is_empty() {
            // Nothing will answer: let the time the host waits for pass (briefly).
            drop(a);
            std::thread::sleep(timeout.min(Duration::from_millis(2)));
        }
        Ok(())
    }
}

impl HostConnections for Fake {
    fn is_connected(&self, slot: usize) -> bool {
        self.0
            .borrow()
            .connected
            .get(slot)
            .copied()
            .unwrap_or(false)
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        Ok(())
    }

    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        dead.extend(std::mem::take(&mut self.0.borrow_mut().dead));
    }
}

/// A host of agents 3 and 7 (ids are not slots) over the fake, both connected and
/// answering, with `wait_for_stop = "timeout"` (the original semantics).
fn host(policy: &str) -> (Host<Fake>, Rc<RefCell<Agents>>) {
    host_waiting(policy, "timeout", 0.2)
}

/// [`host`] with `wait_for_stop = wait` and `stop_timeout = stop_timeout_s`.
fn host_waiting(
    policy: &str,
    wait: &str,
    stop_timeout_s: f64,
) -> (Host<Fake>, Rc<RefCell<Agents>>) {
    let text = format!(
        "session = \"fake\"\n[sync]\nstop_timeout = {stop_timeout_s}\nconnect_timeout = 0.2\n\
         on_agent_lost = {policy:?}\nwait_for_stop = {wait:?}\n[[agent]]\nid = 3\n\
         [[agent]]\nid = 7\n"
    );
    let config = Config::from_toml_str(&text, Path::new("fake.toml")).unwrap();
    let agents = Rc::new(RefCell::new(Agents {
        connected: vec![true, true],
        answers: vec![true, true],
        ..Agents::default()
    }));
    let mut host = Host::over(&config, Fake(agents.clone()), SignalHandling::Leave);
    host.wait_for_agents(Duration::from_secs(1)).unwrap();
    (host, agents)
}

fn publish_all(host: &mut Host<Fake>) {
    for id in [3, 7] {
        let frame = host.loan_frame(id).unwrap();
        assert_eq!(frame.header().cycle, host.cycle());
        assert_eq!(frame.header().agent_id, id);
        host.publish(frame).unwrap();
    }
    host.start().unwrap();
}

fn outcomes(report: &CycleReport) -> Vec<(u32, AgentOutcome)> {
    report
        .agents()
        .iter()
        .map(|a| (a.agent_id, a.outcome))
        .collect()
}

#[test]
fn a_cycle_ends_when_every_awaited_agent_stopped_with_its_commands() {
    let (mut host, _agents) = host("evict");
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(report.cycle, 0);
    assert!(!report.timed_out);
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
    );
    assert!(report.agents().iter().all(|a| a.commands().len() == 1));
    assert_eq!(host.cycle(), 1);
}

#[test]
fn a_late_stop_never_completes_the_next_cycle_and_the_timeout_names_the_agent() {
    let (mut host, agents) = host("evict");
    publish_all(&mut host);
    host.collect().unwrap();
    // Cycle 1: agent 3 is silent; its stop for cycle 0 arrives again (late), and
    // agent 7 sends a batch for cycle 5 (future) besides its stop.
    {
        let mut a = agents.borrow_mut();
        a.answers[0] = false;
        a.batch(0, 0, true, Vec::new());
        a.batch(1, 5, true, Vec::new());
    }
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(report.cycle, 1);
    assert!(report.timed_out);
    assert_eq!(report.timed_out_agents().collect::<Vec<_>>(), [3]);
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::TimedOut), (7, AgentOutcome::Stopped)]
    );
    assert_eq!(report.late_batches, 1);
    let stats = host.stats();
    assert_eq!((stats.late_batches, stats.future_batches), (1, 1));
    assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (1, 1));
}

/// The slow reports a test's `on_slow` hook recorded: (agent, cycle, waited).
type SlowReports = Rc<RefCell<Vec<(u32, u64, Duration)>>>;

/// A host with `wait_for_stop = "alive"` (stop_timeout 50 ms) whose agent 3 is busy
/// for `busy`, recording the slow reports.
fn busy_agent_3(busy: Duration) -> (Host<Fake>, Rc<RefCell<Agents>>, SlowReports) {
    let (mut host, agents) = host_waiting("evict", "alive", 0.05);
    let slow = Rc::new(RefCell::new(Vec::new()));
    let seen = slow.clone();
    host.on_slow(move |agent, cycle, waited| seen.borrow_mut().push((agent, cycle, waited)));
    publish_all(&mut host);
    host.collect().unwrap();
    agents.borrow_mut().busy_until = vec![Some(Instant::now() + busy), None];
    (host, agents, slow)
}

#[test]
fn a_live_busy_agent_is_waited_for_and_reported_slow_not_timed_out() {
    let (mut host, _agents, slow) = busy_agent_3(Duration::from_millis(260));
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert!(!report.timed_out);
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
    );
    assert!(report.agents().iter().all(|a| a.commands().len() == 1));
    assert_eq!(report.slow_agents().collect::<Vec<_>>(), [3]);
    assert!(report.agent(3).unwrap().slow && !report.agent(7).unwrap().slow);
    // Reported at 1×, 2× and 4× the stop timeout (0.05, 0.1, 0.2 s) as it waited.
    let slow = slow.borrow();
    assert!(slow.len() >= 3, "{slow:?}");
    assert!(
        slow.iter()
            .all(|&(agent, cycle, _)| (agent, cycle) == (3, 1))
    );
    assert!(slow[0].2 >= Duration::from_millis(50), "{slow:?}");
    assert!(slow[2].2 >= Duration::from_millis(200), "{slow:?}");
    let stats = host.stats();
    assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (0, 0));
    assert_eq!((stats.slow_stops, stats.late_batches), (1, 0));
    // The next cycle is an ordinary one again.
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(report.slow_agents().count(), 0);
    assert_eq!(host.stats().slow_stops, 1);
}

#[test]
fn a_busy_agent_that_dies_is_evicted_and_the_others_go_on() {
    let (mut host, agents, slow) = busy_agent_3(Duration::from_secs(3600));
    publish_all(&mut host);
    // The fake's agent 3 dies after the host reported it slow once.
    let dying = agents.clone();
    let seen = slow.clone();
    host.on_slow(move |agent, cycle, waited| {
        seen.borrow_mut().push((agent, cycle, waited));
        dying.borrow_mut().dead.push(0);
    });
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Evicted), (7, AgentOutcome::Stopped)]
    );
    assert!(!report.timed_out);
    // Evicted at the next reap (100 ms), not waited for on.
    assert!(slow.borrow().len() <= 2, "{:?}", slow.borrow());
    assert_eq!(host.stats().evicted_agents, [3]);
    assert_eq!(host.stats().stop_timeouts, 0);
}

#[test]
fn per_agent_policies_a_timeout_agent_times_out_while_the_cycle_waits_for_a_live_one() {
    let text = "session = \"fake\"\n[sync]\nstop_timeout = 0.05\nconnect_timeout = 0.2\n\
                [[agent]]\nid = 3\nwait_for_stop = \"timeout\"\n[[agent]]\nid = 7\n";
    let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
    let agents = Rc::new(RefCell::new(Agents {
        connected: vec![true, true],
        answers: vec![false, true],
        busy_until: vec![None, Some(Instant::now() + Duration::from_millis(200))],
        ..Agents::default()
    }));
    let mut host = Host::over(&config, Fake(agents.clone()), SignalHandling::Leave);
    host.wait_for_agents(Duration::from_secs(1)).unwrap();
    publish_all(&mut host);
    // Agent 3's stop comes after its timeout, while the cycle still waits for 7.
    agents.borrow_mut().busy_until[0] = Some(Instant::now() + Duration::from_millis(100));
    agents.borrow_mut().answers[0] = true;
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::TimedOut), (7, AgentOutcome::Stopped)]
    );
    assert!(report.timed_out);
    assert_eq!(report.slow_agents().collect::<Vec<_>>(), [7]);
    assert!(report.agent(3).unwrap().commands().is_empty());
    assert_eq!(report.late_batches, 1, "its stop came after its timeout");
    let stats = host.stats();
    assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (1, 1));
    assert_eq!(stats.slow_stops, 1);
}

#[test]
fn a_leaving_agent_is_not_waited_for_counts_a_leave_and_its_id_takes_part_again() {
    let (mut host, agents) = host_waiting("abort", "alive", 0.05);
    publish_all(&mut host);
    host.collect().unwrap();
    // Cycle 1: agent 7 reads its frame and leaves without a stop.
    {
        let mut a = agents.borrow_mut();
        a.answers[1] = false;
        a.inbox.push((
            1,
            MotorHeader {
                protocol_version: PROTOCOL_VERSION,
                agent_id: 7,
                cycle: 1,
                flags: crate::wire::MOTOR_FLAG_LEAVE,
                command_count: 0,
                ack_cycle: 0,
            },
            Vec::new(),
        ));
    }
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Left)]
    );
    assert_eq!(report.left_agents().collect::<Vec<_>>(), [7]);
    assert_eq!(report.evicted_agents().count(), 0);
    assert!(!report.timed_out && report.slow_agents().count() == 0);
    assert!(host.has_left(7) && !host.is_evicted(7));
    // Not lost: on_agent_lost = "abort" does not apply. Cycle 2: a new connection
    // of id 7 answers again.
    {
        let mut a = agents.borrow_mut();
        a.answers[1] = true;
        // The new connection never saw cycle 1's frame.
        a.delivered.retain(|&(slot, _)| slot != 1);
    }
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
    );
    assert_eq!(report.rejoined_agents().collect::<Vec<_>>(), [7]);
    assert!(!host.has_left(7));
    let stats = host.stats();
    assert_eq!((stats.leaves, stats.rejoins, stats.evictions), (1, 1, 0));
    assert!(stats.evicted_agents.is_empty());
    assert_eq!((stats.stop_timeouts, stats.late_batches), (0, 0));
}

#[test]
fn a_disconnected_agent_is_evicted_then_rejoins() {
    let (mut host, agents) = host("evict");
    let evicted = Rc::new(RefCell::new(Vec::new()));
    let seen = evicted.clone();
    host.on_evicted(move |id, cycle| seen.borrow_mut().push((id, cycle)));
    publish_all(&mut host);
    host.collect().unwrap();
    // Cycle 1: agent 7's frame reaches it, then it disconnects without a stop.
    agents.borrow_mut().answers[1] = false;
    publish_all(&mut host);
    agents.borrow_mut().connected[1] = false;
    let report = host.collect().unwrap();
    assert!(!report.timed_out, "a lost agent is evicted, not waited for");
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Evicted)]
    );
    assert_eq!(report.evicted_agents().collect::<Vec<_>>(), [7]);
    assert!(report.agent(7).unwrap().evicted && !report.agent(3).unwrap().evicted);
    assert_eq!(*evicted.borrow(), [(7, 1)]);
    assert!(host.is_evicted(7));
    // Cycle 2: its frame is not delivered; cycle 3: it is back.
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::NotAwaited)]
    );
    assert_eq!(report.evicted_agents().count(), 0);
    assert_eq!(report.rejoined_agents().count(), 0);
    {
        let mut a = agents.borrow_mut();
        a.connected[1] = true;
        a.answers[1] = true;
    }
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
    );
    assert_eq!(report.rejoined_agents().collect::<Vec<_>>(), [7]);
    assert!(report.agent(7).unwrap().rejoined);
    assert!(report.agent(5).is_none());
    assert!(!host.is_evicted(7));
    let stats = host.stats();
    assert_eq!(stats.evicted_agents, [7]);
    assert_eq!((stats.evictions, stats.rejoins), (1, 1));
    assert_eq!(stats.frames_undelivered, 1);
}

#[test]
fn a_dead_agent_process_is_evicted() {
    let (mut host, agents) = host("evict");
    agents.borrow_mut().answers[0] = false;
    publish_all(&mut host);
    agents.borrow_mut().dead.push(0);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Evicted), (7, AgentOutcome::Stopped)]
    );
    assert_eq!(host.stats().evicted_agents, [3]);
}

fn lose_agent_7(host: &mut Host<Fake>, agents: &Rc<RefCell<Agents>>) {
    agents.borrow_mut().answers[1] = false;
    publish_all(host);
    agents.borrow_mut().connected[1] = false;
}

#[test]
fn on_agent_lost_abort_names_the_agent_and_cycle() {
    let (mut host, agents) = host("abort");
    lose_agent_7(&mut host, &agents);
    let err = host.collect().unwrap_err();
    assert!(
        matches!(err, HostCycleError::AgentLost { agent: 7, cycle: 0 }),
        "{err:?}"
    );
}

#[test]
fn on_agent_lost_wait_pauses_until_the_agent_is_back() {
    let (mut host, agents) = host("wait");
    lose_agent_7(&mut host, &agents);
    agents.borrow_mut().reconnect.push(1);
    let report = host.collect().unwrap();
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Evicted)]
    );
    assert!(host.is_connected(7));
}

#[test]
fn on_agent_lost_wait_gives_up_after_the_connect_timeout() {
    let (mut host, agents) = host("wait");
    lose_agent_7(&mut host, &agents);
    let err = host.collect().unwrap_err();
    assert!(
        matches!(err, HostCycleError::AgentNotBack { agent: 7, .. }),
        "{err:?}"
    );
}

/// Publishes agent 3's and 7's frames, agent 3's with `statuses` as the simulator's
/// new events, and collects; returns the (action id, state, seq) agent 3 got.
fn cycle_with_statuses(
    host: &mut Host<Fake>,
    agents: &Rc<RefCell<Agents>>,
    statuses: &[(u32, ActionState)],
) -> Vec<(u32, u32, u64)> {
    for id in [3, 7] {
        let mut frame = host.loan_frame(id).unwrap();
        assert_eq!(
            frame.header().status_count,
            0,
            "a loaned frame starts empty"
        );
        if id == 3 {
            for &(action, state) in statuses {
                frame.header_mut().push_status(action, state);
            }
        }
        host.publish(frame).unwrap();
    }
    host.start().unwrap();
    let got = {
        let a = agents.borrow();
        let (_, h) = a
            .published
            .iter()
            .rev()
            .find(|(slot, _)| *slot == 0)
            .unwrap();
        h.statuses()
            .iter()
            .map(|s| (s.action_id, s.state, s.seq))
            .collect()
    };
    host.collect().unwrap();
    got
}

#[test]
fn events_repeat_until_a_batch_acknowledges_a_frame_that_carried_them() {
    let (mut host, agents) = host("evict");
    let (fin, walk) = (ActionState::Finished as u32, ActionState::Walking as u32);
    // Agent 3 answers: each frame's events are acknowledged by its stop.
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &[(1, ActionState::Finished)]),
        [(1, fin, 1)]
    );
    assert_eq!(host.report.agent(3).unwrap().read_cycle, Some(0));
    assert!(cycle_with_statuses(&mut host, &agents, &[]).is_empty());
    // Agent 3 stalls for two cycles: its events pile up and repeat.
    agents.borrow_mut().answers[0] = false;
    let two = [(2, ActionState::Walking)];
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &two),
        [(2, walk, 2)]
    );
    let three = [(2, ActionState::Finished)];
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &three),
        [(2, walk, 2), (2, fin, 3)]
    );
    // It is back: the frame it reads still carries both, then they are gone.
    agents.borrow_mut().answers[0] = true;
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &[]),
        [(2, walk, 2), (2, fin, 3)]
    );
    assert_eq!(host.report.agent(3).unwrap().read_cycle, Some(4));
    assert!(cycle_with_statuses(&mut host, &agents, &[]).is_empty());
    let stats = host.stats();
    assert_eq!(stats.frames_delivered, 12);
    // Agent 3 read 4 of its 6 frames (and skipped 2); agent 7 all 6.
    assert_eq!(stats.frames_read, 10);
    assert_eq!(stats.statuses_dropped, 0);
}

#[test]
fn the_commands_of_a_dropped_batch_are_reported_aborted() {
    let (mut host, agents) = host("evict");
    agents.borrow_mut().answers[0] = false;
    cycle_with_statuses(&mut host, &agents, &[]);
    // Agent 3's batch for cycle 0 arrives in cycle 1: late, its command never runs.
    agents
        .borrow_mut()
        .batch(0, 0, true, vec![Command::CancelMove.encode(42)]);
    cycle_with_statuses(&mut host, &agents, &[]);
    let abort = ActionState::Aborted as u32;
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &[]),
        [(42, abort, 1)]
    );
    assert_eq!(host.stats().late_batches, 1);
}

#[test]
fn an_evicted_agent_does_not_inherit_its_old_events() {
    let (mut host, agents) = host("evict");
    agents.borrow_mut().answers[0] = false;
    cycle_with_statuses(&mut host, &agents, &[(1, ActionState::Finished)]);
    // Gone during cycle 1, back for cycle 2: a new process starts afresh.
    agents.borrow_mut().connected[0] = false;
    cycle_with_statuses(&mut host, &agents, &[]);
    assert!(host.is_evicted(3));
    {
        let mut a = agents.borrow_mut();
        a.connected[0] = true;
        a.answers[0] = true;
    }
    let fin = ActionState::Finished as u32;
    assert_eq!(
        cycle_with_statuses(&mut host, &agents, &[(9, ActionState::Finished)]),
        [(9, fin, 2)]
    );
}

#[test]
fn waiting_for_agents_names_the_missing_ones_and_the_session() {
    let text = "session = \"fake\"\n[[agent]]\nid = 3\n[[agent]]\nid = 7\n";
    let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
    let agents = Rc::new(RefCell::new(Agents {
        connected: vec![true, false],
        answers: vec![true, true],
        ..Agents::default()
    }));
    let mut host = Host::over(&config, Fake(agents), SignalHandling::Leave);
    let err = host.wait_for_agents(Duration::from_millis(20)).unwrap_err();
    match &err {
        HostWaitError::AgentsMissing {
            session, missing, ..
        } => {
            assert_eq!(session, "fake");
            assert_eq!(missing, &[7]);
        }
        other => panic!("{other:?}"),
    }
    assert!(!err.to_string().contains("vr-agent"), "{err}");
}

#[test]
fn an_agent_that_connected_and_left_is_named_as_such() {
    let text = "session = \"fake\"\n[[agent]]\nid = 3\n[[agent]]\nid = 7\n";
    let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
    let agents = Rc::new(RefCell::new(Agents {
        connected: vec![false, true],
        answers: vec![true, true],
        ..Agents::default()
    }));
    let mut host = Host::over(&config, Fake(agents.clone()), SignalHandling::Leave);
    assert!(host.wait_for_agents(Duration::from_millis(5)).is_err());
    agents.borrow_mut().connected[1] = false;
    let err = host.wait_for_agents(Duration::from_millis(5)).unwrap_err();
    let HostWaitError::AgentsMissing { missing, left, .. } = &err else {
        panic!("{err:?}");
    };
    assert_eq!(
        (missing.as_slice(), left.as_slice()),
        (&[3, 7][..], &[7][..])
    );
    let message = err.to_string();
    assert!(
        message.contains("agents [3] did not connect within ")
            && message.contains("agents [7] connected and left again"),
        "{message}"
    );
}

#[test]
fn an_interrupted_collect_is_finished_by_the_next_with_what_came_before() {
    let (mut host, agents) = host_waiting("evict", "alive", 5.0);
    // Agent 7 is busy; agent 3 answers at the first wait, and the interrupt comes at the
    // second, after the host took agent 3's command.
    agents.borrow_mut().busy_until = vec![None, Some(Instant::now() + Duration::from_secs(3600))];
    let calls = Rc::new(RefCell::new(0u32));
    let counted = calls.clone();
    host.set_interrupt(move || {
        *counted.borrow_mut() += 1;
        *counted.borrow() >= 3
    });
    publish_all(&mut host);
    assert!(matches!(host.collect(), Err(HostCycleError::Terminated)));
    assert_eq!(host.cycle(), 0, "the cycle did not end");
    host.set_interrupt(|| false);
    agents.borrow_mut().busy_until[1] = None;
    let report = host.collect().unwrap();
    assert_eq!(report.cycle, 0);
    assert_eq!(
        outcomes(report),
        [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
    );
    assert!(
        report.agents().iter().all(|a| a.commands().len() == 1),
        "{report:?}"
    );
    assert_eq!(host.cycle(), 1);
    // The next cycle starts afresh.
    publish_all(&mut host);
    let report = host.collect().unwrap();
    assert!(
        report.agents().iter().all(|a| a.commands().len() == 1),
        "{report:?}"
    );
}
