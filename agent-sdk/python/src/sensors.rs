//! The scalar sensors of a frame as small immutable Python classes.

use pyo3::prelude::*;
use vrsync_bridge::ActionState;

type V3 = (f32, f32, f32);

fn v3(a: [f32; 3]) -> V3 {
    (a[0], a[1], a[2])
}

/// Body pose in the world frame: `position` in metres (x, y, z; y is up) and `rotation`
/// as a unit quaternion (x, y, z, w).
#[pyclass(module = "vrsync._vrsync", name = "Pose", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyPose {
    position: V3,
    rotation: (f32, f32, f32, f32),
}

#[pymethods]
impl PyPose {
    /// The heading (yaw about +y) in degrees, 0 ≤ h < 360: 0 faces +z, 90 faces +x (the
    /// convention of `Move.heading_deg`).
    #[getter]
    fn heading_deg(&self) -> f32 {
        let (_, y, _, w) = self.rotation;
        (2.0 * y.atan2(w)).to_degrees().rem_euclid(360.0)
    }

    fn __repr__(&self) -> String {
        format!(
            "Pose(position={:?}, rotation={:?})",
            self.position, self.rotation
        )
    }
}

impl From<vrsync_bridge::Pose> for PyPose {
    fn from(p: vrsync_bridge::Pose) -> Self {
        let r = p.rotation;
        Self {
            position: v3(p.position),
            rotation: (r[0], r[1], r[2], r[3]),
        }
    }
}

/// The grid position sensor: `position` in metres and `rotation_deg` as Euler angles in
/// degrees (x, y, z; y is up), as the original `MsgGridPosition`.
#[pyclass(module = "vrsync._vrsync", name = "GridPosition", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyGridPosition {
    position: V3,
    rotation_deg: V3,
}

#[pymethods]
impl PyGridPosition {
    fn __repr__(&self) -> String {
        format!(
            "GridPosition(position={:?}, rotation_deg={:?})",
            self.position, self.rotation_deg
        )
    }
}

impl From<vrsync_bridge::GridPosition> for PyGridPosition {
    fn from(g: vrsync_bridge::GridPosition) -> Self {
        Self {
            position: v3(g.position),
            rotation_deg: v3(g.rotation_deg),
        }
    }
}

/// The head motion sensor: velocity (m/s), acceleration (m/s²), angular velocity (°/s)
/// and angular acceleration (°/s²), each (x, y, z).
#[pyclass(module = "vrsync._vrsync", name = "HeadMotion", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyHeadMotion {
    velocity: V3,
    acceleration: V3,
    angular_velocity_deg: V3,
    angular_acceleration_deg: V3,
}

#[pymethods]
impl PyHeadMotion {
    fn __repr__(&self) -> String {
        format!(
            "HeadMotion(velocity={:?}, acceleration={:?}, angular_velocity_deg={:?}, \
             angular_acceleration_deg={:?})",
            self.velocity,
            self.acceleration,
            self.angular_velocity_deg,
            self.angular_acceleration_deg
        )
    }
}

impl From<vrsync_bridge::HeadMotion> for PyHeadMotion {
    fn from(h: vrsync_bridge::HeadMotion) -> Self {
        Self {
            velocity: v3(h.velocity),
            acceleration: v3(h.acceleration),
            angular_velocity_deg: v3(h.angular_velocity_deg),
            angular_acceleration_deg: v3(h.angular_acceleration_deg),
        }
    }
}

/// The eye position sensor: `rotation_deg` (pan left, pan right, tilt) and its change per
/// cycle, `rotation_velocity_deg`.
#[pyclass(module = "vrsync._vrsync", name = "EyePosition", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyEyePosition {
    rotation_deg: V3,
    rotation_velocity_deg: V3,
}

#[pymethods]
impl PyEyePosition {
    fn __repr__(&self) -> String {
        format!(
            "EyePosition(rotation_deg={:?}, rotation_velocity_deg={:?})",
            self.rotation_deg, self.rotation_velocity_deg
        )
    }
}

impl From<vrsync_bridge::EyePosition> for PyEyePosition {
    fn from(e: vrsync_bridge::EyePosition) -> Self {
        Self {
            rotation_deg: v3(e.rotation_deg),
            rotation_velocity_deg: v3(e.rotation_velocity_deg),
        }
    }
}

/// Execution state of an action (the values of the original `MsgActionExecutationStatus`).
#[pyclass(
    module = "vrsync._vrsync",
    name = "ActionState",
    frozen,
    eq,
    eq_int,
    hash
)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum PyActionState {
    /// Accepted, not finished yet.
    InExecution = 0,
    /// Completed.
    Finished = 1,
    /// Cancelled, replaced by a newer action, or impossible.
    Aborted = 2,
    /// A movement is walking.
    Walking = 3,
    /// A movement is rotating.
    Rotating = 4,
    /// A movement is walking and rotating.
    WalkingRotating = 5,
}

#[pymethods]
impl PyActionState {
    /// Whether the action has ended (`Finished` or `Aborted`).
    #[getter]
    fn done(&self) -> bool {
        matches!(self, Self::Finished | Self::Aborted)
    }
}

impl From<ActionState> for PyActionState {
    fn from(s: ActionState) -> Self {
        match s {
            ActionState::InExecution => Self::InExecution,
            ActionState::Finished => Self::Finished,
            ActionState::Aborted => Self::Aborted,
            ActionState::Walking => Self::Walking,
            ActionState::Rotating => Self::Rotating,
            ActionState::WalkingRotating => Self::WalkingRotating,
        }
    }
}

/// One action status of a frame: the action id the agent's command got, and its state.
#[pyclass(module = "vrsync._vrsync", name = "ActionStatus", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyActionStatus {
    action_id: u32,
    state: PyActionState,
}

#[pymethods]
impl PyActionStatus {
    fn __repr__(&self) -> String {
        format!(
            "ActionStatus(action_id={}, state=ActionState.{:?})",
            self.action_id, self.state
        )
    }
}

impl PyActionStatus {
    /// `None` for a state value this SDK does not know (a newer host).
    pub(crate) fn from_wire(s: &vrsync_bridge::ActionStatus) -> Option<Self> {
        Some(Self {
            action_id: s.action_id,
            state: ActionState::from_u32(s.state)?.into(),
        })
    }
}

/// One collision of a frame: the action that was running and the id of what was hit.
#[pyclass(module = "vrsync._vrsync", name = "Collision", frozen, eq, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyCollision {
    action_id: u32,
    collider_id: u32,
}

#[pymethods]
impl PyCollision {
    fn __repr__(&self) -> String {
        format!(
            "Collision(action_id={}, collider_id={})",
            self.action_id, self.collider_id
        )
    }
}

impl From<&vrsync_bridge::Collision> for PyCollision {
    fn from(c: &vrsync_bridge::Collision) -> Self {
        Self {
            action_id: c.action_id,
            collider_id: c.collider_id,
        }
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPose>()?;
    m.add_class::<PyGridPosition>()?;
    m.add_class::<PyHeadMotion>()?;
    m.add_class::<PyEyePosition>()?;
    m.add_class::<PyActionState>()?;
    m.add_class::<PyActionStatus>()?;
    m.add_class::<PyCollision>()?;
    Ok(())
}
