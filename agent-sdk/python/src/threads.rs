//! Every `unsafe impl Send` and `Sync` of the extension, in one place, each with why it
//! holds.
//!
//! The SDK's agent and its frames are not `Send`: the shared-memory transport runs on
//! iceoryx2's single-threaded `ipc` service (its ports hold `Rc`s) with pools of its own.
//! iceoryx2's thread-safe service (`ipc_threadsafe`) would make them `Send`, and with it
//! these impls and the frame graveyard would go; it cost 36 % more per shared-memory cycle
//! at 16 agents in `vr-sim bench` (BENCHMARKS.md, "iceoryx2's thread-safe service"), so the
//! extension keeps them. PyO3 requires `Send` of a `#[pyclass]` (and `Sync` of what it
//! shares), and `Python::detach` of what its closure captures: the impls below say why
//! each value never actually crosses a thread unguarded.

use crate::agent::AgentCell;
use crate::detach::SameThread;
use crate::frame::{Buried, Corpse, Owned};
use crate::group::{Agents, Held};

// SAFETY: only used to pass values into and out of `Python::detach`, whose closure runs
// synchronously on the current thread.
unsafe impl<T> Send for SameThread<T> {}

// SAFETY: every use goes through `PyAgent::enter`, which admits only the owner thread (or
// moves ownership when no frame of the agent is alive anywhere); PyO3's borrow flag
// makes those uses exclusive.
unsafe impl Send for AgentCell {}
// SAFETY: as above; there is no shared (`&`) use of the agent.
unsafe impl Sync for AgentCell {}

// SAFETY: an agent is used by one thread at a time (PyO3's exclusive borrow of the
// group), and no frame of it outlives a call of the group (frames are copied and dropped
// inside `step`), which is the condition under which `vrsync.Agent` also lets an agent
// move to another thread. The stacked samples that a group's zero-copy images hold
// outlive calls; they are `OwnedStack`s, and the group moves to another thread only
// when none is alive (`AgentGroup::enter`).
unsafe impl Send for Agents {}
// SAFETY: as above; there is no shared (`&`) use of the agents.
unsafe impl Sync for Agents {}

// SAFETY: a `Corpse` is never used; it is only stored until the owner thread drops it
// (see the module docs).
unsafe impl Send for Corpse {}

// SAFETY: see the module docs: every thread only reads the frame (or a group's stacked
// sample: shared memory nobody writes while it is held), and `Drop` moves it back to the
// owner thread. `Buried` is implemented for those two only.
unsafe impl<T: Buried> Send for Owned<T> {}
// SAFETY: as above; shared access is read-only.
unsafe impl<T: Buried> Sync for Owned<T> {}

// SAFETY: the stacked samples a group keeps during a step are its own (shared only with
// its agents' reader and with `OwnedStack`s); the group is used by one thread at a time
// and moves to another only when no `OwnedStack` of it is alive (`AgentGroup::enter`).
unsafe impl Send for Held {}
// SAFETY: as above; there is no shared (`&`) use across threads.
unsafe impl Sync for Held {}
