//! The vrsync rows: full sync cycles through the host API with bench agents (Rust,
//! Python, the Python vector env) over every transport, and through the Python host API
//! (`python-host`) with Rust bench agents.

use super::*;

/// Render work per measurement of [`measure_render`]: about this many rays (at least one
/// timed render, at most [`MAX_RENDERS`]).
const RENDER_RAYS: u64 = 40_000_000;
/// The most timed renders of one [`measure_render`].
const MAX_RENDERS: u64 = 15;

/// Renders every agent's frame into loaned (never published) samples, a few times: what
/// the simulator would add to each cycle, µs per cycle. One render first, not timed (the
/// pool's threads start, the samples' pages are touched the first time), then the
/// median of the timed ones (one render preempted by another process cannot move it).
pub(super) fn measure_render(config: &Config, host: &mut Host) -> anyhow::Result<f64> {
    Ok(median(&render_times(config, host)?))
}

/// The timed renders of [`measure_render`], µs each.
pub(super) fn render_times(config: &Config, host: &mut Host) -> anyhow::Result<Vec<f64>> {
    let world = crate::world::World::from_config(config)?;
    let mut renderer = crate::render::Renderer::new(0)?;
    let rays: u64 = world
        .bodies()
        .iter()
        .flat_map(|b| b.cameras())
        .map(|c| u64::from(c.width_px) * u64::from(c.height_px))
        .sum();
    let n = (RENDER_RAYS / rays.max(1)).clamp(1, MAX_RENDERS);
    let ids: Vec<u32> = host.agent_ids().collect();
    let mut times_us = Vec::new();
    for i in 0..=n {
        let mut total = Duration::ZERO;
        // In batches, as `vr-sim run` renders.
        for batch in ids.chunks(renderer.agents_per_batch()) {
            let mut frames = Vec::with_capacity(batch.len());
            for &id in batch {
                frames.push((id, host.loan_frame(id)?));
            }
            let t0 = Instant::now();
            renderer.render_agents(
                &world,
                frames.iter_mut().map(|(id, f)| (*id, f.images_mut())),
            );
            total += t0.elapsed();
        }
        if i > 0 {
            times_us.push(total.as_secs_f64() * 1e6);
        }
    }
    Ok(times_us)
}

/// A CA and one certificate (naming 127.0.0.1, for server and client use) for the
/// `zenoh-tls` rows, in `dir`: `ca.pem`, `bench.pem`, `bench.key`.
pub(super) fn make_certificates(dir: &Path) -> anyhow::Result<()> {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair,
    };
    let mut p = CertificateParams::new(Vec::<String>::new())?;
    p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    p.distinguished_name
        .push(DnType::CommonName, "vrsync bench CA");
    let ca = CertifiedIssuer::self_signed(p, KeyPair::generate()?)?;
    let mut p = CertificateParams::new(vec!["127.0.0.1".to_string()])?;
    p.distinguished_name
        .push(DnType::CommonName, "vrsync bench");
    p.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    let key = KeyPair::generate()?;
    let cert = p.signed_by(&key, &ca)?;
    for (name, text) in [
        ("ca.pem", ca.pem()),
        ("bench.pem", cert.pem()),
        ("bench.key", key.serialize_pem()),
    ] {
        std::fs::write(dir.join(name), text).with_context(|| format!("write {name}"))?;
    }
    Ok(())
}

/// `transport.zenoh.lease` of every case with zenoh agents (`zenoh`, `zenoh-tls`,
/// `mixed`), s: zenoh's own default, as in `floor-zenoh` (vrsync's default is 2). At 4
/// agents x 3x1920x1080 (56 MB per frame, 5 processes on 2 cores) some cycles take over
/// 2 s (p99 2.6 s measured with TLS): with a 2 s lease an agent's link was closed mid-run
/// in 3 of 4 `zenoh-tls` runs, and once in a plain `zenoh` run, which failed the bench.
pub(super) const ZENOH_LEASE_S: f64 = 10.0;

/// The `mixed` rows' transports, agent by agent (cycling): one host serving agents over
/// shared memory, TCP and zenoh at once.
pub(super) const MIXED: [&str; 4] = ["shm", "shm", "tcp", "zenoh"];

/// The config of `case`; `certs`: the folder of [`make_certificates`] (`zenoh-tls`).
pub(super) fn config_text(case: &Case, session: &str, certs: &Path) -> String {
    let (kind, wait) = match case.transport {
        "tcp" => ("tcp", "block"),
        "zenoh" | "zenoh-tls" => ("zenoh", "block"),
        "shm-spin" => ("shm", "spin"),
        _ => ("shm", "block"),
    };
    let mixed = case.transport == "mixed";
    let mut s = format!(
        "session = {session:?}\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n\
         stop_timeout = 10.0\nconnect_timeout = 30.0\nwait = {wait:?}\n[transport]\nkind = {kind:?}\n\
         tcp_listen = \"127.0.0.1:0\"\nmax_commands_per_cycle = 8\n"
    );
    if case.transport == "python-vec-stacked" {
        s += "[transport.shm]\nstacked_images = true\n";
    }
    if kind == "zenoh" || mixed {
        // Loopback, a port free a moment ago (zenoh's stable API cannot report the port
        // of a port-0 listener), scouting off (the default).
        let endpoint = loopback_endpoint().unwrap_or_default();
        s += &format!("[transport.zenoh]\nlease = {ZENOH_LEASE_S:.1}\n");
        if case.transport == "zenoh-tls" {
            // Mutual TLS: host and agents share the config, hence the certificate.
            let file = |name: &str| certs.join(name).display().to_string();
            s += &format!(
                "listen = [{:?}]\ntls_ca = {:?}\ntls_cert = {:?}\ntls_key = {:?}\nmtls = true\n",
                endpoint.replacen("tcp/", "tls/", 1),
                file("ca.pem"),
                file("bench.pem"),
                file("bench.key")
            );
        } else {
            s += &format!("listen = [{endpoint:?}]\n");
        }
    }
    for id in 0..case.agents {
        s += &format!("[[agent]]\nid = {id}\n");
        if mixed {
            let transport = MIXED[id as usize % MIXED.len()];
            s += &format!("transport = {transport:?}\n");
        }
        for c in 0..case.cameras {
            s += &format!(
                "[[agent.camera]]\nname = \"c{c}\"\nwidth = {}\nheight = {}\nformat = \"rgb8\"\n",
                case.width, case.height
            );
        }
    }
    s
}

/// The interpreter for the Python rows (`python`, `python-vec`, `python-host`), if it can
/// import `vrsync`'s bench modules (else the rows are left out, saying why).
pub(super) fn python_agent(python: Option<&Path>) -> Option<PathBuf> {
    let python = python?;
    let ok = Command::new(python)
        .args([
            "-c",
            "import vrsync.bench_agent, vrsync.bench_numpy, vrsync.bench_vector, \
             vrsync.bench_host",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Some(python.to_path_buf())
    } else {
        println!(
            "python rows left out: {} cannot import vrsync (pip install ./agent-sdk/python, \
             or give --python)",
            python.display()
        );
        None
    }
}

/// A full vrsync cycle through the host API.
pub(super) fn bench_vrsync(
    case: &Case,
    session: &str,
    dir: &Path,
    render: bool,
    python: Option<&Path>,
) -> anyhow::Result<Measured> {
    let text = config_text(case, session, dir);
    let mut config = Config::from_toml_str(&text, Path::new("<bench>"))?;
    let mut host = Host::builder(&config)
        .signal_handling(SignalHandling::Install)
        .create()
        .context("create the bench host")?;
    if let Some(addr) = host.tcp_local_addr() {
        config.transport.tcp_listen = addr;
    }
    let path = dir.join(format!("{session}.toml"));
    std::fs::write(&path, config.to_toml_string()).context("write the bench config")?;
    // Before the agents exist: nothing else competes for the cores (spinning agents would).
    let render_us = if render {
        measure_render(&config, &mut host)?
    } else {
        f64::NAN
    };
    let agents = spawn_agents(case, &path, python)?;
    // The agents' start-up (a Python interpreter importing numpy, 16 processes on 2
    // cores) happens here, before cycle 0; the warm-up cycles follow.
    host.wait_for_agents(Duration::from_secs(60))?;
    let (hist, host_allocs) = measure_cycles(case, &mut host)?;
    drop(host);
    let reported = agents.finish()?;
    let _ = std::fs::remove_file(&path);
    let mut m = Measured::new(hist, host_allocs, reported.allocs_per_cycle);
    m.render_us = render_us;
    if !reported.sdk_us_per_agent_step.is_nan() {
        m.round_sdk_us.push(reported.sdk_us_per_agent_step);
    }
    Ok(m)
}

/// What `python -m vrsync.bench_host` writes to its `--out` file (the fields `vr-sim
/// bench` reads; its module doc lists them all).
#[derive(Debug, serde::Deserialize)]
pub(super) struct PythonHostReport {
    /// Agents the host served.
    pub agents: u32,
    /// Measured cycles.
    pub cycles: u64,
    /// Each measured cycle's round trip (first loan to the end of `collect`), ns.
    pub round_trip_ns: Vec<u64>,
    /// The host's own wall time (outside `collect`) per agent and cycle, µs (mean over
    /// the measured cycles; `null` if none were measured).
    pub host_us_per_agent_cycle: Option<f64>,
    /// The host thread's CPU time in the same parts, per agent and cycle, µs (mean;
    /// `null` if none were measured, absent from a report of an older `vrsync`).
    #[serde(default)]
    pub host_cpu_us_per_agent_cycle: Option<f64>,
}

impl PythonHostReport {
    /// Reads the report of a `python-host` measurement of `case`.
    ///
    /// # Errors
    /// Malformed JSON, or other agent or cycle counts than `case` asked for.
    pub(super) fn parse(text: &str, case: &Case) -> anyhow::Result<Self> {
        let r: Self = serde_json::from_str(text).context("parse the Python host's report")?;
        if r.agents != case.agents || r.cycles != case.cycles {
            bail!(
                "the Python host measured {} cycles of {} agents, not {} of {}",
                r.cycles,
                r.agents,
                case.cycles,
                case.agents
            );
        }
        if r.round_trip_ns.len() as u64 != r.cycles {
            bail!(
                "the Python host's report has {} round trips for {} cycles",
                r.round_trip_ns.len(),
                r.cycles
            );
        }
        Ok(r)
    }

    /// The round trips as a histogram, the host's own wall time as the row's SDK time and
    /// its CPU time as the row's host CPU time (host allocations: not counted in a Python
    /// process, NaN).
    pub(super) fn measured(&self, agent_allocs: f64) -> anyhow::Result<Measured> {
        let mut m = Measured::new(histogram_of(&self.round_trip_ns)?, f64::NAN, agent_allocs);
        if let Some(us) = self.host_us_per_agent_cycle.filter(|us| us.is_finite()) {
            m.round_sdk_us.push(us);
        }
        if let Some(us) = self.host_cpu_us_per_agent_cycle.filter(|us| us.is_finite()) {
            m.round_host_cpu_us.push(us);
        }
        Ok(m)
    }
}

/// A histogram of the times a Python bench module reported, ns.
pub(super) fn histogram_of(ns: &[u64]) -> anyhow::Result<Histogram<u64>> {
    let mut hist = histogram()?;
    for &t in ns {
        hist.record(t.max(1)).context("record")?;
    }
    Ok(hist)
}

/// `python -m <module> --warmup W --cycles C --out <out>` for `case` (a Python bench
/// module that writes its measurements to `out`), its output to nowhere, its errors to
/// ours.
pub(super) fn python_bench(python: &Path, module: &str, case: &Case, out: &Path) -> Command {
    let mut command = Command::new(python);
    command
        .args(["-m", module])
        .args(["--warmup", &case.warmup.to_string()])
        .args(["--cycles", &case.cycles.to_string()])
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::inherit());
    command
}

/// A child process killed (and reaped) on drop unless it was waited for.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

/// A `python-host` cycle: the same `vr-bench-agent` processes as the `shm` rows, served by
/// `python -m vrsync.bench_host` (a `vrsync.Host` in a Python process doing the Rust bench
/// host's work) instead of vr-sim's Rust host. The Python host measures the cycles and
/// writes them to a JSON file; its own time per agent-cycle becomes the row's
/// `sdk_us_per_agent_step`.
pub(super) fn bench_python_host(
    case: &Case,
    session: &str,
    dir: &Path,
    python: &Path,
) -> anyhow::Result<Measured> {
    let path = dir.join(format!("{session}.toml"));
    std::fs::write(&path, config_text(case, session, dir)).context("write the bench config")?;
    let out = dir.join(format!("{session}.json"));
    let host = python_bench(python, "vrsync.bench_host", case, &out)
        .arg("--config")
        .arg(&path)
        .spawn()
        .with_context(|| format!("start {} -m vrsync.bench_host", python.display()))?;
    let mut host = KillOnDrop(host);
    // The agents retry until a host serves the session, whichever starts first.
    let agents = spawn_agents(case, &path, None)?;
    // The Python host has its own deadlines (60 s for the agents, the config's stop
    // timeout per cycle) and exits 1 when one passes.
    let status = host.0.wait().context("wait for the Python host")?;
    if !status.success() {
        bail!(
            "python-host agents={}: the Python host failed ({status})",
            case.agents
        );
    }
    let reported = agents.finish()?;
    let text = std::fs::read_to_string(&out)
        .with_context(|| format!("read the Python host's report {}", out.display()))?;
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_file(&path);
    PythonHostReport::parse(&text, case)?.measured(reported.allocs_per_cycle)
}

/// The bench agents of `case` on the config at `config`: `vr-bench-agent` processes, or
/// the Python agent (`python`), or one Python vector-env process (`python-vec`,
/// `python-loop`).
pub(super) fn spawn_agents(
    case: &Case,
    config: &Path,
    python: Option<&Path>,
) -> anyhow::Result<Agents> {
    let config_arg = config.display().to_string();
    let args = |words: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = words.iter().map(|w| (*w).to_string()).collect();
        a.extend(["--config".to_string(), config_arg.clone()]);
        a
    };
    let warmup = case.warmup.to_string();
    match python {
        // One Python process drives every agent through the batched vector env, doing
        // the same work per agent (`python-loop`: served by `vr-sim run`'s loop).
        Some(python)
            if matches!(
                case.transport,
                "python-vec" | "python-vec-stacked" | "python-loop"
            ) =>
        {
            Agents::spawn_program(
                python,
                |_| args(&["-m", "vrsync.bench_vector", "--warmup", &warmup]),
                1,
            )
        }
        // The Python agent does the Rust agent's work (first and last byte of every row,
        // one command, stop) through the Python SDK.
        Some(python) if case.transport == "python" => Agents::spawn_program(
            python,
            |id| args(&["-m", "vrsync.bench_agent", "--id", &id.to_string()]),
            case.agents,
        ),
        _ => Agents::spawn(
            |id| {
                args(&[
                    "--mode",
                    "sdk",
                    "--id",
                    &id.to_string(),
                    "--warmup",
                    &warmup,
                ])
            },
            case.agents,
        ),
    }
}

/// Runs the warm-up and measured cycles of `case` (every agent connected): the histogram
/// of the measured cycles (ns) and the host's allocations per measured cycle.
fn measure_cycles(case: &Case, host: &mut Host) -> anyhow::Result<(Histogram<u64>, f64)> {
    let ids: Vec<u32> = host.agent_ids().collect();
    measure_loop(case, |cycle| {
        for &id in &ids {
            let mut frame = host.loan_frame(id)?;
            // The host's part of "rendering": mark each image (the frame is already in
            // shared memory; nothing is copied).
            for image in frame.images_mut() {
                if let Some(b) = image.data.first_mut() {
                    *b = cycle as u8;
                }
            }
            host.publish(frame)?;
        }
        host.start()?;
        if host.collect()?.timed_out {
            bail!(
                "{} agents={} {}x{}: cycle {cycle} timed out",
                case.transport,
                case.agents,
                case.width,
                case.height
            );
        }
        Ok(())
    })
}

/// `tcp/127.0.0.1:<a port free a moment ago>`.
pub(super) fn loopback_endpoint() -> anyhow::Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("find a free loopback port")?
        .port();
    Ok(format!("tcp/127.0.0.1:{port}"))
}
