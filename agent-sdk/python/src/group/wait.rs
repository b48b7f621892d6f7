//! Waiting for every agent's next frame, copying each into the outputs.

use std::time::{Duration, Instant};

use vrsync_agent::{Agent, WaitStartError};

use super::sink::{Sink, check_frame};

/// How one wait phase ended.
pub(super) enum Waited {
    /// Every pending agent got its frame.
    Done,
    /// The slice ended with agents still pending.
    Pending,
    /// Agent `k` failed.
    Failed(usize, WaitStartError),
}

/// Receives the next frame of every agent in `pending` until `slice_end`, copying each
/// into the outputs and dropping it; removes the agents done from `pending`. Agents are
/// taken in order (the host publishes in that order): a non-blocking try first, then a
/// blocking wait only if the frame is not there yet, so each agent costs at most two
/// calls. Returns the outcome and the nanoseconds spent in tries that found no frame and
/// in blocking waits (the time waited for the host, not spent in the SDK).
pub(super) fn wait_all(
    agents: &mut [Agent],
    pending: &mut Vec<usize>,
    rotations: &mut [[f32; 4]],
    sink: &Sink,
    slice_end: Instant,
) -> (Waited, u64) {
    let mut blocked = 0u64;
    let ns = |since: Instant| u64::try_from(since.elapsed().as_nanos()).unwrap_or(u64::MAX);
    let mut done = 0;
    let mut outcome = Waited::Done;
    for &k in pending.iter() {
        let Some(agent) = agents.get_mut(k) else {
            done += 1;
            continue;
        };
        let tried = Instant::now();
        let mut r = agent.wait_start(Some(Duration::ZERO));
        if matches!(r, Err(WaitStartError::Timeout { .. })) {
            let now = Instant::now();
            if now >= slice_end {
                blocked += ns(tried);
                outcome = Waited::Pending;
                break;
            }
            r = agent.wait_start(Some(slice_end - now));
            blocked += ns(tried);
        }
        match r {
            Ok(frame) => {
                if let Err(reason) = check_frame(sink, &frame) {
                    let cycle = frame.cycle();
                    outcome = Waited::Failed(k, WaitStartError::BadFrame { cycle, reason });
                    break;
                }
                let skipped = agent.frames_skipped();
                // SAFETY: the sink points to the group's output arrays (alive: the group
                // holds them and is exclusively borrowed), k < N, and the frame was checked.
                unsafe { sink.write(k, &frame, skipped) };
                rotations[k] = frame.header().pose.rotation;
                done += 1;
            }
            Err(WaitStartError::Timeout { .. }) => {
                outcome = Waited::Pending;
                break;
            }
            Err(e) => {
                outcome = Waited::Failed(k, e);
                break;
            }
        }
    }
    pending.drain(..done);
    (outcome, blocked)
}
