//! Opaque handles that are registry keys.
//!
//! A handle (`vrs_agent_t*`, `vrs_host_t*`) carries a number from a counter that is never
//! reused, and the objects live in a per-thread map keyed by that number: the library
//! never dereferences a handle, so a null handle, one already released (double free) or a
//! made-up value is an error with a message, never a crash, and a stale handle never
//! aliases a newer object. (A magic / tombstone scheme would have to read freed memory to
//! detect a double free.) The objects stay on the thread that made them (iceoryx2 `ipc`
//! ports are neither `Send` nor `Sync`); a process-wide map remembers which thread owns
//! each live handle, to tell "wrong thread" from "unknown handle", and holds the
//! destructions other threads asked for.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::thread::{LocalKey, ThreadId};

/// How one ABI's messages name its handles.
#[derive(Debug)]
pub struct HandleKind {
    /// The object: `"agent"`.
    pub noun: &'static str,
    /// With its article: `"an agent"`.
    pub a_noun: &'static str,
    /// What releasing it is called: `"disconnected"`.
    pub released: &'static str,
    /// How its thread got it: `"connected it"`.
    pub made_by: &'static str,
}

/// A handle that does not name a live object of the calling thread.
#[derive(Debug, thiserror::Error)]
pub enum HandleError {
    /// The handle is null.
    #[error("invalid {} handle: null", .0.noun)]
    Null(&'static HandleKind),
    /// Not a handle, or one already released.
    #[error(
        "invalid {} handle {key:#x}: not {}, or already {} (double free?)",
        .kind.noun, .kind.a_noun, .kind.released
    )]
    Unknown {
        /// The ABI's names.
        kind: &'static HandleKind,
        /// The handle's value.
        key: usize,
    },
    /// The handle belongs to another thread.
    #[error(
        "{} handle {key:#x} belongs to another thread: use {} only on the thread that {}",
        .kind.noun, .kind.a_noun, .kind.made_by
    )]
    WrongThread {
        /// The ABI's names.
        kind: &'static HandleKind,
        /// The handle's value.
        key: usize,
    },
    /// The calling thread is exiting: its objects are gone.
    #[error("the calling thread is exiting; its {}s are already {}", .0.noun, .0.released)]
    ThreadExiting(&'static HandleKind),
}

/// What [`Registry::remove_or_defer`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Removal {
    /// Released now (the object was the calling thread's).
    Removed,
    /// Another thread owns it: it is released at that thread's next call through
    /// [`Registry::drop_deferred`].
    Deferred,
}

/// Owner of a live handle, and whether another thread asked to release it.
#[derive(Debug)]
struct Owner {
    thread: ThreadId,
    release_requested: bool,
}

/// One object of the per-thread map; releases its owner entry when dropped (also when
/// its thread exits with the object still registered).
#[derive(Debug)]
pub struct Entry<T: 'static> {
    key: usize,
    registry: &'static Registry<T>,
    value: T,
}

impl<T: 'static> Drop for Entry<T> {
    fn drop(&mut self) {
        if self
            .registry
            .owners()
            .remove(&self.key)
            .is_some_and(|o| o.release_requested)
        {
            self.registry.pending.fetch_sub(1, Ordering::Relaxed);
        }
    }
}

/// The per-thread map a [`Registry`] keeps its objects in: declare one with
/// `thread_local!` per ABI.
pub type LocalMap<T> = RefCell<HashMap<usize, Entry<T>>>;

/// The handles of one ABI: a `static`, over a `thread_local!` [`LocalMap`].
#[derive(Debug)]
pub struct Registry<T: 'static> {
    kind: &'static HandleKind,
    local: &'static LocalKey<LocalMap<T>>,
    /// The next handle value; never reused, never 0.
    next: AtomicUsize,
    owners: Mutex<BTreeMap<usize, Owner>>,
    /// How many handles have a release requested (lets every call skip the lock).
    pending: AtomicUsize,
}

impl<T: 'static> Registry<T> {
    /// A registry whose messages use `kind`'s names and whose objects live in `local`.
    pub const fn new(kind: &'static HandleKind, local: &'static LocalKey<LocalMap<T>>) -> Self {
        Self {
            kind,
            local,
            next: AtomicUsize::new(1),
            owners: Mutex::new(BTreeMap::new()),
            pending: AtomicUsize::new(0),
        }
    }

    fn owners(&self) -> MutexGuard<'_, BTreeMap<usize, Owner>> {
        // The map stays consistent even if a holder panicked: every operation is one call.
        self.owners
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The error for a handle that is not in this thread's map.
    fn not_here(&self, key: usize) -> HandleError {
        match self.owners().get(&key) {
            Some(owner) if owner.thread != std::thread::current().id() => {
                HandleError::WrongThread {
                    kind: self.kind,
                    key,
                }
            }
            _ => HandleError::Unknown {
                kind: self.kind,
                key,
            },
        }
    }

    fn key<H>(&self, handle: *const H) -> Result<usize, HandleError> {
        match handle.addr() {
            0 => Err(HandleError::Null(self.kind)),
            key => Ok(key),
        }
    }

    /// Registers the object `make` builds from its handle value on the calling thread and
    /// returns the handle value.
    ///
    /// # Errors
    /// [`HandleError::ThreadExiting`].
    pub fn insert(&'static self, make: impl FnOnce(usize) -> T) -> Result<usize, HandleError> {
        let key = self.next.fetch_add(1, Ordering::Relaxed);
        let entry = Entry {
            key,
            registry: self,
            value: make(key),
        };
        self.owners().insert(
            key,
            Owner {
                thread: std::thread::current().id(),
                release_requested: false,
            },
        );
        self.local
            .try_with(|map| {
                map.borrow_mut().insert(key, entry);
            })
            .map_err(|_| HandleError::ThreadExiting(self.kind))?;
        Ok(key)
    }

    /// Runs `f` on the object behind `handle`.
    ///
    /// # Errors
    /// A [`HandleError`] (converted) for a handle that is not the calling thread's, or
    /// what `f` returns.
    pub fn with<H, R, E: From<HandleError>>(
        &'static self,
        handle: *const H,
        f: impl FnOnce(&mut T) -> Result<R, E>,
    ) -> Result<R, E> {
        let key = self.key(handle)?;
        self.local
            .try_with(|map| {
                let mut map = map.borrow_mut();
                match map.get_mut(&key) {
                    Some(entry) => f(&mut entry.value),
                    None => Err(self.not_here(key).into()),
                }
            })
            .unwrap_or(Err(HandleError::ThreadExiting(self.kind).into()))
    }

    /// Releases the calling thread's object behind `handle`.
    ///
    /// # Errors
    /// A [`HandleError`]: also for another thread's handle.
    pub fn remove<H>(&'static self, handle: *const H) -> Result<(), HandleError> {
        let key = self.key(handle)?;
        match self.take(key)? {
            // Dropped outside the map's borrow.
            Some(entry) => {
                drop(entry);
                Ok(())
            }
            None => Err(self.not_here(key)),
        }
    }

    /// Like [`remove`](Self::remove), but another thread's handle is released at that
    /// thread's next [`drop_deferred`](Self::drop_deferred) (a .NET finalizer runs on its
    /// own thread).
    ///
    /// # Errors
    /// A [`HandleError`]; a second request for one handle is [`HandleError::Unknown`].
    pub fn remove_or_defer<H>(&'static self, handle: *const H) -> Result<Removal, HandleError> {
        let key = self.key(handle)?;
        if let Some(entry) = self.take(key)? {
            drop(entry);
            return Ok(Removal::Removed);
        }
        let mut owners = self.owners();
        match owners.get_mut(&key) {
            Some(owner) if !owner.release_requested => {
                owner.release_requested = true;
                self.pending.fetch_add(1, Ordering::Relaxed);
                Ok(Removal::Deferred)
            }
            _ => Err(HandleError::Unknown {
                kind: self.kind,
                key,
            }),
        }
    }

    fn take(&'static self, key: usize) -> Result<Option<Entry<T>>, HandleError> {
        self.local
            .try_with(|map| map.borrow_mut().remove(&key))
            .map_err(|_| HandleError::ThreadExiting(self.kind))
    }

    /// Releases the calling thread's objects whose release other threads asked for.
    pub fn drop_deferred(&'static self) {
        if self.pending.load(Ordering::Relaxed) == 0 {
            return;
        }
        let me = std::thread::current().id();
        let doomed: Vec<usize> = self
            .owners()
            .iter()
            .filter(|(_, o)| o.release_requested && o.thread == me)
            .map(|(&k, _)| k)
            .collect();
        for key in doomed {
            if let Ok(Some(entry)) = self.take(key) {
                drop(entry);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::ptr;

    use super::*;

    static KIND: HandleKind = HandleKind {
        noun: "widget",
        a_noun: "a widget",
        released: "freed",
        made_by: "made it",
    };
    thread_local! {
        static LOCAL: LocalMap<u32> = RefCell::new(HashMap::new());
    }
    static WIDGETS: Registry<u32> = Registry::new(&KIND, &LOCAL);

    fn handle(key: usize) -> *const u8 {
        ptr::without_provenance(key)
    }

    fn get(key: usize) -> Result<u32, HandleError> {
        WIDGETS.with(handle(key), |v| Ok(*v))
    }

    #[test]
    fn null_unknown_released_and_foreign_handles_are_errors() {
        let key = WIDGETS.insert(|k| k as u32 * 10).unwrap();
        assert_eq!(get(key).unwrap(), key as u32 * 10);
        let null = get(0).unwrap_err().to_string();
        assert_eq!(null, "invalid widget handle: null");
        let bogus = get(0xdead_beef).unwrap_err().to_string();
        assert!(bogus.contains("0xdeadbeef: not a widget"), "{bogus}");

        let (foreign, deferred) = std::thread::spawn(move || {
            (
                get(key).unwrap_err().to_string(),
                WIDGETS.remove_or_defer(handle(key)).unwrap(),
            )
        })
        .join()
        .unwrap();
        assert!(foreign.contains("belongs to another thread"), "{foreign}");
        assert!(
            foreign.contains("only on the thread that made it"),
            "{foreign}"
        );
        assert_eq!(deferred, Removal::Deferred);
        // Still here until this thread's next call releases it.
        assert!(get(key).is_ok());
        WIDGETS.drop_deferred();
        let gone = get(key).unwrap_err().to_string();
        assert!(gone.contains("already freed (double free?)"), "{gone}");

        let second = WIDGETS.insert(|_| 7).unwrap();
        assert_ne!(second, key, "handle values are never reused");
        WIDGETS.remove(handle(second)).unwrap();
        assert!(matches!(
            WIDGETS.remove(handle(second)),
            Err(HandleError::Unknown { .. })
        ));
    }
}
