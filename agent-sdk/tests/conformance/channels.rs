//! The suite's channel cases: vectors and actions each cycle, and layouts compared at
//! connect (instantiated per transport by `conformance!`).

use std::path::Path;

use vrsync_agent::{AgentBuilder, AgentConnectError, Command};
use vrsync_bridge::{ActionValue, AgentOutcome, Config, MotorCommand};

use super::{WAIT, config, publish, with_host};

/// The config of [`config`] with channels on agent 4: two vectors, a continuous action
/// of 6 values (two chunks on the wire) and a discrete one.
fn config_with_channels(kind: &str, joints: u32) -> Config {
    let base = config(kind, true);
    let text = format!(
        "{}[[agent.vector]]\nname = \"joints\"\nlen = {joints}\n\
         [[agent.vector]]\nname = \"speed\"\nlen = 1\n\
         [[agent.action]]\nname = \"torque\"\nlen = 6\nlow = -100.0\nhigh = 100.0\n\
         [[agent.action]]\nname = \"gear\"\nn = 3\n",
        base.to_toml_string()
    );
    Config::from_toml_str(&text, Path::new("<conformance>")).unwrap()
}

/// Vectors reach the agent in its frame; each cycle's actions reach the host in that
/// cycle's report (the last value sent wins, none when none was sent); malformed chunks
/// are counted and never applied.
pub(super) fn channels_carry_vectors_and_actions_each_cycle(kind: &str) {
    const CYCLES: u64 = 30;
    let (config, host) = with_host(config_with_channels(kind, 6), |host| {
        for cycle in 0..CYCLES {
            let mut frame = host.loan_frame(4).unwrap();
            let joints = frame.vector_mut("joints").unwrap();
            for (i, v) in joints.iter_mut().enumerate() {
                *v = cycle as f32 + i as f32 * 0.5;
            }
            frame.vector_mut("speed").unwrap()[0] = -(cycle as f32);
            assert!(frame.vector_mut("nope").is_none());
            host.publish(frame).unwrap();
            host.start().unwrap();
            let report = host.collect().unwrap();
            let a = &report.agents()[0];
            assert_eq!(a.outcome, AgentOutcome::Stopped, "cycle {cycle}");
            if cycle % 5 == 4 {
                assert_eq!(a.action("torque"), None, "cycle {cycle}: none sent");
                assert_eq!(a.action("gear"), None, "cycle {cycle}: none sent");
            } else {
                let want: Vec<f32> = (0..6)
                    .map(|i| 2.0 * (cycle as f32 + i as f32 * 0.5))
                    .collect();
                assert_eq!(
                    a.action("torque"),
                    Some(ActionValue::Box(&want)),
                    "cycle {cycle}"
                );
                assert_eq!(
                    a.action("gear"),
                    Some(ActionValue::Discrete((cycle % 3) as u32)),
                    "cycle {cycle}"
                );
            }
            assert_eq!(a.actions_rejected(), u32::from(cycle == 7), "cycle {cycle}");
            // Action chunks are not commands; the command beside them is.
            assert_eq!(a.commands().len(), 1, "cycle {cycle}");
        }
        assert_eq!(host.stats().actions_rejected, 1);
        assert_eq!(host.stats().stop_timeouts, 0);
    });
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    for cycle in 0..CYCLES {
        let frame = agent.wait_start(Some(WAIT)).unwrap();
        assert_eq!(frame.cycle(), cycle);
        let joints = frame.vector("joints").unwrap().to_vec();
        assert_eq!(joints.len(), 6);
        assert_eq!(joints[1], cycle as f32 + 0.5);
        assert_eq!(frame.vector("speed").unwrap(), [-(cycle as f32)]);
        assert!(frame.vector("nope").is_none());
        drop(frame);
        if cycle % 5 != 4 {
            // A first value, then the one that counts.
            agent.act("torque", &[0.0; 6]).unwrap();
            let torque: Vec<f32> = joints.iter().map(|j| 2.0 * j).collect();
            agent.act("torque", &torque).unwrap();
            agent.act_discrete("gear", (cycle % 3) as u32).unwrap();
        }
        if cycle == 7 {
            // Out of bounds: refused at the agent, and refused by the host when sent raw.
            let err = agent.act("torque", &[500.0; 6]).unwrap_err();
            assert!(err.to_string().contains("torque"), "{err}");
            let mut raw: Vec<MotorCommand> = vrsync_bridge::action_chunks(0, &[500.0; 6]).collect();
            agent.send_wire(raw.remove(0)).unwrap();
        }
        agent.send(Command::CancelMove).unwrap();
        agent.stop().unwrap();
    }
    host.join().unwrap();
}

/// A host and an agent whose configs disagree on a channel refuse each other at connect,
/// and the error names the channel; the refused agent holds nothing: an agent with the
/// host's channels connects after it and runs a cycle.
pub(super) fn a_channel_mismatch_is_refused_naming_the_channel(kind: &str) {
    let (config, host) = with_host(config_with_channels(kind, 6), move |host| {
        publish(host);
        let report = host.collect().unwrap();
        assert_eq!(report.agents()[0].outcome, AgentOutcome::Stopped);
    });
    // The same session and endpoints, one vector longer.
    let mut theirs = config.clone();
    let joints = &mut theirs.agents[0].vectors[0];
    joints.len = 7;
    joints.low.push(f32::NEG_INFINITY);
    joints.high.push(f32::INFINITY);
    let err = AgentBuilder::new(&theirs, 4).connect().unwrap_err();
    let message = err.to_string();
    assert!(
        matches!(
            &err,
            AgentConnectError::ChannelMismatch { difference, .. }
                if difference.name == "joints" && difference.table == "vector"
        ) && message.contains("\"joints\"")
            && message.contains("6 floats")
            && message.contains("7 floats"),
        "{kind}: {message}"
    );
    // One action fewer: named too.
    let mut fewer = config.clone();
    fewer.agents[0].actions.pop();
    let err = AgentBuilder::new(&fewer, 4).connect().unwrap_err();
    assert!(
        matches!(&err, AgentConnectError::ChannelMismatch { difference, .. }
            if difference.table == "action"),
        "{kind}: {err}"
    );
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    agent.wait_start(Some(WAIT)).unwrap();
    agent.stop().unwrap();
    host.join().unwrap();
}

/// The longest layout there is (8 vectors and 8 actions, every name 16 bytes, the widest
/// numbers): host and agent agree on it at connect — over shm its text is split into
/// several service attributes — and a difference in the last action is named.
pub(super) fn the_longest_channel_layout_is_compared_at_connect(kind: &str) {
    let base = config(kind, true).to_toml_string();
    let mut text = base.clone();
    for i in 0..8 {
        text += &format!("[[agent.vector]]\nname = \"vector_number_{i:02}\"\nlen = 4096\n");
    }
    for i in 0..7 {
        text += &format!(
            "[[agent.action]]\nname = \"action_number_{i:02}\"\nlen = 256\nlow = -1.5\n\
             high = 1.5\n"
        );
    }
    let last = |n: u32| format!("[[agent.action]]\nname = \"action_number_07\"\nn = {n}\n");
    let ours =
        Config::from_toml_str(&(text.clone() + &last(4_000_000_000)), Path::new("<a>")).unwrap();
    let theirs = Config::from_toml_str(&(text + &last(3_999_999_999)), Path::new("<b>")).unwrap();
    // Over shm: more than one attribute's worth (256 bytes).
    assert!(ours.agents[0].channel_layout().to_text().len() > 256);
    let (config, host) = with_host(ours, |host| {
        publish(host);
        assert_eq!(
            host.collect().unwrap().agents()[0].outcome,
            AgentOutcome::Stopped
        );
    });
    let mut theirs = theirs;
    theirs.transport = config.transport.clone();
    let err = AgentBuilder::new(&theirs, 4).connect().unwrap_err();
    assert!(
        matches!(&err, AgentConnectError::ChannelMismatch { difference, .. }
            if difference.name == "action_number_07"
                && difference.host == "a choice in 0..4000000000"),
        "{kind}: {err}"
    );
    let mut agent = AgentBuilder::new(&config, 4).connect().unwrap();
    agent.wait_start(Some(WAIT)).unwrap();
    agent.stop().unwrap();
    host.join().unwrap();
}
