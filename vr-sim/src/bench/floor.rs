//! The floor rows: the raw iceoryx2, TCP and zenoh round trips the vrsync rows are
//! compared with.

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

/// `tcp/127.0.0.1:<a port free a moment ago>`.
pub(super) fn loopback_endpoint() -> anyhow::Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("find a free loopback port")?
        .port();
    Ok(format!("tcp/127.0.0.1:{port}"))
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
