//! Unit tests of the channel keys (`[[agent.vector]]`, `[[agent.action]]`).

use super::*;

fn parse(text: &str) -> Result<Config, ConfigLoadError> {
    Config::from_toml_str(text, Path::new("test.toml"))
}

const ARM: &str = "session = \"t\"\n[[agent]]\nid = 0\n\
    [[agent.camera]]\nname = \"eye\"\nwidth = 3\nheight = 2\n\
    [[agent.vector]]\nname = \"joints\"\nlen = 7\nlow = -3.0\nhigh = [1, 2, 3, 4, 5, 6, 7]\n\
    [[agent.vector]]\nname = \"speed\"\nlen = 1\n\
    [[agent.action]]\nname = \"torque\"\nlen = 7\nlow = -1.0\nhigh = 1.0\n\
    [[agent.action]]\nname = \"gear\"\nn = 3\n";

fn err(text: &str) -> String {
    parse(text).unwrap_err().to_string()
}

#[test]
fn vectors_and_actions_are_read_with_their_bounds() {
    let c = parse(ARM).unwrap();
    let a = &c.agents[0];
    assert_eq!(a.vectors.len(), 2);
    assert_eq!(a.vectors[0].name, "joints");
    assert_eq!(a.vectors[0].low, vec![-3.0; 7]);
    assert_eq!(a.vectors[0].high, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    assert_eq!(a.vectors[1].low, vec![f32::NEG_INFINITY]);
    assert_eq!(
        a.actions[0].space,
        ActionSpace::Box {
            low: vec![-1.0; 7],
            high: vec![1.0; 7]
        }
    );
    assert_eq!(a.actions[1].space, ActionSpace::Discrete { n: 3 });
    assert_eq!(a.action_index("gear"), Some(1));
    // Vectors follow the images, each 64-byte aligned.
    let (descs, total) = a.vector_layout();
    assert_eq!(
        (descs[0].name(), descs[0].offset, descs[0].len),
        ("joints", 64, 7)
    );
    assert_eq!((descs[1].offset, descs[1].len), (128, 1));
    assert_eq!(total, 132);
    assert_eq!(a.frame_bytes(), 132);
    // Written back and read again: the same channels.
    let again = Config::from_toml_str(&c.to_toml_string(), Path::new("again.toml")).unwrap();
    assert_eq!(again.agents, c.agents);
}

#[test]
fn added_agents_copy_the_channels_of_the_last_agent() {
    let c = parse(ARM).unwrap().with_agent_count(3).unwrap();
    assert_eq!(c.agents[2].vectors, c.agents[0].vectors);
    assert_eq!(c.agents[2].actions, c.agents[0].actions);
    assert_eq!(c.agents[2].cameras, c.agents[0].cameras);
}

#[test]
fn a_legacy_agent_with_channels_is_refused_naming_it() {
    let text = ARM.replace("id = 0\n", "id = 0\ntransport = \"legacy\"\n");
    let e = err(&text);
    assert!(e.contains("agent 0") && e.contains("legacy"), "{e}");
    // Added legacy agents would copy channels: refused too.
    let text = ARM
        .replace(
            "session = \"t\"\n",
            "session = \"t\"\n[transport]\nkind = \"legacy\"\n",
        )
        .replace("id = 0\n", "id = 0\ntransport = \"shm\"\n");
    let e = parse(&text)
        .unwrap()
        .with_agent_count(2)
        .unwrap_err()
        .to_string();
    assert!(e.contains("agent 1") && e.contains("legacy"), "{e}");
}

#[test]
fn bad_channels_are_refused_naming_key_and_line() {
    for (from, to, words) in [
        ("name = \"joints\"", "name = \"\"", "agent.vector.name"),
        ("name = \"joints\"", "name = \"a b\"", "agent.vector.name"),
        (
            "name = \"speed\"",
            "name = \"joints\"",
            "two channels named \"joints\"",
        ),
        (
            "len = 7\nlow = -3.0",
            "len = 0\nlow = -3.0",
            "agent.vector.len",
        ),
        ("len = 7\nlow = -3.0", "len = 5000\nlow = -3.0", "1..=4096"),
        (
            "high = [1, 2, 3, 4, 5, 6, 7]",
            "high = [1, 2]",
            "has 2 values, the channel has 7",
        ),
        ("high = [1, 2, 3, 4, 5, 6, 7]", "high = -4.0", "below low"),
        ("len = 7\nlow = -1.0", "len = 300\nlow = -1.0", "1..=256"),
        (
            "low = -1.0\nhigh = 1.0\n",
            "high = 1.0\n",
            "needs both `low` and `high`",
        ),
        (
            "low = -1.0\nhigh = 1.0\n",
            "low = -inf\nhigh = 1.0\n",
            "finite",
        ),
        ("n = 3", "n = 0", "agent.action.n"),
        ("n = 3", "n = 3\nlen = 2", "either `len`"),
        ("n = 3", "n = 3\nlow = 0", "takes no `low`"),
        ("n = 3", "n = 3\ncolour = 1", "colour"),
    ] {
        assert!(ARM.contains(from), "{from}");
        let e = err(&ARM.replacen(from, to, 1));
        assert!(e.contains(words), "{to:?}: {e}");
        assert!(e.contains("test.toml"), "{e}");
    }
    let many: String = (0..9)
        .map(|i| format!("[[agent.vector]]\nname = \"v{i}\"\nlen = 1\n"))
        .collect();
    let e = err(&format!("session = \"t\"\n[[agent]]\nid = 0\n{many}"));
    assert!(e.contains("9 vectors, at most 8"), "{e}");
}
