//! The config loader on arbitrary and mutated text: no panic, an error names the file and
//! a line, nothing allocated in proportion to a value in the file, and a config it
//! accepts survives the effective config that spawned agents receive.

use std::path::Path;

use proptest::prelude::*;
use vrsync_bridge::{Config, ConfigLoadError, DEFAULT_CONFIG_TOML};

use crate::hostile::decoding::allocations_in;

/// Values that probe ranges, types and parsing corners.
const VALUES: &[&str] = &[
    "-1",
    "0",
    "1",
    "0.0000001",
    "-0.0",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "9223372036854775807",
    "-9223372036854775808",
    "250",
    "251",
    "4096",
    "4097",
    "8192",
    "8193",
    "true",
    "\"\"",
    "\"x\"",
    "\"a/b\"",
    "\"\\u0000\"",
    "\"\\u007f\"",
    "\"é\"",
    "[]",
    "{}",
    "[1, 2]",
    "{ a = 1 }",
    "\"127.0.0.1:0\"",
    "\"[::1]:7400\"",
    "\"0.0.0.0:7400\"",
    "\"localhost:7400\"",
    "\"rgba8\"",
    "\"depth32f\"",
    "\"gray8\"",
    "\"tcp\"",
    "\"spin\"",
    "\"abort\"",
    "1979-05-27T07:32:00Z",
];

/// Lines that add, duplicate or break structure.
const SNIPPETS: &[&str] = &[
    "[[agent]]",
    "id = 0",
    "id = 1",
    "id = 250",
    "[[agent.camera]]",
    "name = \"n\"",
    "width = 8192",
    "height = 8192",
    "format = \"depth32f\"",
    "[sync]",
    "[transport]",
    "[world]",
    "kind = \"tcp\"",
    "tcp_token = \"t\"",
    "tcp_listen = \"127.0.0.1:0\"",
    "wait = \"spin\"",
    "on_agent_lost = \"wait\"",
    "session = \"s\"",
    "bogus = 1",
    "= 1",
    "[",
    "]",
    "\"",
    "\'\'\'",
    "#",
    "a.b.c = 1",
    "agent = 1",
    "[agent]",
    "[[sync]]",
    "sync = 1",
    "[agent.camera]",
    "SyncMode = false",
    "SimulationTimePerFrame = 0.05",
];

/// One edit of a config text, line-wise.
#[derive(Debug, Clone)]
enum Mutation {
    DeleteLine(usize),
    DuplicateLine(usize),
    InsertSnippet(usize, usize),
    ReplaceValue(usize, usize),
    SwapLines(usize, usize),
    TruncateAt(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::DeleteLine),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        (any::<usize>(), 0..SNIPPETS.len()).prop_map(|(l, s)| Mutation::InsertSnippet(l, s)),
        (any::<usize>(), 0..VALUES.len()).prop_map(|(l, v)| Mutation::ReplaceValue(l, v)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        any::<usize>().prop_map(Mutation::TruncateAt),
    ]
}

fn mutate(text: &str, mutations: &[Mutation]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for m in mutations {
        let n = lines.len().max(1);
        match *m {
            Mutation::DeleteLine(i) if !lines.is_empty() => {
                lines.remove(i % n);
            }
            Mutation::DuplicateLine(i) if !lines.is_empty() => {
                let l = lines[i % n].clone();
                lines.insert(i % n, l);
            }
            Mutation::InsertSnippet(i, s) => {
                lines.insert(i % (lines.len() + 1), SNIPPETS[s].into())
            }
            Mutation::ReplaceValue(i, v) if !lines.is_empty() => {
                let l = &mut lines[i % n];
                if let Some(eq) = l.find('=') {
                    l.truncate(eq + 1);
                    l.push(' ');
                    l.push_str(VALUES[v]);
                }
            }
            Mutation::SwapLines(a, b) if !lines.is_empty() => lines.swap(a % n, b % n),
            Mutation::TruncateAt(i) => lines.truncate(i % (lines.len() + 1)),
            _ => {}
        }
    }
    lines.join("\n") + "\n"
}

/// The loader on `text`: no panic; an error names the file and a line of the text; no
/// allocation beyond a small multiple of the text (nothing is sized by a value in the
/// file); a config it accepts survives the round trip through the effective config that
/// spawned agents receive.
fn check_loader(text: &str) -> Result<(), TestCaseError> {
    let path = Path::new("fuzz.toml");
    let (result, cost) = allocations_in(|| Config::from_toml_str(text, path));
    let limit = 256 * 1024 + 64 * text.len();
    prop_assert!(
        cost.largest <= limit,
        "loading {} bytes allocated {} bytes at once",
        text.len(),
        cost.largest
    );
    match result {
        Ok(config) => {
            let effective = config.to_toml_string();
            let back = Config::from_toml_str(&effective, Path::new("effective.toml"));
            prop_assert!(
                back.is_ok(),
                "effective config does not load: {:?}\n{effective}",
                back.err()
            );
            if let Ok(back) = back {
                prop_assert_eq!(&back.session, &config.session);
                prop_assert_eq!(back.seed, config.seed);
                prop_assert_eq!(&back.sync, &config.sync);
                prop_assert_eq!(&back.transport, &config.transport);
                prop_assert_eq!(&back.agents, &config.agents);
            }
        }
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(msg.starts_with("fuzz.toml:"), "{msg}");
            let line = match e {
                ConfigLoadError::Parse { line, .. } | ConfigLoadError::Invalid { line, .. } => line,
                other => return Err(TestCaseError::fail(format!("unexpected {other:?}"))),
            };
            prop_assert!(
                line >= 1 && line <= text.lines().count().max(1) + 1,
                "{msg}"
            );
        }
    }
    Ok(())
}

/// `s` as a TOML basic string, every character but ASCII letters and digits escaped.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c);
        } else {
            out += &format!("\\U{:08X}", c as u32);
        }
    }
    out + "\""
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Spawned agents get the host's effective config: camera names and tokens with any
    /// characters must survive it.
    #[test]
    fn effective_config_keeps_any_camera_name_and_token(
        name in "(?s).{1,6}",
        token in "(?s).{1,40}",
    ) {
        let text = format!(
            "[transport]\nkind = \"tcp\"\ntcp_token = {}\n[[agent]]\nid = 0\n\
             [[agent.camera]]\nname = {}\nwidth = 8\n",
            toml_string(&token),
            toml_string(&name)
        );
        check_loader(&text)?;
    }

    #[test]
    fn config_loader_survives_arbitrary_text(text in "(?s).{0,300}") {
        check_loader(&text)?;
    }

    #[test]
    fn config_loader_survives_toml_like_text(
        text in "([a-z_]{1,12}( ?= ?([0-9.e-]{1,6}|\"[a-z0-9:.]{0,8}\"|true|\\[\\])?)?|\\[{1,2}[a-z.]{1,12}\\]{1,2}|#.{0,5})?(\n([a-z_]{1,12}( ?= ?([0-9.e-]{1,6}|\"[a-z0-9:.]{0,8}\"|true|\\[\\])?)?|\\[{1,2}[a-z.]{1,12}\\]{1,2}|#.{0,5})?){0,20}"
    ) {
        check_loader(&text)?;
    }

    #[test]
    fn config_loader_survives_mutated_default_toml(
        mutations in proptest::collection::vec(mutation(), 1..6)
    ) {
        check_loader(&mutate(DEFAULT_CONFIG_TOML, &mutations))?;
    }
}
