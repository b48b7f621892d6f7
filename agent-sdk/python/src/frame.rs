//! A received frame, and its images and vectors as zero-copy, read-only numpy arrays.
//!
//! # Threads
//! The frame owns a sample of the agent's subscriber (shared memory) or a buffer of its
//! receive pool (TCP); both refer to per-agent state that is not thread-safe, and the
//! agent's wait touches that state with the GIL released. So a frame is *dropped* only on
//! the thread that owns the agent: a frame whose last reference goes away on another
//! thread is handed to the agent's [`Graveyard`] and dropped by the owner's next call. Any
//! thread may *read* a frame: the header and the pixels are plain memory that nobody
//! writes while the frame is held.

use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::{self, ThreadId};

use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vrsync_agent::Frame;
use vrsync_bridge::{ActionState, WireOutcome};

use crate::buffer::{Layout, array};
use crate::sensors::{
    PyActionState, PyActionStatus, PyCollision, PyEyePosition, PyGridPosition, PyHeadMotion, PyPose,
};

/// A frame (or a group's stacked sample) moved to another thread only to be dropped later
/// on its owner's thread.
pub(crate) enum Corpse {
    /// An agent's frame.
    Frame(#[allow(dead_code)] Frame),
    /// The stacked sample of a group's zero-copy images.
    Stack(#[allow(dead_code)] std::rc::Rc<vrsync_agent::StackSample>),
}

/// Frames released on foreign threads, waiting to be dropped by their agent's owner
/// thread; plus the number of this agent's frames alive anywhere (held or buried).
#[derive(Default)]
pub(crate) struct Graveyard {
    corpses: Mutex<Vec<Corpse>>,
    alive: AtomicUsize,
}

impl Graveyard {
    /// Drops the buried frames. Call only on the owner thread, with the agent idle.
    pub(crate) fn drain(&self) {
        let corpses =
            std::mem::take(&mut *self.corpses.lock().unwrap_or_else(PoisonError::into_inner));
        self.alive.fetch_sub(corpses.len(), Ordering::AcqRel);
        drop(corpses);
    }

    /// Frames of this agent alive anywhere (held by Python or buried).
    pub(crate) fn alive(&self) -> usize {
        self.alive.load(Ordering::Acquire)
    }

    /// Counts one more held value.
    pub(crate) fn born(&self) {
        self.alive.fetch_add(1, Ordering::AcqRel);
    }

    /// Counts a held value dropped on its owner thread.
    pub(crate) fn died(&self) {
        self.alive.fetch_sub(1, Ordering::AcqRel);
    }

    /// Keeps a value released on a foreign thread until the owner's next `drain`.
    pub(crate) fn bury(&self, corpse: Corpse) {
        self.corpses
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(corpse);
    }
}

/// A value that must be dropped on its owner's thread, and the corpse it becomes when
/// released on another.
pub(crate) trait Buried {
    fn corpse(self) -> Corpse;
}

impl Buried for Frame {
    fn corpse(self) -> Corpse {
        Corpse::Frame(self)
    }
}

impl Buried for std::rc::Rc<vrsync_agent::StackSample> {
    fn corpse(self) -> Corpse {
        Corpse::Stack(self)
    }
}

/// A value (a frame, a group's stacked sample) with the thread that may drop it, counted
/// in its graveyard while it lives.
pub(crate) struct Owned<T: Buried> {
    value: ManuallyDrop<T>,
    owner: ThreadId,
    graveyard: Arc<Graveyard>,
}

/// A frame with the thread that may drop it.
pub(crate) type OwnedFrame = Owned<Frame>;

impl<T: Buried> Owned<T> {
    pub(crate) fn new(value: T, graveyard: Arc<Graveyard>) -> Self {
        graveyard.born();
        Self {
            value: ManuallyDrop::new(value),
            owner: thread::current().id(),
            graveyard,
        }
    }

    /// The value.
    pub(crate) fn get(&self) -> &T {
        &self.value
    }
}

impl<T: Buried> Drop for Owned<T> {
    fn drop(&mut self) {
        // SAFETY: `drop` runs once, and `value` is not used after this.
        let value = unsafe { ManuallyDrop::take(&mut self.value) };
        if thread::current().id() == self.owner {
            drop(value);
            self.graveyard.died();
        } else {
            self.graveyard.bury(value.corpse());
        }
    }
}

/// One sensor frame: the cycle, simulated time, pose and the other sensors, and the
/// camera images as read-only numpy arrays that view the frame's memory without a copy.
///
/// An image array keeps its frame alive. An agent can hold at most `MAX_FRAMES_HELD` (2)
/// frames at once: the one it is reading and one more (each held frame is a sample of
/// the host's per-agent pool in shared memory: 1 queued + 2 held + 1 being written, so a
/// slow agent never blocks the host). Keep copies (`arr.copy()`) of what you need beyond
/// the current cycle, or the next wait raises `TooManyFramesHeldError`.
#[pyclass(module = "vrsync._vrsync", name = "Frame", frozen)]
pub(crate) struct PyFrame {
    owned: OwnedFrame,
    frames_skipped: u64,
}

impl PyFrame {
    pub(crate) fn new(frame: Frame, graveyard: Arc<Graveyard>, frames_skipped: u64) -> Self {
        Self {
            owned: OwnedFrame::new(frame, graveyard),
            frames_skipped,
        }
    }

    fn frame(&self) -> &Frame {
        self.owned.get()
    }

    pub(crate) fn header(&self) -> &vrsync_agent::SensorHeader {
        self.frame().header()
    }
}

fn outcome_name(v: u32) -> &'static str {
    match v {
        x if x == WireOutcome::Stopped as u32 => "stopped",
        x if x == WireOutcome::TimedOut as u32 => "timed_out",
        _ => "none",
    }
}

#[pymethods]
impl PyFrame {
    /// The cycle number `f` of this frame.
    #[getter]
    fn cycle(&self) -> u64 {
        self.header().cycle
    }

    /// Simulated time at the start of this cycle, in seconds.
    #[getter]
    fn sim_time(&self) -> f64 {
        self.header().sim_time_ns as f64 * 1e-9
    }

    /// Simulated time at the start of this cycle, in nanoseconds (exact).
    #[getter]
    fn sim_time_ns(&self) -> u64 {
        self.header().sim_time_ns
    }

    /// The agent this frame is for.
    #[getter]
    fn agent_id(&self) -> u32 {
        self.header().agent_id
    }

    /// Whether the host runs in lock-step (sync) mode.
    #[getter]
    fn sync_mode(&self) -> bool {
        self.header().sync_mode()
    }

    /// Body pose (position in metres, rotation quaternion x, y, z, w).
    #[getter]
    fn pose(&self) -> PyPose {
        self.header().pose.into()
    }

    /// Grid position sensor (position, Euler rotation in degrees).
    #[getter]
    fn grid(&self) -> PyGridPosition {
        self.header().grid.into()
    }

    /// Head motion sensor.
    #[getter]
    fn head_motion(&self) -> PyHeadMotion {
        self.header().head_motion.into()
    }

    /// Eye position sensor.
    #[getter]
    fn eye(&self) -> PyEyePosition {
        self.header().eye.into()
    }

    /// Reward received since the previous frame.
    #[getter]
    fn reward(&self) -> f32 {
        self.header().reward
    }

    /// Action statuses this frame brings, in the host's order: each status exactly once,
    /// also those of frames the agent skipped.
    #[getter]
    fn statuses(&self) -> Vec<PyActionStatus> {
        self.frame()
            .statuses()
            .iter()
            .filter_map(PyActionStatus::from_wire)
            .collect()
    }

    /// The newest state per action id this frame brings, as a dict.
    #[getter]
    fn action_states<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for s in self.frame().statuses() {
            if let Some(state) = ActionState::from_u32(s.state) {
                d.set_item(s.action_id, PyActionState::from(state))?;
            }
        }
        Ok(d)
    }

    /// Collisions this frame brings, each exactly once.
    #[getter]
    fn collisions(&self) -> Vec<PyCollision> {
        self.frame().collisions().iter().map(Into::into).collect()
    }

    /// How this agent's previous cycle ended: `"stopped"`, `"timed_out"` (the host did not
    /// get the stop in time) or `"none"` (first frame, or async mode).
    #[getter]
    fn previous_outcome(&self) -> &'static str {
        outcome_name(self.header().previous_outcome)
    }

    /// How many of this agent's commands the host rejected in the previous cycle.
    #[getter]
    fn previous_rejected(&self) -> u32 {
        self.header().previous_rejected
    }

    /// Frames the host published that this agent never saw because a newer one was
    /// waiting (async mode, or after a late stop), counted since the agent connected.
    #[getter]
    fn frames_skipped(&self) -> u64 {
        self.frames_skipped
    }

    /// Camera names, in image order.
    #[getter]
    fn camera_names(&self) -> Vec<String> {
        self.frame().images().map(|i| i.name().to_owned()).collect()
    }

    /// The image of camera `name` as a read-only numpy array viewing the frame's memory:
    /// H×W×3 (rgb8) or H×W×4 (rgba8) `uint8`, H×W `uint8` (gray8), H×W `float32` (depth
    /// in metres). The array keeps this frame alive.
    ///
    /// Raises `KeyError` for an unknown camera.
    fn image<'py>(slf: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        let me = slf.get();
        let index = me
            .frame()
            .images()
            .position(|i| i.name() == name)
            .ok_or_else(|| {
                PyKeyError::new_err(format!(
                    "no camera {name:?} in this frame (cameras: {:?})",
                    me.camera_names()
                ))
            })?;
        image_at(slf, index)
    }

    /// Every image by camera name (see `image`), in camera order.
    #[getter]
    fn images<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let py = slf.py();
        let d = PyDict::new(py);
        for (i, name) in slf.get().camera_names().into_iter().enumerate() {
            d.set_item(name, image_at(slf, i)?)?;
        }
        Ok(d)
    }

    /// Vector names (`[[agent.vector]]`), in payload order.
    #[getter]
    fn vector_names(&self) -> Vec<String> {
        self.frame()
            .vector_descs()
            .iter()
            .map(|d| d.name().to_owned())
            .collect()
    }

    /// The vector `name` (`[[agent.vector]]`) as a read-only 1-d `float32` numpy array
    /// viewing the frame's memory (no copy). The array keeps this frame alive.
    ///
    /// Raises `KeyError` for an unknown vector.
    fn vector<'py>(slf: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        let me = slf.get();
        let values = me.frame().vector(name).ok_or_else(|| {
            PyKeyError::new_err(format!(
                "no vector {name:?} in this frame (vectors: {:?})",
                me.vector_names()
            ))
        })?;
        let ptr = values.as_ptr().cast::<u8>().cast_mut();
        // SAFETY: the values lie in the frame, which the array's base (the frame itself)
        // keeps alive and nobody writes while it is held; the array is read-only.
        unsafe {
            array(
                slf.clone().into_any(),
                ptr,
                &Layout::vector(values.len()),
                false,
            )
        }
    }

    /// Every vector by name (see `vector`), in payload order.
    #[getter]
    fn vectors<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(slf.py());
        for name in slf.get().vector_names() {
            d.set_item(&name, Self::vector(slf, &name)?)?;
        }
        Ok(d)
    }

    /// The address range `(start, end)` of this frame's images in memory. For checking
    /// that image arrays are views (their data pointer lies inside it), not copies.
    #[getter]
    fn memory_range(&self) -> (usize, usize) {
        let mut start = usize::MAX;
        let mut end = 0;
        for img in self.frame().images() {
            let d = img.data();
            start = start.min(d.as_ptr() as usize);
            end = end.max(d.as_ptr() as usize + d.len());
        }
        if start > end { (0, 0) } else { (start, end) }
    }

    fn __repr__(&self) -> String {
        format!(
            "<vrsync.Frame agent={} cycle={} sim_time={:.3}s images={:?}>",
            self.header().agent_id,
            self.header().cycle,
            self.sim_time(),
            self.camera_names()
        )
    }
}

fn image_at<'py>(frame: &Bound<'py, PyFrame>, index: usize) -> PyResult<Bound<'py, PyAny>> {
    let img = frame
        .get()
        .frame()
        .image(index)
        .ok_or_else(|| PyKeyError::new_err(format!("no image {index} in this frame")))?;
    let data = img.data();
    let layout = Layout::image(img.format(), img.width(), img.height(), img.stride());
    let ptr = data.as_ptr().cast_mut();
    // SAFETY: the pixels lie in the frame, which the array's base (the frame itself) keeps
    // alive and nobody writes while it is held; the array is read-only.
    unsafe { array(frame.clone().into_any(), ptr, &layout, false) }
}
