//! libFuzzer entry of [`checks::records`](../checks.rs): what it feeds and what it checks
//! is documented there (the same check replays the corpus in CI).

#![no_main]

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

libfuzzer_sys::fuzz_target!(|input: &[u8]| checks::records(input));
