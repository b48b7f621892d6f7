use std::ffi::{CStr, CString};
use std::path::{Path, PathBuf};
use std::ptr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use vrsync_bridge::{Config, Host};

use super::state::boundary;
use super::vrs_status_t::*;
use super::*;

pub(super) fn last_error() -> String {
    // SAFETY: the library returns a valid C string, never NULL.
    unsafe { CStr::from_ptr(vrs_last_error_message()) }
        .to_string_lossy()
        .into_owned()
}

pub(super) fn session(tag: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "ffi{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// A one-agent config (two 8×4 cameras) in `dir`.
fn write_config(dir: &Path, tag: &str) -> PathBuf {
    let toml = format!(
        "session = {:?}\n[sync]\nstop_timeout = 5.0\nconnect_timeout = 5.0\n\
         [transport]\nmax_commands_per_cycle = 4\n\
         [[agent]]\nid = 0\n\
         [[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n\
         [[agent.camera]]\nname = \"right\"\nwidth = 8\nheight = 4\nformat = \"gray8\"\n",
        session(tag)
    );
    let path = dir.join(format!("{tag}.toml"));
    std::fs::write(&path, toml).unwrap();
    path
}

pub(super) fn c_path(path: &Path) -> CString {
    CString::new(path.to_str().unwrap()).unwrap()
}

fn connect(path: &Path) -> *mut vrs_agent_t {
    let mut agent = ptr::null_mut();
    // SAFETY: valid C string and out pointer.
    let st = unsafe { vrs_agent_connect(c_path(path).as_ptr(), 0, 5000, &mut agent) };
    assert_eq!(st, VRS_OK, "{}", last_error());
    assert!(!agent.is_null());
    agent
}

/// Publishes one frame for agent 0 and signals start.
fn publish(host: &mut Host) {
    let mut frame = host.loan_frame(0).unwrap();
    frame.header_mut().pose.position = [1.0, 2.0, 3.0];
    frame.header_mut().reward = 0.5;
    frame
        .header_mut()
        .push_status(7, vrsync_bridge::ActionState::Walking);
    frame.header_mut().push_collision(7, 99);
    host.publish(frame).unwrap();
    host.start().unwrap();
}

#[test]
fn header_is_up_to_date() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("../../bridge/cabi/src/sensors.rs"))
        .with_src(dir.join("src/types.rs"))
        .with_src(dir.join("src/exports.rs"))
        .with_src(dir.join("src/send.rs"))
        .with_src(dir.join("src/channels.rs"))
        .generate()
        .expect("cbindgen")
        .write(&mut generated);
    let path = dir.join("../include/vrsync.h");
    if std::env::var_os("VRSYNC_UPDATE_HEADER").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is out of date with agent-sdk/ffi/src/; regenerate it with \
         `VRSYNC_UPDATE_HEADER=1 cargo test -p vrsync-agent-ffi header` and commit it",
        path.display()
    );
}

#[test]
fn version_and_status_names() {
    // SAFETY: static strings.
    let v = unsafe { CStr::from_ptr(vrs_version()) }.to_str().unwrap();
    assert_eq!(v, env!("CARGO_PKG_VERSION"));
    assert_eq!(vrs_protocol_version(), vrsync_bridge::PROTOCOL_VERSION);
    // SAFETY: static strings.
    let name = |s: i32| {
        unsafe { CStr::from_ptr(vrs_status_name(s)) }
            .to_str()
            .unwrap()
    };
    assert_eq!(name(0), "VRS_OK");
    assert_eq!(name(VRS_TIMEOUT as i32), "VRS_TIMEOUT");
    assert_eq!(
        name(VRS_ERROR_INVALID_HANDLE as i32),
        "VRS_ERROR_INVALID_HANDLE"
    );
    assert_eq!(name(12345), "VRS_UNKNOWN_STATUS");
}

#[test]
fn null_and_made_up_handles_are_errors_with_messages() {
    let null = ptr::null_mut();
    let bogus: *mut vrs_agent_t = ptr::without_provenance_mut(0xdead_beef);
    for h in [null, bogus] {
        let mut frame = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
        let mut image = std::mem::MaybeUninit::<vrs_image_t>::uninit();
        let mut id = 0u32;
        // SAFETY: every out pointer is valid; the handle is never dereferenced.
        unsafe {
            assert_eq!(
                vrs_agent_wait_start(h, 0, frame.as_mut_ptr()),
                VRS_ERROR_INVALID_HANDLE
            );
            assert!(
                last_error().starts_with("invalid agent handle"),
                "{}",
                last_error()
            );
            assert_eq!(
                vrs_agent_frame(h, frame.as_mut_ptr()),
                VRS_ERROR_INVALID_HANDLE
            );
            assert_eq!(
                vrs_agent_image(h, 0, image.as_mut_ptr()),
                VRS_ERROR_INVALID_HANDLE
            );
            assert_eq!(
                vrs_agent_send_move(h, 0.0, 1.0, &mut id),
                VRS_ERROR_INVALID_HANDLE
            );
            assert_eq!(
                vrs_agent_send_grasp_release(h, ptr::null_mut()),
                VRS_ERROR_INVALID_HANDLE
            );
            assert_eq!(vrs_agent_stop(h), VRS_ERROR_INVALID_HANDLE);
            assert_eq!(vrs_agent_id(h, &mut id), VRS_ERROR_INVALID_HANDLE);
            assert_eq!(vrs_agent_disconnect(h), VRS_ERROR_INVALID_HANDLE);
        }
    }
    // SAFETY: the handle is never dereferenced.
    unsafe { vrs_agent_stop(bogus) };
    assert!(last_error().contains("0xdeadbeef"), "{}", last_error());
}

#[test]
fn connect_reports_bad_arguments_config_and_missing_host() {
    let dir = tempfile::tempdir().unwrap();
    let mut agent: *mut vrs_agent_t = ptr::without_provenance_mut(1);
    // SAFETY: valid (or null, on purpose) pointers.
    unsafe {
        assert_eq!(
            vrs_agent_connect(ptr::null(), 0, 0, &mut agent),
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert!(agent.is_null(), "a failed connect leaves NULL behind");
        assert_eq!(last_error(), "config_path must not be null");
        let path = c_path(&dir.path().join("missing.toml"));
        assert_eq!(
            vrs_agent_connect(path.as_ptr(), 0, 0, ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert_eq!(
            vrs_agent_connect(path.as_ptr(), 0, 0, &mut agent),
            VRS_ERROR_CONFIG
        );
        assert!(last_error().contains("missing.toml"), "{}", last_error());
        let not_utf8 = CString::new(vec![0xff, 0xfe]).unwrap();
        assert_eq!(
            vrs_agent_connect(not_utf8.as_ptr(), 0, 0, &mut agent),
            VRS_ERROR_INVALID_ARGUMENT
        );
        let config = c_path(&write_config(dir.path(), "nohost"));
        assert_eq!(
            vrs_agent_connect(config.as_ptr(), 0, 0, &mut agent),
            VRS_ERROR_CONNECT
        );
        assert!(last_error().contains("no host"), "{}", last_error());
        assert!(agent.is_null());
    }
}

#[test]
fn logging_filter_is_checked() {
    let bad = CString::new("[[[").unwrap();
    // SAFETY: a valid C string.
    assert_eq!(
        unsafe { vrs_init_logging(bad.as_ptr()) },
        VRS_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("bad log filter"), "{}", last_error());
}

#[test]
fn a_cycle_through_the_c_abi_and_double_free() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "cycle");
    let config = Config::load(&path).unwrap();
    let mut host = Host::builder(&config).create().unwrap();
    let agent = connect(&path);
    host.wait_for_agents(Duration::from_secs(5)).unwrap();

    let mut frame = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
    // SAFETY: `agent` is a live handle from connect until the disconnect below.
    let first = unsafe {
        reads_the_first_frame(agent, &mut host);
        reads_images_statuses_and_collisions(agent);
        sends_commands_and_stops(agent)
    };
    let report = host.collect().unwrap();
    let got: Vec<_> = report.agents()[0]
        .commands()
        .iter()
        .map(|c| (c.decode().unwrap().name(), c.action_id))
        .collect();
    assert_eq!(got.len(), 4);
    assert_eq!(got[0], ("move", first));
    assert_eq!(got[2], ("turn", 4242));
    assert_eq!(got[3].0, "cancel_move");

    // SAFETY: as above.
    unsafe {
        drop(host);
        assert_eq!(
            vrs_agent_wait_start(agent, 5000, frame.as_mut_ptr()),
            VRS_SESSION_CLOSED
        );
        assert_eq!(vrs_agent_disconnect(agent), VRS_OK);
        assert_eq!(vrs_agent_disconnect(agent), VRS_ERROR_INVALID_HANDLE);
        assert!(
            last_error().contains("already disconnected"),
            "{}",
            last_error()
        );
        assert_eq!(vrs_agent_stop(agent), VRS_ERROR_INVALID_HANDLE);
    }
}

/// Nothing before the first frame (a poll is a timeout); then cycle 0's frame, as the
/// host published it, read twice alike.
///
/// # Safety
/// `agent` is a live handle.
unsafe fn reads_the_first_frame(agent: *mut vrs_agent_t, host: &mut Host) {
    let mut frame = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use.
    unsafe {
        // Before the first frame.
        assert_eq!(
            vrs_agent_frame(agent, frame.as_mut_ptr()),
            VRS_ERROR_NO_FRAME
        );
        assert_eq!(vrs_agent_stop(agent), VRS_ERROR_NO_FRAME);
        assert!(
            last_error().contains("before the first frame"),
            "{}",
            last_error()
        );
        // A poll with nothing published: a timeout, not an error.
        assert_eq!(
            vrs_agent_wait_start(agent, 0, frame.as_mut_ptr()),
            VRS_TIMEOUT
        );
        assert!(last_error().contains("no start"), "{}", last_error());

        publish(host);
        assert_eq!(
            vrs_agent_wait_start(agent, 5000, frame.as_mut_ptr()),
            VRS_OK
        );
        assert_eq!(last_error(), "");
        let f = frame.assume_init();
        assert_eq!((f.cycle, f.sim_time_ns, f.agent_id), (0, 0, 0));
        assert!(f.sync_mode);
        assert_eq!(f.pose.position, [1.0, 2.0, 3.0]);
        assert_eq!(f.reward, 0.5);
        assert_eq!(
            (f.image_count, f.status_count, f.collision_count),
            (2, 1, 1)
        );
        assert_eq!(f.previous_outcome, vrs_outcome_t::VRS_OUTCOME_NONE);

        let mut again = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
        assert_eq!(vrs_agent_frame(agent, again.as_mut_ptr()), VRS_OK);
        assert_eq!(again.assume_init(), f);
        assert_eq!(
            vrs_agent_frame(agent, ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT
        );
    }
}

/// The current frame's images (zero copy, in camera order), status and collision; bad
/// indices and names refused.
///
/// # Safety
/// `agent` is a live handle with a current frame.
unsafe fn reads_images_statuses_and_collisions(agent: *mut vrs_agent_t) {
    let mut image = std::mem::MaybeUninit::<vrs_image_t>::uninit();
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use.
    unsafe {
        assert_eq!(vrs_agent_image(agent, 0, image.as_mut_ptr()), VRS_OK);
        let left = image.assume_init();
        assert_eq!(
            (left.width, left.height, left.stride, left.len),
            (8, 4, 24, 96)
        );
        assert_eq!(left.format, vrs_pixel_format_t::VRS_PIXEL_FORMAT_RGB8);
        assert_eq!(CStr::from_ptr(left.name.as_ptr()).to_str().unwrap(), "left");
        assert!(!left.data.is_null());
        let name = CString::new("right").unwrap();
        assert_eq!(
            vrs_agent_image_by_name(agent, name.as_ptr(), image.as_mut_ptr()),
            VRS_OK
        );
        let right = image.assume_init();
        assert_eq!((right.width, right.stride, right.camera), (8, 8, 1));
        assert_eq!(right.format, vrs_pixel_format_t::VRS_PIXEL_FORMAT_GRAY8);
        // Zero copy: both views point into one shared-memory payload, in camera order
        // (the host may align each image).
        let gap = right.data.offset_from(left.data.add(left.len));
        assert!((0..256).contains(&gap), "gap {gap}");
        assert_eq!(
            vrs_agent_image(agent, 2, image.as_mut_ptr()),
            VRS_ERROR_OUT_OF_RANGE
        );
        assert!(last_error().contains("image index 2"), "{}", last_error());
        let nope = CString::new("main").unwrap();
        assert_eq!(
            vrs_agent_image_by_name(agent, nope.as_ptr(), image.as_mut_ptr()),
            VRS_ERROR_INVALID_ARGUMENT
        );

        let mut status = vrs_action_status_t::default();
        assert_eq!(vrs_agent_status(agent, 0, &mut status), VRS_OK);
        assert_eq!((status.action_id, status.state), (7, 3));
        assert_eq!(
            vrs_agent_status(agent, 1, &mut status),
            VRS_ERROR_OUT_OF_RANGE
        );
        let mut collision = vrs_collision_t::default();
        assert_eq!(vrs_agent_collision(agent, 0, &mut collision), VRS_OK);
        assert_eq!((collision.action_id, collision.collider_id), (7, 99));
    }
}

/// Commands: typed, generic, with an id of our own; bad ones refused here; then the stop,
/// which ends the frame. Returns the first command's action id.
///
/// # Safety
/// `agent` is a live handle with a current frame.
unsafe fn sends_commands_and_stops(agent: *mut vrs_agent_t) -> u32 {
    let mut image = std::mem::MaybeUninit::<vrs_image_t>::uninit();
    let mut id = 0u32;
    let first;
    // SAFETY: `agent` is live (the caller's promise); every pointer below is valid for its
    // use.
    unsafe {
        // Commands: typed, generic, with an id of our own; bad ones refused here.
        assert_eq!(vrs_agent_send_move(agent, 90.0, 1.0, &mut id), VRS_OK);
        first = id;
        assert_eq!(
            vrs_agent_send_turn(agent, f32::NAN, &mut id),
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("turn"), "{}", last_error());
        assert_eq!(id, first, "a refused command leaves the id alone");
        let cmd = vrs_command_t {
            kind: vrs_command_kind_t::VRS_COMMAND_TURN as u32,
            object_id: 0,
            args: [45.0, 0.0, 0.0, 0.0],
        };
        assert_eq!(vrs_agent_send(agent, &cmd, &mut id), VRS_OK);
        assert_ne!(id, first);
        assert_eq!(vrs_agent_send_with_id(agent, 4242, &cmd), VRS_OK);
        let bad = vrs_command_t { kind: 77, ..cmd };
        assert_eq!(
            vrs_agent_send(agent, &bad, ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert!(
            last_error().contains("unknown command kind 77"),
            "{}",
            last_error()
        );
        assert_eq!(
            vrs_agent_send(agent, ptr::null(), ptr::null_mut()),
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert_eq!(vrs_agent_send_cancel_move(agent, ptr::null_mut()), VRS_OK);
        // max_commands_per_cycle = 4
        assert_eq!(
            vrs_agent_send_grasp_id(agent, 1, ptr::null_mut()),
            VRS_ERROR_QUEUE_FULL
        );

        assert_eq!(vrs_agent_stop(agent), VRS_OK);
        assert_eq!(vrs_agent_stop(agent), VRS_ERROR_ALREADY_STOPPED);
        // The frame ended with the stop.
        assert_eq!(
            vrs_agent_image(agent, 0, image.as_mut_ptr()),
            VRS_ERROR_NO_FRAME
        );
    }
    first
}

#[test]
fn a_handle_belongs_to_its_thread() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "thread");
    let config = Config::load(&path).unwrap();
    let _host = Host::builder(&config).create().unwrap();
    let agent = connect(&path);
    let key = agent.addr();
    let from_other_thread = std::thread::spawn(move || {
        let agent: *mut vrs_agent_t = ptr::without_provenance_mut(key);
        // SAFETY: the handle is never dereferenced.
        let st = unsafe { vrs_agent_stop(agent) };
        // SAFETY: as above.
        let dc = unsafe { vrs_agent_disconnect(agent) };
        (st, dc, last_error())
    })
    .join()
    .unwrap();
    assert_eq!(from_other_thread.0, VRS_ERROR_WRONG_THREAD);
    assert_eq!(from_other_thread.1, VRS_ERROR_WRONG_THREAD);
    assert!(
        from_other_thread.2.contains("another thread"),
        "{}",
        from_other_thread.2
    );
    // SAFETY: as above.
    assert_eq!(unsafe { vrs_agent_disconnect(agent) }, VRS_OK);
}

#[test]
fn panics_become_a_status() {
    let st = boundary(|| panic!("boom"));
    assert_eq!(st, VRS_ERROR_PANIC);
    assert!(last_error().contains("boom"), "{}", last_error());
}
