//! The exported functions that queue motor commands, and the stop that sends them.

use vrsync_transport::Command;

use super::calls::{command_from, send_impl, send_with_id_impl, stop_impl};
use vrsync_cabi::ArgError;

use super::state::boundary;
use super::types::*;

/// Queues a command of any kind with a fresh action id, written to `*out_action_id` if
/// not NULL. Commands go out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (unknown kind, NaN or infinite argument, NULL command),
/// `VRS_ERROR_QUEUE_FULL`, handle errors.
///
/// # Safety
/// `command` is NULL or points to a readable `vrs_command_t`; `out_action_id` is NULL or
/// valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send(
    agent: *mut vrs_agent_t,
    command: *const vrs_command_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        let command = if command.is_null() {
            Err(ArgError::Null("command").into())
        } else {
            // SAFETY: non-null and readable by the caller's contract; any bit pattern is
            // a valid vrs_command_t.
            command_from(unsafe { &*command })
        };
        send_impl(agent, command, out_action_id)
    })
}

/// Queues a command with an action id of the caller's choice (statuses and collisions
/// quote it).
///
/// # Errors
/// As [`vrs_agent_send`].
///
/// # Safety
/// `command` is NULL or points to a readable `vrs_command_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_with_id(
    agent: *mut vrs_agent_t,
    action_id: u32,
    command: *const vrs_command_t,
) -> vrs_status_t {
    boundary(|| send_with_id_impl(agent, action_id, command))
}

/// Walk towards `heading_deg` (world frame, 0..360) for `distance_m` metres (the
/// original `sendAgentMovement(degree, distance)`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_move(
    agent: *mut vrs_agent_t,
    heading_deg: f32,
    distance_m: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::Move {
                heading_deg,
                distance: distance_m,
            }),
            out_action_id,
        )
    })
}

/// Turn in place by `angle_deg` degrees (positive: clockwise seen from above; the original
/// `sendAgentTurn(degree)`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_turn(
    agent: *mut vrs_agent_t,
    angle_deg: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::Turn { angle_deg }), out_action_id))
}

/// Walk in a straight line to the world position (`x`, `y`, `z`) in metres.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_move_to(
    agent: *mut vrs_agent_t,
    x: f32,
    y: f32,
    z: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::MoveTo {
                target: glam::Vec3::new(x, y, z),
            }),
            out_action_id,
        )
    })
}

/// Cancel the running movement.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_cancel_move(
    agent: *mut vrs_agent_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::CancelMove), out_action_id))
}

/// Move the eyes: pan of the left and right eye and tilt of both, in degrees.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_eye_movement(
    agent: *mut vrs_agent_t,
    pan_left_deg: f32,
    pan_right_deg: f32,
    tilt_deg: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            }),
            out_action_id,
        )
    })
}

/// Fixate both eyes on the world point (`x`, `y`, `z`) in metres.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_eye_fixation(
    agent: *mut vrs_agent_t,
    x: f32,
    y: f32,
    z: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EyeFixation {
                target: glam::Vec3::new(x, y, z),
            }),
            out_action_id,
        )
    })
}

/// Grasp the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspId { object_id }), out_action_id))
}

/// Grasp what is seen at left-eye pixel (`x_px`, `y_px`), 0/0 = top left.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspPos { x_px, y_px }), out_action_id))
}

/// Point at the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_point_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::PointId { object_id }), out_action_id))
}

/// Point at what is seen at left-eye pixel (`x_px`, `y_px`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_point_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::PointPos { x_px, y_px }), out_action_id))
}

/// Interact with the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_interact_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::InteractId { object_id }), out_action_id))
}

/// Interact with what is seen at left-eye pixel (`x_px`, `y_px`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_interact_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::InteractPos { x_px, y_px }),
            out_action_id,
        )
    })
}

/// Release the grasped object.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_release(
    agent: *mut vrs_agent_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspRelease), out_action_id))
}

/// Reset the environment (`reset_type` 0 = default).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_environment_reset(
    agent: *mut vrs_agent_t,
    reset_type: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EnvironmentReset { reset_type }),
            out_action_id,
        )
    })
}

/// Reset the trial (`reset_type` 0 = default).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_trial_reset(
    agent: *mut vrs_agent_t,
    reset_type: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::TrialReset { reset_type }), out_action_id))
}

/// Ends this agent's cycle: sends the queued commands with the *stop* for the cycle of
/// the newest frame, and ends the current frame (its image pointers become invalid).
///
/// # Errors
/// `VRS_SESSION_CLOSED` (the host already ended the run: not an error),
/// `VRS_ERROR_NO_FRAME` (no frame received yet), `VRS_ERROR_ALREADY_STOPPED`,
/// `VRS_ERROR_TRANSPORT`, handle errors.
///
/// # Safety
/// Any handle value may be passed (it is looked up, never dereferenced).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_stop(agent: *mut vrs_agent_t) -> vrs_status_t {
    boundary(|| stop_impl(agent))
}
