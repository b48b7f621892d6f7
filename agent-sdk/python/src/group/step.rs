//! The step engine of [`AgentGroup`]: every agent's commands and stop, then every agent's
//! next frame copied into the group's stacked arrays.

use std::time::Instant;

use pyo3::prelude::*;
use vrsync_agent::{Agent, WaitStartError};
use vrsync_bridge::Command;

use super::out::Out;
use super::stacked;
use super::wait::{Waited, wait_all};
use super::{AgentGroup, Agents, WAIT_SLICE, closed};
use crate::agent::{SameThread, stop_error, wait_error};
use crate::errors::send_error;

impl AgentGroup {
    /// Sends the commands `commands(k, rotation, buffer)` puts into `buffer` and the stop
    /// for every agent `k`, then waits for and copies every agent's next frame.
    /// `commands` returns `false` for an agent that has no frame yet (it only waits for
    /// its first). Allocates nothing in steady state: the buffers are the group's.
    pub(super) fn run(
        &mut self,
        py: Python<'_>,
        mut commands: impl FnMut(usize, [f32; 4], &mut Vec<Command>) -> bool,
    ) -> PyResult<()> {
        let started = Instant::now();
        self.enter()?;
        if self.fresh && !self.zero_copy {
            self.renew_images(py)?;
        }
        // The last step's views are the caller's now (the group's reference would count
        // against the held-frame limit).
        self.views.clear();
        self.held.clear();
        let zero_copy = self.zero_copy;
        let Self {
            agents,
            ids,
            session,
            rotations,
            pending,
            commands: buffer,
            sink,
            step_timeout,
            held,
            ..
        } = self;
        let Some(Agents(agents)) = agents.as_mut() else {
            return Err(closed(session));
        };
        // 1. every agent's commands and stop
        for (k, agent) in agents.iter_mut().enumerate() {
            buffer.clear();
            if !commands(k, rotations[k], buffer) {
                continue;
            }
            for &c in buffer.iter() {
                agent.send(c).map_err(|e| send_error(py, e, ids[k]))?;
            }
            agent
                .stop()
                .map_err(|e| stop_error(py, e, session, ids[k]))?;
        }
        // 2. every agent's next frame, copied into the outputs and dropped at once
        pending.clear();
        pending.extend(0..ids.len());
        let deadline = step_timeout.map(|t| started + t);
        let mut wait_ns = 0u64;
        loop {
            let slice_end = deadline.map_or(Instant::now() + WAIT_SLICE, |d| {
                (Instant::now() + WAIT_SLICE).min(d)
            });
            let held = zero_copy.then_some(&mut *held);
            let job = SameThread((&mut *agents, &mut *pending, &mut *rotations, &*sink, held));
            let (outcome, waited) = py
                .detach(move || {
                    let job = job;
                    let (agents, pending, rotations, sink, held) = job.0;
                    SameThread(wait_all(agents, pending, rotations, sink, held, slice_end))
                })
                .0;
            wait_ns += waited;
            match outcome {
                Waited::Done => break,
                Waited::Pending => {
                    py.check_signals()?;
                    if deadline.is_some_and(|d| Instant::now() >= d) {
                        let k = pending.first().copied().unwrap_or(0);
                        let last_cycle = agents.get(k).and_then(Agent::last_cycle);
                        let e = WaitStartError::Timeout {
                            waited: started.elapsed(),
                            last_cycle,
                        };
                        return Err(wait_error(py, e, session, ids[k], started.elapsed()));
                    }
                }
                Waited::Failed(k, e) => {
                    return Err(wait_error(py, e, session, ids[k], started.elapsed()));
                }
            }
        }
        if zero_copy {
            self.make_views(py)?;
        }
        self.primed.iter_mut().for_each(|p| *p = true);
        let total = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.sdk_ns += total.saturating_sub(wait_ns);
        self.wait_ns += wait_ns;
        self.steps += 1;
        Ok(())
    }
    /// The step's zero-copy images: views of the stacked sample, or (frames of different
    /// cycles) copies into the group's arrays.
    fn make_views(&mut self, py: Python<'_>) -> PyResult<()> {
        let stride = self.stacked.unwrap_or(0);
        let n = self.ids.len();
        let result = match self.held.viewable(stride) {
            Some(v) => stacked::views(
                py,
                v,
                &self.sink.images,
                &self.held,
                n,
                &self.graveyard,
                &mut self.views,
            ),
            None => {
                // SAFETY: the sinks point to the group's live arrays (it holds them).
                unsafe { self.held.copy_into(&self.sink.images) };
                Ok(())
            }
        };
        self.held.clear();
        result
    }

    /// Admits a call on this thread: the group's zero-copy images are dropped on the
    /// thread that made them, so it moves to another thread only when none is held.
    fn enter(&mut self) -> PyResult<()> {
        let here = std::thread::current().id();
        if here == self.owner {
            self.graveyard.drain();
            return Ok(());
        }
        if self.graveyard.alive() > 0 {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
                "the AgentGroup of session {:?} is used from another thread while {} of its \
                 zero-copy image sets made on its first thread are alive: drop them there \
                 first (or keep copies)",
                self.session,
                self.graveyard.alive()
            )));
        }
        self.owner = here;
        Ok(())
    }

    /// New (uninitialised) image arrays, which the next wait fills: the arrays handed out
    /// before keep their contents.
    pub(super) fn renew_images(&mut self, py: Python<'_>) -> PyResult<()> {
        let numpy = self.numpy.bind(py);
        let n = self.ids.len();
        for ((_, out), (camera, sink)) in self
            .images
            .iter_mut()
            .zip(self.cameras.iter().zip(&mut self.sink.images))
        {
            let mut shape = vec![n];
            shape.extend(camera.shape().iter().map(|&d| d as usize));
            *out = Out::empty(py, numpy, &shape, camera.dtype())?;
            sink.ptr = out.ptr;
        }
        Ok(())
    }
}
