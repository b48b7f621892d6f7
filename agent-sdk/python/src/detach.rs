//! Carrying values that are not `Send` through `Python::detach` (its `Send` impl is in
//! `threads.rs`, with the others).

/// Moves a value that is not `Send` through [`Python::detach`](pyo3::Python::detach),
/// which runs its closure on the *calling* thread: nothing crosses a thread.
pub(crate) struct SameThread<T>(pub(crate) T);
