//! The floor rows: the raw iceoryx2, TCP and zenoh round trips the vrsync rows are
//! compared with, and numpy's row reads alone (`floor-numpy`) beside the Python agent.

use super::vrsync::{histogram_of, loopback_endpoint, python_bench};
use super::*;

/// The raw iceoryx2 round trip.
pub(super) fn bench_floor_shm(case: &Case, session: &str, spin: bool) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    // The same waiting strategy as vrsync with the default config (see
    // `SyncConfig::effective_spin_before_block`).
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let spin_before_block = if case.agents as usize + 1 > cores {
        Duration::ZERO
    } else {
        Duration::from_micros(vrsync_bridge::DEFAULT_SPIN_BEFORE_BLOCK_US)
    };
    let mut host = ShmFloorHost::create(session, case.agents, bytes, spin, spin_before_block)?;
    let spin_us = spin_before_block.as_micros().to_string();
    let agents = Agents::spawn(
        |id| {
            let mut a = floor_args("floor-shm", case, Some(id));
            a.extend(["--session", session, "--spin-before-block-us", &spin_us].map(String::from));
            if spin {
                a.push("--spin".into());
            }
            a
        },
        case.agents,
    )?;
    host.wait_connected(Duration::from_secs(30))?;
    let (hist, host_allocs) =
        measure_loop(
            case,
            |cycle| Ok(host.cycle(cycle, Duration::from_secs(10))?),
        )?;
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    drop(host);
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// The bench agent's arguments every floor mode takes: `--mode`, `--id` (if the mode
/// takes one), the cycles, the bytes of an image row it reads, the warm-up.
fn floor_args(mode: &str, case: &Case, id: Option<u32>) -> Vec<String> {
    let mut a = vec!["--mode".to_string(), mode.to_string()];
    if let Some(id) = id {
        a.extend(["--id".to_string(), id.to_string()]);
    }
    let row_bytes = case.width as usize * BPP;
    for (flag, value) in [
        ("--cycles", case.warmup + case.cycles),
        ("--row-bytes", row_bytes as u64),
        ("--warmup", case.warmup),
    ] {
        a.extend([flag.to_string(), value.to_string()]);
    }
    a
}

/// The raw zenoh round trip (put → subscriber → 8-byte reply, same fan-out).
pub(super) fn bench_floor_zenoh(case: &Case, session: &str) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    let endpoint = loopback_endpoint()?;
    let mut host = ZenohFloorHost::create(session, &endpoint, case.agents, bytes)?;
    let agents = Agents::spawn(
        |id| {
            let mut a = floor_args("floor-zenoh", case, Some(id));
            a.extend(["--session", session, "--endpoint", &endpoint].map(String::from));
            a
        },
        case.agents,
    )?;
    host.wait_connected(Duration::from_secs(30))?;
    let (hist, host_allocs) =
        measure_loop(
            case,
            |cycle| Ok(host.cycle(cycle, Duration::from_secs(10))?),
        )?;
    drop(host);
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// The raw TCP round trip.
pub(super) fn bench_floor_tcp(case: &Case) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    let mut host = TcpFloorHost::create(bytes)?;
    let addr = host.addr()?;
    let (addr, bytes) = (addr.to_string(), bytes.to_string());
    let agents = Agents::spawn(
        |_| {
            let mut a = floor_args("floor-tcp", case, None);
            a.extend(["--addr", &addr, "--frame-bytes", &bytes].map(String::from));
            a
        },
        case.agents,
    )?;
    host.accept(case.agents, Duration::from_secs(30))?;
    let (hist, host_allocs) = measure_loop(case, |cycle| Ok(host.cycle(cycle)?))?;
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// What `python -m vrsync.bench_numpy` writes to its `--out` file.
#[derive(Debug, serde::Deserialize)]
pub(super) struct NumpyFloorReport {
    /// Measured cycles.
    pub cycles: u64,
    /// Each measured cycle's row reads, ns.
    pub read_ns: Vec<u64>,
}

/// numpy's row reads alone (`floor-numpy`): `python -m vrsync.bench_numpy` times the
/// `python` agent's reads of `case`'s images (rgb8) on shared memory, no SDK, no host; the
/// row's "cycle" is one frame's reads.
pub(super) fn bench_floor_numpy(
    case: &Case,
    session: &str,
    dir: &Path,
    python: &Path,
) -> anyhow::Result<Measured> {
    let out = dir.join(format!("{session}-numpy.json"));
    let status = python_bench(python, "vrsync.bench_numpy", case, &out)
        .args(["--width", &case.width.to_string()])
        .args(["--height", &case.height.to_string()])
        .args(["--cameras", &case.cameras.to_string()])
        .status()
        .with_context(|| format!("start {} -m vrsync.bench_numpy", python.display()))?;
    if !status.success() {
        bail!(
            "floor-numpy: {} -m vrsync.bench_numpy failed ({status})",
            python.display()
        );
    }
    let text = std::fs::read_to_string(&out)
        .with_context(|| format!("read the numpy floor's report {}", out.display()))?;
    let _ = std::fs::remove_file(&out);
    let report: NumpyFloorReport =
        serde_json::from_str(&text).context("parse the numpy floor's report")?;
    if report.cycles != case.cycles || report.read_ns.len() as u64 != case.cycles {
        bail!(
            "floor-numpy: {} reads of {} cycles reported, {} asked for",
            report.read_ns.len(),
            report.cycles,
            case.cycles
        );
    }
    // No host and no SDK: no allocations of ours to count.
    Ok(Measured::new(
        histogram_of(&report.read_ns)?,
        f64::NAN,
        f64::NAN,
    ))
}
