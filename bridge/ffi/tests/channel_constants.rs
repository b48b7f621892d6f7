//! The channel constants of both C ABIs and the C# binding against the bridge: every
//! action space has its kind, with the same name and value in the host header
//! (`vrs_host_action_kind_t`), the agent header (`vrs_action_kind_t`) and the C# binding
//! (`ActionKind`); the channel limits of both headers are the wire's; and a status both
//! ABIs have (`VRS_ERROR_UNKNOWN_CHANNEL` and `VRS_HOST_ERROR_UNKNOWN_CHANNEL`, …) has one
//! number. (The C# side of the host header is checked field by field by the binding's
//! `test.sh`.)

use std::collections::BTreeMap;

use vrsync_bridge::ActionSpace;
use vrsync_host::vrs_host_action_kind_t;

mod common;
use common::{block, define, members, repo_file};

/// One action space of each variant, with its name. The `match` fails to compile when the
/// bridge gains a variant: add it here (and its constant: `vrs_host_action_kind_t::of`).
fn spaces() -> Vec<(&'static str, ActionSpace)> {
    let all = vec![
        (
            "box",
            ActionSpace::Box {
                low: vec![0.0],
                high: vec![1.0],
            },
        ),
        ("discrete", ActionSpace::Discrete { n: 2 }),
    ];
    for (_, space) in &all {
        match space {
            ActionSpace::Box { .. } | ActionSpace::Discrete { .. } => {}
        }
    }
    all
}

/// The kinds (without prefix) and values: NONE and one per action space.
fn expected_kinds() -> BTreeMap<String, i64> {
    let none = vrs_host_action_kind_t::VRS_HOST_ACTION_KIND_NONE;
    let mut kinds = BTreeMap::from([("NONE".to_owned(), i64::from(none as u32))]);
    for (name, space) in spaces() {
        let kind = vrs_host_action_kind_t::of(&space);
        assert_eq!(
            format!("{kind:?}"),
            format!("VRS_HOST_ACTION_KIND_{}", name.to_uppercase()),
            "the constant of action space {name:?} is not named after it"
        );
        kinds.insert(name.to_uppercase(), i64::from(kind as u32));
    }
    kinds
}

/// The members of `enum_name` in the file, with `prefix` removed from their names.
fn enum_in(file: &str, start: &str, end: &str, prefix: &str) -> BTreeMap<String, i64> {
    let (path, text) = repo_file(file);
    members(&block(&text, start, end, &path), &path)
        .into_iter()
        .map(|(name, value)| {
            let short = name.strip_prefix(prefix).unwrap_or_else(|| {
                panic!("{}: {name} does not start with {prefix}", path.display())
            });
            (short.to_owned(), value)
        })
        .collect()
}

#[test]
fn every_action_space_has_its_kind_in_both_headers_and_the_csharp_binding() {
    let want = expected_kinds();
    let host = enum_in(
        "include/vrsync_host.h",
        "enum vrs_host_action_kind_t",
        "};",
        "VRS_HOST_ACTION_KIND_",
    );
    assert_eq!(host, want, "vrsync_host.h: vrs_host_action_kind_t");
    let agent = enum_in(
        "../../agent-sdk/include/vrsync.h",
        "enum vrs_action_kind_t",
        "};",
        "VRS_ACTION_KIND_",
    );
    assert_eq!(agent, want, "vrsync.h: vrs_action_kind_t");
    // C#: the PascalCase of each name (None, Box, Discrete).
    let pascal: BTreeMap<String, i64> = want
        .iter()
        .map(|(name, &v)| {
            let lower = name.to_lowercase();
            (format!("{}{}", lower[..1].to_uppercase(), &lower[1..]), v)
        })
        .collect();
    let cs = enum_in(
        "../bindings/unity/com.vrsync.host/Runtime/Binding/Channels.cs",
        "public enum ActionKind : uint",
        "}",
        "",
    );
    assert_eq!(cs, pascal, "Channels.cs: enum ActionKind");
}

#[test]
fn channel_limits_are_the_wires_in_both_headers() {
    let wire = [
        ("MAX_VECTORS", vrsync_bridge::MAX_VECTORS as i64),
        ("MAX_ACTIONS", vrsync_bridge::MAX_ACTIONS as i64),
        (
            "CHANNEL_NAME_SIZE",
            vrsync_bridge::CHANNEL_NAME_LEN as i64 + 1,
        ),
    ];
    let (host_path, host) = repo_file("include/vrsync_host.h");
    let (agent_path, agent) = repo_file("../../agent-sdk/include/vrsync.h");
    for (name, value) in wire {
        assert_eq!(
            define(&host, &format!("VRS_HOST_{name}"), &host_path),
            value,
            "VRS_HOST_{name}"
        );
        assert_eq!(
            define(&agent, &format!("VRS_{name}"), &agent_path),
            value,
            "VRS_{name}"
        );
    }
}

#[test]
fn a_status_both_abis_name_has_one_number() {
    let host = enum_in(
        "include/vrsync_host.h",
        "enum vrs_host_status_t",
        "};",
        "VRS_HOST_",
    );
    let agent = enum_in(
        "../../agent-sdk/include/vrsync.h",
        "enum vrs_status_t",
        "};",
        "VRS_",
    );
    let shared: Vec<&String> = host.keys().filter(|k| agent.contains_key(*k)).collect();
    for name in &shared {
        assert_eq!(
            host[*name], agent[*name],
            "VRS_HOST_{name} and VRS_{name} have different numbers"
        );
    }
    // The channel status is among them (and the common ones, as a check of the parsing).
    for name in [
        "ERROR_UNKNOWN_CHANNEL",
        "ERROR_INVALID_ARGUMENT",
        "OK",
        "ERROR_PANIC",
    ] {
        assert!(
            shared.iter().any(|s| *s == name),
            "{name} is not in both headers"
        );
    }
}
