//! Waiting for every agent's next frame, copying each into the outputs.

use std::time::Instant;

use vrsync_agent::{Agent, Frame, WaitStartError};

use super::sink::{Sink, check_frame};
use super::stacked::Held;

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
/// into the outputs and dropping it; removes the agents done from `pending`. First every
/// frame that is already there is taken ([`Agent::try_next_frame`]: over shared memory
/// no system call); only when some agent's frame is not there yet does it wait, for the
/// first such agent ([`Agent::wait_start`]), then it takes what arrived meanwhile, and
/// so on. Returns the outcome and the nanoseconds spent in those waits (the time waited
/// for the host, not spent in the SDK).
pub(super) fn wait_all(
    agents: &mut [Agent],
    pending: &mut Vec<usize>,
    rotations: &mut [[f32; 4]],
    sink: &Sink,
    held: Option<&mut Held>,
    slice_end: Instant,
) -> (Waited, u64) {
    let mut held = held;
    let mut blocked = 0u64;
    loop {
        // 1. every frame that is there, keeping the others' order
        let mut kept = 0;
        for i in 0..pending.len() {
            let k = pending[i];
            let Some(agent) = agents.get_mut(k) else {
                continue;
            };
            match agent.try_next_frame() {
                Ok(Some(frame)) => {
                    if let Err(failed) =
                        take(k, agent, &frame, rotations, sink, held.as_deref_mut())
                    {
                        return (failed, blocked);
                    }
                }
                Ok(None) => {
                    pending[kept] = k;
                    kept += 1;
                }
                Err(e) => return (Waited::Failed(k, e), blocked),
            }
        }
        pending.truncate(kept);
        // 2. a wait for the first agent whose frame has not come
        let Some(&k) = pending.first() else {
            return (Waited::Done, blocked);
        };
        let Some(agent) = agents.get_mut(k) else {
            pending.remove(0);
            continue;
        };
        let tried = Instant::now();
        if tried >= slice_end {
            return (Waited::Pending, blocked);
        }
        let r = agent.wait_start(Some(slice_end - tried));
        blocked += u64::try_from(tried.elapsed().as_nanos()).unwrap_or(u64::MAX);
        match r {
            Ok(frame) => {
                if let Err(failed) = take(k, agent, &frame, rotations, sink, held.as_deref_mut()) {
                    return (failed, blocked);
                }
                pending.remove(0);
            }
            Err(WaitStartError::Timeout { .. }) => return (Waited::Pending, blocked),
            Err(e) => return (Waited::Failed(k, e), blocked),
        }
    }
}

/// Checks agent `k`'s new frame and copies it into row `k` of the outputs; with `held`
/// (zero-copy images) its images stay in its stacked sample, which `held` keeps.
fn take(
    k: usize,
    agent: &Agent,
    frame: &Frame,
    rotations: &mut [[f32; 4]],
    sink: &Sink,
    held: Option<&mut Held>,
) -> Result<(), Waited> {
    if let Err(reason) = check_frame(sink, frame) {
        let cycle = frame.cycle();
        return Err(Waited::Failed(
            k,
            WaitStartError::BadFrame { cycle, reason },
        ));
    }
    // With zero-copy images a stacked frame's images stay where they are (a frame with a
    // payload of its own, which a stacked group does not get, is copied as usual).
    let viewed = held.is_some() && Agent::stacked_payload(frame).is_some();
    // SAFETY: the sink points to the group's output arrays (alive: the group holds them
    // and is exclusively borrowed), k < N, and the frame was checked.
    unsafe { sink.write(k, frame, agent.frames_skipped(), !viewed) };
    if let Some(held) = held {
        held.note(k, frame);
    }
    if let Some(r) = rotations.get_mut(k) {
        *r = frame.header().pose.rotation;
    }
    Ok(())
}
