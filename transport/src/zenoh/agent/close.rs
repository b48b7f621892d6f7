//! Closing an agent's zenoh session: after the host's close, let the host go first; in a
//! thread of its own, waited for a bounded time when the agent is dropped.

use std::time::{Duration, Instant};

use ::zenoh::Wait as _;
use tracing::debug;

use super::{AgentShared, ZenohAgent, lock};

/// Where closing the agent's zenoh session is.
#[derive(Debug)]
pub(super) enum Closing {
    /// Not begun.
    Open,
    /// In a thread of its own, which says when it is done; begun at the instant.
    InThread(std::sync::mpsc::Receiver<()>, Instant),
    /// Done (in place: no thread could be started).
    Closed,
}

/// How long an agent that saw its host's `host/closed` lets the host close first before
/// it closes its own session: the host closes once its agents confirmed, and both sides
/// tearing one TLS link down at once crashed the host's process in a test run (a segfault
/// in zenoh's TX thread, in rustls' error handling: the link's reading and writing halves
/// share one TLS state).
const HOST_CLOSES_FIRST: Duration = Duration::from_millis(500);

impl AgentShared {
    /// After `host/closed`: waits (at most [`HOST_CLOSES_FIRST`]) until the host's token
    /// went, i.e. the host closed its side.
    fn let_a_closing_host_go_first(&self) {
        let deadline = Instant::now() + HOST_CLOSES_FIRST;
        loop {
            {
                let st = lock(&self.state);
                if !st.closed || st.host_left {
                    return;
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return;
            }
            self.wake.wait(deadline - now);
            self.wake.clear();
        }
    }
}

/// How long dropping an agent waits for its zenoh session to close, from the moment the
/// close began. zenoh's close waits up to its own 10 s for a host that does not answer (a
/// frozen process, a lost link); past this bound the close goes on in a thread of its
/// own and the drop returns.
const CLOSE_BOUND: Duration = Duration::from_secs(1);

impl ZenohAgent {
    /// Starts closing the session in a thread of its own (once).
    pub(super) fn start_close(&mut self) {
        if !matches!(self.closing, Closing::Open) {
            return;
        }
        self.beat_stop = None;
        let session = self.session.clone();
        let shared = self.shared.clone();
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("vrsync-zenoh-close".into())
            .spawn(move || {
                shared.let_a_closing_host_go_first();
                let _ = session.close().wait();
                let _ = done_tx.send(());
            });
        self.closing = match spawned {
            Ok(_) => Closing::InThread(done_rx, Instant::now()),
            Err(_) => {
                // No thread to spare: closed here, within zenoh's own timeout.
                let _ = self.session.close().wait();
                Closing::Closed
            }
        };
    }
}

impl Drop for ZenohAgent {
    fn drop(&mut self) {
        self.start_close();
        if let Closing::InThread(done, began) = &self.closing {
            let left = CLOSE_BOUND.saturating_sub(began.elapsed());
            if done.recv_timeout(left).is_err() {
                debug!(
                    agent = self.id,
                    "the zenoh session did not close within {CLOSE_BOUND:?}: the host does \
                     not answer; closing in the background"
                );
            }
        }
    }
}
