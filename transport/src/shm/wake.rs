//! The session's wake word: how the host tells every shared-memory agent "a frame is
//! there" (and "the session closed") with one system call, however many agents wait.
//!
//! An iceoryx2 event notifies each listener on its own (a datagram per listening agent):
//! measured on the 2-core test machine that is the largest part of a 16-agent host's own
//! time per cycle. The wake word is a 32-bit counter in a page of shared memory that the
//! host creates beside the session's services. The host bumps it after publishing the
//! cycle's frames; an agent that finds no frame sleeps with `FUTEX_WAIT` on the value it
//! last saw (the kernel compares the value before it sleeps, so a bump between the
//! agent's look and its sleep is never missed). The top bit says the host closed the
//! session.
//!
//! # The wake tree
//! Waking N sleepers costs the waker N scheduler wake-ups inside its `FUTEX_WAKE`
//! (measured on the 2-core test machine: 1.5–2.8 µs of the host's CPU per agent at 16
//! agents, the largest part of the Python host's own time). So the host wakes only
//! `FAN_OUT` sleepers, and only if an agent sleeps; every agent woken by a change
//! wakes `FAN_OUT` more before it looks at its frame, while sleepers are counted: N
//! sleepers are woken in about log2(N) rounds, the work spread over the agents. The
//! kernel wakes the longest-waiting first, so the sleepers of the cycle before the bump
//! go before an agent that already read the new frame and sleeps again. An agent that
//! dies between its wake-up and passing it on leaves the sleepers it would have woken to
//! their own timeout (an agent sleeps at most one wait slice): late, never lost. The
//! close wakes every sleeper at once.
//!
//! An agent killed while asleep leaves the sleeper count one too high: `FUTEX_WAKE`s are
//! then made when nobody sleeps, which costs those system calls and nothing else.
//!
//! The page is named after the session (`vrsync_<hash of the session name>.wake` in
//! `/dev/shm`); the host owns it and removes it when it ends. A host that crashed (or was
//! killed) leaves it behind: the next host of the session replaces it, and
//! [`super::cleanup_dead_nodes`] removes it with the dead host's node. Sessions are often
//! one-off (a test, a sweep of configs): their pages would never see a next host. So a
//! host also holds an advisory lock (`flock`) on its page for as long as it lives, which
//! the kernel releases when the process ends however it ends, and every host at its
//! start removes the pages of other sessions that say they were locked by their host and
//! are not locked now (`sweep_orphans`): their host is gone. The lock works across PID
//! namespaces (containers sharing `/dev/shm`), where a process id would not.

use std::fs::File;
use std::os::fd::AsRawFd;
use std::os::unix::fs::{FileExt, MetadataExt};
use std::path::Path;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use iceoryx2_bb_posix::creation_mode::CreationMode;
use iceoryx2_bb_posix::permission::Permission;
use iceoryx2_bb_posix::shared_memory::{AccessMode, SharedMemory, SharedMemoryBuilder};
use iceoryx2_bb_system_types::file_name::{FileName, SemanticString as _};

use vrsync_protocol::channel_layout::fnv1a;

/// Bit of the word that says the host closed the session.
const CLOSED: u32 = 1 << 31;
/// Byte offset of the counter of agents asleep on the word (its own cache line, so the
/// agents' counting does not slow the host's bump).
const SLEEPERS_AT: usize = 64;
/// Byte offset of [`MAGIC`].
const MAGIC_AT: usize = 128;
/// Byte offset of the host's "polling" flag (its own cache line): 1 while the host looks
/// at the agents' motor queues itself, so an agent's *stop* needs no notification.
const HOST_POLLING_AT: usize = 192;
/// Written by the host once the page is set up: an agent that opens a page without it
/// (another program's file of the same name, or one being created) does not use it.
const MAGIC: u32 = u32::from_le_bytes(*b"vrsW");
/// Byte offset of [`LOCKED`].
const LOCKED_AT: usize = 132;
/// Written by a host once it holds the page's lock, before [`MAGIC`]: only a page with it
/// is removed by another host's sweep when nobody holds its lock (a page of an older
/// build, or one still being created, is left alone).
const LOCKED: u32 = u32::from_le_bytes(*b"vrsL");
/// Where the pages are (iceoryx2's POSIX shared memory: `shm_open`).
const SHM_DIR: &str = "/dev/shm";
/// Bytes of the page.
const SIZE: usize = 4096;

/// How many sleepers the host wakes at a bump, and each woken agent after it (see the
/// module docs).
pub(crate) const FAN_OUT: i32 = 2;

/// Why the wake word could not be created or opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WakeWordError {
    /// The session's page name is not a valid file name (cannot happen for a hash; kept
    /// typed rather than unwrapped).
    #[error("invalid wake word file name {0:?}")]
    Name(String),
    /// The page could not be created or opened.
    #[error("cannot {action} the wake word {name:?} in /dev/shm: {reason}")]
    Shm {
        /// "create" or "open".
        action: &'static str,
        /// The file name.
        name: String,
        /// iceoryx2's error.
        reason: String,
    },
    /// The page exists but is not (yet) a wake word.
    #[error("the wake word {0:?} in /dev/shm is not set up")]
    NotSetUp(String),
}

/// The file name of `session`'s wake word.
pub fn wake_word_name(session: &str) -> String {
    format!("vrsync_{:016x}.wake", fnv1a(session.as_bytes()))
}

fn file_name(session: &str) -> Result<(FileName, String), WakeWordError> {
    let name = wake_word_name(session);
    let file = FileName::new(name.as_bytes()).map_err(|_| WakeWordError::Name(name.clone()))?;
    Ok((file, name))
}

/// Removes `session`'s wake word if one is left behind (by a host that died).
pub fn remove_wake_word(session: &str) {
    if let Ok((file, _)) = file_name(session) {
        let _ = SharedMemory::remove(&file);
    }
}

/// Whether `name` is a wake word's file name (`vrsync_<16 hex digits>.wake`).
fn is_wake_name(name: &str) -> bool {
    name.strip_prefix("vrsync_")
        .and_then(|rest| rest.strip_suffix(".wake"))
        .is_some_and(|hash| hash.len() == 16 && hash.bytes().all(|b| b.is_ascii_hexdigit()))
}

/// Takes the advisory lock of `file` (a page) without waiting; held until it is closed.
fn try_lock(file: &File) -> bool {
    // SAFETY: flock on a descriptor `file` owns for the call; no memory is passed.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Removes the wake words in `/dev/shm` whose host is gone: pages (other than `own`) that
/// say their host locked them ([`LOCKED`]) and that nobody holds locked now. Returns how
/// many it removed. A page whose name a new host of its session took over in the
/// meantime is left (the name must still be the file it locked).
pub(crate) fn sweep_orphans(own: &str) -> usize {
    let Ok(dir) = std::fs::read_dir(SHM_DIR) else {
        return 0;
    };
    let mut removed = 0;
    for entry in dir.flatten() {
        let name = entry.file_name();
        if name.to_str().is_none_or(|n| n == own || !is_wake_name(n)) {
            continue;
        }
        let path = entry.path();
        let Ok(page) = File::open(&path) else {
            continue;
        };
        let mut mark = [0u8; 4];
        let marked = page
            .read_exact_at(&mut mark, LOCKED_AT as u64)
            .is_ok_and(|()| u32::from_le_bytes(mark) == LOCKED);
        if !marked || !try_lock(&page) {
            continue; // not a page of this build's hosts, or its host lives
        }
        let same_file = match (page.metadata(), std::fs::symlink_metadata(&path)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        };
        if same_file && std::fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// One side's mapping of the session's wake word.
pub struct WakeWord {
    shm: SharedMemory,
    /// The host's lock on its page (`None` for agents, or if the page could not be
    /// locked: it is then never swept by another host, see the module docs).
    lock: Option<File>,
}

impl core::fmt::Debug for WakeWord {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("WakeWord")
            .field("value", &self.value())
            .finish()
    }
}

impl WakeWord {
    /// The host's word: created (replacing one a dead host left) and owned, so it is
    /// removed when dropped.
    ///
    /// # Errors
    /// [`WakeWordError`].
    pub fn create(session: &str) -> Result<Self, WakeWordError> {
        let (file, name) = file_name(session)?;
        let shm = SharedMemoryBuilder::new(&file)
            .creation_mode(CreationMode::PurgeAndCreate)
            .size(SIZE)
            .permission(Permission::OWNER_READ | Permission::OWNER_WRITE)
            .zero_memory(true)
            .has_ownership(true)
            .create()
            .map_err(|e| WakeWordError::Shm {
                action: "create",
                name: name.clone(),
                reason: format!("{e:?}"),
            })?;
        let lock = File::open(Path::new(SHM_DIR).join(&name))
            .ok()
            .filter(try_lock);
        let word = Self { shm, lock };
        if word.lock.is_some() {
            word.at(LOCKED_AT).store(LOCKED, Ordering::Release);
        } else {
            tracing::debug!("wake word {name}: no lock taken; it is not swept if this host dies");
        }
        word.at(MAGIC_AT).store(MAGIC, Ordering::Release);
        let swept = sweep_orphans(&name);
        if swept > 0 {
            tracing::debug!("removed {swept} wake words in {SHM_DIR} whose hosts are gone");
        }
        Ok(word)
    }

    /// An agent's view of the host's word.
    ///
    /// # Errors
    /// [`WakeWordError`]; [`WakeWordError::NotSetUp`] while the host is still creating it.
    pub fn open(session: &str) -> Result<Self, WakeWordError> {
        let (file, name) = file_name(session)?;
        let shm = SharedMemoryBuilder::new(&file)
            .open_existing(AccessMode::ReadWrite)
            .map_err(|e| WakeWordError::Shm {
                action: "open",
                name: name.clone(),
                reason: format!("{e:?}"),
            })?;
        if shm.size() < SIZE {
            return Err(WakeWordError::NotSetUp(name));
        }
        let word = Self { shm, lock: None };
        if word.at(MAGIC_AT).load(Ordering::Acquire) != MAGIC {
            return Err(WakeWordError::NotSetUp(name));
        }
        Ok(word)
    }

    /// The 32-bit atomic at byte `offset` of the page.
    fn at(&self, offset: usize) -> &AtomicU32 {
        debug_assert!(offset + 4 <= SIZE && offset.is_multiple_of(4));
        let base: NonNull<u8> = self.shm.base_address();
        // SAFETY: the mapping is SIZE bytes (checked at open, set at create), page-aligned,
        // alive as long as `self.shm`, which the returned reference borrows; every access to
        // it, in this process and the others that map it, is atomic.
        unsafe { &*base.as_ptr().add(offset).cast::<AtomicU32>() }
    }

    fn word(&self) -> &AtomicU32 {
        self.at(0)
    }

    /// The word's value now (compare with a later one: it changed when a frame came).
    pub fn value(&self) -> u32 {
        self.word().load(Ordering::SeqCst)
    }

    /// Whether the host closed the session.
    pub fn closed(&self) -> bool {
        self.value() & CLOSED != 0
    }

    /// Host: a new frame for the agents; starts the wake tree (one system call waking
    /// `FAN_OUT` sleepers, none when no agent sleeps).
    pub fn bump(&self) {
        let old = self.word().load(Ordering::Relaxed);
        self.word().store(
            (old.wrapping_add(1) & !CLOSED) | (old & CLOSED),
            Ordering::SeqCst,
        );
        self.wake_sleepers(FAN_OUT);
    }

    /// Host: the session closed; wakes every sleeper.
    pub fn close(&self) {
        self.word().fetch_or(CLOSED, Ordering::SeqCst);
        self.wake_sleepers(i32::MAX);
    }

    /// Wakes up to `n` sleepers if any is counted.
    fn wake_sleepers(&self, n: i32) {
        // SeqCst on both sides: either this load sees an agent's sleeper count or that
        // agent's check of the word sees the new value (and it does not sleep).
        if self.at(SLEEPERS_AT).load(Ordering::SeqCst) != 0 {
            crate::wait::futex_wake(self.word(), n);
        }
    }

    /// Host: says whether it polls the agents' motor queues itself (`true`) or may go to
    /// sleep on the *stop* listener (`false`). After `false` the host must look at the
    /// queues once more before it sleeps: a batch an agent published before it read the
    /// flag as `true` is then seen (both sides order their accesses with full fences).
    pub fn set_host_polling(&self, polling: bool) {
        self.at(HOST_POLLING_AT)
            .store(u32::from(polling), Ordering::SeqCst);
        std::sync::atomic::fence(Ordering::SeqCst);
    }

    /// Agent, after publishing a batch with the stop flag: whether the host polls, so the
    /// *stop* notification (a system call that may wake it) can be left out.
    pub fn host_polling(&self) -> bool {
        // Orders the batch's publication before this read (the host's side pairs with it).
        std::sync::atomic::fence(Ordering::SeqCst);
        self.at(HOST_POLLING_AT).load(Ordering::SeqCst) != 0
    }

    /// Agent: sleeps while the word still holds `seen` (the value of an earlier
    /// [`Self::value`]), at most `timeout`; returns the value now. Wakes early on a bump,
    /// the close, a signal, or spuriously: the caller looks for its frame again. Woken by
    /// a change, it first passes the wake-up on to `FAN_OUT` other sleepers (the wake
    /// tree, see the module docs).
    pub fn wait_change(&self, seen: u32, timeout: Duration) -> u32 {
        if seen & CLOSED != 0 {
            return seen;
        }
        let sleepers = self.at(SLEEPERS_AT);
        sleepers.fetch_add(1, Ordering::SeqCst);
        let slept = self.word().load(Ordering::SeqCst) == seen;
        if slept {
            crate::wait::futex_wait(self.word(), seen, timeout);
        }
        sleepers.fetch_sub(1, Ordering::SeqCst);
        let now = self.value();
        if slept && now != seen {
            self.wake_sleepers(FAN_OUT);
        }
        now
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    fn session(tag: &str) -> String {
        format!("wake-test-{tag}-{}", std::process::id())
    }

    /// An agent in another thread that opens `session`'s word and sleeps on `seen` (for up to
    /// a minute: a lost wake-up would show as `seen` returned); returns, once it has opened
    /// the word, the handle yielding the value it woke to and whether it saw the close.
    fn sleeper(session: &str, seen: u32) -> std::thread::JoinHandle<(u32, bool)> {
        let (tx, rx) = mpsc::channel();
        let s = session.to_owned();
        let handle = std::thread::spawn(move || {
            let agent = WakeWord::open(&s).unwrap();
            tx.send(()).unwrap();
            let v = agent.wait_change(seen, Duration::from_secs(60));
            (v, agent.closed())
        });
        rx.recv_timeout(Duration::from_secs(10)).unwrap();
        handle
    }

    #[test]
    fn a_bump_ends_a_sleep_on_the_value_before_it() {
        let s = session("bump");
        let host = WakeWord::create(&s).unwrap();
        let seen = host.value();
        let sleeper = sleeper(&s, seen);
        host.bump();
        let (now, closed) = sleeper.join().unwrap();
        assert_ne!(now, seen);
        assert_eq!(now, host.value());
        assert!(!closed);
    }

    #[test]
    fn one_bump_wakes_every_sleeper_through_the_tree() {
        let s = session("tree");
        let host = WakeWord::create(&s).unwrap();
        let seen = host.value();
        const N: u32 = 9;
        let sleepers: Vec<_> = (0..N).map(|_| sleeper(&s, seen)).collect();
        // All of them counted as asleep (each may still be on its way into the kernel,
        // where it then finds the word changed): the host's one call wakes FAN_OUT of
        // them, and they wake the rest.
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while host.at(SLEEPERS_AT).load(Ordering::SeqCst) != N {
            assert!(
                std::time::Instant::now() < deadline,
                "the sleepers never slept"
            );
            std::thread::yield_now();
        }
        let bumped = std::time::Instant::now();
        host.bump();
        for s in sleepers {
            let (now, closed) = s.join().unwrap();
            assert_eq!(now, host.value());
            assert!(!closed);
        }
        // Each sleeper sleeps up to 60 s: one that was not woken returns only then.
        assert!(
            bumped.elapsed() < Duration::from_secs(30),
            "a sleeper was not woken"
        );
        assert_eq!(host.at(SLEEPERS_AT).load(Ordering::SeqCst), 0);
    }

    #[test]
    fn a_bump_before_the_sleep_is_not_lost() {
        let s = session("early");
        let host = WakeWord::create(&s).unwrap();
        let agent = WakeWord::open(&s).unwrap();
        let seen = agent.value();
        host.bump();
        // Returns at once: the word no longer holds `seen`.
        assert_eq!(
            agent.wait_change(seen, Duration::from_secs(60)),
            host.value()
        );
    }

    #[test]
    fn the_close_wakes_sleepers_and_stays_seen() {
        let s = session("close");
        let host = WakeWord::create(&s).unwrap();
        let seen = host.value();
        let sleeper = sleeper(&s, seen);
        host.close();
        let (v, closed) = sleeper.join().unwrap();
        assert!(closed);
        assert_ne!(v, seen);
        // Bumps after the close keep it.
        host.bump();
        assert!(host.closed());
    }

    #[test]
    fn the_hosts_word_goes_with_it_and_an_agent_cannot_open_a_missing_one() {
        let s = session("gone");
        let host = WakeWord::create(&s).unwrap();
        assert!(WakeWord::open(&s).is_ok());
        drop(host);
        assert!(matches!(
            WakeWord::open(&s),
            Err(WakeWordError::Shm { action: "open", .. })
        ));
        // A word left behind (here: released by its host) is removed by name. (Without
        // its lock mark, so that no host's sweep, of a test beside this one, takes it
        // first.)
        let host = WakeWord::create(&s).unwrap();
        host.at(LOCKED_AT).store(0, Ordering::Release);
        host.shm.release_ownership();
        drop(host);
        assert!(WakeWord::open(&s).is_ok());
        remove_wake_word(&s);
        assert!(WakeWord::open(&s).is_err());
    }

    #[test]
    fn an_agent_sees_whether_the_host_polls() {
        let s = session("polling");
        let host = WakeWord::create(&s).unwrap();
        let agent = WakeWord::open(&s).unwrap();
        // A new host sleeps on its listener until it says otherwise: stops are notified.
        assert!(!agent.host_polling());
        host.set_host_polling(true);
        assert!(agent.host_polling());
        host.set_host_polling(false);
        assert!(!agent.host_polling());
    }

    /// A page with `session`'s wake word name that no host set up (another program's, or
    /// one being created), removed when dropped.
    fn foreign_page(session: &str) -> SharedMemory {
        let (file, _) = file_name(session).unwrap();
        SharedMemoryBuilder::new(&file)
            .creation_mode(CreationMode::PurgeAndCreate)
            .size(SIZE)
            .permission(Permission::OWNER_READ | Permission::OWNER_WRITE)
            .zero_memory(true)
            .has_ownership(true)
            .create()
            .unwrap()
    }

    #[test]
    fn a_sweep_removes_the_pages_of_gone_hosts_only() {
        let path = |s: &str| Path::new(SHM_DIR).join(wake_word_name(s));
        let live = session("sweep-live");
        let gone = session("sweep-gone");
        let unmarked = session("sweep-unmarked");
        let _live = WakeWord::create(&live).unwrap();
        // A host that died: its page stays (no owner removes it), its lock goes with it
        // (here: the test holds it until the page is shown to be there, so that no sweep
        // of a host beside this test takes it before).
        let mut dead = WakeWord::create(&gone).unwrap();
        let held = dead.lock.take().unwrap();
        dead.shm.release_ownership();
        drop(dead);
        // A page of that name no host of this build locked (an older build's, or one
        // being created): left alone.
        let other = foreign_page(&unmarked);
        assert!(path(&gone).exists() && path(&unmarked).exists());
        drop(held);
        // (Not its count: a host created by a test running beside this one may sweep
        // first.)
        sweep_orphans("");
        assert!(!path(&gone).exists(), "the dead host's page was swept");
        assert!(path(&live).exists(), "a live host's page stays");
        assert!(WakeWord::open(&live).is_ok());
        assert!(
            path(&unmarked).exists(),
            "a page without the lock mark stays"
        );
        drop(other);
    }

    #[test]
    fn a_new_host_sweeps_what_a_killed_one_left() {
        let gone = session("killed");
        let dead = WakeWord::create(&gone).unwrap();
        dead.shm.release_ownership();
        drop(dead);
        let _next = WakeWord::create(&session("next")).unwrap();
        assert!(!Path::new(SHM_DIR).join(wake_word_name(&gone)).exists());
    }

    #[test]
    fn wake_names_are_recognised() {
        assert!(is_wake_name(&wake_word_name("any")));
        assert!(!is_wake_name("vrsync_0123.wake"));
        assert!(!is_wake_name("iox2_0354a209029e7d09.data"));
        assert!(!is_wake_name("vrsync_0123456789abcdeg.wake"));
    }

    #[test]
    fn a_page_that_is_not_set_up_is_not_used() {
        let s = session("foreign");
        let other = foreign_page(&s);
        assert!(matches!(
            WakeWord::open(&s),
            Err(WakeWordError::NotSetUp(_))
        ));
        drop(other);
    }
}
