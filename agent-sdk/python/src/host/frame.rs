//! `vrsync.HostFrame`: a sensor frame loaned for one agent, written from Python in place.
//!
//! # Views and publish
//! `image(name)` and `vector(name)` return writable numpy arrays over the loaned memory
//! itself (the agent's shared-memory sample, or the transport's pooled send buffer). `publish` hands
//! that memory to the transport, after which it may be read by the agent, reused for
//! another cycle, or unmapped: a write through an old array would corrupt a frame or
//! crash. So each view's base object (a [`HostBuffer`], which every array made from the
//! view refers to through its chain of bases) counts as one export of the frame from its
//! making until it is freed, and `Host.publish` refuses, with `FrameInUseError`, a frame
//! of which any export is alive. The base exports nothing itself (it is no buffer), so
//! the memory is reachable only through arrays that keep it counted. After publish the
//! frame makes no more views (`image` and `vector` raise `UsageError`).
//!
//! # Threads
//! The loan belongs to the host's transports, which are not thread-safe (iceoryx2
//! `ipc::Service` ports): frames and their buffers are `unsendable` classes, usable only on
//! the thread that loaned them (PyO3 raises `PanicException` on any other).

use std::cell::Cell;
use std::rc::Rc;

use pyo3::exceptions::{PyBufferError, PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vrsync_bridge::{ActionState, EyePosition, GridPosition, HeadMotion, Pose, SensorFrameMut};

use crate::buffer::{Layout, array};
use crate::errors::{error, obj};
use crate::sensors::PyActionState;

/// One agent's sensor frame of the current cycle, loaned by `Host.loan(agent_id)`:
/// write the images (`image(name)` is a writable numpy view of the frame's memory, no
/// copy), the vectors (`vector(name)`, the same), the pose and the reward, then
/// `Host.publish(frame)`.
///
/// A view must not outlive the publish: `publish` raises `FrameInUseError` while any
/// array viewing this frame is alive (`del` them first; arrays made from a view, such as
/// slices, count too). Render into the view (`renderer.render(out=view)`, `view[:] = ...`)
/// and drop it. A frame that is dropped without being published returns its memory
/// unpublished.
///
/// Used only on the thread that loaned it.
#[pyclass(module = "vrsync._vrsync", name = "HostFrame", unsendable)]
pub(crate) struct PyHostFrame {
    frame: Option<SensorFrameMut>,
    /// Buffers exported and not released yet.
    exports: Rc<Cell<usize>>,
    /// The `Host` that loaned it.
    host: u64,
    agent_id: u32,
    cycle: u64,
    sim_time_ns: u64,
    /// Its agent's camera and vector names, shared by every frame of that agent.
    names: Rc<FrameNames>,
}

/// An agent's camera names (in image order) and vector names (`[[agent.vector]]`, in
/// payload order): the same in every frame of the agent, so made once per agent and
/// shared, not copied into each loan.
#[derive(Debug, Default)]
pub(crate) struct FrameNames {
    cameras: Vec<String>,
    vectors: Vec<String>,
}

impl FrameNames {
    /// The names in `frame`'s image and vector tables.
    pub(crate) fn of(frame: &SensorFrameMut) -> Self {
        let h = frame.header();
        Self {
            cameras: h
                .images
                .iter()
                .take(h.image_count as usize)
                .map(|d| d.name().to_owned())
                .collect(),
            vectors: frame
                .vector_descs()
                .iter()
                .map(|d| d.name().to_owned())
                .collect(),
        }
    }

    /// Whether these could be `frame`'s names: as many cameras and vectors. (An agent's
    /// tables come from its configuration, which does not change while the host lives;
    /// this guards the cache against a frame of another layout, without comparing names
    /// every cycle.)
    pub(crate) fn fits(&self, frame: &SensorFrameMut) -> bool {
        self.cameras.len() == frame.header().image_count as usize
            && self.vectors.len() == frame.vector_descs().len()
    }
}

/// A part of a frame that can be exported: an image (by index) or a vector (by name).
#[derive(Debug, Clone, Copy)]
enum Part<'a> {
    Image(usize),
    Vector(&'a str),
}

impl PyHostFrame {
    /// A loaned `frame` of host `host`, whose names are `names` (see [`FrameNames::fits`]).
    pub(crate) fn new(mut frame: SensorFrameMut, host: u64, names: Rc<FrameNames>) -> Self {
        // The memory holds what it held when last used: every frame starts from neutral
        // sensors, so that what a Python world does not set reads the same every cycle.
        let h = frame.header_mut();
        h.pose = Pose {
            position: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        h.reward = 0.0;
        h.grid = GridPosition::default();
        h.head_motion = HeadMotion::default();
        h.eye = EyePosition::default();
        let (cycle, sim_time_ns) = (h.cycle, h.sim_time_ns);
        Self {
            agent_id: frame.agent_id(),
            cycle,
            sim_time_ns,
            frame: Some(frame),
            exports: Rc::default(),
            host,
            names,
        }
    }

    /// Takes the loan out for `Host.publish` of host `host`.
    ///
    /// # Errors
    /// `FrameInUseError` while views are alive; `UsageError` for a frame published already
    /// or loaned by another host.
    pub(crate) fn take(&mut self, py: Python<'_>, host: u64) -> PyResult<SensorFrameMut> {
        if host != self.host {
            return Err(self.usage(py, "this frame was loaned by another vrsync.Host"));
        }
        if self.frame.is_none() {
            return Err(self.usage(py, "this frame was published already"));
        }
        let views = self.exports.get();
        if views > 0 {
            return Err(error(
                py,
                "FrameInUseError",
                format!(
                    "cannot publish the frame of agent {} (cycle {}): {views} numpy view(s) of \
                     it are still alive, and its memory belongs to the agent once published; \
                     `del` every array returned by image() (and arrays made from them) first",
                    self.agent_id, self.cycle
                ),
                &[
                    ("agent_id", obj(py, self.agent_id)),
                    ("cycle", obj(py, self.cycle)),
                    ("views", obj(py, views)),
                ],
            ));
        }
        self.frame
            .take()
            .ok_or_else(|| self.usage(py, "this frame was published already"))
    }

    fn usage(&self, py: Python<'_>, what: &str) -> PyErr {
        error(
            py,
            "UsageError",
            format!("{what} (agent {}, cycle {})", self.agent_id, self.cycle),
            &[("agent_id", obj(py, self.agent_id))],
        )
    }

    fn loaned(&mut self, py: Python<'_>) -> PyResult<&mut SensorFrameMut> {
        match self.frame.as_mut() {
            Some(f) => Ok(f),
            None => Err(error(
                py,
                "UsageError",
                format!(
                    "the frame of agent {} (cycle {}) was published: its memory is the \
                     agent's now; loan the next one",
                    self.agent_id, self.cycle
                ),
                &[("agent_id", obj(py, self.agent_id))],
            )),
        }
    }

    fn camera_index(&self, name: &str) -> PyResult<usize> {
        self.names
            .cameras
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| {
                PyKeyError::new_err(format!(
                    "agent {} has no camera {name:?} (its cameras: {:?})",
                    self.agent_id, self.names.cameras
                ))
            })
    }

    /// Where `part` is and how it is shaped.
    fn memory(&mut self, part: Part<'_>) -> PyResult<(*mut u8, Layout)> {
        let frame = self
            .frame
            .as_mut()
            .ok_or_else(|| PyBufferError::new_err("the frame was published"))?;
        match part {
            Part::Image(index) => {
                let img = frame.images_mut().nth(index).ok_or_else(|| {
                    PyBufferError::new_err(format!("no image {index} in this frame"))
                })?;
                let format = img.desc.pixel_format().ok_or_else(|| {
                    PyBufferError::new_err(format!("image {index} has an unknown pixel format"))
                })?;
                let layout = Layout::image(
                    format,
                    img.desc.width_px,
                    img.desc.height_px,
                    img.desc.stride_bytes as usize,
                );
                Ok((img.data.as_mut_ptr(), layout))
            }
            Part::Vector(name) => {
                let values = frame.vector_mut(name).ok_or_else(|| {
                    PyBufferError::new_err(format!("no vector {name:?} in this frame"))
                })?;
                let layout = Layout::vector(values.len());
                Ok((values.as_mut_ptr().cast::<u8>(), layout))
            }
        }
    }
}

/// A writable numpy view of `part` of `frame`: its base is a new [`HostBuffer`], counted
/// as an export of the frame until it is freed.
fn view<'py>(frame: &Bound<'py, PyHostFrame>, part: Part<'_>) -> PyResult<Bound<'py, PyAny>> {
    let py = frame.py();
    let (ptr, layout, exports) = {
        let mut me = frame.try_borrow_mut()?;
        me.loaned(py)?;
        let (ptr, layout) = me.memory(part)?;
        (ptr, layout, me.exports.clone())
    };
    exports.set(exports.get() + 1);
    let buffer = Bound::new(
        py,
        HostBuffer {
            _frame: frame.clone().unbind(),
            exports,
        },
    )?;
    // SAFETY: the memory is the frame's loan, which lives as long as the frame (kept alive
    // by the buffer, the array's base) and is not handed on while the buffer is alive:
    // `PyHostFrame::take` refuses while an export is counted. It is written only through
    // the arrays, on the frame's thread (unsendable classes).
    unsafe { array(buffer.into_any(), ptr, &layout, true) }
}

/// `v` as `N` finite `f32`s; `ValueError` naming `name` otherwise.
fn floats<const N: usize>(name: &str, v: &[f64]) -> PyResult<[f32; N]> {
    let bad = || PyValueError::new_err(format!("{name} must be {N} finite numbers, got {v:?}"));
    if v.iter()
        .any(|x| !x.is_finite() || x.abs() > f64::from(f32::MAX))
    {
        return Err(bad());
    }
    let v: [f64; N] = v.try_into().map_err(|_| bad())?;
    Ok(v.map(|x| x as f32))
}

#[pymethods]
impl PyHostFrame {
    /// The agent this frame is for.
    #[getter]
    fn agent_id(&self) -> u32 {
        self.agent_id
    }

    /// The cycle this frame belongs to.
    #[getter]
    fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Simulated time at the start of this frame's cycle, in nanoseconds.
    #[getter]
    fn sim_time_ns(&self) -> u64 {
        self.sim_time_ns
    }

    /// Camera names, in image order.
    #[getter]
    fn camera_names(&self) -> Vec<String> {
        self.names.cameras.clone()
    }

    /// Whether the frame was published (its memory is the agent's then).
    #[getter]
    fn published(&self) -> bool {
        self.frame.is_none()
    }

    /// How many buffers of this frame are exported now (each numpy array viewing it holds
    /// one); `Host.publish` requires 0.
    #[getter]
    fn views(&self) -> usize {
        self.exports.get()
    }

    /// The image of camera `name` as a WRITABLE numpy array over the frame's memory (no
    /// copy): H×W×3 (rgb8) or H×W×4 (rgba8) `uint8`, H×W `uint8` (gray8), H×W `float32`
    /// (depth32f, metres). Rows are top to bottom. Its contents are whatever the memory
    /// held (the previous use of the sample): write every pixel.
    ///
    /// The array must be gone before `Host.publish(frame)` (see the class docs).
    ///
    /// Raises `KeyError` for an unknown camera, `UsageError` after publish.
    fn image<'py>(slf: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        let index = slf.try_borrow()?.camera_index(name)?;
        view(slf, Part::Image(index))
    }

    /// Every image by camera name (see `image`), in camera order.
    #[getter]
    fn images<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let py = slf.py();
        let d = PyDict::new(py);
        let names = slf.try_borrow()?.names.clone();
        for (i, name) in names.cameras.iter().enumerate() {
            d.set_item(name, view(slf, Part::Image(i))?)?;
        }
        Ok(d)
    }

    /// Vector names (`[[agent.vector]]`), in payload order.
    #[getter]
    fn vector_names(&self) -> Vec<String> {
        self.names.vectors.clone()
    }

    /// The vector `name` (`[[agent.vector]]`) as a WRITABLE 1-d `float32` numpy array
    /// over the frame's memory (no copy), as long as configured. Like an image view, it
    /// must be gone before `Host.publish(frame)`; write every value.
    ///
    /// Raises `KeyError` for an unknown vector, `UsageError` after publish.
    fn vector<'py>(slf: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        {
            let me = slf.try_borrow()?;
            if !me.names.vectors.iter().any(|v| v == name) {
                return Err(PyKeyError::new_err(format!(
                    "agent {} has no vector {name:?} (its vectors: {:?})",
                    me.agent_id, me.names.vectors
                )));
            }
        }
        view(slf, Part::Vector(name))
    }

    /// Every vector by name (see `vector`), in payload order.
    #[getter]
    fn vectors<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(slf.py());
        let names = slf.try_borrow()?.names.clone();
        for name in &names.vectors {
            d.set_item(name, view(slf, Part::Vector(name))?)?;
        }
        Ok(d)
    }

    /// Sets the body pose the agent reads: `position` (x, y, z) in metres, `rotation` a
    /// unit quaternion (x, y, z, w). Default: the origin, identity rotation (a frame's
    /// sensors start neutral every cycle: zero, reward 0).
    fn set_pose(&mut self, py: Python<'_>, position: Vec<f64>, rotation: Vec<f64>) -> PyResult<()> {
        let pose = Pose {
            position: floats("position", &position)?,
            rotation: floats("rotation", &rotation)?,
        };
        self.loaned(py)?.header_mut().pose = pose;
        Ok(())
    }

    /// Sets the grid position sensor: `position` (x, y, z) in metres, `rotation_deg`
    /// Euler angles in degrees.
    fn set_grid(
        &mut self,
        py: Python<'_>,
        position: Vec<f64>,
        rotation_deg: Vec<f64>,
    ) -> PyResult<()> {
        let grid = GridPosition {
            position: floats("position", &position)?,
            rotation_deg: floats("rotation_deg", &rotation_deg)?,
        };
        self.loaned(py)?.header_mut().grid = grid;
        Ok(())
    }

    /// Sets the head motion sensor (each an x, y, z triple).
    fn set_head_motion(
        &mut self,
        py: Python<'_>,
        velocity: Vec<f64>,
        acceleration: Vec<f64>,
        angular_velocity_deg: Vec<f64>,
        angular_acceleration_deg: Vec<f64>,
    ) -> PyResult<()> {
        let motion = HeadMotion {
            velocity: floats("velocity", &velocity)?,
            acceleration: floats("acceleration", &acceleration)?,
            angular_velocity_deg: floats("angular_velocity_deg", &angular_velocity_deg)?,
            angular_acceleration_deg: floats(
                "angular_acceleration_deg",
                &angular_acceleration_deg,
            )?,
        };
        self.loaned(py)?.header_mut().head_motion = motion;
        Ok(())
    }

    /// Sets the eye position sensor: `rotation_deg` (pan left, pan right, tilt) and its
    /// change per cycle, in degrees.
    #[pyo3(signature = (rotation_deg, rotation_velocity_deg = vec![0.0; 3]))]
    fn set_eye(
        &mut self,
        py: Python<'_>,
        rotation_deg: Vec<f64>,
        rotation_velocity_deg: Vec<f64>,
    ) -> PyResult<()> {
        let eye = EyePosition {
            rotation_deg: floats("rotation_deg", &rotation_deg)?,
            rotation_velocity_deg: floats("rotation_velocity_deg", &rotation_velocity_deg)?,
        };
        self.loaned(py)?.header_mut().eye = eye;
        Ok(())
    }

    /// Reports a new state of the agent's action `action_id` (the id it sent the command
    /// with) in this frame. Report each change once: the host repeats it in later frames
    /// until the agent has read one. Returns `False` (and drops it) when this frame's
    /// table is full.
    fn add_status(
        &mut self,
        py: Python<'_>,
        action_id: u32,
        state: PyRef<'_, PyActionState>,
    ) -> PyResult<bool> {
        let state = *state;
        let state = ActionState::from_u32(state as u32)
            .ok_or_else(|| PyValueError::new_err(format!("unknown action state {state:?}")))?;
        Ok(self.loaned(py)?.header_mut().push_status(action_id, state))
    }

    /// Reports that the agent's body hit `collider_id` while action `action_id` ran, in
    /// this frame (once: the host repeats it until read). Returns `False` (and drops it)
    /// when this frame's table is full.
    fn add_collision(
        &mut self,
        py: Python<'_>,
        action_id: u32,
        collider_id: u32,
    ) -> PyResult<bool> {
        Ok(self
            .loaned(py)?
            .header_mut()
            .push_collision(action_id, collider_id))
    }

    /// The reward the agent reads in this frame.
    #[getter]
    fn get_reward(&mut self, py: Python<'_>) -> PyResult<f32> {
        Ok(self.loaned(py)?.header().reward)
    }

    #[setter]
    fn set_reward(&mut self, py: Python<'_>, reward: f64) -> PyResult<()> {
        if !reward.is_finite() {
            return Err(PyValueError::new_err(format!(
                "reward must be a finite number, got {reward}"
            )));
        }
        self.loaned(py)?.header_mut().reward = reward as f32;
        Ok(())
    }

    /// The address range `(start, end)` of this frame's images in memory: for checking
    /// that image arrays are views of it (their data pointer lies inside), not copies.
    #[getter]
    fn memory_range(&mut self, py: Python<'_>) -> PyResult<(usize, usize)> {
        let frame = self.loaned(py)?;
        let mut start = usize::MAX;
        let mut end = 0;
        for img in frame.images_mut() {
            start = start.min(img.data.as_ptr() as usize);
            end = end.max(img.data.as_ptr() as usize + img.data.len());
        }
        Ok(if start > end { (0, 0) } else { (start, end) })
    }

    fn __repr__(&self) -> String {
        format!(
            "<vrsync.HostFrame agent={} cycle={} images={:?}{}>",
            self.agent_id,
            self.cycle,
            self.names.cameras,
            if self.frame.is_none() {
                " published"
            } else {
                ""
            }
        )
    }
}

/// The base object of a `HostFrame`'s numpy views: keeps the frame alive and counts as
/// one export of it from the view's making until the last array viewing it is freed.
#[pyclass(module = "vrsync._vrsync", unsendable)]
pub(crate) struct HostBuffer {
    _frame: Py<PyHostFrame>,
    exports: Rc<Cell<usize>>,
}

impl Drop for HostBuffer {
    fn drop(&mut self) {
        self.exports.set(self.exports.get().saturating_sub(1));
    }
}
