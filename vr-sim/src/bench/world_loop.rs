//! The whole-loop rows (`python-loop`): `vr-sim run`'s own loop (sensors, rendering every
//! agent's images, publish, start, collect, apply, the world's step) serving one Python
//! process that steps every agent through the vector env (`vrsync.bench_vector`), against
//! the time the same renderer needs for the same images alone, measured in the same
//! round just before and just after.

use super::vrsync::{config_text, render_times, spawn_agents};
use super::*;
use crate::events::Events;
use crate::run::{CycleTimes, RunOptions, run_observed};

/// One round of a `python-loop` case: renders the cycle's images alone (a host of its
/// own, before any agent process exists), runs `vr-sim run`'s loop for the case's
/// warm-up and measured cycles with `python -m vrsync.bench_vector` as the agents, and
/// renders alone again once they left: the render alone is the median of both sets
/// (another process that takes a core for a while hits one of them, not the row).
pub(super) fn bench_python_loop(
    case: &Case,
    session: &str,
    dir: &Path,
    python: &Path,
) -> anyhow::Result<Measured> {
    let text = config_text(case, session, dir);
    let config = Config::from_toml_str(&text, Path::new("<bench>"))?;
    let render_alone = |config: &Config| -> anyhow::Result<Vec<f64>> {
        let mut host = Host::builder(config)
            .signal_handling(SignalHandling::Install)
            .create()
            .context("create the host of the render-alone measurement")?;
        render_times(config, &mut host)
    };
    let mut render_alone_us = render_alone(&config)?;
    let path = dir.join(format!("{session}.toml"));
    std::fs::write(&path, config.to_toml_string()).context("write the bench config")?;
    let agents = spawn_agents(case, &path, Some(python))?;
    let mut cycles = LoopCycles::new(case)?;
    let opts = RunOptions {
        config: config.clone(),
        agent_config_path: path.clone(),
        frames: Some(case.warmup + case.cycles),
        spawn: false,
        agent_args: Vec::new(),
        record: None,
        progress: false,
        map: None,
        dump_frames: None,
        // One per core, bound to its CPU: `vr-sim run`'s defaults, and `measure_render`'s.
        render_threads: 0,
        render_affinity: crate::render::Affinity::Auto,
        rerun: None,
    };
    let summary = run_observed(opts, &mut Events::disabled(), |t| cycles.observe(t))
        .with_context(|| format!("python-loop agents={}: the run failed", case.agents))?;
    if summary.stop_timeouts > 0 {
        bail!(
            "python-loop agents={}: {} stop timeouts",
            case.agents,
            summary.stop_timeouts
        );
    }
    let reported = agents.finish()?;
    let _ = std::fs::remove_file(&path);
    render_alone_us.extend(render_alone(&config)?);
    cycles.measured(median(&render_alone_us), reported)
}

/// The measured cycles of a `python-loop` round, as `run_observed` reports them.
struct LoopCycles {
    warmup: u64,
    seen: u64,
    hist: Histogram<u64>,
    total: Duration,
    frame1: Duration,
    render: Duration,
    collect: Duration,
    /// The host's allocation count when the warm-up ended.
    allocs_at_warmup: u64,
    allocs_at_end: u64,
}

impl LoopCycles {
    fn new(case: &Case) -> anyhow::Result<Self> {
        Ok(Self {
            warmup: case.warmup,
            seen: 0,
            hist: histogram()?,
            total: Duration::ZERO,
            frame1: Duration::ZERO,
            render: Duration::ZERO,
            collect: Duration::ZERO,
            allocs_at_warmup: 0,
            allocs_at_end: 0,
        })
    }

    fn observe(&mut self, t: &CycleTimes) {
        self.seen += 1;
        if self.seen == self.warmup {
            self.allocs_at_warmup = allocations();
        }
        if self.seen <= self.warmup {
            return;
        }
        // A value beyond the histogram's range is left out (10 minutes per cycle).
        let _ = self.hist.record(t.total.as_nanos().max(1) as u64);
        self.total += t.total;
        self.frame1 += t.frame1;
        self.render += t.render;
        self.collect += t.collect;
        self.allocs_at_end = allocations();
    }

    fn measured(self, render_alone_us: f64, reported: Reported) -> anyhow::Result<Measured> {
        let n = self.hist.len();
        if n == 0 {
            bail!("python-loop: no cycle measured");
        }
        let per_cycle_us = |d: Duration| d.as_secs_f64() * 1e6 / n as f64;
        let allocs = self.allocs_at_end.saturating_sub(self.allocs_at_warmup) as f64 / n as f64;
        let mut m = Measured::new(self.hist, allocs, reported.allocs_per_cycle);
        m.render_us = render_alone_us;
        m.round_render_us.push(render_alone_us);
        m.round_loop_render_us.push(per_cycle_us(self.render));
        m.round_loop_publish_us
            .push(per_cycle_us(self.frame1.saturating_sub(self.render)));
        let frame2_rest = self
            .total
            .saturating_sub(self.frame1)
            .saturating_sub(self.collect);
        m.round_loop_rest_us.push(per_cycle_us(frame2_rest));
        m.round_loop_wait_us.push(per_cycle_us(self.collect));
        if !reported.sdk_us_per_agent_step.is_nan() {
            m.round_sdk_us.push(reported.sdk_us_per_agent_step);
        }
        Ok(m)
    }
}
