//! Reading the C headers and the C# binding in the drift tests: the file, a block of it,
//! the `NAME = value` members of an enum and the `#define`s.

// Each test crate that includes this module uses a part of it.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A file of the repository, relative to this crate (`bridge/ffi`).
pub fn repo_file(relative: &str) -> (PathBuf, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(relative);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    (path, text)
}

/// The lines of `text` from the first one containing `start` to the next one that
/// starts (trimmed) with `end`.
pub fn block<'t>(text: &'t str, start: &str, end: &str, path: &Path) -> Vec<&'t str> {
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
pub fn members(lines: &[&str], path: &Path) -> BTreeMap<String, i64> {
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

/// The value of `#define NAME value` in `text`.
pub fn define(text: &str, name: &str, path: &Path) -> i64 {
    let prefix = format!("#define {name} ");
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix(&prefix))
        .unwrap_or_else(|| panic!("{}: no #define {name}", path.display()));
    line.trim()
        .parse()
        .unwrap_or_else(|e| panic!("{}: #define {name} {line}: {e}", path.display()))
}
