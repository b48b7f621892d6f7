use std::ffi::{CStr, CString};
use std::mem::MaybeUninit;
use std::path::{Path, PathBuf};
use std::ptr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use vrsync_agent::Agent;
use vrsync_bridge::Config;

use crate::types::vrs_host_status_t::*;
use crate::*;

pub(crate) fn last_error() -> String {
    // SAFETY: the library returns a valid C string, never NULL.
    unsafe { CStr::from_ptr(vrs_host_last_error_message()) }
        .to_string_lossy()
        .into_owned()
}

pub(crate) fn session(tag: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "hffi{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// A config with agents `0..agents` (two 8×4 cameras each) in `dir`.
pub(crate) fn write_config(dir: &Path, tag: &str, agents: u32, stop_timeout_s: f64) -> PathBuf {
    let mut toml = format!(
        "session = {:?}\n[sync]\nstop_timeout = {stop_timeout_s}\nconnect_timeout = 5.0\n\
         [transport]\nmax_commands_per_cycle = 4\n",
        session(tag)
    );
    for id in 0..agents {
        toml.push_str(&format!(
            "[[agent]]\nid = {id}\n\
             [[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n\
             [[agent.camera]]\nname = \"right\"\nwidth = 8\nheight = 4\nformat = \"gray8\"\n"
        ));
    }
    let path = dir.join(format!("{tag}.toml"));
    std::fs::write(&path, toml).unwrap();
    path
}

fn c_path(path: &Path) -> CString {
    CString::new(path.to_str().unwrap()).unwrap()
}

pub(crate) fn create(path: &Path) -> *mut vrs_host_t {
    let mut host = ptr::null_mut();
    // SAFETY: valid C string and out pointer.
    let st = unsafe { vrs_host_create(c_path(path).as_ptr(), &mut host) };
    assert_eq!(st, VRS_HOST_OK, "{}", last_error());
    assert!(!host.is_null());
    host
}

/// Waits (up to 10 s) until the host closes the session, skipping frames.
pub(crate) fn wait_for_close(agent: &mut Agent) {
    for _ in 0..100 {
        match agent.wait_start(Some(Duration::from_millis(100))) {
            Err(vrsync_agent::WaitStartError::HostClosed) => return,
            Ok(frame) => drop(frame),
            Err(vrsync_agent::WaitStartError::Timeout { .. }) => {}
            Err(e) => panic!("waiting for the session to close: {e}"),
        }
    }
    panic!("the host did not close the session");
}

pub(crate) fn connect_agent(path: &Path, id: u32) -> Agent {
    let config = Config::load(path).unwrap();
    Agent::connect(&config, id).unwrap()
}

#[test]
fn header_is_up_to_date() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("../cabi/src/sensors.rs"))
        .with_src(dir.join("src/types.rs"))
        .with_src(dir.join("src/ffi.rs"))
        .with_src(dir.join("src/channels.rs"))
        .generate()
        .expect("cbindgen")
        .write(&mut generated);
    let path = dir.join("include/vrsync_host.h");
    if std::env::var_os("VRSYNC_UPDATE_HEADER").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is out of date with src/types.rs and src/ffi.rs; regenerate it with \
         `VRSYNC_UPDATE_HEADER=1 cargo test -p vrsync-host-ffi header` and commit it",
        path.display()
    );
}

#[test]
fn version_status_names_and_sizes() {
    // SAFETY: static strings.
    let v = unsafe { CStr::from_ptr(vrs_host_version()) }
        .to_str()
        .unwrap();
    assert_eq!(v, env!("CARGO_PKG_VERSION"));
    assert_eq!(vrs_host_protocol_version(), vrsync_bridge::PROTOCOL_VERSION);
    // SAFETY: static strings.
    let name = |s: i32| {
        unsafe { CStr::from_ptr(vrs_host_status_name(s)) }
            .to_str()
            .unwrap()
    };
    assert_eq!(name(0), "VRS_HOST_OK");
    assert_eq!(name(VRS_HOST_TIMEOUT as i32), "VRS_HOST_TIMEOUT");
    assert_eq!(
        name(VRS_HOST_ERROR_WRONG_STATE as i32),
        "VRS_HOST_ERROR_WRONG_STATE"
    );
    assert_eq!(name(12345), "VRS_HOST_UNKNOWN_STATUS");
    assert_eq!(vrs_host_sizeof_sensors(), 328);
    assert_eq!(vrs_host_sizeof_command(), 32);
    assert_eq!(vrs_host_sizeof_cycle(), 48);
    assert_eq!(
        vrs_host_sizeof_agent_report(),
        std::mem::size_of::<vrs_host_agent_report_t>()
    );
    assert_eq!(vrs_host_sizeof_stats(), 152);
    assert_eq!(
        vrs_host_sizeof_image(),
        std::mem::size_of::<vrs_host_image_t>()
    );
}

#[test]
fn null_and_made_up_handles_are_errors_with_messages() {
    let null = ptr::null_mut();
    let bogus: *mut vrs_host_t = ptr::without_provenance_mut(0xdead_beef);
    for h in [null, bogus] {
        let mut info = MaybeUninit::<vrs_host_info_t>::uninit();
        let mut frame = MaybeUninit::<vrs_host_frame_t>::uninit();
        let mut cycle = MaybeUninit::<vrs_host_cycle_t>::uninit();
        // SAFETY: every out pointer is valid; the handle is never dereferenced.
        unsafe {
            assert_eq!(
                vrs_host_info(h, info.as_mut_ptr()),
                VRS_HOST_ERROR_INVALID_HANDLE
            );
            assert!(
                last_error().starts_with("invalid host handle"),
                "{}",
                last_error()
            );
            assert_eq!(
                vrs_host_loan_frame(h, 0, frame.as_mut_ptr()),
                VRS_HOST_ERROR_INVALID_HANDLE
            );
            assert_eq!(
                vrs_host_publish(h, 0, ptr::null()),
                VRS_HOST_ERROR_INVALID_HANDLE
            );
            assert_eq!(vrs_host_start(h), VRS_HOST_ERROR_INVALID_HANDLE);
            assert_eq!(
                vrs_host_collect(h, cycle.as_mut_ptr()),
                VRS_HOST_ERROR_INVALID_HANDLE
            );
            assert_eq!(vrs_host_end_cycle(h), VRS_HOST_ERROR_INVALID_HANDLE);
            assert_eq!(
                vrs_host_wait_for_agents(h, 0, ptr::null_mut(), 0, ptr::null_mut()),
                VRS_HOST_ERROR_INVALID_HANDLE
            );
            assert_eq!(vrs_host_destroy(h), VRS_HOST_ERROR_INVALID_HANDLE);
        }
    }
    // SAFETY: the handle is never dereferenced.
    unsafe { vrs_host_start(bogus) };
    assert!(last_error().contains("0xdeadbeef"), "{}", last_error());
}

#[test]
fn create_reports_bad_arguments_and_config_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut host: *mut vrs_host_t = ptr::without_provenance_mut(1);
    // SAFETY: valid (or null, on purpose) pointers.
    unsafe {
        assert_eq!(
            vrs_host_create(ptr::null(), &mut host),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
        assert!(host.is_null(), "a failed create leaves NULL behind");
        assert_eq!(last_error(), "config_path must not be null");
        let path = c_path(&dir.path().join("missing.toml"));
        assert_eq!(
            vrs_host_create(path.as_ptr(), ptr::null_mut()),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
        assert_eq!(
            vrs_host_create(path.as_ptr(), &mut host),
            VRS_HOST_ERROR_CONFIG
        );
        assert!(last_error().contains("missing.toml"), "{}", last_error());
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, "session = \"x\"\nbogus_key = 1\n").unwrap();
        assert_eq!(
            vrs_host_create(c_path(&bad).as_ptr(), &mut host),
            VRS_HOST_ERROR_CONFIG
        );
        assert!(last_error().contains("bogus_key"), "{}", last_error());
        assert!(host.is_null());
        let bad_filter = CString::new("[[[").unwrap();
        assert_eq!(
            vrs_host_init_logging(bad_filter.as_ptr()),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );
    }
}

#[test]
fn missing_agents_and_stop_timeouts_are_outcomes_not_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "timeout", 2, 0.2);
    // The original semantics: a cycle ends without a live agent after stop_timeout.
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(
        &path,
        text.replace("[sync]\n", "[sync]\nwait_for_stop = \"timeout\"\n"),
    )
    .unwrap();
    let host = create(&path);
    // Agent 0 answers every cycle; agent 1 connects but never stops.
    let agent_path = path.clone();
    let responsive = std::thread::spawn(move || {
        let mut agent = connect_agent(&agent_path, 0);
        for _ in 0..2 {
            drop(agent.wait_start(Some(Duration::from_secs(5))).unwrap());
            agent.stop().unwrap();
        }
        wait_for_close(&mut agent);
    });
    let mut missing = [u32::MAX; 1];
    let mut missing_count = 0u32;
    let mut cycle = MaybeUninit::<vrs_host_cycle_t>::uninit();
    let mut report = MaybeUninit::<vrs_host_agent_report_t>::uninit();
    // SAFETY: every pointer below is valid for its use.
    unsafe {
        // Wait until agent 0 is in, then find agent 1 missing.
        let mut waited = 0;
        loop {
            let st = vrs_host_wait_for_agents(
                host,
                100,
                missing.as_mut_ptr(),
                missing.len() as u32,
                &mut missing_count,
            );
            assert_eq!(st, VRS_HOST_TIMEOUT);
            assert!(last_error().contains("did not connect"), "{}", last_error());
            if missing_count == 1 {
                break;
            }
            waited += 1;
            assert!(waited < 50, "agent 0 never connected");
        }
        assert_eq!(missing, [1]);
        // Too small a buffer: the count says how many there are.
        let mut agent_info = MaybeUninit::<vrs_host_agent_info_t>::uninit();
        assert_eq!(
            vrs_host_agent_info(host, 1, agent_info.as_mut_ptr()),
            VRS_HOST_OK
        );
        assert_eq!(agent_info.assume_init().connected, 0);
        assert_eq!(
            vrs_host_wait_for_agents(host, 0, ptr::null_mut(), 1, ptr::null_mut()),
            VRS_HOST_ERROR_INVALID_ARGUMENT
        );

        let _silent = connect_agent(&path, 1);
        assert_eq!(
            vrs_host_wait_for_agents(host, 5000, ptr::null_mut(), 0, &mut missing_count),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        assert_eq!(missing_count, 0);
        for n in 0..2u64 {
            for id in 0..2 {
                assert_eq!(vrs_host_loan_frame(host, id, ptr::null_mut()), VRS_HOST_OK);
                assert_eq!(vrs_host_publish(host, id, ptr::null()), VRS_HOST_OK);
            }
            assert_eq!(vrs_host_start(host), VRS_HOST_OK);
            assert_eq!(
                vrs_host_collect(host, cycle.as_mut_ptr()),
                VRS_HOST_OK,
                "a stop timeout is not an error: {}",
                last_error()
            );
            let c = cycle.assume_init();
            assert_eq!((c.cycle, c.timed_out_agents), (n, 1));
            assert_eq!(
                vrs_host_agent_report(host, 0, report.as_mut_ptr()),
                VRS_HOST_OK
            );
            let r0 = report.assume_init();
            assert_eq!(r0.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_STOPPED);
            assert!(r0.commands.is_null());
            assert_eq!(
                vrs_host_agent_report(host, 1, report.as_mut_ptr()),
                VRS_HOST_OK
            );
            let r1 = report.assume_init();
            assert_eq!(r1.agent_id, 1);
            assert_eq!(r1.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_TIMED_OUT);
            // `wait_for_stop = "timeout"`: a timeout, not a slow agent.
            assert_eq!((r1.slow, r1.left, c.slow_agents), (0, 0, 0));
            assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);
        }
        // A discarded frame: the agent is not waited for.
        assert_eq!(vrs_host_loan_frame(host, 1, ptr::null_mut()), VRS_HOST_OK);
        assert_eq!(vrs_host_discard_frame(host, 1), VRS_HOST_OK);
        assert_eq!(vrs_host_discard_frame(host, 1), VRS_HOST_ERROR_NO_FRAME);
        assert_eq!(vrs_host_start(host), VRS_HOST_OK);
        assert_eq!(vrs_host_collect(host, cycle.as_mut_ptr()), VRS_HOST_OK);
        assert_eq!(cycle.assume_init().timed_out_agents, 0);
        assert_eq!(
            vrs_host_agent_report(host, 1, report.as_mut_ptr()),
            VRS_HOST_OK
        );
        assert_eq!(
            report.assume_init().outcome,
            vrs_host_outcome_t::VRS_HOST_OUTCOME_NOT_AWAITED
        );
        let mut stats = MaybeUninit::<vrs_host_stats_t>::uninit();
        assert_eq!(vrs_host_stats(host, stats.as_mut_ptr()), VRS_HOST_OK);
        let s = stats.assume_init();
        assert_eq!((s.cycles, s.stop_timeouts, s.agent_timeouts), (3, 2, 2));
        assert_eq!((s.slow_stops, s.leaves), (0, 0));
        assert_eq!(vrs_host_destroy(host), VRS_HOST_OK);
    }
    responsive.join().unwrap();
}

/// Loans and publishes a frame for every agent, starts the cycle and collects it.
///
/// # Safety
/// `host` is a live handle of this thread.
unsafe fn run_cycle(host: *mut vrs_host_t, agents: u32) -> vrs_host_cycle_t {
    let mut cycle = MaybeUninit::<vrs_host_cycle_t>::uninit();
    // SAFETY: the caller's contract; the out pointer is valid.
    unsafe {
        for id in 0..agents {
            assert_eq!(vrs_host_loan_frame(host, id, ptr::null_mut()), VRS_HOST_OK);
            assert_eq!(vrs_host_publish(host, id, ptr::null()), VRS_HOST_OK);
        }
        assert_eq!(vrs_host_start(host), VRS_HOST_OK);
        assert_eq!(
            vrs_host_collect(host, cycle.as_mut_ptr()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        cycle.assume_init()
    }
}

/// The report of agent `id` in the collected cycle.
///
/// # Safety
/// `host` is a live handle of this thread, its cycle collected.
unsafe fn report_of(host: *mut vrs_host_t, id: u32) -> vrs_host_agent_report_t {
    let mut report = MaybeUninit::<vrs_host_agent_report_t>::uninit();
    // SAFETY: the caller's contract; the out pointer is valid.
    unsafe {
        assert_eq!(
            vrs_host_agent_report_by_id(host, id, report.as_mut_ptr()),
            VRS_HOST_OK
        );
        report.assume_init()
    }
}

#[test]
fn leaves_and_slow_agents_are_reported_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    // The default `wait_for_stop = "alive"`: the host waits past stop_timeout for a live
    // agent and reports it slow.
    let stop_timeout = Duration::from_millis(500);
    let path = write_config(dir.path(), "leave", 2, stop_timeout.as_secs_f64());
    let host = create(&path);
    // Agent 1 stops cycle 0, reads cycle 1 and closes without stopping it.
    let leaving_path = path.clone();
    let leaving = std::thread::spawn(move || {
        let mut agent = connect_agent(&leaving_path, 1);
        drop(agent.wait_start(Some(Duration::from_secs(5))).unwrap());
        agent.stop().unwrap();
        let frame = agent.wait_start(Some(Duration::from_secs(5))).unwrap();
        assert_eq!(frame.cycle(), 1);
        drop(frame);
        agent.close();
    });
    // Agent 0 stops every cycle; in cycle 2 it computes for 2 stop timeouts first.
    let busy_path = path.clone();
    let busy = std::thread::spawn(move || {
        let mut agent = connect_agent(&busy_path, 0);
        for n in 0..4u64 {
            let frame = agent.wait_start(Some(Duration::from_secs(5))).unwrap();
            assert_eq!(frame.cycle(), n);
            drop(frame);
            if n == 2 {
                // Simulated compute time (a learner's update), not synchronisation.
                std::thread::sleep(stop_timeout * 2);
            }
            agent.stop().unwrap();
        }
        wait_for_close(&mut agent);
    });
    // SAFETY: every pointer below is valid for its use.
    unsafe {
        assert_eq!(
            vrs_host_wait_for_agents(host, 5000, ptr::null_mut(), 0, ptr::null_mut()),
            VRS_HOST_OK,
            "{}",
            last_error()
        );
        let c = run_cycle(host, 2);
        assert_eq!((c.cycle, c.left_agents, c.slow_agents), (0, 0, 0));
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);

        // Cycle 1: agent 1 leaves instead of stopping: neither slow nor timed out.
        let c = run_cycle(host, 2);
        assert_eq!((c.cycle, c.left_agents, c.slow_agents), (1, 1, 0));
        assert_eq!((c.timed_out_agents, c.evicted_agents), (0, 0));
        let r1 = report_of(host, 1);
        assert_eq!(r1.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_LEFT);
        assert_eq!((r1.left, r1.slow, r1.evicted), (1, 0, 0));
        let r0 = report_of(host, 0);
        assert_eq!(r0.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_STOPPED);
        assert_eq!((r0.left, r0.slow), (0, 0));
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);
        leaving.join().unwrap();

        // Cycle 2: agent 0 is busy for 2 stop timeouts: waited for, reported slow.
        let c = run_cycle(host, 2);
        assert_eq!((c.cycle, c.left_agents, c.slow_agents), (2, 0, 1));
        assert_eq!(c.timed_out_agents, 0);
        let r0 = report_of(host, 0);
        assert_eq!(r0.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_STOPPED);
        assert_eq!((r0.slow, r0.left, r0.read_cycle), (1, 0, 2));
        let r1 = report_of(host, 1);
        assert_eq!(r1.outcome, vrs_host_outcome_t::VRS_HOST_OUTCOME_NOT_AWAITED);
        assert_eq!((r1.left, r1.slow), (0, 0), "a leave is reported once");
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);

        // Cycle 3: an ordinary cycle again.
        let c = run_cycle(host, 2);
        assert_eq!((c.cycle, c.left_agents, c.slow_agents), (3, 0, 0));
        assert_eq!(report_of(host, 0).slow, 0);
        assert_eq!(vrs_host_end_cycle(host), VRS_HOST_OK);

        let mut stats = MaybeUninit::<vrs_host_stats_t>::uninit();
        assert_eq!(vrs_host_stats(host, stats.as_mut_ptr()), VRS_HOST_OK);
        let s = stats.assume_init();
        assert_eq!(s.cycles, 4);
        assert_eq!((s.leaves, s.slow_stops, s.peers_refused), (1, 1, 0));
        assert_eq!((s.evictions, s.stop_timeouts, s.agent_timeouts), (0, 0, 0));
        assert_eq!(vrs_host_destroy(host), VRS_HOST_OK);
    }
    busy.join().unwrap();
}

#[test]
fn a_host_belongs_to_its_thread_and_finalizers_defer_destruction() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_config(dir.path(), "thread", 1, 1.0);
    let first = create(&path);
    let key = first.addr();
    let from_other_thread = std::thread::spawn(move || {
        let host: *mut vrs_host_t = ptr::without_provenance_mut(key);
        // SAFETY: the handle is never dereferenced.
        let start = unsafe { vrs_host_start(host) };
        let message = last_error();
        // SAFETY: as above.
        let destroy = unsafe { vrs_host_destroy(host) };
        let deferred_message = last_error();
        // SAFETY: as above.
        let again = unsafe { vrs_host_destroy(host) };
        (start, message, destroy, deferred_message, again)
    })
    .join()
    .unwrap();
    assert_eq!(from_other_thread.0, VRS_HOST_ERROR_WRONG_THREAD);
    assert!(
        from_other_thread.1.contains("another thread"),
        "{}",
        from_other_thread.1
    );
    assert_eq!(from_other_thread.2, VRS_HOST_DEFERRED);
    assert!(
        from_other_thread.3.contains("next vrs_host_ call"),
        "{}",
        from_other_thread.3
    );
    assert_eq!(
        from_other_thread.4, VRS_HOST_ERROR_INVALID_HANDLE,
        "a second destroy is a double free"
    );
    // The owner's next call destroys it: the session is free again for a new host, as
    // after a Unity domain reload whose finalizers released the old one.
    let second = create(&path);
    // SAFETY: the handles are never dereferenced.
    unsafe {
        assert_eq!(vrs_host_start(first), VRS_HOST_ERROR_INVALID_HANDLE);
        assert_eq!(vrs_host_destroy(second), VRS_HOST_OK);
    }
}

#[test]
fn panics_become_a_status() {
    let st = crate::state::boundary(|| panic!("boom"));
    assert_eq!(st, VRS_HOST_ERROR_PANIC);
    assert!(last_error().contains("boom"), "{}", last_error());
}

#[test]
fn every_outcome_has_its_own_abi_code() {
    use vrsync_bridge::AgentOutcome::*;
    let all = [Stopped, TimedOut, NotAwaited, Async, Evicted, Left];
    let codes: std::collections::HashSet<u32> = all
        .iter()
        .map(|&o| crate::state::outcome(o) as u32)
        .collect();
    assert_eq!(codes.len(), all.len());
    assert!(!codes.contains(&(vrs_host_outcome_t::VRS_HOST_OUTCOME_OTHER as u32)));
}
