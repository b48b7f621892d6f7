//! What SIGINT and SIGTERM do in a process that uses vrsync: the one place that decides.
//!
//! A library must not take a process's signals from it: a Python interpreter turns Ctrl-C
//! into `KeyboardInterrupt`, Unity has its own handlers. So by default
//! ([`SignalHandling::Leave`]) vrsync installs no handler and tells iceoryx2 not to
//! install its own (`SignalHandlingMode::Disabled` on every node); waits then end by
//! their timeouts, and the embedding program decides what a signal means.
//!
//! The command-line programs and the C ABIs opt in ([`SignalHandling::Install`]): SIGINT
//! and SIGTERM then only set a sticky, process-wide termination flag, which every wait of
//! the host and the agent honours (`Terminated` errors), so a run ends cleanly between two
//! cycles. The handler is installed without `SA_RESTART`, so a blocking wait is interrupted
//! and notices the flag at once. iceoryx2's own handling stays disabled in both modes: one
//! handler, one flag, whichever transports the process uses.

use std::sync::Once;
use std::sync::atomic::{AtomicBool, Ordering};

/// Whether vrsync installs handlers for SIGINT and SIGTERM (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SignalHandling {
    /// Install nothing and keep iceoryx2 from installing anything: the process's own
    /// handlers stay. Waits never report a termination request. The library default.
    #[default]
    Leave,
    /// Install process-wide handlers for SIGINT and SIGTERM that set a sticky termination
    /// flag; waits then return their `Terminated` error. For programs that own their
    /// process (`vr-sim`, `vr-agent`, the C ABIs).
    Install,
}

static TERMINATE: AtomicBool = AtomicBool::new(false);
static INSTALL: Once = Once::new();

extern "C" fn on_termination_signal(_: libc::c_int) {
    TERMINATE.store(true, Ordering::SeqCst);
}

impl SignalHandling {
    /// Installs the handlers if this is [`SignalHandling::Install`] (once per process;
    /// later calls do nothing). [`SignalHandling::Leave`] does nothing.
    pub fn apply(self) {
        if self != Self::Install {
            return;
        }
        INSTALL.call_once(|| {
            let handler: extern "C" fn(libc::c_int) = on_termination_signal;
            for sig in [libc::SIGINT, libc::SIGTERM] {
                // SAFETY: a zeroed sigaction is a valid "no flags, empty mask" value;
                // the handler only stores to an atomic, which is async-signal-safe. No
                // SA_RESTART: a blocked wait returns EINTR and checks the flag.
                unsafe {
                    let mut action: libc::sigaction = core::mem::zeroed();
                    action.sa_sigaction = handler as libc::sighandler_t;
                    libc::sigemptyset(&mut action.sa_mask);
                    libc::sigaction(sig, &action, core::ptr::null_mut());
                }
            }
        });
    }

    /// Whether a termination was requested: always `false` with
    /// [`SignalHandling::Leave`]; with [`SignalHandling::Install`], whether SIGINT or
    /// SIGTERM arrived since the handlers were installed (sticky).
    pub fn termination_requested(self) -> bool {
        self == Self::Install && TERMINATE.load(Ordering::SeqCst)
    }
}
