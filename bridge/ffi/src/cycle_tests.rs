//! One agent's three cycles through the host C ABI, called from Rust as a C program calls
//! it, with a real agent (the Rust SDK) on another thread: the host's description of its
//! agent and cameras, each call out of order refused with its status and message, and per
//! cycle a loaned frame written in place, its sensors published, the agent's commands in
//! the collected report; the statistics at the end.

use std::ffi::{CStr, CString};
use std::mem::MaybeUninit;
use std::path::PathBuf;
use std::ptr;
use std::thread::JoinHandle;
use std::time::Duration;

use vrsync_agent::Command;

use crate::tests::{connect_agent, create, last_error, wait_for_close, write_config};
use crate::types::vrs_host_status_t::*;
use crate::*;

/// What the agent thread saw in one cycle.
#[derive(Debug, Clone, PartialEq)]
struct Seen {
    cycle: u64,
    position: [f32; 3],
    rotation: [f32; 4],
    reward: f32,
    statuses: Vec<(u32, u32)>,
    collisions: Vec<(u32, u32)>,
    left_first: u8,
    right_last: u8,
    previous_rejected: u32,
}

#[test]
fn cycles_through_the_c_abi_with_a_real_agent() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "cycle", 1, 5.0);
    let host = create(&path);
    let agent = spawn_agent(path.clone());
    // SAFETY: `host` is a live handle from create until the destroy below.
    unsafe {
        describes_its_agent(host);
        refuses_calls_out_of_order(host);
        for n in 0..3u32 {
            loan_and_fill(host, n);
            publish_sensors(host, n);
            collect_and_end(host, n);
        }
        counted_three_cycles(host);
    }
    // SAFETY: a handle from create.
    assert_eq!(unsafe { vrs_host_destroy(host) }, VRS_HOST_OK);
    let seen = agent.join().unwrap();
    assert_eq!(seen.len(), 3);
    for (n, s) in seen.iter().enumerate() {
        assert_eq!(s.cycle, n as u64);
        assert_eq!(s.position, [n as f32, 0.0, 2.0]);
        assert_eq!(s.reward, 0.25 * n as f32);
        let rotation = if n == 2 {
            [0.0, 0.0, 0.0, 1.0]
        } else {
            [0.0, 1.0, 0.0, 0.0]
        };
        assert_eq!(s.rotation, rotation);
        assert_eq!(s.statuses, vec![(100, 3)]);
        let collisions = if n == 1 { vec![(100, 77)] } else { vec![] };
        assert_eq!(s.collisions, collisions);
        assert_eq!((s.left_first, s.right_last), (10 + n as u8, 200 + n as u8));
        assert_eq!(s.previous_rejected, n.saturating_sub(1) as u32);
    }
    // SAFETY: a destroyed handle: a double free.
    unsafe {
        assert_eq!(vrs_host_destroy(host), VRS_HOST_ERROR_INVALID_HANDLE);
        assert!(
            last_error().contains("already destroyed"),
            "{}",
            last_error()
        );
    }
}

/// Agent 0 of the config at `agent_path`, on its own thread: three cycles, each answered
/// with a move (action id 100) and a turn; then it waits for the host to close the session.
fn spawn_agent(agent_path: PathBuf) -> JoinHandle<Vec<Seen>> {
    std::thread::spawn(move || {
        let mut agent = connect_agent(&agent_path, 0);
        let mut seen = Vec::new();
        for _ in 0..3 {
            let frame = agent.wait_start(Some(Duration::from_secs(5))).unwrap();
            let h = frame.header();
            seen.push(Seen {
                cycle: frame.cycle(),
                position: h.pose.position,
                rotation: h.pose.rotation,
                reward: h.reward,
                statuses: frame
                    .statuses()
                    .iter()
                    .map(|s| (s.action_id, s.state))
                    .collect(),
                collisions: frame
                    .collisions()
                    .iter()
                    .map(|c| (c.action_id, c.collider_id))
                    .collect(),
                left_first: frame.image_by_name("left").unwrap().data()[0],
                right_last: *frame.image_by_name("right").unwrap().data().last().unwrap(),
                previous_rejected: h.previous_rejected,
            });
            drop(frame);
            agent
                .send_with_id(
                    100,
                    Command::Move {
                        heading_deg: 90.0,
                        distance: 1.5,
                    },
                )
                .unwrap();
            agent.send(Command::Turn { angle_deg: -30.0 }).unwrap();
            agent.stop().unwrap();
        }
        // Stay connected until the host closes the session: an agent that leaves is
        // evicted, and that would race with the host's last collect.
        wait_for_close(&mut agent);
        seen
    })
}

/// Waits for agent 0; the host's, the agent's and a camera's descriptions.
///
/// # Safety
/// `host` is a live handle.
unsafe fn describes_its_agent(host: *mut vrs_host_t) {
    let mut missing = [u32::MAX; 4];
    let mut missing_count = 99u32;
    let mut info = MaybeUninit::<vrs_host_info_t>::uninit();
    let mut agent_info = MaybeUninit::<vrs_host_agent_info_t>::uninit();
    let mut camera = MaybeUninit::<vrs_host_camera_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its use.
    unsafe {
        assert_eq!(
            vrs_host_wait_for_agents(
                host,
                5000,
                missing.as_mut_ptr(),
                missing.len() as u32,
                &mut missing_count
            ),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        assert_eq!(missing_count, 0);
        assert_eq!(vrs_host_info(host, info.as_mut_ptr()), VRS_HOST_OK);
        let i = info.assume_init();
        assert_eq!((i.agent_count, i.sync_mode, i.cycle), (1, 1, 0));
        assert_eq!(i.simulation_time_per_frame_ns, 100_000_000);
        assert_eq!(i.stop_timeout_ns, 5_000_000_000);
        assert_eq!(i.transport, vrs_host_transport_t::VRS_HOST_TRANSPORT_SHM);
        assert_eq!(
            vrs_host_agent_info(host, 0, agent_info.as_mut_ptr()),
            VRS_HOST_OK
        );
        let a = agent_info.assume_init();
        assert_eq!((a.agent_id, a.camera_count, a.connected), (0, 2, 1));
        assert_eq!(
            vrs_host_agent_info(host, 1, agent_info.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE
        );
        assert_eq!(
            vrs_host_camera(host, 0, 1, camera.as_mut_ptr()),
            VRS_HOST_OK
        );
        let c = camera.assume_init();
        assert_eq!((c.width, c.height, c.stride, c.len), (8, 4, 8, 32));
        assert_eq!(
            c.format,
            vrs_host_pixel_format_t::VRS_HOST_PIXEL_FORMAT_GRAY8
        );
        assert_eq!(CStr::from_ptr(c.name.as_ptr()).to_str().unwrap(), "right");
        assert_eq!(
            vrs_host_camera(host, 7, 0, camera.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_AGENT
        );
    }
}

/// Nothing loaned, nothing started: the calls that belong later are refused.
///
/// # Safety
/// `host` is a live handle.
unsafe fn refuses_calls_out_of_order(host: *mut vrs_host_t) {
    let mut frame = MaybeUninit::<vrs_host_frame_t>::uninit();
    let mut cycle = MaybeUninit::<vrs_host_cycle_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its use.
    unsafe {
        // Out of order: nothing loaned, nothing started.
        assert_eq!(
            vrs_host_publish(host, 0, ptr::null()),
            VRS_HOST_ERROR_NO_FRAME
        );
        assert_eq!(
            vrs_host_collect(host, cycle.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE
        );
        assert!(
            last_error().contains("belongs after vrs_host_start"),
            "{}",
            last_error()
        );
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_ERROR_WRONG_STATE);
        assert_eq!(
            vrs_host_loan_frame(host, 3, frame.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_AGENT
        );
    }
}

/// Cycle `n`: loans agent 0's frame and fills its images (left `10 + n`, right `200 + n`).
///
/// # Safety
/// `host` is a live handle.
unsafe fn loan_and_fill(host: *mut vrs_host_t, n: u32) {
    let mut frame = MaybeUninit::<vrs_host_frame_t>::uninit();
    let mut image = MaybeUninit::<vrs_host_image_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its
    // use; image writes stay within `len`.
    unsafe {
        assert_eq!(
            vrs_host_loan_frame(host, 0, frame.as_mut_ptr()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        let f = frame.assume_init();
        assert_eq!((f.cycle, f.agent_id, f.image_count), (u64::from(n), 0, 2));
        assert_eq!(f.sim_time_ns, u64::from(n) * 100_000_000);
        assert_eq!(
            vrs_host_loan_frame(host, 0, frame.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE,
            "a second loan is refused"
        );
        assert_eq!(
            vrs_host_frame_image(host, 0, 0, image.as_mut_ptr()),
            VRS_HOST_OK
        );
        let left = image.assume_init();
        assert_eq!(
            (left.width, left.height, left.stride, left.len),
            (8, 4, 24, 96)
        );
        assert_eq!(
            left.format,
            vrs_host_pixel_format_t::VRS_HOST_PIXEL_FORMAT_RGB8
        );
        std::slice::from_raw_parts_mut(left.data, left.len as usize).fill(10 + n as u8);
        let name = CString::new("right").unwrap();
        assert_eq!(
            vrs_host_frame_image_by_name(host, 0, name.as_ptr(), image.as_mut_ptr()),
            VRS_HOST_OK
        );
        let right = image.assume_init();
        assert_eq!(right.camera, 1);
        std::slice::from_raw_parts_mut(right.data, right.len as usize).fill(200 + n as u8);
        assert_eq!(
            vrs_host_frame_image(host, 0, 2, image.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE
        );
        let nope = CString::new("main").unwrap();
        assert_eq!(
            vrs_host_frame_image_by_name(host, 0, nope.as_ptr(), image.as_mut_ptr()),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
    }
}

/// Cycle `n`: invalid sensors are refused, the valid ones published, and the cycle
/// started.
///
/// # Safety
/// `host` is a live handle with agent 0's frame of cycle `n` loaned.
unsafe fn publish_sensors(host: *mut vrs_host_t, n: u32) {
    let mut frame = MaybeUninit::<vrs_host_frame_t>::uninit();
    let mut image = MaybeUninit::<vrs_host_image_t>::uninit();
    let mut report = MaybeUninit::<vrs_host_agent_report_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its use.
    unsafe {
        let mut sensors = vrs_host_sensors_t::default();
        sensors.pose.position = [n as f32, 0.0, 2.0];
        sensors.reward = 0.25 * n as f32;
        sensors.status_count = 1;
        sensors.statuses[0] = vrs_host_action_status_t {
            action_id: 100,
            state: vrs_host_action_state_t::VRS_HOST_ACTION_WALKING as u32,
        };
        if n == 2 {
            // A zero-initialised rotation arrives as the identity.
            sensors.pose.rotation = [0.0; 4];
        } else {
            sensors.pose.rotation = [0.0, 1.0, 0.0, 0.0];
        }
        if n == 1 {
            sensors.collision_count = 1;
            sensors.collisions[0] = vrs_host_collision_t {
                action_id: 100,
                collider_id: 77,
            };
        }
        // Invalid sensors are refused and the frame stays loaned.
        let mut bad = sensors;
        bad.status_count = 17;
        assert_eq!(
            vrs_host_publish(host, 0, &bad),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
        assert!(
            last_error().contains("status_count = 17"),
            "{}",
            last_error()
        );
        bad.status_count = 1;
        bad.statuses[0].state = 9;
        assert_eq!(
            vrs_host_publish(host, 0, &bad),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
        assert_eq!(
            vrs_host_start(host),
            VRS_HOST_ERROR_WRONG_STATE,
            "start with a loaned frame"
        );
        assert!(last_error().contains("[0]"), "{}", last_error());
        assert_eq!(
            vrs_host_publish(host, 0, &sensors),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        assert_eq!(
            vrs_host_frame_image(host, 0, 0, image.as_mut_ptr()),
            VRS_HOST_ERROR_NO_FRAME
        );
        assert_eq!(
            vrs_host_loan_frame(host, 0, frame.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE,
            "one frame per agent and cycle"
        );
        assert_eq!(vrs_host_start(host), VRS_HOST_OK);
        assert_eq!(vrs_host_start(host), VRS_HOST_ERROR_WRONG_STATE);
        assert_eq!(
            vrs_host_agent_report(host, 0, report.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE
        );
    }
}

/// Cycle `n`: the collected report holds agent 0's move and turn; the cycle ends.
///
/// # Safety
/// `host` is a live handle whose cycle `n` was started.
unsafe fn collect_and_end(host: *mut vrs_host_t, n: u32) {
    let mut frame = MaybeUninit::<vrs_host_frame_t>::uninit();
    let mut cycle = MaybeUninit::<vrs_host_cycle_t>::uninit();
    let mut report = MaybeUninit::<vrs_host_agent_report_t>::uninit();
    let mut command = MaybeUninit::<vrs_host_command_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its
    // use; `r.commands` holds `r.command_count` commands until the cycle ends.
    unsafe {
        assert_eq!(
            vrs_host_collect(host, cycle.as_mut_ptr()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        let c = cycle.assume_init();
        assert_eq!(c.cycle, u64::from(n));
        assert_eq!(
            (c.agent_count, c.timed_out_agents, c.command_count),
            (1, 0, 2)
        );
        assert_eq!(
            vrs_host_agent_report(host, 0, report.as_mut_ptr()),
            VRS_HOST_OK
        );
        let r = report.assume_init();
        assert_eq!(r.agent_id, 0);
        assert_eq!(r.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_STOPPED);
        assert_eq!(r.command_count, 2);
        // The agent's stop acknowledged the frame it answered.
        assert_eq!((r.read_cycle, r.evicted, r.rejoined), (i64::from(n), 0, 0));
        assert_eq!((c.evicted_agents, c.rejoined_agents), (0, 0));
        assert_eq!((c.left_agents, c.slow_agents, r.left, r.slow), (0, 0, 0, 0));
        let mut by_id = MaybeUninit::<vrs_host_agent_report_t>::uninit();
        assert_eq!(
            vrs_host_agent_report_by_id(host, 0, by_id.as_mut_ptr()),
            VRS_HOST_OK
        );
        let by_id = by_id.assume_init();
        assert_eq!((by_id.agent_id, by_id.commands), (0, r.commands));
        assert_eq!(
            vrs_host_agent_report_by_id(host, 9, report.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_AGENT
        );
        let commands = std::slice::from_raw_parts(r.commands, r.command_count as usize);
        assert_eq!(
            commands[0].kind,
            vrs_host_command_kind_t::VRS_HOST_COMMAND_MOVE as u32
        );
        assert_eq!(commands[0].action_id, 100);
        assert_eq!(commands[0].args[..2], [90.0, 1.5]);
        assert_eq!(
            commands[1].kind,
            vrs_host_command_kind_t::VRS_HOST_COMMAND_TURN as u32
        );
        assert_eq!(commands[1].args[0], -30.0);
        assert_eq!(
            vrs_host_command(host, 0, 1, command.as_mut_ptr()),
            VRS_HOST_OK
        );
        assert_eq!(command.assume_init(), commands[1]);
        assert_eq!(
            vrs_host_command(host, 0, 2, command.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE
        );
        assert_eq!(
            vrs_host_agent_report(host, 1, report.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE
        );
        assert_eq!(
            vrs_host_loan_frame(host, 0, frame.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE,
            "no loan before end_cycle"
        );
        assert!(
            last_error().contains("vrs_host_end_cycle"),
            "{}",
            last_error()
        );
        assert_eq!(vrs_host_set_rejected(host, 0, n), VRS_HOST_OK);
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_ERROR_WRONG_STATE);
    }
}

/// The statistics after three cycles.
///
/// # Safety
/// `host` is a live handle.
unsafe fn counted_three_cycles(host: *mut vrs_host_t) {
    // SAFETY: `host` is live (the caller's promise); the pointer is valid for its use.
    unsafe {
        let mut stats = MaybeUninit::<vrs_host_stats_t>::uninit();
        assert_eq!(vrs_host_stats(host, stats.as_mut_ptr()), VRS_HOST_OK);
        let s = stats.assume_init();
        assert_eq!((s.cycles, s.stop_timeouts, s.commands_received), (3, 0, 6));
        assert_eq!((s.frames_delivered, s.frames_read), (3, 3));
        assert_eq!((s.evictions, s.rejoins, s.statuses_dropped), (0, 0, 0));
        assert_eq!((s.slow_stops, s.leaves, s.peers_refused), (0, 0, 0));
    }
}
