//! Integration tests of vrsync live in `tests.rs`; this library is empty.
