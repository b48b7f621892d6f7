//! The zenoh floor: a raw zenoh put of the frame's bytes to each agent's subscriber and a
//! small reply back, with nothing of vrsync around it (explicit loopback endpoint,
//! scouting off, blocking congestion control: the zenoh transport's settings).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::sample::Sample;

use crate::floor::{FloorAgentReport, FloorError, touch_rows};

fn z(what: &str, e: impl core::fmt::Display) -> FloorError {
    FloorError::Zenoh(format!("{what}: {e}"))
}

fn session(listen: &[&str], connect: &[&str]) -> Result<zenoh::Session, FloorError> {
    let mut c = zenoh::Config::default();
    let list = |v: &[&str]| {
        let q: Vec<String> = v.iter().map(|e| format!("{e:?}")).collect();
        format!("[{}]", q.join(","))
    };
    for (key, value) in [
        ("mode", "\"peer\"".to_string()),
        ("listen/endpoints", list(listen)),
        ("connect/endpoints", list(connect)),
        ("connect/exit_on_failure", "false".into()),
        (
            "connect/retry",
            "{period_init_ms: 50, period_max_ms: 500, period_increase_factor: 2}".into(),
        ),
        ("scouting/multicast/enabled", "false".into()),
        ("scouting/gossip/enabled", "false".into()),
    ] {
        c.insert_json5(key, &value).map_err(|e| z(key, e))?;
    }
    zenoh::open(c).wait().map_err(|e| z("open", e))
}

type Pool = Arc<Mutex<Vec<Vec<u8>>>>;

/// A frame buffer lent to zenoh, back to the pool when zenoh is done with it (as the
/// zenoh transport's host does: no copy and no allocation of ours per frame).
struct Pooled {
    buf: Vec<u8>,
    pool: Pool,
}

impl AsRef<[u8]> for Pooled {
    fn as_ref(&self) -> &[u8] {
        &self.buf
    }
}

impl Drop for Pooled {
    fn drop(&mut self) {
        let buf = std::mem::take(&mut self.buf);
        if let Ok(mut pool) = self.pool.lock() {
            pool.push(buf);
        }
    }
}

/// Host side of the zenoh floor.
pub struct ZenohFloorHost {
    publishers: Vec<Publisher<'static>>,
    replies: Subscriber<FifoChannelHandler<Sample>>,
    frame_bytes: usize,
    pool: Pool,
    _session: zenoh::Session,
}

impl core::fmt::Debug for ZenohFloorHost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ZenohFloorHost")
            .field("agents", &self.publishers.len())
            .finish_non_exhaustive()
    }
}

impl ZenohFloorHost {
    /// Listens on `endpoint` (e.g. `tcp/127.0.0.1:7447`) for `agents` agents of floor
    /// session `name`, with frames of `frame_bytes`.
    ///
    /// # Errors
    /// [`FloorError::Zenoh`].
    pub fn create(
        name: &str,
        endpoint: &str,
        agents: u32,
        frame_bytes: usize,
    ) -> Result<Self, FloorError> {
        let session = session(&[endpoint], &[])?;
        let publishers = (0..agents)
            .map(|id| {
                session
                    .declare_publisher(format!("vrsync-floor/{name}/{id}/frame"))
                    .congestion_control(CongestionControl::Block)
                    .wait()
                    .map_err(|e| z("publisher", e))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let replies = session
            .declare_subscriber(format!("vrsync-floor/{name}/*/reply"))
            .wait()
            .map_err(|e| z("subscriber", e))?;
        Ok(Self {
            publishers,
            replies,
            frame_bytes,
            pool: Pool::default(),
            _session: session,
        })
    }

    /// Waits until every agent's subscriber matches.
    ///
    /// # Errors
    /// [`FloorError`].
    pub fn wait_connected(&mut self, timeout: Duration) -> Result<(), FloorError> {
        let deadline = Instant::now() + timeout;
        for p in &self.publishers {
            loop {
                let matched = p
                    .matching_status()
                    .wait()
                    .map_err(|e| z("matching status", e))?;
                if matched.matching() {
                    break;
                }
                if Instant::now() >= deadline {
                    return Err(FloorError::Timeout(timeout));
                }
                // No event to wait on before the agents exist: poll (bench set-up only).
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        Ok(())
    }

    /// One round trip: the frame bytes to every agent, an 8-byte reply from each.
    ///
    /// # Errors
    /// [`FloorError`].
    pub fn cycle(&mut self, cycle: u64, timeout: Duration) -> Result<(), FloorError> {
        let mut buf = self
            .pool
            .lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_else(|| vec![0u8; self.frame_bytes]);
        let n = buf.len().min(8);
        buf[..n].copy_from_slice(&cycle.to_le_bytes()[..n]);
        let pool = self.pool.clone();
        // One buffer for every agent (the fan-out): zenoh copies it into each link's
        // batches.
        let payload = ZBytes::from(bytes::Bytes::from_owner(Pooled { buf, pool }));
        for p in &self.publishers {
            p.put(payload.clone()).wait().map_err(|e| z("put", e))?;
        }
        let deadline = Instant::now() + timeout;
        for _ in 0..self.publishers.len() {
            match self.replies.recv_deadline(deadline) {
                Ok(Some(_)) => {}
                Ok(None) => return Err(FloorError::Timeout(timeout)),
                Err(e) => return Err(z("reply", e)),
            }
        }
        Ok(())
    }
}

/// Agent side of the zenoh floor: receives `cycles` frames on its key, reads every row,
/// replies with 8 bytes.
///
/// # Errors
/// [`FloorError`].
pub fn zenoh_floor_agent(
    name: &str,
    endpoint: &str,
    id: u32,
    cycles: u64,
    warmup: u64,
    row_len: usize,
    timeout: Duration,
) -> Result<FloorAgentReport, FloorError> {
    let session = session(&[], &[endpoint])?;
    let frames = session
        .declare_subscriber(format!("vrsync-floor/{name}/{id}/frame"))
        .wait()
        .map_err(|e| z("subscriber", e))?;
    let reply = session
        .declare_publisher(format!("vrsync-floor/{name}/{id}/reply"))
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| z("publisher", e))?;
    let mut sum = 0u64;
    let mut allocs_at_warmup = None;
    for cycle in 0..cycles {
        if cycle == warmup {
            allocs_at_warmup = Some((vrsync_alloc_count::allocations(), cycle));
        }
        let sample = match frames.recv_timeout(timeout) {
            Ok(Some(s)) => s,
            Ok(None) => return Err(FloorError::Timeout(timeout)),
            Err(e) => return Err(z("frame", e)),
        };
        // Contiguous as zenoh delivers it (a copy only if it arrives in pieces).
        let bytes = sample.payload().to_bytes();
        sum = sum.wrapping_add(touch_rows(&bytes, row_len));
        reply
            .put(sum.to_le_bytes().to_vec())
            .wait()
            .map_err(|e| z("reply", e))?;
    }
    Ok(FloorAgentReport::new(sum, allocs_at_warmup, cycles))
}
