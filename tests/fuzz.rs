//! The fuzz targets' checks (`bridge/fuzz/checks.rs`) on stable, in every CI run: every
//! input of the committed corpus (`bridge/fuzz/corpus/<target>/`, grown by libFuzzer runs
//! on nightly, see `bridge/fuzz/README.md`) is replayed, then mutations of it and random
//! bytes are tried (proptest, `VRSYNC_FUZZ_CASES` per target, default 100 000, ~3 s in all; a failure
//! is shrunk to a minimal input and printed). Without coverage guidance this finds less
//! than libFuzzer, but it runs on every change; an input that ever failed goes into the
//! corpus, so it is replayed for ever after.

use std::path::PathBuf;

use proptest::prelude::*;
use proptest::test_runner::{Config as RunnerConfig, TestRunner};

#[path = "../bridge/fuzz/checks.rs"]
mod checks;

const DEFAULT_CASES: u32 = 100_000;

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir: PathBuf = crate::util::workspace()
        .join("bridge/fuzz/corpus")
        .join(target);
    let mut inputs: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("the corpus {} cannot be read: {e}", dir.display()))
        .map(|entry| {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            (path, bytes)
        })
        .collect();
    assert!(!inputs.is_empty(), "the corpus {} is empty", dir.display());
    inputs.sort();
    inputs.into_iter().map(|(_, bytes)| bytes).collect()
}

/// Corpus inputs with a few edits each (overwrite, insert, remove a byte; cut the tail),
/// or plain random bytes.
fn inputs(corpus: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    let n = corpus.len();
    let edited = (
        0..n,
        prop::collection::vec((any::<u16>(), any::<u8>(), 0u8..4), 1..8),
    )
        .prop_map(move |(i, edits)| {
            let mut bytes = corpus[i].clone();
            for (pos, byte, op) in edits {
                let at = usize::from(pos) % (bytes.len() + 1);
                match op {
                    0 if at < bytes.len() => bytes[at] = byte,
                    0 | 1 => bytes.insert(at, byte),
                    2 if at < bytes.len() => {
                        bytes.remove(at);
                    }
                    _ => bytes.truncate(at),
                }
            }
            bytes
        });
    prop_oneof![4 => edited, 1 => prop::collection::vec(any::<u8>(), 0..512)]
}

fn fuzz(target: &str, check: checks::Check) {
    let corpus = corpus(target);
    for input in &corpus {
        check(input);
    }
    let cases = std::env::var("VRSYNC_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_CASES);
    let mut runner = TestRunner::new(RunnerConfig {
        cases,
        failure_persistence: None,
        ..RunnerConfig::default()
    });
    let replayed = corpus.len();
    if let Err(e) = runner.run(&inputs(corpus), |input| {
        check(&input);
        Ok(())
    }) {
        panic!("{target}: {e}\n(add the minimal input to bridge/fuzz/corpus/{target}/ once fixed)");
    }
    println!("{target}: {replayed} corpus inputs replayed, {cases} mutated and random inputs");
}

#[test]
fn every_target_replays_its_corpus_and_survives_mutations() {
    for (target, check) in checks::TARGETS {
        fuzz(target, check);
    }
}

#[test]
fn the_checks_cover_every_fuzz_target() {
    // Each [[bin]] of bridge/fuzz/Cargo.toml is a libFuzzer target: its check is here too.
    let manifest =
        std::fs::read_to_string(crate::util::workspace().join("bridge/fuzz/Cargo.toml")).unwrap();
    let mut bins: Vec<&str> = manifest
        .split("[[bin]]")
        .skip(1)
        .filter_map(|section| {
            section
                .lines()
                .find_map(|l| l.strip_prefix("name = \""))
                .and_then(|l| l.strip_suffix('"'))
        })
        .collect();
    let mut checked: Vec<&str> = checks::TARGETS.iter().map(|(name, _)| *name).collect();
    bins.sort_unstable();
    checked.sort_unstable();
    assert_eq!(bins, checked);
}
