//! The step engine of [`AgentGroup`]: every agent's commands and stop, then every agent's
//! next frame copied into the group's stacked arrays.

use std::time::Instant;

use pyo3::prelude::*;
use vrsync_agent::{Agent, WaitStartError};
use vrsync_bridge::Command;

use super::out::Out;
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
        if self.fresh {
            self.renew_images(py)?;
        }
        let Self {
            agents,
            ids,
            session,
            rotations,
            pending,
            commands: buffer,
            sink,
            step_timeout,
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
            let job = SameThread((&mut *agents, &mut *pending, &mut *rotations, &*sink));
            let (outcome, waited) = py
                .detach(move || {
                    let job = job;
                    let (agents, pending, rotations, sink) = job.0;
                    SameThread(wait_all(agents, pending, rotations, sink, slice_end))
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
        self.primed.iter_mut().for_each(|p| *p = true);
        let total = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.sdk_ns += total.saturating_sub(wait_ns);
        self.wait_ns += wait_ns;
        self.steps += 1;
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
