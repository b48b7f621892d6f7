//! Readiness: the bridge's only calls to `poll(2)`, `epoll(7)`, `eventfd(2)` and `futex(2)`.
//!
//! Every host transport's readiness is one descriptor (an [`EpollSet`] of its sockets, an
//! iceoryx2 listener, a [`WakeFd`] written by zenoh's callbacks), so a host over several
//! transports waits once, on an [`EpollSet`] of those descriptors (see `mixed.rs`).
//! Everything here is level-triggered: a descriptor stays ready until its data is read,
//! so a wake-up is never lost between a wait and the drain after it.

use std::io::{self, ErrorKind, Write};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::sync::atomic::AtomicU32;
use std::time::{Duration, Instant};

/// `timeout` in whole milliseconds for `poll`/`epoll_wait`: sub-millisecond timeouts
/// round up (a short wait must not spin), long ones saturate.
fn timeout_ms(timeout: Duration) -> i32 {
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    if ms == 0 && !timeout.is_zero() { 1 } else { ms }
}

/// Waits until `fd` has one of `events` (or a hang-up or an error) or `timeout` passed;
/// returns the events it has (empty: the time passed, or a signal interrupted the wait).
///
/// # Errors
/// `poll(2)`'s error other than an interruption.
pub(crate) fn poll_one(fd: RawFd, events: i16, timeout: Duration) -> io::Result<i16> {
    let mut pfd = libc::pollfd {
        fd,
        events,
        revents: 0,
    };
    // SAFETY: one valid pollfd for the duration of the call.
    let n = unsafe { libc::poll(&mut pfd, 1, timeout_ms(timeout)) };
    if n < 0 {
        let e = io::Error::last_os_error();
        return if e.kind() == ErrorKind::Interrupted {
            Ok(0)
        } else {
            Err(e)
        };
    }
    Ok(if n == 0 { 0 } else { pfd.revents })
}

/// Whether `fd` is readable right now (data, or the peer's close).
#[cfg(test)]
pub(crate) fn readable_now(fd: RawFd) -> bool {
    poll_one(fd, libc::POLLIN, Duration::ZERO).is_ok_and(|r| r != 0)
}

/// Whether a write to `fd` would not block right now.
pub(crate) fn writable_now(fd: RawFd) -> bool {
    poll_one(fd, libc::POLLOUT, Duration::ZERO).is_ok_and(|r| r & libc::POLLOUT != 0)
}

/// Whether the peer of socket `fd` closed or reset the connection (without reading
/// anything).
pub(crate) fn peer_closed(fd: RawFd) -> bool {
    poll_one(fd, libc::POLLRDHUP, Duration::ZERO)
        .is_ok_and(|r| r & (libc::POLLRDHUP | libc::POLLHUP | libc::POLLERR) != 0)
}

/// Writes all of `data` to a non-blocking socket, waiting for writability until
/// `deadline` (a peer that stops reading cannot hold the writer for ever): the TCP and
/// legacy hosts' write. `stalled` is the error text when the deadline passes.
///
/// # Errors
/// The write's error; [`ErrorKind::TimedOut`] with `stalled` after the deadline;
/// [`ErrorKind::WriteZero`] when the socket takes nothing.
pub fn write_all_until<S: Write + AsRawFd>(
    stream: &mut S,
    mut data: &[u8],
    deadline: Instant,
    stalled: &'static str,
) -> io::Result<()> {
    while !data.is_empty() {
        match stream.write(data) {
            Ok(0) => return Err(io::Error::new(ErrorKind::WriteZero, "connection closed")),
            Ok(n) => data = &data[n..],
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return Err(io::Error::new(ErrorKind::TimedOut, stalled));
                }
                // A failed or interrupted poll only ends this wait early: the next write
                // says what broke.
                let _ = poll_one(
                    stream.as_raw_fd(),
                    libc::POLLOUT,
                    left.max(Duration::from_millis(1)),
                );
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Waits until one of `fds` (at most 4) is readable or `timeout` passed; returns whether
/// one is.
///
/// # Errors
/// `poll(2)`'s error (an interruption is a return without readiness).
// Used by the zenoh transport only (through `WakeFd`), absent without its feature.
#[cfg_attr(not(feature = "zenoh"), allow(dead_code))]
pub(crate) fn readable_any(fds: &[RawFd], timeout: Duration) -> io::Result<bool> {
    let mut pfds = [libc::pollfd {
        fd: -1,
        events: 0,
        revents: 0,
    }; 4];
    let n = fds.len().min(pfds.len());
    for (p, &fd) in pfds.iter_mut().zip(fds) {
        p.fd = fd;
        p.events = libc::POLLIN;
    }
    // SAFETY: `pfds` holds `n` valid pollfd structs for the whole call.
    let r = unsafe { libc::poll(pfds.as_mut_ptr(), n as libc::nfds_t, timeout_ms(timeout)) };
    if r < 0 {
        let e = io::Error::last_os_error();
        if e.kind() == ErrorKind::Interrupted {
            return Ok(false);
        }
        return Err(e);
    }
    Ok(r > 0)
}

/// A level-triggered `epoll` set. Its own descriptor is readable while one of its members
/// is ready, so sets nest: a transport's set joins the mixed host's.
#[derive(Debug)]
pub struct EpollSet {
    fd: OwnedFd,
    events: Vec<libc::epoll_event>,
}

impl EpollSet {
    /// A new, empty set reporting at most `capacity` ready members per wait.
    ///
    /// # Errors
    /// `epoll_create1(2)`'s error.
    pub fn new(capacity: usize) -> io::Result<Self> {
        // SAFETY: plain syscall; the result is checked before use.
        let fd = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(Self {
            // SAFETY: `fd` is a fresh descriptor nobody else owns.
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
            events: vec![libc::epoll_event { events: 0, u64: 0 }; capacity.max(1)],
        })
    }

    /// Watches `fd` for readability, reporting it as `token`. Closing the descriptor
    /// removes it again.
    ///
    /// # Errors
    /// `epoll_ctl(2)`'s error.
    pub fn add(&self, fd: RawFd, token: u64) -> io::Result<()> {
        let mut ev = libc::epoll_event {
            events: libc::EPOLLIN as u32,
            u64: token,
        };
        // SAFETY: valid epoll descriptor and event struct for the call.
        let r = unsafe { libc::epoll_ctl(self.fd.as_raw_fd(), libc::EPOLL_CTL_ADD, fd, &mut ev) };
        if r < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(())
    }

    /// Watches member `fd` for readability again (`true`), or only for errors and
    /// hang-ups (`false`: its unread input no longer makes the set ready).
    ///
    /// # Errors
    /// `epoll_ctl(2)`'s error.
    pub fn set_readable(&self, fd: RawFd, token: u64, readable: bool) -> io::Result<()> {
        let mut ev = libc::epoll_event {
            events: if readable { libc::EPOLLIN as u32 } else { 0 },
            u64: token,
        };
        // SAFETY: valid epoll descriptor and event struct for the call.
        let r = unsafe { libc::epoll_ctl(self.fd.as_raw_fd(), libc::EPOLL_CTL_MOD, fd, &mut ev) };
        if r < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(())
    }

    /// Waits until a member is ready or `timeout` passed; returns the tokens of the ready
    /// members (empty: the time passed, or a signal interrupted the wait).
    ///
    /// # Errors
    /// `epoll_wait(2)`'s error other than an interruption.
    pub fn wait(&mut self, timeout: Duration) -> io::Result<impl Iterator<Item = u64> + '_> {
        // SAFETY: `events` is a valid buffer of `events.len()` entries for the call.
        let n = unsafe {
            libc::epoll_wait(
                self.fd.as_raw_fd(),
                self.events.as_mut_ptr(),
                self.events.len() as i32,
                timeout_ms(timeout),
            )
        };
        let n = if n < 0 {
            let e = io::Error::last_os_error();
            if e.kind() != ErrorKind::Interrupted {
                return Err(e);
            }
            0
        } else {
            n as usize
        };
        Ok(self.events[..n].iter().map(|e| e.u64))
    }

    /// The set's own descriptor (readable while a member is ready).
    pub fn raw(&self) -> RawFd {
        self.fd.as_raw_fd()
    }
}

/// An `eventfd`: written by callbacks on other threads (zenoh's), waited on like a socket.
#[derive(Debug)]
#[cfg_attr(not(feature = "zenoh"), allow(dead_code))]
pub(crate) struct WakeFd(OwnedFd);

#[cfg_attr(not(feature = "zenoh"), allow(dead_code))]
impl WakeFd {
    /// A new, unwoken descriptor.
    ///
    /// # Errors
    /// `eventfd(2)`'s error.
    pub(crate) fn new() -> io::Result<Self> {
        // SAFETY: plain syscall; the result is checked before use.
        let fd = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: `fd` is a fresh descriptor nobody else owns.
        Ok(Self(unsafe { OwnedFd::from_raw_fd(fd) }))
    }

    /// Makes the descriptor readable (wake-ups merge).
    pub(crate) fn wake(&self) {
        let one: u64 = 1;
        // SAFETY: writes 8 bytes from a valid u64. A full counter (EAGAIN) is readable
        // already, which is all a wake-up needs.
        unsafe { libc::write(self.0.as_raw_fd(), (&raw const one).cast(), 8) };
    }

    /// Forgets pending wake-ups.
    pub(crate) fn clear(&self) {
        let mut n: u64 = 0;
        // SAFETY: reads at most 8 bytes into a valid u64; non-blocking.
        unsafe { libc::read(self.0.as_raw_fd(), (&raw mut n).cast(), 8) };
    }

    /// Waits until woken or `timeout` passed; returns whether it was woken (the wake-up
    /// stays pending until [`WakeFd::clear`]).
    pub(crate) fn wait(&self, timeout: Duration) -> bool {
        readable_any(&[self.0.as_raw_fd()], timeout).unwrap_or(false)
    }

    /// The descriptor.
    pub(crate) fn raw(&self) -> RawFd {
        self.0.as_raw_fd()
    }
}

/// Sleeps while `word` (in memory shared between processes) holds `expected`, at most
/// `timeout`. Returns on a wake, a changed value, a signal, the timeout, or spuriously:
/// the caller looks again.
pub(crate) fn futex_wait(word: &AtomicU32, expected: u32, timeout: Duration) {
    let ts = libc::timespec {
        tv_sec: libc::time_t::try_from(timeout.as_secs()).unwrap_or(libc::time_t::MAX),
        tv_nsec: libc::c_long::from(timeout.subsec_nanos()),
    };
    // SAFETY: FUTEX_WAIT reads the 32-bit word at a valid, aligned address that outlives
    // the call (`word` is borrowed) and the timespec on the stack; it writes nothing. Not
    // FUTEX_PRIVATE: the word is shared with other processes. Every outcome (woken,
    // EAGAIN for a changed value, ETIMEDOUT, EINTR) is a return to the caller's check.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAIT,
            expected,
            &ts as *const libc::timespec,
            std::ptr::null::<u32>(),
            0u32,
        );
    }
}

/// Wakes up to `n` of the processes and threads asleep in [`futex_wait`] on `word`, the
/// longest-waiting first (the kernel queues waiters of one priority in arrival order).
pub(crate) fn futex_wake(word: &AtomicU32, n: i32) {
    // SAFETY: FUTEX_WAKE only uses the address as the key of the wait queue.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAKE,
            n,
            std::ptr::null::<libc::timespec>(),
            std::ptr::null::<u32>(),
            0u32,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_woken_fd_is_readable_until_cleared_and_sets_nest() {
        let wake = WakeFd::new().unwrap();
        let mut inner = EpollSet::new(4).unwrap();
        inner.add(wake.raw(), 7).unwrap();
        let mut outer = EpollSet::new(4).unwrap();
        outer.add(inner.raw(), 1).unwrap();
        assert_eq!(outer.wait(Duration::ZERO).unwrap().count(), 0);
        assert!(!wake.wait(Duration::ZERO));
        wake.wake();
        wake.wake();
        // Level-triggered: still ready at the second look.
        for _ in 0..2 {
            assert_eq!(outer.wait(Duration::ZERO).unwrap().collect::<Vec<_>>(), [1]);
            assert_eq!(inner.wait(Duration::ZERO).unwrap().collect::<Vec<_>>(), [7]);
        }
        assert!(readable_any(&[wake.raw()], Duration::ZERO).unwrap());
        wake.clear();
        assert_eq!(outer.wait(Duration::ZERO).unwrap().count(), 0);
        assert!(!readable_now(wake.raw()));
    }

    #[test]
    fn timeouts_round_up_and_saturate() {
        assert_eq!(timeout_ms(Duration::ZERO), 0);
        assert_eq!(timeout_ms(Duration::from_micros(10)), 1);
        assert_eq!(timeout_ms(Duration::from_millis(1500)), 1500);
        assert_eq!(timeout_ms(Duration::MAX), i32::MAX);
    }
}
