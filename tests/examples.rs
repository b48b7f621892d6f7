//! The Rust examples of `agent-sdk/examples/`, run end to end against `vr-sim run`, and
//! the README's code blocks that show them (a block is the example's text, so the two
//! cannot drift apart).

use crate::util::{
    EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, TestConfig, Transport, example, spawn_host,
    summary, workspace,
};

/// The text of the first fenced ` ```LANG ` block after `heading` in the README.
pub(crate) fn readme_block(heading: &str, lang: &str) -> String {
    let readme = std::fs::read_to_string(workspace().join("README.md")).unwrap();
    let section = readme
        .split_once(&format!("\n{heading}\n"))
        .unwrap_or_else(|| panic!("README.md has no heading {heading:?}"))
        .1;
    let fence = format!("```{lang}\n");
    let body = section
        .split_once(&fence)
        .unwrap_or_else(|| panic!("no {fence:?} block after {heading:?}"))
        .1;
    let end = body.find("\n```\n").expect("an unterminated code block");
    body[..=end].to_string()
}

#[test]
fn readme_rust_agent_is_the_minimal_agent_example() {
    let example =
        std::fs::read_to_string(workspace().join("agent-sdk/examples/minimal_agent.rs")).unwrap();
    let block = readme_block("### Writing an agent (Rust)", "rust");
    assert!(
        block == example,
        "README.md's \"Writing an agent (Rust)\" block differs from \
         agent-sdk/examples/minimal_agent.rs: copy the file into the block\n\
         --- README:\n{block}\n--- example:\n{example}"
    );
}

/// `minimal_agent` takes part in a whole `vr-sim run` and ends cleanly when the host
/// closes: every cycle completes without a stop timeout, and its moves (one at a time, the
/// next after a Finished/Aborted status) reach the world.
fn minimal_agent_runs_against_vr_sim(transport: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("minimal-agent", 1, transport);
    // A move of 1 m takes about a simulated second.
    cfg.dt_s = 0.1;
    let path = cfg.write(dir.path());
    let events = Events::in_dir(dir.path());
    let s = dir.path().join("summary.json");
    let host = spawn_host(
        &path,
        &events,
        &["--frames", "80", "--summary-json", s.to_str().unwrap()],
    );
    cfg.follow_host(&events, &path);
    let agent = Proc::spawn(&example("minimal_agent"), &[path.to_str().unwrap(), "0"]);
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    let host_out = host.wait(RUN_DEADLINE);
    assert_eq!(host_out.code(), Some(0), "vr-sim: {}", host_out.stderr);
    let agent_out = agent.wait(RUN_DEADLINE);
    assert_eq!(
        agent_out.code(),
        Some(0),
        "minimal_agent: {}",
        agent_out.stderr
    );
    let sum = summary(&s);
    assert_eq!(sum["frames"], 80, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["commands_rejected"], 0, "{sum}");
    let applied = sum["commands_applied"].as_u64().unwrap();
    assert!(
        applied >= 2,
        "the agent's next move waits for the previous one's status: {applied} moves in 80 \
         cycles of 0.1 s\n{sum}"
    );
}

/// `channel_agent` reads its vectors and sends its actions every cycle through a whole
/// `vr-sim run` (whose world has no use for them: the vectors arrive zeroed, the actions
/// are received, checked and left alone) and ends cleanly when the host closes.
fn channel_agent_runs_against_vr_sim(transport: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("channel-agent", 2, transport);
    cfg.agent_extra = "[[agent.vector]]\nname = \"joints\"\nlen = 7\n\
                       [[agent.action]]\nname = \"torque\"\nlen = 7\nlow = -2.0\nhigh = 2.0\n\
                       [[agent.action]]\nname = \"gear\"\nn = 3\n"
        .into();
    let path = cfg.write(dir.path());
    let events = Events::in_dir(dir.path());
    let s = dir.path().join("summary.json");
    let host = spawn_host(
        &path,
        &events,
        &["--frames", "40", "--summary-json", s.to_str().unwrap()],
    );
    cfg.follow_host(&events, &path);
    let agents: Vec<Proc> = (0..2)
        .map(|id| {
            let id = id.to_string();
            Proc::spawn(
                &example("channel_agent"),
                &[path.to_str().unwrap(), &id, "3"],
            )
        })
        .collect();
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    let host_out = host.wait(RUN_DEADLINE);
    assert_eq!(host_out.code(), Some(0), "vr-sim: {}", host_out.stderr);
    for agent in agents {
        let out = agent.wait(RUN_DEADLINE);
        assert_eq!(out.code(), Some(0), "channel_agent: {}", out.stderr);
    }
    let sum = summary(&s);
    assert_eq!(sum["frames"], 40, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["frames_read"], 80, "{sum}");
}

for_each_transport!(
    minimal_agent_runs_against_vr_sim,
    channel_agent_runs_against_vr_sim
);
