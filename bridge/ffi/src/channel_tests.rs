//! The channel functions of the host C ABI, called from Rust as a C program calls them,
//! with a real agent (the Rust SDK) on another thread: vectors written through the ABI
//! reach the agent, the agent's actions reach the ABI's report, and every bad input has
//! its status and message.

use std::ffi::{CStr, c_char};
use std::mem::MaybeUninit;
use std::path::{Path, PathBuf};
use std::ptr;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::tests::{connect_agent, create, last_error, session, wait_for_close};
use crate::types::vrs_host_status_t::*;
use crate::vrs_host_action_kind_t::*;
use crate::*;

/// A one-agent config with two vectors and two actions.
fn write_config(dir: &Path, tag: &str) -> PathBuf {
    let toml = format!(
        "session = {:?}\n[sync]\nstop_timeout = 5.0\nconnect_timeout = 5.0\n\
         [transport]\nmax_commands_per_cycle = 8\n\
         [[agent]]\nid = 0\n\
         [[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n\
         [[agent.vector]]\nname = \"joints\"\nlen = 3\nlow = -1.0\nhigh = [1.0, 2.0, 3.0]\n\
         [[agent.vector]]\nname = \"vel\"\nlen = 5\n\
         [[agent.action]]\nname = \"torque\"\nlen = 5\nlow = -1.0\nhigh = 1.0\n\
         [[agent.action]]\nname = \"gear\"\nn = 3\n",
        session(tag)
    );
    let path = dir.join(format!("{tag}.toml"));
    std::fs::write(&path, toml).unwrap();
    path
}

fn name_of(name: &[c_char]) -> &str {
    // SAFETY: the library writes NUL-terminated names.
    unsafe { CStr::from_ptr(name.as_ptr()) }.to_str().unwrap()
}

/// `status` and a message containing every one of `words`.
#[track_caller]
fn refused(status: vrs_host_status_t, expected: vrs_host_status_t, words: &[&str]) {
    let message = last_error();
    assert_eq!(status, expected, "{message}");
    for w in words {
        assert!(message.contains(w), "{w:?} not in {message:?}");
    }
}

#[test]
fn channel_calls_with_null_or_made_up_handles_are_errors() {
    let bogus: *mut vrs_host_t = ptr::without_provenance_mut(0xdead_beef);
    let mut count = 0u32;
    let mut vector = MaybeUninit::<vrs_host_vector_t>::uninit();
    let mut vspec = MaybeUninit::<vrs_host_vector_spec_t>::uninit();
    let mut aspec = MaybeUninit::<vrs_host_action_spec_t>::uninit();
    let mut value = MaybeUninit::<vrs_host_action_value_t>::uninit();
    for h in [ptr::null_mut(), bogus] {
        // SAFETY: valid out pointers; the handle is never dereferenced.
        unsafe {
            let all = [
                vrs_host_channel_counts(h, 0, &mut count, &mut count),
                vrs_host_vector_spec(h, 0, 0, vspec.as_mut_ptr()),
                vrs_host_action_spec(h, 0, 0, aspec.as_mut_ptr()),
                vrs_host_frame_vector(h, 0, 0, vector.as_mut_ptr()),
                vrs_host_frame_vector_by_name(h, 0, c"joints".as_ptr(), vector.as_mut_ptr()),
                vrs_host_action(h, 0, 0, value.as_mut_ptr()),
                vrs_host_action_by_name(h, 0, c"torque".as_ptr(), value.as_mut_ptr()),
                vrs_host_actions_rejected(h, 0, &mut count),
            ];
            for st in all {
                assert_eq!(st, VRS_HOST_ERROR_INVALID_HANDLE, "{}", last_error());
            }
        }
        assert!(
            last_error().starts_with("invalid host handle"),
            "{}",
            last_error()
        );
    }
    assert_eq!(
        vrs_host_sizeof_vector(),
        std::mem::size_of::<vrs_host_vector_t>()
    );
    assert_eq!(vrs_host_sizeof_action_value(), 48);
    assert_eq!(vrs_host_sizeof_vector_spec(), 48);
    assert_eq!(vrs_host_sizeof_action_spec(), 56);
}

#[test]
fn channel_specs_come_from_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let host = create(&write_config(dir.path(), "specs"));
    let (mut vectors, mut actions) = (0u32, 0u32);
    let mut v = MaybeUninit::<vrs_host_vector_spec_t>::uninit();
    let mut a = MaybeUninit::<vrs_host_action_spec_t>::uninit();
    // SAFETY: every pointer below is valid for its use; bounds are read within `len`.
    unsafe {
        assert_eq!(
            vrs_host_channel_counts(host, 0, &mut vectors, &mut actions),
            VRS_HOST_OK
        );
        assert_eq!((vectors, actions), (2, 2));
        refused(
            vrs_host_channel_counts(host, 7, &mut vectors, ptr::null_mut()),
            VRS_HOST_ERROR_UNKNOWN_AGENT,
            &["agent 7"],
        );

        assert_eq!(
            vrs_host_vector_spec(host, 0, 0, v.as_mut_ptr()),
            VRS_HOST_OK
        );
        let joints = v.assume_init();
        assert_eq!(
            (name_of(&joints.name), joints.len, joints.index),
            ("joints", 3, 0)
        );
        assert_eq!(std::slice::from_raw_parts(joints.low, 3), [-1.0; 3]);
        assert_eq!(std::slice::from_raw_parts(joints.high, 3), [1.0, 2.0, 3.0]);
        assert_eq!(
            vrs_host_vector_spec(host, 0, 1, v.as_mut_ptr()),
            VRS_HOST_OK
        );
        let vel = v.assume_init();
        assert_eq!((name_of(&vel.name), vel.len), ("vel", 5));
        assert_eq!(std::slice::from_raw_parts(vel.high, 5), [f32::INFINITY; 5]);
        refused(
            vrs_host_vector_spec(host, 0, 2, v.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE,
            &["vector index 2"],
        );
        refused(
            vrs_host_vector_spec(host, 0, 0, ptr::null_mut()),
            VRS_HOST_ERROR_INVALID_ARGUMENT,
            &["out_spec"],
        );

        assert_eq!(
            vrs_host_action_spec(host, 0, 0, a.as_mut_ptr()),
            VRS_HOST_OK
        );
        let torque = a.assume_init();
        assert_eq!(torque.kind, VRS_HOST_ACTION_KIND_BOX);
        assert_eq!(
            (name_of(&torque.name), torque.len, torque.n),
            ("torque", 5, 0)
        );
        assert_eq!(std::slice::from_raw_parts(torque.low, 5), [-1.0; 5]);
        assert_eq!(std::slice::from_raw_parts(torque.high, 5), [1.0; 5]);
        assert_eq!(
            vrs_host_action_spec(host, 0, 1, a.as_mut_ptr()),
            VRS_HOST_OK
        );
        let gear = a.assume_init();
        assert_eq!(gear.kind, VRS_HOST_ACTION_KIND_DISCRETE);
        assert_eq!(
            (name_of(&gear.name), gear.len, gear.n, gear.index),
            ("gear", 0, 3, 1)
        );
        assert!(gear.low.is_null() && gear.high.is_null());
        refused(
            vrs_host_action_spec(host, 0, 2, a.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE,
            &["action index 2"],
        );
        assert_eq!(vrs_host_destroy(host), VRS_HOST_OK);
    }
}

/// What the agent read in cycle 0: each vector's values.
type Read = Vec<(String, Vec<f32>)>;

#[test]
fn vectors_reach_the_agent_and_actions_reach_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "cycle");
    let host = create(&path);
    let torque = [0.1f32, -0.2, 0.3, -0.4, 1.0];
    let agent = spawn_agent(path.clone(), torque);
    // SAFETY: `host` is a live handle from create until the destroy below.
    unsafe {
        writes_vectors_and_collects(host);
        reads_the_actions(host, &torque);
        reports_no_action_when_none_was_sent(host);
        assert_eq!(vrs_host_destroy(host), VRS_HOST_OK);
    }
    let read = agent.join().unwrap();
    assert_eq!(
        read,
        [
            ("joints".to_owned(), vec![0.5, -0.5, 0.25]),
            ("vel".to_owned(), vec![0.0, 10.0, 20.0, 30.0, 40.0]),
        ]
    );
}

/// Agent 0 of the config at `agent_path`, on its own thread: reads its vectors in cycle 0
/// and acts (`torque`, gear 2, then a torque out of bounds sent raw); no action in cycle
/// 1; then it waits for the host to close the session.
fn spawn_agent(agent_path: PathBuf, torque: [f32; 5]) -> JoinHandle<Read> {
    std::thread::spawn(move || -> Read {
        let mut agent = connect_agent(&agent_path, 0);
        let frame = agent.wait_start(Some(Duration::from_secs(5))).unwrap();
        let read = frame
            .vector_descs()
            .iter()
            .map(|d| {
                (
                    d.name().to_owned(),
                    frame.vector(d.name()).unwrap().to_vec(),
                )
            })
            .collect();
        drop(frame);
        agent.act("torque", &torque).unwrap();
        agent.act_discrete("gear", 2).unwrap();
        // Past the SDK's checks, as a foreign agent could: the host refuses both chunks
        // of a value out of bounds and keeps the last good value.
        for chunk in vrsync_bridge::action_chunks(0, &[0.0, 0.0, 2.0, 0.0, 0.0]) {
            agent.send_wire(chunk).unwrap();
        }
        agent.stop().unwrap();
        // Cycle 1: no action at all.
        drop(agent.wait_start(Some(Duration::from_secs(5))).unwrap());
        agent.stop().unwrap();
        wait_for_close(&mut agent);
        read
    })
}

/// Cycle 0: agent 0's vectors written through the ABI while its frame is loaned (bad
/// indices, names and agents refused), the frame published, the cycle started and
/// collected.
///
/// # Safety
/// `host` is a live handle.
unsafe fn writes_vectors_and_collects(host: *mut vrs_host_t) {
    let mut vector = MaybeUninit::<vrs_host_vector_t>::uninit();
    let mut value = MaybeUninit::<vrs_host_action_value_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its
    // use; vectors are written within `len` while the frame is loaned.
    unsafe {
        assert_eq!(
            vrs_host_wait_for_agents(host, 5000, ptr::null_mut(), 0, ptr::null_mut()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        refused(
            vrs_host_frame_vector(host, 0, 0, vector.as_mut_ptr()),
            VRS_HOST_ERROR_NO_FRAME,
            &["vrs_host_frame_vector", "agent 0"],
        );
        assert_eq!(vrs_host_loan_frame(host, 0, ptr::null_mut()), VRS_HOST_OK);
        assert_eq!(
            vrs_host_frame_vector_by_name(host, 0, c"joints".as_ptr(), vector.as_mut_ptr()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        let joints = vector.assume_init();
        assert_eq!((joints.len, joints.index), (3, 0));
        assert_eq!(name_of(&joints.name), "joints");
        std::slice::from_raw_parts_mut(joints.data, 3).copy_from_slice(&[0.5, -0.5, 0.25]);
        assert_eq!(
            vrs_host_frame_vector(host, 0, 1, vector.as_mut_ptr()),
            VRS_HOST_OK
        );
        let vel = vector.assume_init();
        assert_eq!((name_of(&vel.name), vel.len), ("vel", 5));
        for (i, x) in std::slice::from_raw_parts_mut(vel.data, 5)
            .iter_mut()
            .enumerate()
        {
            *x = i as f32 * 10.0;
        }
        refused(
            vrs_host_frame_vector(host, 0, 2, vector.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE,
            &["vector index 2", "there are 2"],
        );
        refused(
            vrs_host_frame_vector_by_name(host, 0, c"speed".as_ptr(), vector.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_CHANNEL,
            &["agent 0 has no vector \"speed\"", "joints, vel"],
        );
        refused(
            vrs_host_frame_vector_by_name(host, 0, ptr::null(), vector.as_mut_ptr()),
            VRS_HOST_ERROR_INVALID_ARGUMENT,
            &["name must not be null"],
        );
        refused(
            vrs_host_frame_vector(host, 0, 0, ptr::null_mut()),
            VRS_HOST_ERROR_INVALID_ARGUMENT,
            &["out_vector"],
        );
        refused(
            vrs_host_frame_vector(host, 3, 0, vector.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_AGENT,
            &["agent 3"],
        );
        assert_eq!(vrs_host_publish(host, 0, ptr::null()), VRS_HOST_OK);
        refused(
            vrs_host_frame_vector(host, 0, 0, vector.as_mut_ptr()),
            VRS_HOST_ERROR_NO_FRAME,
            &[],
        );
        assert_eq!(vrs_host_start(host), VRS_HOST_OK);
        refused(
            vrs_host_action(host, 0, 0, value.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE,
            &["vrs_host_action", "after vrs_host_collect"],
        );
        assert_eq!(
            vrs_host_collect(host, ptr::null_mut()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
    }
}

/// Cycle 0, collected: agent 0's actions in the report (the torque it sent, gear 2; bad
/// indices, names and agents refused), its two rejected chunks, no command; then the
/// cycle ends.
///
/// # Safety
/// `host` is a live handle whose cycle 0 was collected.
unsafe fn reads_the_actions(host: *mut vrs_host_t, torque: &[f32; 5]) {
    let mut value = MaybeUninit::<vrs_host_action_value_t>::uninit();
    let mut rejected = 0u32;
    let mut report = MaybeUninit::<vrs_host_agent_report_t>::uninit();
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its
    // use; action values are read within `len` before the cycle ends.
    unsafe {
        assert_eq!(
            vrs_host_action_by_name(host, 0, c"torque".as_ptr(), value.as_mut_ptr()),
            VRS_HOST_OK
        );
        let t = value.assume_init();
        assert_eq!((t.kind, t.index, t.len), (VRS_HOST_ACTION_KIND_BOX, 0, 5));
        assert_eq!(name_of(&t.name), "torque");
        assert_eq!(std::slice::from_raw_parts(t.values, 5), torque);
        assert_eq!(vrs_host_action(host, 0, 1, value.as_mut_ptr()), VRS_HOST_OK);
        let g = value.assume_init();
        assert_eq!(
            (g.kind, g.choice, g.len),
            (VRS_HOST_ACTION_KIND_DISCRETE, 2, 0)
        );
        assert!(g.values.is_null());
        assert_eq!(name_of(&g.name), "gear");
        refused(
            vrs_host_action_by_name(host, 0, c"thrust".as_ptr(), value.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_CHANNEL,
            &["agent 0 has no action \"thrust\"", "torque, gear"],
        );
        refused(
            vrs_host_action(host, 0, 2, value.as_mut_ptr()),
            VRS_HOST_ERROR_OUT_OF_RANGE,
            &["action index 2"],
        );
        refused(
            vrs_host_action(host, 5, 0, value.as_mut_ptr()),
            VRS_HOST_ERROR_UNKNOWN_AGENT,
            &["agent 5"],
        );
        refused(
            vrs_host_action(host, 0, 0, ptr::null_mut()),
            VRS_HOST_ERROR_INVALID_ARGUMENT,
            &["out_action"],
        );
        assert_eq!(
            vrs_host_actions_rejected(host, 0, &mut rejected),
            VRS_HOST_OK
        );
        assert_eq!(rejected, 2, "both chunks of the value out of bounds");
        // Actions are not commands.
        assert_eq!(
            vrs_host_agent_report(host, 0, report.as_mut_ptr()),
            VRS_HOST_OK
        );
        assert_eq!(report.assume_init().command_count, 0);
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);
        refused(
            vrs_host_action(host, 0, 0, value.as_mut_ptr()),
            VRS_HOST_ERROR_WRONG_STATE,
            &[],
        );
        refused(
            vrs_host_actions_rejected(host, 0, &mut rejected),
            VRS_HOST_ERROR_WRONG_STATE,
            &["vrs_host_actions_rejected"],
        );
    }
}

/// Cycle 1: nothing sent, nothing reported; the statistics count cycle 0's rejected chunks.
///
/// # Safety
/// `host` is a live handle after cycle 0.
unsafe fn reports_no_action_when_none_was_sent(host: *mut vrs_host_t) {
    let mut value = MaybeUninit::<vrs_host_action_value_t>::uninit();
    let mut rejected = 0u32;
    // SAFETY: `host` is live (the caller's promise); every pointer below is valid for its use.
    unsafe {
        // Cycle 1: nothing sent, nothing reported.
        assert_eq!(vrs_host_loan_frame(host, 0, ptr::null_mut()), VRS_HOST_OK);
        assert_eq!(vrs_host_publish(host, 0, ptr::null()), VRS_HOST_OK);
        assert_eq!(vrs_host_start(host), VRS_HOST_OK);
        assert_eq!(vrs_host_collect(host, ptr::null_mut()), VRS_HOST_OK);
        for i in 0..2 {
            assert_eq!(vrs_host_action(host, 0, i, value.as_mut_ptr()), VRS_HOST_OK);
            let v = value.assume_init();
            assert_eq!((v.kind, v.len, v.choice), (VRS_HOST_ACTION_KIND_NONE, 0, 0));
            assert!(v.values.is_null());
        }
        assert_eq!(
            vrs_host_actions_rejected(host, 0, &mut rejected),
            VRS_HOST_OK
        );
        assert_eq!(rejected, 0);
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);
        let mut stats = MaybeUninit::<vrs_host_stats_t>::uninit();
        assert_eq!(vrs_host_stats(host, stats.as_mut_ptr()), VRS_HOST_OK);
        assert_eq!(stats.assume_init().actions_rejected, 2);
    }
}

/// Every status of the header has its name in `vrs_host_status_name` (the table there is
/// written by hand).
#[test]
fn every_status_of_the_header_has_its_name() {
    let header = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("include/vrsync_host.h"),
    )
    .unwrap();
    let body = header
        .split("enum vrs_host_status_t")
        .nth(1)
        .and_then(|rest| rest.split("};").next())
        .unwrap();
    let statuses: Vec<(&str, i32)> = body
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("VRS_HOST_"))
        .map(|l| {
            let (name, value) = l.trim_end_matches(',').split_once(" = ").unwrap();
            (name, value.parse().unwrap())
        })
        .collect();
    assert!(
        statuses.contains(&("VRS_HOST_ERROR_UNKNOWN_CHANNEL", -14)),
        "{statuses:?}"
    );
    for (name, value) in statuses {
        // SAFETY: a static string.
        let got = unsafe { CStr::from_ptr(vrs_host_status_name(value)) };
        assert_eq!(got.to_str().unwrap(), name);
    }
}
