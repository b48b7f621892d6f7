//! A lost TCP link that comes back within the resume window (`[sync] resume_window`,
//! 30 s by default) is resumed, not ended.

use super::{Bench, FRAMES, Fault, LEASE_S, Remote};
use vrsync_bridge::tcp::LINK_TIMEOUT;

/// CI: the link cut for longer than TCP's link timeout, so that both sides declare it lost
/// (the host holds the remote agents' places, they connect again by themselves), and back
/// well within the window: the clean run's trajectory, every command applied once, nobody
/// evicted, and the agents answer within seconds of the link's return (TCP's own
/// retransmission back-off answered a 30 s partition 24 s late).
#[test]
fn a_tcp_link_lost_past_the_link_timeout_and_back_within_the_window_is_resumed() {
    let Some(bench) = Bench::new(Remote::Tcp) else {
        return;
    };
    let clean = bench.run(Fault::Clean, FRAMES, LEASE_S);
    clean.report(None);
    let secs = LINK_TIMEOUT.as_secs() + 4;
    let out = bench.run(Fault::Partition { at_cycle: 40, secs }, FRAMES, LEASE_S);
    out.report(Some(&clean));
    out.assert_intact(&clean);
    let answered = out.resumed_after_s.unwrap_or(f64::INFINITY);
    assert!(
        answered < 8.0,
        "answered {answered} s after the link returned: {out:#?}"
    );
}
