/*
 * Prints the size of every struct of vrsync_host.h, the offset of every field and the
 * value of every enum constant, one per line, in the format VrsyncTests.exe layout prints
 * them from the C# side: test.sh compares the two (the C# binding and the C header must
 * agree field by field, not only in size).
 */
#include <stddef.h>
#include <stdio.h>

#include "vrsync_host.h"

#define S(T) printf("%s sizeof %zu\n", #T, sizeof(T))
#define F(T, f) printf("%s.%s %zu\n", #T, #f, offsetof(T, f))
#define E(c) printf("%s %lld\n", #c, (long long)(c))

int main(void) {
    S(vrs_host_pose_t);
    F(vrs_host_pose_t, position);
    F(vrs_host_pose_t, rotation);
    S(vrs_host_grid_position_t);
    F(vrs_host_grid_position_t, position);
    F(vrs_host_grid_position_t, rotation_deg);
    S(vrs_host_head_motion_t);
    F(vrs_host_head_motion_t, velocity);
    F(vrs_host_head_motion_t, acceleration);
    F(vrs_host_head_motion_t, angular_velocity_deg);
    F(vrs_host_head_motion_t, angular_acceleration_deg);
    S(vrs_host_eye_position_t);
    F(vrs_host_eye_position_t, rotation_deg);
    F(vrs_host_eye_position_t, rotation_velocity_deg);
    S(vrs_host_action_status_t);
    F(vrs_host_action_status_t, action_id);
    F(vrs_host_action_status_t, state);
    S(vrs_host_collision_t);
    F(vrs_host_collision_t, action_id);
    F(vrs_host_collision_t, collider_id);
    S(vrs_host_sensors_t);
    F(vrs_host_sensors_t, pose);
    F(vrs_host_sensors_t, reward);
    F(vrs_host_sensors_t, grid);
    F(vrs_host_sensors_t, head_motion);
    F(vrs_host_sensors_t, eye);
    F(vrs_host_sensors_t, status_count);
    F(vrs_host_sensors_t, collision_count);
    F(vrs_host_sensors_t, statuses);
    F(vrs_host_sensors_t, collisions);
    S(vrs_host_frame_t);
    F(vrs_host_frame_t, cycle);
    F(vrs_host_frame_t, sim_time_ns);
    F(vrs_host_frame_t, agent_id);
    F(vrs_host_frame_t, image_count);
    S(vrs_host_image_t);
    F(vrs_host_image_t, data);
    F(vrs_host_image_t, len);
    F(vrs_host_image_t, stride);
    F(vrs_host_image_t, width);
    F(vrs_host_image_t, height);
    F(vrs_host_image_t, format);
    F(vrs_host_image_t, camera);
    F(vrs_host_image_t, name);
    S(vrs_host_camera_t);
    F(vrs_host_camera_t, len);
    F(vrs_host_camera_t, stride);
    F(vrs_host_camera_t, width);
    F(vrs_host_camera_t, height);
    F(vrs_host_camera_t, format);
    F(vrs_host_camera_t, fov_horizontal_deg);
    F(vrs_host_camera_t, fov_vertical_deg);
    F(vrs_host_camera_t, name);
    S(vrs_host_agent_info_t);
    F(vrs_host_agent_info_t, agent_id);
    F(vrs_host_agent_info_t, camera_count);
    F(vrs_host_agent_info_t, connected);
    F(vrs_host_agent_info_t, reserved);
    S(vrs_host_info_t);
    F(vrs_host_info_t, cycle);
    F(vrs_host_info_t, sim_time_ns);
    F(vrs_host_info_t, simulation_time_per_frame_ns);
    F(vrs_host_info_t, stop_timeout_ns);
    F(vrs_host_info_t, connect_timeout_ns);
    F(vrs_host_info_t, agent_count);
    F(vrs_host_info_t, sync_mode);
    F(vrs_host_info_t, transport);
    F(vrs_host_info_t, tcp_port);
    F(vrs_host_info_t, max_commands_per_cycle);
    F(vrs_host_info_t, protocol_version);
    S(vrs_host_cycle_t);
    F(vrs_host_cycle_t, cycle);
    F(vrs_host_cycle_t, sim_time_ns);
    F(vrs_host_cycle_t, agent_count);
    F(vrs_host_cycle_t, timed_out_agents);
    F(vrs_host_cycle_t, late_batches);
    F(vrs_host_cycle_t, command_count);
    F(vrs_host_cycle_t, evicted_agents);
    F(vrs_host_cycle_t, rejoined_agents);
    S(vrs_host_command_t);
    F(vrs_host_command_t, kind);
    F(vrs_host_command_t, action_id);
    F(vrs_host_command_t, object_id);
    F(vrs_host_command_t, reserved);
    F(vrs_host_command_t, args);
    S(vrs_host_agent_report_t);
    F(vrs_host_agent_report_t, agent_id);
    F(vrs_host_agent_report_t, outcome);
    F(vrs_host_agent_report_t, command_count);
    F(vrs_host_agent_report_t, reserved);
    F(vrs_host_agent_report_t, commands);
    F(vrs_host_agent_report_t, read_cycle);
    F(vrs_host_agent_report_t, evicted);
    F(vrs_host_agent_report_t, rejoined);
    S(vrs_host_stats_t);
    F(vrs_host_stats_t, cycles);
    F(vrs_host_stats_t, stop_timeouts);
    F(vrs_host_stats_t, agent_timeouts);
    F(vrs_host_stats_t, late_batches);
    F(vrs_host_stats_t, future_batches);
    F(vrs_host_stats_t, commands_received);
    F(vrs_host_stats_t, commands_overflowed);
    F(vrs_host_stats_t, frames_undelivered);
    F(vrs_host_stats_t, evictions);
    F(vrs_host_stats_t, rejoins);
    F(vrs_host_stats_t, frames_delivered);
    F(vrs_host_stats_t, frames_read);
    F(vrs_host_stats_t, statuses_dropped);
    F(vrs_host_stats_t, collisions_dropped);

    E(VRS_HOST_OK);
    E(VRS_HOST_TIMEOUT);
    E(VRS_HOST_DEFERRED);
    E(VRS_HOST_ERROR_INVALID_ARGUMENT);
    E(VRS_HOST_ERROR_INVALID_HANDLE);
    E(VRS_HOST_ERROR_WRONG_THREAD);
    E(VRS_HOST_ERROR_CONFIG);
    E(VRS_HOST_ERROR_CREATE);
    E(VRS_HOST_ERROR_UNKNOWN_AGENT);
    E(VRS_HOST_ERROR_WRONG_STATE);
    E(VRS_HOST_ERROR_NO_FRAME);
    E(VRS_HOST_ERROR_OUT_OF_RANGE);
    E(VRS_HOST_ERROR_AGENT_LOST);
    E(VRS_HOST_ERROR_TRANSPORT);
    E(VRS_HOST_ERROR_TERMINATED);
    E(VRS_HOST_ERROR_OTHER);
    E(VRS_HOST_ERROR_PANIC);
    E(VRS_HOST_PIXEL_FORMAT_RGB8);
    E(VRS_HOST_PIXEL_FORMAT_RGBA8);
    E(VRS_HOST_PIXEL_FORMAT_GRAY8);
    E(VRS_HOST_PIXEL_FORMAT_DEPTH32F);
    E(VRS_HOST_ACTION_IN_EXECUTION);
    E(VRS_HOST_ACTION_FINISHED);
    E(VRS_HOST_ACTION_ABORTED);
    E(VRS_HOST_ACTION_WALKING);
    E(VRS_HOST_ACTION_ROTATING);
    E(VRS_HOST_ACTION_WALKING_ROTATING);
    E(VRS_HOST_OUTCOME_NOT_AWAITED);
    E(VRS_HOST_OUTCOME_STOPPED);
    E(VRS_HOST_OUTCOME_TIMED_OUT);
    E(VRS_HOST_OUTCOME_ASYNC);
    E(VRS_HOST_OUTCOME_EVICTED);
    E(VRS_HOST_OUTCOME_LEFT);
    E(VRS_HOST_OUTCOME_OTHER);
    E(VRS_HOST_COMMAND_MOVE);
    E(VRS_HOST_COMMAND_TURN);
    E(VRS_HOST_COMMAND_MOVE_TO);
    E(VRS_HOST_COMMAND_CANCEL_MOVE);
    E(VRS_HOST_COMMAND_EYE_MOVEMENT);
    E(VRS_HOST_COMMAND_EYE_FIXATION);
    E(VRS_HOST_COMMAND_GRASP_ID);
    E(VRS_HOST_COMMAND_GRASP_POS);
    E(VRS_HOST_COMMAND_POINT_ID);
    E(VRS_HOST_COMMAND_POINT_POS);
    E(VRS_HOST_COMMAND_INTERACT_ID);
    E(VRS_HOST_COMMAND_INTERACT_POS);
    E(VRS_HOST_COMMAND_GRASP_RELEASE);
    E(VRS_HOST_COMMAND_ENVIRONMENT_RESET);
    E(VRS_HOST_COMMAND_TRIAL_RESET);
    E(VRS_HOST_TRANSPORT_SHM);
    E(VRS_HOST_TRANSPORT_TCP);
    E(VRS_HOST_TRANSPORT_ZENOH);
    E(VRS_HOST_TRANSPORT_LEGACY);
    E(VRS_HOST_MAX_STATUSES);
    E(VRS_HOST_MAX_COLLISIONS);
    E(VRS_HOST_MAX_IMAGES);
    E(VRS_HOST_CAMERA_NAME_SIZE);
    return 0;
}
