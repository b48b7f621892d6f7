//! The channel functions of the C ABI, called from Rust as a C program calls them, against
//! a host in this process: vectors the host writes reach the agent, actions the agent
//! sends reach the host's report, and every bad input has its status and message.

use std::ffi::{CStr, CString};
use std::mem::MaybeUninit;
use std::path::{Path, PathBuf};
use std::ptr;
use std::time::Duration;

use vrsync_bridge::{ActionValue, Config, Host};

use super::tests::{c_path, last_error, session};
use super::vrs_status_t::*;
use super::*;

/// A one-agent config with two vectors and two actions (and `max_commands_per_cycle = 4`).
fn write_config(dir: &Path, tag: &str) -> PathBuf {
    let toml = format!(
        "session = {:?}\n[sync]\nstop_timeout = 5.0\nconnect_timeout = 5.0\n\
         [transport]\nmax_commands_per_cycle = 4\n\
         [[agent]]\nid = 0\n\
         [[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n\
         [[agent.vector]]\nname = \"joints\"\nlen = 3\nlow = -3.5\nhigh = [1.0, 2.0, 3.0]\n\
         [[agent.vector]]\nname = \"vel\"\nlen = 5\n\
         [[agent.action]]\nname = \"torque\"\nlen = 5\nlow = -1.0\nhigh = 1.0\n\
         [[agent.action]]\nname = \"gear\"\nn = 3\n",
        session(tag)
    );
    let path = dir.join(format!("{tag}.toml"));
    std::fs::write(&path, toml).unwrap();
    path
}

fn connect(path: &Path) -> *mut vrs_agent_t {
    let mut agent = ptr::null_mut();
    // SAFETY: valid C string and out pointer.
    let st = unsafe { vrs_agent_connect(c_path(path).as_ptr(), 0, 5000, &mut agent) };
    assert_eq!(st, VRS_OK, "{}", last_error());
    agent
}

fn name_of(name: &[std::ffi::c_char]) -> &str {
    // SAFETY: the library writes NUL-terminated names.
    unsafe { CStr::from_ptr(name.as_ptr()) }.to_str().unwrap()
}

/// `status` and a message containing every one of `words`.
#[track_caller]
fn refused(status: vrs_status_t, expected: vrs_status_t, words: &[&str]) {
    let message = last_error();
    assert_eq!(status, expected, "{message}");
    for w in words {
        assert!(message.contains(w), "{w:?} not in {message:?}");
    }
}

/// Every status of the header has its name in `vrs_status_name` (the table there is
/// written by hand; the channel statuses were added to both).
#[test]
fn every_status_of_the_header_has_its_name() {
    let header =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../include/vrsync.h"))
            .unwrap();
    let body = header
        .split("enum vrs_status_t")
        .nth(1)
        .and_then(|rest| rest.split("};").next())
        .unwrap();
    let statuses: Vec<(&str, i32)> = body
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("VRS_"))
        .map(|l| {
            let (name, value) = l.trim_end_matches(',').split_once(" = ").unwrap();
            (name, value.parse().unwrap())
        })
        .collect();
    assert!(statuses.len() >= 22, "{statuses:?}");
    assert!(statuses.contains(&("VRS_ERROR_WRONG_ACTION_KIND", -18)));
    for (name, value) in statuses {
        // SAFETY: a static string.
        let got = unsafe { CStr::from_ptr(vrs_status_name(value)) };
        assert_eq!(got.to_str().unwrap(), name);
    }
}

#[test]
fn channel_calls_with_null_or_made_up_handles_are_errors() {
    let bogus: *mut vrs_agent_t = ptr::without_provenance_mut(0xdead_beef);
    let torque = c"torque";
    let mut vector = MaybeUninit::<vrs_vector_t>::uninit();
    let mut vspec = MaybeUninit::<vrs_vector_spec_t>::uninit();
    let mut aspec = MaybeUninit::<vrs_action_spec_t>::uninit();
    let mut count = 0u32;
    for h in [ptr::null_mut(), bogus] {
        // SAFETY: valid out pointers; the handle is never dereferenced.
        unsafe {
            let all = [
                vrs_agent_vector(h, 0, vector.as_mut_ptr()),
                vrs_agent_vector_by_name(h, c"joints".as_ptr(), vector.as_mut_ptr()),
                vrs_agent_channel_counts(h, &mut count, &mut count),
                vrs_agent_vector_spec(h, 0, vspec.as_mut_ptr()),
                vrs_agent_action_spec(h, 0, aspec.as_mut_ptr()),
                vrs_agent_act(h, torque.as_ptr(), [0.0f32; 5].as_ptr(), 5),
                vrs_agent_act_discrete(h, c"gear".as_ptr(), 0),
            ];
            for st in all {
                assert_eq!(st, VRS_ERROR_INVALID_HANDLE);
            }
        }
        assert!(
            last_error().starts_with("invalid agent handle"),
            "{}",
            last_error()
        );
    }
}

#[test]
fn channel_specs_come_from_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "specs");
    let config = Config::load(&path).unwrap();
    let _host = Host::builder(&config).create().unwrap();
    let agent = connect(&path);
    let (mut vectors, mut actions) = (0u32, 0u32);
    let mut v = MaybeUninit::<vrs_vector_spec_t>::uninit();
    let mut a = MaybeUninit::<vrs_action_spec_t>::uninit();
    // SAFETY: every pointer below is valid for its use; bounds are read within `len`.
    unsafe {
        assert_eq!(
            vrs_agent_channel_counts(agent, &mut vectors, &mut actions),
            VRS_OK
        );
        assert_eq!((vectors, actions), (2, 2));
        assert_eq!(
            vrs_agent_channel_counts(agent, ptr::null_mut(), ptr::null_mut()),
            VRS_OK,
            "either count may be skipped"
        );

        assert_eq!(vrs_agent_vector_spec(agent, 0, v.as_mut_ptr()), VRS_OK);
        let joints = v.assume_init();
        assert_eq!(
            (name_of(&joints.name), joints.len, joints.index),
            ("joints", 3, 0)
        );
        assert_eq!(std::slice::from_raw_parts(joints.low, 3), [-3.5; 3]);
        assert_eq!(std::slice::from_raw_parts(joints.high, 3), [1.0, 2.0, 3.0]);
        assert_eq!(vrs_agent_vector_spec(agent, 1, v.as_mut_ptr()), VRS_OK);
        let vel = v.assume_init();
        assert_eq!((name_of(&vel.name), vel.len, vel.index), ("vel", 5, 1));
        assert_eq!(
            std::slice::from_raw_parts(vel.low, 5),
            [f32::NEG_INFINITY; 5]
        );
        assert_eq!(std::slice::from_raw_parts(vel.high, 5), [f32::INFINITY; 5]);
        refused(
            vrs_agent_vector_spec(agent, 2, v.as_mut_ptr()),
            VRS_ERROR_OUT_OF_RANGE,
            &["vector index 2"],
        );
        refused(
            vrs_agent_vector_spec(agent, 0, ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT,
            &["out_spec"],
        );

        assert_eq!(vrs_agent_action_spec(agent, 0, a.as_mut_ptr()), VRS_OK);
        let torque = a.assume_init();
        assert_eq!(torque.kind, vrs_action_kind_t::VRS_ACTION_KIND_BOX);
        assert_eq!(
            (name_of(&torque.name), torque.len, torque.n),
            ("torque", 5, 0)
        );
        assert_eq!(std::slice::from_raw_parts(torque.low, 5), [-1.0; 5]);
        assert_eq!(std::slice::from_raw_parts(torque.high, 5), [1.0; 5]);
        assert_eq!(vrs_agent_action_spec(agent, 1, a.as_mut_ptr()), VRS_OK);
        let gear = a.assume_init();
        assert_eq!(gear.kind, vrs_action_kind_t::VRS_ACTION_KIND_DISCRETE);
        assert_eq!(
            (name_of(&gear.name), gear.len, gear.n, gear.index),
            ("gear", 0, 3, 1)
        );
        assert!(gear.low.is_null() && gear.high.is_null());
        refused(
            vrs_agent_action_spec(agent, 2, a.as_mut_ptr()),
            VRS_ERROR_OUT_OF_RANGE,
            &["action index 2"],
        );

        // Vectors belong to a frame.
        let mut vector = MaybeUninit::<vrs_vector_t>::uninit();
        refused(
            vrs_agent_vector(agent, 0, vector.as_mut_ptr()),
            VRS_ERROR_NO_FRAME,
            &["wait_start"],
        );
        assert_eq!(vrs_agent_disconnect(agent), VRS_OK);
    }
}

#[test]
fn vectors_reach_the_agent_and_actions_reach_the_host() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "cycle");
    let config = Config::load(&path).unwrap();
    let mut host = Host::builder(&config).create().unwrap();
    let agent = connect(&path);
    host.wait_for_agents(Duration::from_secs(5)).unwrap();

    let mut frame = host.loan_frame(0).unwrap();
    frame
        .vector_mut("joints")
        .unwrap()
        .copy_from_slice(&[0.5, -1.5, 2.5]);
    frame
        .vector_mut("vel")
        .unwrap()
        .copy_from_slice(&[1.0, 2.0, 3.0, 4.0, 5.0]);
    host.publish(frame).unwrap();
    host.start().unwrap();

    let value = [0.1f32, -0.2, 0.3, -0.4, 1.0];
    // SAFETY: `agent` is a live handle from connect until the disconnect below.
    unsafe {
        reads_the_vectors(agent);
        refuses_bad_actions(agent, &value);
        acts_until_the_queue_is_full(agent, &value);
    }

    let report = host.collect().unwrap();
    let r = &report.agents()[0];
    assert_eq!(r.action("torque"), Some(ActionValue::Box(&value)));
    assert_eq!(r.action("gear"), Some(ActionValue::Discrete(2)));
    assert_eq!(r.actions_rejected(), 0);
    let commands: Vec<_> = r
        .commands()
        .iter()
        .map(|c| c.decode().unwrap().name())
        .collect();
    assert_eq!(commands, ["turn"], "actions are not commands");
    assert_eq!(host.stats().actions_rejected, 0);

    drop(host);
    // SAFETY: as above.
    unsafe {
        assert_eq!(
            vrs_agent_wait_start(agent, 5000, ptr::null_mut()),
            VRS_SESSION_CLOSED
        );
        assert_eq!(vrs_agent_disconnect(agent), VRS_OK);
    }
}

/// Cycle 0's vectors, as the host wrote them; bad indices, names and pointers refused.
///
/// # Safety
/// `agent` is a live handle.
unsafe fn reads_the_vectors(agent: *mut vrs_agent_t) {
    let mut vector = MaybeUninit::<vrs_vector_t>::uninit();
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use; vectors are read within `len` while the frame is current.
    unsafe {
        assert_eq!(vrs_agent_wait_start(agent, 5000, ptr::null_mut()), VRS_OK);
        assert_eq!(
            vrs_agent_vector_by_name(agent, c"joints".as_ptr(), vector.as_mut_ptr()),
            VRS_OK,
            "{}",
            last_error()
        );
        let joints = vector.assume_init();
        assert_eq!((joints.len, joints.index), (3, 0));
        assert_eq!(name_of(&joints.name), "joints");
        assert_eq!(
            std::slice::from_raw_parts(joints.data, joints.len),
            [0.5, -1.5, 2.5]
        );
        assert_eq!(vrs_agent_vector(agent, 1, vector.as_mut_ptr()), VRS_OK);
        let vel = vector.assume_init();
        assert_eq!(name_of(&vel.name), "vel");
        assert_eq!(
            std::slice::from_raw_parts(vel.data, vel.len),
            [1.0, 2.0, 3.0, 4.0, 5.0]
        );
        refused(
            vrs_agent_vector(agent, 2, vector.as_mut_ptr()),
            VRS_ERROR_OUT_OF_RANGE,
            &["vector index 2", "has 2"],
        );
        refused(
            vrs_agent_vector_by_name(agent, c"speed".as_ptr(), vector.as_mut_ptr()),
            VRS_ERROR_UNKNOWN_CHANNEL,
            &["\"speed\"", "joints, vel"],
        );
        refused(
            vrs_agent_vector_by_name(agent, ptr::null(), vector.as_mut_ptr()),
            VRS_ERROR_INVALID_ARGUMENT,
            &["name must not be null"],
        );
        refused(
            vrs_agent_vector_by_name(agent, c"vel".as_ptr(), ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT,
            &["out_vector"],
        );
    }
}

/// Each refusal has its status and names the action.
///
/// # Safety
/// `agent` is a live handle with a current frame.
unsafe fn refuses_bad_actions(agent: *mut vrs_agent_t, value: &[f32; 5]) {
    let torque = c"torque";
    let gear = c"gear";
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use.
    unsafe {
        refused(
            vrs_agent_act(agent, c"thrust".as_ptr(), value.as_ptr(), 5),
            VRS_ERROR_UNKNOWN_CHANNEL,
            &["\"thrust\"", "torque, gear"],
        );
        refused(
            vrs_agent_act(agent, torque.as_ptr(), value.as_ptr(), 3),
            VRS_ERROR_WRONG_LENGTH,
            &["\"torque\"", "takes 5", "got 3"],
        );
        refused(
            vrs_agent_act(agent, torque.as_ptr(), ptr::null(), 0),
            VRS_ERROR_WRONG_LENGTH,
            &["\"torque\"", "got 0"],
        );
        let high = [0.0f32, 0.0, 1.5, 0.0, 0.0];
        refused(
            vrs_agent_act(agent, torque.as_ptr(), high.as_ptr(), 5),
            VRS_ERROR_OUT_OF_BOUNDS,
            &["\"torque\"", "value 2 is 1.5", "[-1, 1]"],
        );
        let nan = [f32::NAN; 5];
        refused(
            vrs_agent_act(agent, torque.as_ptr(), nan.as_ptr(), 5),
            VRS_ERROR_OUT_OF_BOUNDS,
            &["\"torque\"", "NaN"],
        );
        refused(
            vrs_agent_act(agent, gear.as_ptr(), value.as_ptr(), 1),
            VRS_ERROR_WRONG_ACTION_KIND,
            &["\"gear\"", "act_discrete"],
        );
        refused(
            vrs_agent_act_discrete(agent, torque.as_ptr(), 1),
            VRS_ERROR_WRONG_ACTION_KIND,
            &["\"torque\"", "continuous"],
        );
        refused(
            vrs_agent_act_discrete(agent, gear.as_ptr(), 3),
            VRS_ERROR_CHOICE_OUT_OF_RANGE,
            &["\"gear\"", "0..3", "got 3"],
        );
        refused(
            vrs_agent_act_discrete(agent, c"clutch".as_ptr(), 0),
            VRS_ERROR_UNKNOWN_CHANNEL,
            &["\"clutch\""],
        );
        refused(
            vrs_agent_act(agent, torque.as_ptr(), ptr::null(), 5),
            VRS_ERROR_INVALID_ARGUMENT,
            &["values"],
        );
        refused(
            vrs_agent_act(agent, ptr::null(), value.as_ptr(), 5),
            VRS_ERROR_INVALID_ARGUMENT,
            &["name must not be null"],
        );
        let not_utf8 = CString::new(vec![0xff, 0xfe]).unwrap();
        refused(
            vrs_agent_act_discrete(agent, not_utf8.as_ptr(), 0),
            VRS_ERROR_INVALID_ARGUMENT,
            &["not UTF-8"],
        );
    }
}

/// `value` for torque and gear 2 fill the queue but for a turn; the stop ends the frame.
///
/// # Safety
/// `agent` is a live handle with a current frame.
unsafe fn acts_until_the_queue_is_full(agent: *mut vrs_agent_t, value: &[f32; 5]) {
    let torque = c"torque";
    let gear = c"gear";
    let mut vector = MaybeUninit::<vrs_vector_t>::uninit();
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use.
    unsafe {
        // Five floats take two of the four queue entries, a choice one; a second value of
        // torque does not fit, a command still does.
        assert_eq!(
            vrs_agent_act(agent, torque.as_ptr(), value.as_ptr(), 5),
            VRS_OK,
            "{}",
            last_error()
        );
        assert_eq!(last_error(), "");
        assert_eq!(vrs_agent_act_discrete(agent, gear.as_ptr(), 2), VRS_OK);
        refused(
            vrs_agent_act(agent, torque.as_ptr(), value.as_ptr(), 5),
            VRS_ERROR_QUEUE_FULL,
            &["\"torque\"", "more than 4 commands"],
        );
        let mut id = 0u32;
        assert_eq!(vrs_agent_send_turn(agent, 10.0, &mut id), VRS_OK);
        refused(
            vrs_agent_act_discrete(agent, gear.as_ptr(), 0),
            VRS_ERROR_QUEUE_FULL,
            &["\"gear\""],
        );
        assert_eq!(vrs_agent_stop(agent), VRS_OK);
        // The vectors ended with the frame.
        refused(
            vrs_agent_vector(agent, 0, vector.as_mut_ptr()),
            VRS_ERROR_NO_FRAME,
            &[],
        );
    }
}
