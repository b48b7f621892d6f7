//! Every binding's copy of the command catalogue against its one definition
//! (`CommandKind::ALL`, protocol/src/wire/commands.rs), every kind and every parameter, as
//! `transport_constants.rs` does for the transports:
//!
//! - the C headers: `vrs_command_kind_t` (agent, `vrsync.h`) and `vrs_host_command_kind_t`
//!   (host, `vrsync_host.h`), one constant per kind with its tag and nothing else; the
//!   agent's `vrs_agent_send_<name>` functions, their parameters by name and type;
//! - the C++ headers: `Agent::send_<name>` (parameters, and the C function it calls with
//!   them) and the original API's `send*` methods of `vrsync/compat.hpp`;
//! - the C# binding: `CommandKind` (member = variant, value = tag) and
//!   `MotorCommand.ArgCount` (the float arguments each kind uses), and the C side of its
//!   layout check (`tests/layout.c`, whose output `test.sh` diffs against the C# side);
//! - Python: the stub's `Command` subclasses (`_vrsync.pyi`: constructor parameters by
//!   name and type, a property per parameter), their export from `vrsync`, and the original
//!   client's methods in `vrsync.compat`.
//!
//! The action states (`ActionState::ALL`) are checked the same way in both C headers, C#
//! (and `layout.c`) and the stub: the two C ABIs' `vrs_action_state_t` / `vrs_host_action_state_t` are two
//! names for one vocabulary (both headers can be included together), proven identical to
//! the wire's here. Each C header is the output of its crate's Rust enums (the crates'
//! `header_is_up_to_date` tests), so those enums are covered too; the stub is checked
//! against the compiled module by the Python suite (`tests/test_stubs.py`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use vrsync_bridge::{ActionState, CommandKind, ParamType};

mod common;
use common::{block, members, repo_file};

/// `MoveTo` → `MOVE_TO`.
fn screaming(pascal: &str) -> String {
    let mut out = String::new();
    for (i, c) in pascal.chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

/// `(C constant, tag)` of every kind, the constants named `<prefix><NAME>`.
fn c_constants(prefix: &str) -> BTreeMap<String, i64> {
    CommandKind::ALL
        .iter()
        .map(|k| {
            (
                format!("{prefix}{}", k.name.to_uppercase()),
                i64::from(k.tag),
            )
        })
        .collect()
}

/// The parameter (or argument) list of the first `name(...)` in `text`, each entry
/// whitespace-normalised, default values dropped; parentheses nest.
fn params(text: &str, name: &str, path: &Path) -> Vec<String> {
    let open = format!("{name}(");
    let at = text
        .find(&open)
        .unwrap_or_else(|| panic!("{}: no `{open}`", path.display()));
    let mut list = vec![String::new()];
    let mut depth = 0;
    for c in text[at + open.len()..].chars() {
        match c {
            ')' if depth == 0 => {
                return list
                    .iter()
                    .map(|p| {
                        let p = p.split('=').next().unwrap_or_default();
                        p.split_whitespace().collect::<Vec<_>>().join(" ")
                    })
                    .filter(|p| !p.is_empty())
                    .collect();
            }
            ',' if depth == 0 => list.push(String::new()),
            _ => {
                depth += i32::from(c == '(') - i32::from(c == ')');
                list.last_mut().map(|p| p.push(c)).unwrap_or_default();
            }
        }
    }
    panic!("{}: `{open}` not closed", path.display())
}

/// Every `prefix<ident>(` in `text`: the names after `prefix`.
fn idents_after(text: &str, prefix: &str) -> BTreeSet<String> {
    text.match_indices(prefix)
        .filter_map(|(at, _)| {
            let rest = &text[at + prefix.len()..];
            let end = rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))?;
            rest[end..].starts_with('(').then(|| rest[..end].to_owned())
        })
        .filter(|n| !n.is_empty())
        .collect()
}

/// The text from `start` to the first line after it that starts (trimmed) with `end`.
fn section(text: &str, start: &str, end: &str, path: &Path) -> String {
    block(text, start, end, path).join("\n")
}

fn ty(t: ParamType, f32_name: &str, u32_name: &str) -> String {
    match t {
        ParamType::F32 => f32_name.to_owned(),
        ParamType::U32 => u32_name.to_owned(),
    }
}

#[test]
fn both_c_headers_have_one_constant_per_kind() {
    for (file, enum_name, prefix) in [
        (
            "../../agent-sdk/include/vrsync.h",
            "enum vrs_command_kind_t",
            "VRS_COMMAND_",
        ),
        (
            "include/vrsync_host.h",
            "enum vrs_host_command_kind_t",
            "VRS_HOST_COMMAND_",
        ),
    ] {
        let (path, text) = repo_file(file);
        let found = members(&block(&text, enum_name, "};", &path), &path);
        assert_eq!(
            found,
            c_constants(prefix),
            "{}: {enum_name}",
            path.display()
        );
    }
}

#[test]
fn the_agent_c_abi_has_a_send_function_per_kind() {
    let (path, text) = repo_file("../../agent-sdk/include/vrsync.h");
    for k in CommandKind::ALL {
        let mut want = vec!["struct vrs_agent_t *agent".to_owned()];
        want.extend(
            k.params
                .iter()
                .map(|p| format!("{} {}", ty(p.ty, "float", "uint32_t"), p.name)),
        );
        want.push("uint32_t *out_action_id".to_owned());
        let function = format!("vrs_agent_send_{}", k.name);
        assert_eq!(
            params(&text, &format!("vrs_status_t {function}"), &path),
            want,
            "{}: {function}",
            path.display()
        );
    }
    let mut found = idents_after(&text, "vrs_agent_send_");
    found.remove("with_id");
    let want: BTreeSet<String> = CommandKind::ALL.iter().map(|k| k.name.into()).collect();
    assert_eq!(
        found,
        want,
        "{}: one vrs_agent_send_<name> per kind (besides vrs_agent_send and \
         vrs_agent_send_with_id, which take a vrs_command_t of any kind)",
        path.display()
    );
}

#[test]
fn the_cpp_agent_has_a_send_method_per_kind() {
    let (path, text) = repo_file("../../agent-sdk/include/vrsync/agent.hpp");
    for k in CommandKind::ALL {
        let method = format!("std::uint32_t send_{}", k.name);
        let definition = format!("{method}(");
        let want: Vec<String> = k
            .params
            .iter()
            .map(|p| format!("{} {}", ty(p.ty, "float", "std::uint32_t"), p.name))
            .collect();
        assert_eq!(
            params(&text, &method, &path),
            want,
            "{}: {method}",
            path.display()
        );
        // ... and it passes them, in order, to the C function of its kind.
        let body = &text[text.find(&definition).unwrap_or_default()..];
        let mut call = vec!["handle()".to_owned()];
        call.extend(k.params.iter().map(|p| p.name.to_owned()));
        call.push("&id_".to_owned());
        assert_eq!(
            params(body, &format!("vrs_agent_send_{}", k.name), &path),
            call,
            "{}: the call in {method}",
            path.display()
        );
    }
    let mut found = idents_after(&text, "std::uint32_t send_");
    found.remove("with_id");
    let want: BTreeSet<String> = CommandKind::ALL.iter().map(|k| k.name.into()).collect();
    assert_eq!(found, want, "{}: send_<name> methods", path.display());
}

#[test]
fn the_cpp_compat_layer_has_the_original_method_of_every_kind() {
    let (path, text) = repo_file("../../agent-sdk/include/vrsync/compat.hpp");
    let class = section(&text, "class AnnarProtoSend {", "};", &path);
    for k in CommandKind::ALL {
        let method = format!("int {}(", k.original);
        let at = class
            .find(&method)
            .unwrap_or_else(|| panic!("{}: no `{method}`", path.display()));
        let body = &class[at..];
        let body = &body[..body.find('}').unwrap_or(body.len())];
        assert!(
            body.contains(&format!("agent_->send_{}(", k.name)),
            "{}: {method}...) does not call send_{}",
            path.display(),
            k.name
        );
    }
    let found = idents_after(&class, "int send");
    let want: BTreeSet<String> = CommandKind::ALL
        .iter()
        .map(|k| k.original.trim_start_matches("send").to_owned())
        .collect();
    assert_eq!(
        found,
        want,
        "{}: AnnarProtoSend's int send*",
        path.display()
    );
}

/// The C# binding's file declaring `declaration`, wherever under `bridge/bindings` it is
/// (the binding is being moved into a Unity package).
fn csharp_file(declaration: &str) -> (PathBuf, String) {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "cs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../bindings"),
        &mut files,
    );
    files.sort();
    files
        .into_iter()
        .filter(|p| !p.components().any(|c| c.as_os_str() == "tests"))
        .find_map(|p| {
            let text = std::fs::read_to_string(&p).ok()?;
            text.contains(declaration).then_some((p, text))
        })
        .unwrap_or_else(|| panic!("no C# file under bridge/bindings declares `{declaration}`"))
}

#[test]
fn the_csharp_binding_has_every_kind_and_its_argument_count() {
    let (path, text) = csharp_file("public enum CommandKind : uint");
    let found = members(
        &block(&text, "public enum CommandKind : uint", "}", &path),
        &path,
    );
    let want: BTreeMap<String, i64> = CommandKind::ALL
        .iter()
        .map(|k| (k.variant.to_owned(), i64::from(k.tag)))
        .collect();
    assert_eq!(found, want, "{}: enum CommandKind", path.display());

    // `case CommandKind.X:` lines, each group ended by `return N;`.
    let arg_count = block(&text, "public int ArgCount", "default:", &path);
    let mut found = BTreeMap::new();
    let mut pending = Vec::new();
    for line in arg_count.iter().map(|l| l.trim()) {
        if let Some(v) = line
            .strip_prefix("case CommandKind.")
            .and_then(|r| r.strip_suffix(':'))
        {
            pending.push(v.to_owned());
        } else if let Some(n) = line
            .strip_prefix("return ")
            .and_then(|r| r.strip_suffix(';'))
        {
            let n: usize = n
                .parse()
                .unwrap_or_else(|e| panic!("{}: `{line}`: {e}", path.display()));
            found.extend(pending.drain(..).map(|v| (v, n)));
        }
    }
    let want: BTreeMap<String, usize> = CommandKind::ALL
        .iter()
        .map(|k| (k.variant.to_owned(), k.arg_count))
        .collect();
    assert_eq!(found, want, "{}: MotorCommand.ArgCount", path.display());
}

/// The `E(<prefix>...);` constants of the C side of the C# layout check.
fn layout_c_constants(prefix: &str) -> (PathBuf, BTreeSet<String>) {
    let (path, text) = repo_file("../bindings/csharp/tests/layout.c");
    let found = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("E(")?.strip_suffix(");"))
        .filter(|c| c.starts_with(prefix))
        .map(str::to_owned)
        .collect();
    (path, found)
}

#[test]
fn the_csharp_layout_check_compares_every_kind_and_state() {
    let (path, found) = layout_c_constants("VRS_HOST_COMMAND_");
    let want: BTreeSet<String> = c_constants("VRS_HOST_COMMAND_").into_keys().collect();
    assert_eq!(
        found,
        want,
        "{}: one `E(<constant>);` line per command kind (the C side of test.sh's layout diff)",
        path.display()
    );
    let (path, mut found) = layout_c_constants("VRS_HOST_ACTION_");
    found.retain(|c| !c.starts_with("VRS_HOST_ACTION_KIND_"));
    let want: BTreeSet<String> = ActionState::ALL
        .iter()
        .map(|s| format!("VRS_HOST_ACTION_{}", screaming(&format!("{s:?}"))))
        .collect();
    assert_eq!(
        found,
        want,
        "{}: one `E(<constant>);` line per action state",
        path.display()
    );
}

#[test]
fn the_python_stub_has_a_class_per_kind() {
    let (path, text) = repo_file("../../agent-sdk/python/python/vrsync/_vrsync.pyi");
    for k in CommandKind::ALL {
        let class = section(
            &text,
            &format!("class {}(Command):", k.variant),
            "class ",
            &path,
        );
        let want: Vec<String> = std::iter::once("self".to_owned())
            .chain(
                k.params
                    .iter()
                    .map(|p| format!("{}: {}", p.name, ty(p.ty, "float", "int"))),
            )
            .collect();
        assert_eq!(
            params(&class, "def __init__", &path),
            want,
            "{}: {}.__init__",
            path.display(),
            k.variant
        );
        for p in k.params {
            let getter = format!("def {}(self) -> {}:", p.name, ty(p.ty, "float", "int"));
            assert!(
                class.contains(&getter),
                "{}: {} has no `{getter}`",
                path.display(),
                k.variant
            );
        }
    }
    let found: BTreeSet<String> = text
        .lines()
        .filter_map(|l| l.strip_prefix("class ")?.strip_suffix("(Command):"))
        .map(str::to_owned)
        .collect();
    let want: BTreeSet<String> = CommandKind::ALL
        .iter()
        .map(|k| k.variant.to_owned())
        .collect();
    assert_eq!(found, want, "{}: Command subclasses", path.display());

    let (path, init) = repo_file("../../agent-sdk/python/python/vrsync/__init__.py");
    let all = section(&init, "__all__ = [", "]", &path);
    for k in CommandKind::ALL {
        assert!(
            all.contains(&format!("\"{}\"", k.variant)),
            "{}: __all__ lacks {}",
            path.display(),
            k.variant
        );
    }
}

#[test]
fn the_python_compat_layer_has_the_original_method_of_every_kind() {
    let (path, text) = repo_file("../../agent-sdk/python/python/vrsync/compat.py");
    for k in CommandKind::ALL {
        let def = format!("    def {}(self", k.original);
        let body = section(&text, &def, "def ", &path);
        assert!(
            body.contains(&format!("self._send({}(", k.variant)),
            "{}: {} does not send a {}",
            path.display(),
            k.original,
            k.variant
        );
    }
    let found: BTreeSet<String> = text
        .lines()
        .filter_map(|l| {
            let rest = l.trim().strip_prefix("def send")?;
            let name = &rest[..rest.find('(')?];
            rest.contains("-> int:").then(|| name.to_owned())
        })
        .collect();
    let want: BTreeSet<String> = CommandKind::ALL
        .iter()
        .map(|k| k.original.trim_start_matches("send").to_owned())
        .collect();
    assert_eq!(found, want, "{}: send* methods", path.display());
}

#[test]
fn every_binding_has_the_action_states_of_the_wire() {
    let states = || {
        ActionState::ALL
            .iter()
            .map(|s| (format!("{s:?}"), i64::from(*s as u32)))
    };
    for (file, enum_name, prefix) in [
        (
            "../../agent-sdk/include/vrsync.h",
            "enum vrs_action_state_t",
            "VRS_ACTION_",
        ),
        (
            "include/vrsync_host.h",
            "enum vrs_host_action_state_t",
            "VRS_HOST_ACTION_",
        ),
    ] {
        let (path, text) = repo_file(file);
        let found = members(&block(&text, enum_name, "};", &path), &path);
        let want: BTreeMap<String, i64> = states()
            .map(|(n, v)| (format!("{prefix}{}", screaming(&n)), v))
            .collect();
        assert_eq!(found, want, "{}: {enum_name}", path.display());
    }
    let (path, text) = csharp_file("public enum ActionState : uint");
    let found = members(
        &block(&text, "public enum ActionState : uint", "}", &path),
        &path,
    );
    assert_eq!(
        found,
        states().collect::<BTreeMap<_, _>>(),
        "{}: enum ActionState",
        path.display()
    );
    let (path, text) = repo_file("../../agent-sdk/python/python/vrsync/_vrsync.pyi");
    let class = section(&text, "class ActionState:", "@property", &path);
    let found: Vec<&str> = class
        .lines()
        .filter_map(|l| l.trim().strip_suffix(": ActionState"))
        .collect();
    let want: Vec<String> = states().map(|(n, _)| n).collect();
    assert_eq!(found, want, "{}: class ActionState", path.display());
}
