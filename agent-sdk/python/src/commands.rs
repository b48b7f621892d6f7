//! The command catalogue: one small immutable class per command, all subclasses of
//! `Command`. Arguments are checked when a command is built, so a bad value raises
//! `ValueError`/`TypeError` in the line that made it, before anything is sent. Limits that
//! depend on the world (room size, eye range) are the simulator's to check; it reports a
//! rejected command in the next frame (`Frame.previous_rejected`).

use glam::Vec3;
use pyo3::PyClass;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use vrsync_bridge::Command;

/// Largest magnitude accepted for an angle in degrees (ten turns), as the host checks.
const MAX_ANGLE_DEG: f64 = 3600.0;
/// Largest magnitude accepted for an eye angle in degrees.
const MAX_EYE_DEG: f64 = 180.0;

fn finite(name: &str, v: f64) -> PyResult<f32> {
    if !v.is_finite() {
        return Err(PyValueError::new_err(format!(
            "{name} must be a finite number, got {v}"
        )));
    }
    if v.abs() > f64::from(f32::MAX) {
        return Err(PyValueError::new_err(format!(
            "{name} = {v} does not fit a 32-bit float"
        )));
    }
    Ok(v as f32)
}

fn angle(name: &str, v: f64, max: f64) -> PyResult<f32> {
    let a = finite(name, v)?;
    if v.abs() > max {
        return Err(PyValueError::new_err(format!(
            "{name} = {v}° is out of range (±{max}°)"
        )));
    }
    Ok(a)
}

fn non_negative(name: &str, v: f64) -> PyResult<f32> {
    let x = finite(name, v)?;
    if v < 0.0 {
        return Err(PyValueError::new_err(format!(
            "{name} must be ≥ 0, got {v}"
        )));
    }
    Ok(x)
}

fn id(name: &str, v: i64) -> PyResult<u32> {
    u32::try_from(v)
        .map_err(|_| PyValueError::new_err(format!("{name} must be in 0..={}, got {v}", u32::MAX)))
}

/// The base class of every command. Send one with `Agent.send(command)`.
#[pyclass(module = "vrsync._vrsync", name = "Command", subclass, frozen)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyCommand {
    pub(crate) command: Command,
}

#[pymethods]
impl PyCommand {
    /// The command's short name as in logs and recordings (`"move"`, `"turn"`, …).
    #[getter]
    fn name(&self) -> &'static str {
        self.command.name()
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<PyCommand>()
            .is_ok_and(|o| o.get().command == self.command)
    }

    // The command with its parameters by name (`Move(heading_deg=90, distance_m=0.5)`):
    // the catalogue's spelling (`Command`'s `Display`).
    fn __repr__(&self) -> String {
        self.command.to_string()
    }
}

fn sub<T>(me: T, base: PyCommand) -> PyClassInitializer<T>
where
    T: PyClass<BaseType = PyCommand>,
{
    PyClassInitializer::from(base).add_subclass(me)
}

/// Walk towards `heading_deg` (world frame, 0 = +z, clockwise seen from above) for
/// `distance_m` metres.
#[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
pub(crate) struct Move {
    heading_deg: f32,
    distance_m: f32,
}

#[pymethods]
impl Move {
    #[new]
    fn new(heading_deg: f64, distance_m: f64) -> PyResult<PyClassInitializer<Self>> {
        let heading_deg = angle("heading_deg", heading_deg, MAX_ANGLE_DEG)?;
        let distance_m = non_negative("distance_m", distance_m)?;
        Ok(sub(
            Self {
                heading_deg,
                distance_m,
            },
            PyCommand {
                command: Command::Move {
                    heading_deg,
                    distance: distance_m,
                },
            },
        ))
    }
}

/// Turn in place by `angle_deg` (positive = clockwise seen from above).
#[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
pub(crate) struct Turn {
    angle_deg: f32,
}

#[pymethods]
impl Turn {
    #[new]
    fn new(angle_deg: f64) -> PyResult<PyClassInitializer<Self>> {
        let angle_deg = angle("angle_deg", angle_deg, MAX_ANGLE_DEG)?;
        Ok(sub(
            Self { angle_deg },
            PyCommand {
                command: Command::Turn { angle_deg },
            },
        ))
    }
}

fn point(x: f64, y: f64, z: f64) -> PyResult<Vec3> {
    Ok(Vec3::new(finite("x", x)?, finite("y", y)?, finite("z", z)?))
}

/// Commands on a world point (`x`, `y`, `z`) in metres.
macro_rules! point_command {
    ($($(#[$doc:meta])* $cls:ident => $variant:ident;)*) => {$(
        $(#[$doc])*
        #[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
        pub(crate) struct $cls {
            x: f32,
            y: f32,
            z: f32,
        }

        #[pymethods]
        impl $cls {
            #[new]
            fn new(x: f64, y: f64, z: f64) -> PyResult<PyClassInitializer<Self>> {
                let target = point(x, y, z)?;
                let (x, y, z) = (target.x, target.y, target.z);
                Ok(sub(Self { x, y, z }, PyCommand { command: Command::$variant { target } }))
            }
        }
    )*};
}

point_command! {
    /// Walk in a straight line to the world position (`x`, `y`, `z`) in metres.
    MoveTo => MoveTo;
    /// Fixate the world point (`x`, `y`, `z`) in metres with both eyes.
    EyeFixation => EyeFixation;
}

/// Move the eyes: pan of each eye and tilt of both, in degrees.
#[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
pub(crate) struct EyeMovement {
    pan_left_deg: f32,
    pan_right_deg: f32,
    tilt_deg: f32,
}

#[pymethods]
impl EyeMovement {
    #[new]
    #[pyo3(signature = (pan_left_deg, pan_right_deg, tilt_deg = 0.0))]
    fn new(
        pan_left_deg: f64,
        pan_right_deg: f64,
        tilt_deg: f64,
    ) -> PyResult<PyClassInitializer<Self>> {
        let pan_left_deg = angle("pan_left_deg", pan_left_deg, MAX_EYE_DEG)?;
        let pan_right_deg = angle("pan_right_deg", pan_right_deg, MAX_EYE_DEG)?;
        let tilt_deg = angle("tilt_deg", tilt_deg, MAX_EYE_DEG)?;
        Ok(sub(
            Self {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            },
            PyCommand {
                command: Command::EyeMovement {
                    pan_left_deg,
                    pan_right_deg,
                    tilt_deg,
                },
            },
        ))
    }
}

/// Commands without arguments.
macro_rules! unit_command {
    ($($(#[$doc:meta])* $cls:ident => $variant:ident;)*) => {$(
        $(#[$doc])*
        #[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen)]
        pub(crate) struct $cls;

        #[pymethods]
        impl $cls {
            #[new]
            fn new() -> PyClassInitializer<Self> {
                sub(Self, PyCommand { command: Command::$variant })
            }
        }
    )*};
}

unit_command! {
    /// Cancel the running movement.
    CancelMove => CancelMove;
    /// Release the grasped object.
    GraspRelease => GraspRelease;
}

/// Commands on an object id.
macro_rules! id_command {
    ($($(#[$doc:meta])* $cls:ident => $variant:ident;)*) => {$(
        $(#[$doc])*
        #[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
        pub(crate) struct $cls {
            object_id: u32,
        }

        #[pymethods]
        impl $cls {
            #[new]
            fn new(object_id: i64) -> PyResult<PyClassInitializer<Self>> {
                let object_id = id("object_id", object_id)?;
                Ok(sub(Self { object_id }, PyCommand { command: Command::$variant { object_id } }))
            }
        }
    )*};
}

id_command! {
    /// Grasp the object with id `object_id`.
    GraspId => GraspId;
    /// Point at the object with id `object_id`.
    PointId => PointId;
    /// Interact with the object with id `object_id`.
    InteractId => InteractId;
}

/// Commands on a left-eye image position.
macro_rules! pos_command {
    ($($(#[$doc:meta])* $cls:ident => $variant:ident;)*) => {$(
        $(#[$doc])*
        #[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
        pub(crate) struct $cls {
            x_px: f32,
            y_px: f32,
        }

        #[pymethods]
        impl $cls {
            #[new]
            fn new(x_px: f64, y_px: f64) -> PyResult<PyClassInitializer<Self>> {
                let x_px = non_negative("x_px", x_px)?;
                let y_px = non_negative("y_px", y_px)?;
                Ok(sub(Self { x_px, y_px }, PyCommand { command: Command::$variant { x_px, y_px } }))
            }
        }
    )*};
}

pos_command! {
    /// Grasp what is seen at left-eye pixel (`x_px`, `y_px`); 0/0 is the top left.
    GraspPos => GraspPos;
    /// Point at what is seen at left-eye pixel (`x_px`, `y_px`).
    PointPos => PointPos;
    /// Interact with what is seen at left-eye pixel (`x_px`, `y_px`).
    InteractPos => InteractPos;
}

/// Commands with a reset type.
macro_rules! reset_command {
    ($($(#[$doc:meta])* $cls:ident => $variant:ident;)*) => {$(
        $(#[$doc])*
        #[pyclass(module = "vrsync._vrsync", extends = PyCommand, frozen, get_all)]
        pub(crate) struct $cls {
            reset_type: u32,
        }

        #[pymethods]
        impl $cls {
            #[new]
            #[pyo3(signature = (reset_type = 0))]
            fn new(reset_type: i64) -> PyResult<PyClassInitializer<Self>> {
                let reset_type = id("reset_type", reset_type)?;
                Ok(sub(Self { reset_type }, PyCommand { command: Command::$variant { reset_type } }))
            }
        }
    )*};
}

reset_command! {
    /// Reset the environment (`reset_type` 0 = the default reset).
    EnvironmentReset => EnvironmentReset;
    /// Reset the trial (`reset_type` 0 = the default reset).
    TrialReset => TrialReset;
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCommand>()?;
    m.add_class::<Move>()?;
    m.add_class::<Turn>()?;
    m.add_class::<MoveTo>()?;
    m.add_class::<CancelMove>()?;
    m.add_class::<EyeMovement>()?;
    m.add_class::<EyeFixation>()?;
    m.add_class::<GraspId>()?;
    m.add_class::<GraspPos>()?;
    m.add_class::<PointId>()?;
    m.add_class::<PointPos>()?;
    m.add_class::<InteractId>()?;
    m.add_class::<InteractPos>()?;
    m.add_class::<GraspRelease>()?;
    m.add_class::<EnvironmentReset>()?;
    m.add_class::<TrialReset>()?;
    m.add_class::<MoveAhead>()?;
    Ok(())
}

/// Walk `distance_m` metres towards the body's *current* heading plus
/// `heading_offset_deg` (an entry of an action table: resolved per agent and cycle from
/// the frame the action answers, as `Move(heading_deg=frame.pose.heading_deg +
/// heading_offset_deg, distance_m=distance_m)`). Calling it with a frame gives that
/// `Move`. Not a `Command`: `Agent.send` takes the resolved `Move`.
#[pyclass(module = "vrsync._vrsync", name = "MoveAhead", frozen, get_all, eq)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MoveAhead {
    pub(crate) distance_m: f32,
    pub(crate) heading_offset_deg: f32,
}

impl MoveAhead {
    /// The `Move` for a body with heading `heading_deg`.
    pub(crate) fn resolve(&self, heading_deg: f32) -> Command {
        Command::Move {
            heading_deg: (heading_deg + self.heading_offset_deg).rem_euclid(360.0),
            distance: self.distance_m,
        }
    }
}

#[pymethods]
impl MoveAhead {
    #[new]
    #[pyo3(signature = (distance_m, heading_offset_deg = 0.0))]
    fn new(distance_m: f64, heading_offset_deg: f64) -> PyResult<Self> {
        Ok(Self {
            distance_m: non_negative("distance_m", distance_m)?,
            heading_offset_deg: angle("heading_offset_deg", heading_offset_deg, MAX_ANGLE_DEG)?,
        })
    }

    /// The `Move` this entry means for `frame` (its body's heading plus the offset).
    fn __call__(
        &self,
        py: Python<'_>,
        frame: PyRef<'_, crate::frame::PyFrame>,
    ) -> PyResult<Py<PyAny>> {
        let r = frame.header().pose.rotation;
        let cmd = self.resolve(heading_deg(r));
        let Command::Move {
            heading_deg,
            distance,
        } = cmd
        else {
            return Err(PyValueError::new_err("MoveAhead resolves to a Move"));
        };
        let m = Bound::new(
            py,
            sub(
                Move {
                    heading_deg,
                    distance_m: distance,
                },
                PyCommand { command: cmd },
            ),
        )?;
        Ok(m.into_any().unbind())
    }

    fn __repr__(&self) -> String {
        format!(
            "MoveAhead(distance_m={}, heading_offset_deg={})",
            self.distance_m, self.heading_offset_deg
        )
    }
}

/// The heading (yaw about +y, 0 ≤ h < 360, 0 faces +z) of the rotation quaternion
/// (x, y, z, w): `Pose.heading_deg`.
pub(crate) fn heading_deg(rotation: [f32; 4]) -> f32 {
    (2.0 * rotation[1].atan2(rotation[3]))
        .to_degrees()
        .rem_euclid(360.0)
}

/// `command` as an instance of its class (`Move`, `Turn`, …), as `Agent.send` takes it:
/// what `vrsync.Host` reports an agent sent. Not checked again: the values are what the
/// agent sent (finite, as decoding checked), and range checks are the simulator's.
pub(crate) fn to_object(py: Python<'_>, command: Command) -> PyResult<Bound<'_, PyAny>> {
    fn new<'py, T>(py: Python<'py>, me: T, command: Command) -> PyResult<Bound<'py, PyAny>>
    where
        T: PyClass<BaseType = PyCommand>,
    {
        Ok(Bound::new(py, sub(me, PyCommand { command }))?.into_any())
    }
    use Command as C;
    match command {
        C::Move {
            heading_deg,
            distance,
        } => new(
            py,
            Move {
                heading_deg,
                distance_m: distance,
            },
            command,
        ),
        C::Turn { angle_deg } => new(py, Turn { angle_deg }, command),
        C::MoveTo { target: t } => new(
            py,
            MoveTo {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            command,
        ),
        C::CancelMove => new(py, CancelMove, command),
        C::EyeMovement {
            pan_left_deg,
            pan_right_deg,
            tilt_deg,
        } => new(
            py,
            EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            },
            command,
        ),
        C::EyeFixation { target: t } => new(
            py,
            EyeFixation {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            command,
        ),
        C::GraspId { object_id } => new(py, GraspId { object_id }, command),
        C::GraspPos { x_px, y_px } => new(py, GraspPos { x_px, y_px }, command),
        C::PointId { object_id } => new(py, PointId { object_id }, command),
        C::PointPos { x_px, y_px } => new(py, PointPos { x_px, y_px }, command),
        C::InteractId { object_id } => new(py, InteractId { object_id }, command),
        C::InteractPos { x_px, y_px } => new(py, InteractPos { x_px, y_px }, command),
        C::GraspRelease => new(py, GraspRelease, command),
        C::EnvironmentReset { reset_type } => new(py, EnvironmentReset { reset_type }, command),
        C::TrialReset { reset_type } => new(py, TrialReset { reset_type }, command),
    }
}
