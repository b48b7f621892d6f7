//! A Rust agent for any simulator's channels (`[[agent.vector]]`, `[[agent.action]]`):
//! `cargo run --example channel_agent -- CONFIG ID [SEED]`.
//!
//! Every cycle it reads each of its vectors and sends a value for each of its actions: a
//! continuous one swings between its bounds (around the middle, by the first vector's
//! first value), a discrete one steps through its choices. The values depend only on the
//! seed, the id, the cycle and what the frame holds, so runs of a deterministic world
//! repeat exactly, whatever the timing.
use vrsync_agent::{ActionSpace, Agent, Config, WaitStartError};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: channel_agent CONFIG ID [SEED]")?;
    let id: u32 = args
        .next()
        .ok_or("usage: channel_agent CONFIG ID [SEED]")?
        .parse()?;
    let seed: u32 = args.next().unwrap_or_else(|| "0".into()).parse()?;
    let config = Config::load(&path)?;
    let mut agent = Agent::connect(&config, id)?;
    let actions = agent.actions().to_vec();
    loop {
        let frame = match agent.wait_start(None) {
            Ok(frame) => frame,
            Err(WaitStartError::HostClosed) => break,
            Err(e) => return Err(e.into()),
        };
        let cycle = frame.cycle();
        // The first value of the first vector (joint readings, a speed, ...), 0 without.
        let sensed = frame
            .vector_descs()
            .first()
            .and_then(|d| frame.vector(d.name()))
            .and_then(|v| v.first().copied())
            .filter(|v| v.is_finite())
            .unwrap_or(0.0);
        drop(frame); // release the frame before the next wait
        let phase = (cycle as f32 + seed as f32 + id as f32 * 7.0) * 0.05;
        for a in &actions {
            match &a.space {
                ActionSpace::Box { low, high } => {
                    let value: Vec<f32> = low
                        .iter()
                        .zip(high)
                        .enumerate()
                        .map(|(i, (lo, hi))| {
                            let swing = (phase + i as f32).sin() - 0.1 * sensed.tanh();
                            lo + (hi - lo) * (0.5 + 0.45 * swing.clamp(-1.0, 1.0))
                        })
                        .collect();
                    agent.act(&a.name, &value)?;
                }
                ActionSpace::Discrete { n } => {
                    let choice = ((cycle / 10) as u32 + id + seed) % n;
                    agent.act_discrete(&a.name, choice)?;
                }
            }
        }
        agent.stop()?; // the actions go with the stop
    }
    Ok(())
}
