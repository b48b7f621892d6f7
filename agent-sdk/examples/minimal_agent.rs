//! A minimal Rust agent: `cargo run --example minimal_agent -- [CONFIG] [ID]`.
use vrsync_agent::glam::Vec3;
use vrsync_agent::{ActionState, Agent, Command, Config, WaitStartError};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "config/default.toml".into());
    let id: u32 = args.next().unwrap_or_else(|| "0".into()).parse()?;
    let config = Config::load(&path)?;
    let mut agent = Agent::connect(&config, id)?; // waits for the host (connect_timeout)
    let mut running: Option<u32> = None; // the action id of our current move
    loop {
        // No timeout: before cycle 0 the host waits up to its connect_timeout for the
        // other agents; a host that dies still ends the wait (WaitStartError::HostGone).
        let frame = match agent.wait_start(None) {
            Ok(frame) => frame,
            Err(WaitStartError::HostClosed) => break, // the run is over
            Err(e) => return Err(e.into()),
        };
        let left = frame.image_by_name("left").ok_or("no camera named left")?; // an Image
        let pixels: &[u8] = left.data(); // a view into the frame, no copy
        let position: Vec3 = frame.pose().position(); // glam, re-exported by vrsync_agent
        for status in frame.statuses() {
            let state = ActionState::from_u32(status.state);
            let done = matches!(state, Some(ActionState::Finished | ActionState::Aborted));
            if done && running == Some(status.action_id) {
                running = None;
            }
        }
        let turn = pixels.first().copied().unwrap_or(0) > 128 || position.x > 5.0;
        drop(frame); // release the frame (its shared memory) before the next wait
        if running.is_none() {
            let heading_deg = if turn { 270.0 } else { 90.0 };
            let command = Command::Move {
                heading_deg,
                distance: 1.0,
            };
            running = Some(agent.send(command)?); // send returns the action id
        }
        agent.stop()?; // commands + STOP for this cycle
    }
    Ok(())
}
