//! The C ABI's transport constants against the bridge's transport registry
//! (`TransportKind::ALL`): every transport has its constant in the C header, in the C#
//! binding, and in the C side of the C# layout check (`tests/layout.c`, which the binding's
//! `test.sh` diffs against the C# side; it was forgotten twice when a transport was
//! added), and none of them lists a transport the bridge does not have.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use vrsync_bridge::TransportKind;
use vrsync_host::vrs_host_transport_t;

fn repo_file(relative: &str) -> (PathBuf, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(relative);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    (path, text)
}

/// The lines of `text` from the first one containing `start` to the next one that
/// starts (trimmed) with `end`.
fn block<'t>(text: &'t str, start: &str, end: &str, path: &Path) -> Vec<&'t str> {
    let mut lines = text.lines().skip_while(|l| !l.contains(start));
    assert!(
        lines.next().is_some(),
        "{}: no `{start}` found",
        path.display()
    );
    lines
        .take_while(|l| !l.trim_start().starts_with(end))
        .collect()
}

/// `NAME = value,` lines of an enum body, comments and attributes skipped.
fn members(lines: &[&str], path: &Path) -> BTreeMap<String, u32> {
    lines
        .iter()
        .map(|l| l.trim())
        .filter(|l| l.contains('=') && !l.starts_with("//") && !l.starts_with('#'))
        .map(|l| {
            let (name, value) = l
                .trim_end_matches(',')
                .split_once('=')
                .unwrap_or_else(|| panic!("{}: cannot read `{l}`", path.display()));
            let value = value
                .trim()
                .parse()
                .unwrap_or_else(|e| panic!("{}: `{l}`: {e}", path.display()));
            (name.trim().to_owned(), value)
        })
        .collect()
}

/// The C constant and the C# member of each transport of the registry, with its value.
fn expected() -> (BTreeMap<String, u32>, BTreeMap<String, u32>) {
    let mut c = BTreeMap::new();
    let mut cs = BTreeMap::new();
    for kind in TransportKind::ALL {
        let constant = vrs_host_transport_t::of(kind);
        let name = format!("{constant:?}");
        assert_eq!(
            name,
            format!("VRS_HOST_TRANSPORT_{}", kind.as_str().to_uppercase()),
            "the C constant of transport {:?} is not named after it",
            kind.as_str()
        );
        c.insert(name, constant as u32);
        let mut pascal = kind.as_str().to_owned();
        pascal[..1].make_ascii_uppercase();
        cs.insert(pascal, constant as u32);
    }
    (c, cs)
}

#[test]
fn every_transport_has_its_constant_in_the_c_header() {
    let (c, _) = expected();
    let (path, text) = repo_file("include/vrsync_host.h");
    let found = members(
        &block(&text, "enum vrs_host_transport_t", "};", &path),
        &path,
    );
    assert_eq!(found, c, "{}: vrs_host_transport_t", path.display());
}

#[test]
fn every_transport_has_its_constant_in_the_csharp_binding() {
    let (_, cs) = expected();
    let (path, text) = repo_file("../bindings/csharp/src/Native.cs");
    let found = members(
        &block(&text, "public enum Transport : uint", "}", &path),
        &path,
    );
    assert_eq!(
        found,
        cs,
        "{}: enum Transport (C# member = the config name in PascalCase, same value as \
         the C constant)",
        path.display()
    );
}

#[test]
fn every_transport_is_in_the_c_side_of_the_csharp_layout_check() {
    let (c, _) = expected();
    let (path, text) = repo_file("../bindings/csharp/tests/layout.c");
    let found: Vec<String> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("E(VRS_HOST_TRANSPORT_"))
        .map(|rest| format!("VRS_HOST_TRANSPORT_{}", rest.trim_end_matches(");")))
        .collect();
    let mut sorted = found.clone();
    sorted.sort();
    let want: Vec<String> = c.into_keys().collect();
    assert_eq!(
        sorted,
        want,
        "{}: one `E(<constant>);` line per transport (the C side of test.sh's layout diff)",
        path.display()
    );
}
