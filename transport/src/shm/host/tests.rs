//! The shared-memory host's own tests: its poll and its drains.

use super::*;
use crate::config::SyncConfig;

/// A sync-mode config of agents `0..agents` (one 8x8 camera each) in a session of its
/// own, whose waits poll for `spin_us` µs before they sleep.
fn config(tag: &str, agents: u32, spin_us: u32) -> Config {
    let session = format!("shm-{tag}-{}", std::process::id());
    let mut text = format!(
        "session = {session:?}\n[sync]\nsync_mode = true\nwait = \"block\"\n\
         spin_before_block_us = {spin_us}\n[transport]\nkind = \"shm\"\n"
    );
    for id in 0..agents {
        text += &format!(
            "[[agent]]\nid = {id}\n[[agent.camera]]\nname = \"c\"\nwidth = 8\nheight = 8\n"
        );
    }
    Config::from_toml_str(&text, std::path::Path::new("<test>")).unwrap()
}

/// Every agent of `config`, connected from this process.
fn connect_all(config: &Config) -> Vec<ShmAgent> {
    (config.agents.iter())
        .map(|a| {
            ShmAgent::connect(config, a.id, Duration::from_secs(20), SignalHandling::Leave).unwrap()
        })
        .collect()
}

#[test]
fn the_agents_of_one_process_count_as_one_for_the_hosts_poll() {
    let config = config("processes", 4, 50);
    let spin = config.sync.spin_before_block;
    let polls = |processes| SyncConfig::spin_for_processes(spin, processes);
    let mut host = ShmHost::create(&config, SignalHandling::Leave).unwrap();
    // Nothing connected: each agent counts as a process of its own.
    assert_eq!(host.poll.length(), polls(4));
    // Four agents of this one process connect and get a frame each.
    let _agents = connect_all(&config);
    host.update_connections().unwrap();
    for slot in 0..4 {
        let frame = host.loan(slot).unwrap();
        assert!(host.publish(slot, frame).unwrap());
    }
    assert_eq!(host.poll.length(), polls(1));
    // One leaves: until a connection of its id is served, it counts on its own.
    host.forget_connection(0);
    assert_eq!(host.poll.length(), polls(2));
}

/// The slots whose batches one drain hands out, with each batch's flags.
fn drained(host: &mut ShmHost) -> Vec<(usize, u32)> {
    let mut got = Vec::new();
    host.drain(&mut |slot, h: &MotorHeader, _| got.push((slot, h.flags)))
        .unwrap();
    got
}

#[test]
fn a_drain_takes_what_notified_and_the_cycles_first_takes_every_queue() {
    use crate::wire::{MOTOR_FLAG_LEAVE, MOTOR_FLAG_STOP};
    // No poll: the host sleeps on the stop listener.
    let config = config("drain", 2, 0);
    let mut host = ShmHost::create(&config, SignalHandling::Leave).unwrap();
    let mut agents = connect_all(&config);
    host.update_connections().unwrap();
    // The agents' "here" notifications at connect, taken in.
    host.wait_activity(Duration::ZERO).unwrap();
    assert!(drained(&mut host).is_empty());
    let batch = |id: u32, flags: u32| MotorHeader {
        protocol_version: PROTOCOL_VERSION,
        agent_id: id,
        cycle: 0,
        flags,
        command_count: 0,
        ack_cycle: 0,
    };
    // Agent 1's batch carries no stop: no notification. Agent 0's stop notifies.
    agents[1].send_batch(&batch(1, 0), &[]).unwrap();
    agents[0]
        .send_batch(&batch(0, MOTOR_FLAG_STOP), &[])
        .unwrap();
    // The wait ends at agent 0's notification (long before its timeout); the drain
    // looks at the queue of the agent that notified only.
    host.wait_activity(Duration::from_secs(30)).unwrap();
    assert_eq!(drained(&mut host), [(0, MOTOR_FLAG_STOP)]);
    // The next cycle's first drain looks at every queue.
    host.signal_start().unwrap();
    assert_eq!(drained(&mut host), [(1, 0)]);
    // A leave notifies as a stop does: the host need not find it by a timeout.
    agents[1]
        .send_batch(&batch(1, MOTOR_FLAG_LEAVE), &[])
        .unwrap();
    host.wait_activity(Duration::from_secs(30)).unwrap();
    assert_eq!(drained(&mut host), [(1, MOTOR_FLAG_LEAVE)]);
}
