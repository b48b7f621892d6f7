//! Unit tests of loading, checking and writing configs.

use super::*;
use crate::{LegacyConfig, LegacyDialect, PngCompression, ZenohTls};

fn parse(text: &str) -> Result<Config, ConfigLoadError> {
    Config::from_toml_str(text, Path::new("test.toml"))
}

const MINIMAL: &str = "session = \"t\"\n[[agent]]\nid = 0\n";

#[test]
fn every_transport_of_the_registry_is_read_by_its_config_name() {
    // TransportKind comes from the transport registry: ALL in declaration order (the host's
    // routing indexes by `kind as usize`), one config name each, read back as that kind.
    for (i, kind) in TransportKind::ALL.into_iter().enumerate() {
        assert_eq!(kind as usize, i, "{}", kind.as_str());
        let name = kind.as_str();
        let c = parse(&format!(
            "session = \"t\"\n[transport]\nkind = \"{name}\"\n[[agent]]\nid = 0\n\
             [[agent]]\nid = 1\ntransport = \"{name}\"\n"
        ))
        .unwrap();
        assert_eq!(c.transport.kind, kind, "{name}");
        assert_eq!(c.agents[0].transport, kind, "{name}");
        assert_eq!(c.agents[1].transport, kind, "{name}");
    }
    let mut names: Vec<&str> = TransportKind::ALL.iter().map(|k| k.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), TransportKind::ALL.len());
}

#[test]
fn zenoh_tls_needs_existing_files_and_a_tls_endpoint() {
    let dir = tempfile::tempdir().unwrap();
    for f in ["ca.pem", "host.pem", "host.key"] {
        std::fs::write(dir.path().join(f), "-----BEGIN X-----\n").unwrap();
    }
    let path = dir.path().join("c.toml");
    let load = |zenoh: &str| {
        let text = format!("session = \"t\"\n[transport.zenoh]\n{zenoh}[[agent]]\nid = 0\n");
        std::fs::write(&path, text).unwrap();
        Config::load(&path)
    };
    let err = |zenoh: &str| load(zenoh).unwrap_err().to_string();
    // Relative paths resolve against the config file's folder; written back absolute.
    let files = "tls_ca = \"ca.pem\"\ntls_cert = \"host.pem\"\ntls_key = \"host.key\"\n";
    let c = load(&format!(
        "listen = [\"tls/127.0.0.1:7447\"]\nmtls = true\n{files}"
    ))
    .unwrap();
    let t = &c.transport.zenoh.tls;
    assert_eq!(t.ca.as_deref(), Some(dir.path().join("ca.pem").as_path()));
    assert_eq!(
        t.key.as_deref(),
        Some(dir.path().join("host.key").as_path())
    );
    assert!(t.mtls);
    assert_eq!(c.transport.zenoh.connect, ["tls/127.0.0.1:7447"]);
    let again = Config::from_toml_str(&c.to_toml_string(), Path::new("/elsewhere/x.toml"));
    assert_eq!(again.unwrap().transport.zenoh, c.transport.zenoh);
    // Plain tcp/ stays the default, without TLS.
    assert_eq!(
        parse(MINIMAL).unwrap().transport.zenoh.tls,
        ZenohTls::default()
    );
    // A tls/ listen endpoint without a certificate: file:line:key.
    let e = err("mtls = false\nlisten = [\"tls/127.0.0.1:7447\"]\ntls_ca = \"ca.pem\"\n");
    assert!(
        e.contains("c.toml:4: invalid `transport.zenoh.listen`"),
        "{e}"
    );
    assert!(e.contains("needs `tls_cert`"), "{e}");
    // An agent-side config: a tls/ connect endpoint needs the CA; with mtls its own pair.
    let e = err("connect = [\"tls/10.0.0.1:7447\"]\n");
    assert!(
        e.contains(":3: invalid `transport.zenoh.connect`") && e.contains("`tls_ca`"),
        "{e}"
    );
    let e = err("connect = [\"tls/10.0.0.1:7447\"]\nmtls = true\ntls_ca = \"ca.pem\"\n");
    assert!(e.contains("needs `tls_cert`") && e.contains("mtls"), "{e}");
    // A file that does not exist, named with its line and key.
    let e = err(
        "listen = [\"tls/127.0.0.1:7447\"]\ntls_cert = \"host.pem\"\ntls_key = \"missing.key\"\n",
    );
    assert!(
        e.contains("c.toml:5: invalid `transport.zenoh.tls_key`"),
        "{e}"
    );
    assert!(e.contains("missing.key is not a readable file"), "{e}");
    // Certificates with only tcp/ endpoints: refused, the traffic would be in the clear.
    let e = err("listen = [\"tcp/127.0.0.1:7447\"]\ntls_ca = \"ca.pem\"\n");
    assert!(
        e.contains("c.toml:4: invalid `transport.zenoh.tls_ca`"),
        "{e}"
    );
    assert!(e.contains("in the clear"), "{e}");
    // Another scheme is still refused.
    let e = err("listen = [\"quic/127.0.0.1:7447\"]\n");
    assert!(e.contains("not a tcp/ or tls/ endpoint"), "{e}");
}

#[test]
fn embedded_default_matches_the_documented_defaults() {
    let c = Config::embedded_default().unwrap();
    assert_eq!(c.agents.len(), 2);
    assert!(c.sync.sync_mode);
    assert_eq!(c.sync.simulation_time_per_frame, Duration::from_millis(100));
    assert_eq!(c.sync.stop_timeout, Duration::from_secs(5));
    assert_eq!(c.transport.kind, TransportKind::Shm);
    for a in &c.agents {
        assert_eq!(a.cameras.len(), 2);
        for cam in &a.cameras {
            assert_eq!((cam.width_px, cam.height_px), (256, 148));
            assert_eq!(cam.format, PixelFormat::Rgb8);
        }
    }
}

#[test]
fn the_legacy_section_takes_the_original_key_and_round_trips() {
    let c = parse(MINIMAL).unwrap();
    assert_eq!(c.transport.legacy, LegacyConfig::default());
    assert_eq!(c.transport.legacy.local_port, 1337);
    assert!(c.transport.legacy.bind.is_loopback());
    let c = parse(
        "[transport.legacy]\nLocalPort = 2000\ndialect = \"burkhardt\"\npng_compression = \"fast\"\nbind = \"0.0.0.0\"\n[[agent]]\nid = 3\ntransport = \"legacy\"\n",
    )
    .unwrap();
    let l = &c.transport.legacy;
    assert_eq!(l.local_port, 2000);
    assert_eq!(l.dialect, LegacyDialect::Burkhardt);
    assert_eq!(l.png_compression, PngCompression::Fast);
    assert_eq!(c.agents[0].transport, TransportKind::Legacy);
    let back = parse(&c.to_toml_string()).unwrap();
    assert_eq!(back.transport, c.transport);
    assert_eq!(back.agents, c.agents);
    // The agent ports must fit: local_port + 1 + 250 <= 65535.
    let err = parse("[transport.legacy]\nlocal_port = 65300\n[[agent]]\nid = 0\n").unwrap_err();
    assert!(
        err.to_string().contains("transport.legacy.local_port"),
        "{err}"
    );
    let err = parse("[transport.legacy]\nbind = \"localhost:1\"\n[[agent]]\nid = 0\n").unwrap_err();
    assert!(err.to_string().contains("transport.legacy.bind"), "{err}");
    assert!(parse("[transport.legacy]\nport = 1\n[[agent]]\nid = 0\n").is_err());
}

#[test]
fn each_agent_has_a_transport_defaulting_to_the_kind() {
    let text = "session = \"t\"\n[transport]\nkind = \"tcp\"\n\
                [[agent]]\nid = 0\ntransport = \"shm\"\n[[agent]]\nid = 1\n";
    let c = parse(text).unwrap();
    assert_eq!(c.agents[0].transport, TransportKind::Shm);
    assert_eq!(c.agents[1].transport, TransportKind::Tcp);
    // The effective config keeps each agent's choice, and resizing keeps it too.
    let again = parse(&c.to_toml_string()).unwrap();
    assert_eq!(again.agents, c.agents);
    let more = c.with_agent_count(3).unwrap();
    let kinds: Vec<_> = more.agents.iter().map(|a| a.transport).collect();
    assert_eq!(
        kinds,
        [TransportKind::Shm, TransportKind::Tcp, TransportKind::Tcp]
    );
    let err = parse("[[agent]]\nid = 0\ntransport = \"carrier-pigeon\"\n").unwrap_err();
    assert!(err.to_string().contains("transport"), "{err}");
}

#[test]
fn wait_for_stop_defaults_to_alive_and_each_agent_may_override_it() {
    let c = parse(MINIMAL).unwrap();
    assert_eq!(c.sync.wait_for_stop, None);
    assert_eq!(c.wait_for_stop(0), WaitForStop::Alive);
    assert!(c.waits_for_live_agents());
    let text = "session = \"t\"\n[sync]\nwait_for_stop = \"timeout\"\n[[agent]]\nid = 0\n\
                [[agent]]\nid = 1\nwait_for_stop = \"alive\"\n";
    let c = parse(text).unwrap();
    assert_eq!(c.sync.wait_for_stop, Some(WaitForStop::Timeout));
    assert_eq!(c.wait_for_stop(0), WaitForStop::Timeout);
    assert_eq!(c.wait_for_stop(1), WaitForStop::Alive);
    assert_eq!(
        c.wait_for_stop(9),
        WaitForStop::Timeout,
        "not an agent: the default"
    );
    assert!(c.waits_for_live_agents());
    // Round trip, and agents added by a count take the [sync] default.
    let again = parse(&c.to_toml_string()).unwrap();
    assert_eq!(again.wait_for_stop(1), WaitForStop::Alive);
    let grown = c.with_agent_count(3).unwrap();
    assert_eq!(grown.wait_for_stop(2), WaitForStop::Timeout);
    let all_timeout = parse(&text.replace("\"alive\"", "\"timeout\"")).unwrap();
    assert!(!all_timeout.waits_for_live_agents());
    // Legacy agents (original clients may block on an action's end before stopping)
    // default to "timeout", unless [sync] or the agent says otherwise.
    let legacy = "session = \"t\"\n[[agent]]\nid = 0\ntransport = \"legacy\"\n[[agent]]\nid = 1\n";
    let c = parse(legacy).unwrap();
    assert_eq!(c.wait_for_stop(0), WaitForStop::Timeout);
    assert_eq!(c.wait_for_stop(1), WaitForStop::Alive);
    let c = parse(&legacy.replace(
        "session = \"t\"\n",
        "session = \"t\"\n[sync]\nwait_for_stop = \"alive\"\n",
    ))
    .unwrap();
    assert_eq!(c.wait_for_stop(0), WaitForStop::Alive);
    expect_err(
        "[sync]\nwait_for_stop = \"forever\"\n[[agent]]\nid = 0\n",
        2,
        "sync.wait_for_stop",
    );
}

#[test]
fn resume_window_defaults_to_30_s_and_zero_turns_it_off() {
    let c = parse(MINIMAL).unwrap();
    assert_eq!(c.sync.resume_window, Duration::from_secs(30));
    let c = parse("[sync]\nresume_window = 0\n[[agent]]\nid = 0\n").unwrap();
    assert_eq!(c.sync.resume_window, Duration::ZERO);
    assert_eq!(
        parse(&c.to_toml_string()).unwrap().sync.resume_window,
        Duration::ZERO
    );
    let c = parse("[sync]\nresume_window = 2.5\n[[agent]]\nid = 0\n").unwrap();
    assert_eq!(c.sync.resume_window, Duration::from_millis(2500));
    expect_err(
        "[sync]\nresume_window = -1.0\n[[agent]]\nid = 0\n",
        2,
        "sync.resume_window",
    );
}

#[test]
fn original_names_are_aliases() {
    let c = parse("[sync]\nSyncMode = false\nSimulationTimePerFrame = 0.05\n[[agent]]\nid = 0\n")
        .unwrap();
    assert!(!c.sync.sync_mode);
    assert_eq!(c.sync.simulation_time_per_frame, Duration::from_millis(50));
}

#[test]
fn derived_height_matches_the_original() {
    assert_eq!(derived_height(256, 120.0, 90.0), 148);
    assert_eq!(derived_height(512, 120.0, 90.0), 296);
    assert_eq!(derived_height(1024, 120.0, 90.0), 591);
}

fn expect_err(text: &str, line: usize, needle: &str) {
    let e = parse(text).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("test.toml"), "{msg}");
    assert!(msg.contains(needle), "expected {needle:?} in {msg}");
    match e {
        ConfigLoadError::Parse { line: l, .. } | ConfigLoadError::Invalid { line: l, .. } => {
            assert_eq!(l, line, "{msg}")
        }
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn bad_configs_name_file_line_and_key() {
    expect_err(
        "session = \"t\"\nbogus = 1\n[[agent]]\nid = 0\n",
        2,
        "bogus",
    );
    expect_err(
        "[sync]\nsync_mode = \"yes\"\n[[agent]]\nid = 0\n",
        2,
        "sync_mode",
    );
    expect_err(
        "[sync]\nstop_timeout = -1.0\n[[agent]]\nid = 0\n",
        2,
        "sync.stop_timeout",
    );
    expect_err(
        "[sync]\nsimulation_time_per_frame = 0\n[[agent]]\nid = 0\n",
        2,
        "sync.simulation_time_per_frame",
    );
    expect_err(
        "[[agent]]\nid = 0\n[[agent]]\nid = 0\n",
        4,
        "duplicate agent id 0",
    );
    expect_err("session = \"t\"\n", 1, "agent");
    expect_err(
        "[[agent]]\nid = 0\n[[agent.camera]]\nname = \"l\"\nwidth = 0\n",
        5,
        "agent.camera.width",
    );
    expect_err(
        "[[agent]]\nid = 0\n[[agent.camera]]\nname = \"l\"\nwidth = 64\nformat = \"bgr\"\n",
        6,
        "agent.camera.format",
    );
    expect_err("[transport]\nkind = \"udp\"\n[[agent]]\nid = 0\n", 2, "udp");
    expect_err("[[agent]]\nid = 999\n", 2, "agent.id");
    expect_err("session = \"a/b\"\n[[agent]]\nid = 0\n", 1, "session");
}

#[test]
fn agent_count_override_copies_the_last_agents_cameras() {
    let c = Config::embedded_default()
        .unwrap()
        .with_agent_count(3)
        .unwrap();
    assert_eq!(c.agents.iter().map(|a| a.id).collect::<Vec<_>>(), [0, 1, 2]);
    assert_eq!(c.agents[2].cameras, c.agents[1].cameras);
    assert!(parse(MINIMAL).unwrap().with_agent_count(0).is_err());
}

#[test]
fn effective_config_round_trips() {
    let c = Config::embedded_default()
        .unwrap()
        .with_agent_count(3)
        .unwrap();
    let text = c.to_toml_string();
    let back = Config::from_toml_str(&text, Path::new("eff.toml")).unwrap();
    assert_eq!(back.agents, c.agents);
    assert_eq!(back.sync, c.sync);
    assert_eq!(back.transport, c.transport);
    assert_eq!(back.session, c.session);
    assert_eq!(back.world, c.world);
}
