//! The C ABI's transport constants against the bridge's transport registry
//! (`TransportKind::ALL`): every transport has its constant in the C header, in the C#
//! binding, and in the C side of the C# layout check (`tests/layout.c`, which the binding's
//! `test.sh` diffs against the C# side; it was forgotten twice when a transport was
//! added), and none of them lists a transport the bridge does not have.

use std::collections::BTreeMap;

use vrsync_bridge::TransportKind;
use vrsync_host::vrs_host_transport_t;

mod common;
use common::{block, members, repo_file};

/// The C constant and the C# member of each transport of the registry, with its value.
fn expected() -> (BTreeMap<String, i64>, BTreeMap<String, i64>) {
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
        c.insert(name, i64::from(constant as u32));
        let mut pascal = kind.as_str().to_owned();
        pascal[..1].make_ascii_uppercase();
        cs.insert(pascal, i64::from(constant as u32));
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
    let (path, text) = repo_file("../bindings/unity/com.vrsync.host/Runtime/Binding/Native.cs");
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
