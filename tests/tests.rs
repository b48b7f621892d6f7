//! vrsync integration tests.
