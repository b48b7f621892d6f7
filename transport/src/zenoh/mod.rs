//! The zenoh transport: agents on other machines, over an existing distributed engine
//! (Eclipse zenoh) instead of a network protocol of our own.
//!
//! # Keys (all under `vrsync/<session>/`)
//!
//! | key | what | writer → reader |
//! |---|---|---|
//! | `hello` | queryable: the hello ([`super::record::encode_hello`]) as the query's payload; the reply is a welcome or a refusal | agent → host → agent |
//! | `host/alive` | liveliness token: the host is there | host |
//! | `host/closed` | liveliness token declared when the host closes the session cleanly, before `host/alive` goes | host |
//! | `agent/<id>/alive/<nonce>` | liveliness token of an admitted agent (`nonce` from its welcome) | agent |
//! | `agent/<id>/sensors` | the sensor frame: `SensorHeader` bytes then the images; the frame of cycle *f* is its start | host → agent |
//! | `agent/<id>/motor` | a motor batch: `MotorHeader` then the commands; the stop flag ends the agent's cycle | agent → host |
//! | `agent/<id>/beat` | empty, every lease / 4: the agent's process lives (tells a silent link from a closed connection); [`CLOSED_BEAT`] once: the agent saw `host/closed` | agent → host |
//!
//! # Presence
//! The host treats an agent as connected only once it answered its hello with a welcome,
//! the agent's liveliness token with that welcome's nonce exists, and the host's sensor
//! publisher of that agent matches a subscriber. A vanished token (the agent's process
//! died: at once; its link was lost: after the `lease`) evicts it; a new hello and token
//! rejoin it at the next cycle. Agents see `host/closed` as a clean close; the host's
//! `host/alive` token vanishing without it as a lost link (see below), "host gone" once
//! the resume window passed (at once without a window).
//!
//! # A clean close
//! The host declares `host/closed`, then waits until every connected agent confirmed it
//! ([`CLOSED_BEAT`]) or its token went, at most the lease, and only then lets `host/alive`
//! go and closes its session. zenoh sends declarations in order on a link, but a session's
//! close flushes its queue for at most a keep-alive period (lease / 4) per batch: on a
//! link that just came back from a partition (TCP still backing off) the close could
//! otherwise end the link before `host/closed` is through, and the agent would take the
//! close for a lost link and wait for its window.
//!
//! # A lost link (`[sync] resume_window`)
//! With a resume window (30 s by default), an agent whose token vanishes without a leave
//! batch is not let go at once. If the host heard nothing from it for at least half the
//! lease (a live agent beats every lease / 4: zenoh's lease ran out on the host's side, a
//! partition, heavy loss) the host holds its place for the window. If it was heard from
//! until then (its process was killed, or its link stalled one way and its own side
//! closed it first: its session connects again at once), the place is held for the lease
//! (at least 2 s), then the agent is evicted. A held agent counts as connected meanwhile (in sync mode the cycle waits for it), frames published to
//! it are kept (the newest), and the batches that arrived before the link went stay. The
//! agent's zenoh session connects again by itself (its `connect` endpoints are retried
//! every 0.5 s at most, each attempt bounded by zenoh's open timeout, 10 s) and declares
//! its token (the same nonce) and subscriber again on the new link; once both are there the
//! agent is back: the frame published last goes out again unless its stop arrived, and a
//! stop that arrives twice is applied once. A hello of the same id within the window (a
//! restarted agent) takes the place back the same way. Past the window the host evicts it
//! (`on_agent_lost`) and the world goes on; when it is back it rejoins at the next cycle.
//! The agent, seeing the host's token vanish without `host/closed`, waits for it to come
//! back for the window (its waits see a live host), and gives up (host gone) once the
//! window passed: a killed host is thus gone for its agents after the window. A graceful
//! leave (a leave batch) frees the place at once, as without a window.
//!
//! # What is validated
//! Everything received is checked as over TCP: a hello is decoded by the TCP decoder
//! (bounded); a motor batch longer than the largest the config allows, or not a header
//! plus exactly `command_count` commands, or naming another agent, or from an agent that is
//! not connected, is dropped, counted ([`ZenohHostStats`]) and logged (a warning at the
//! 1st, 2nd, 4th, … of each kind); at most [`MAX_QUEUED_BATCHES`] batches wait per agent
//! (a flood beyond is dropped the same way; stops have as much room again, so an agent's
//! own flood does not lose its stop). Refused hellos reach the host's
//! [`super::HostConnections::take_refusals`]. Received bytes are copied into buffers
//! allocated up front; no allocation follows a length read from the network. zenoh's own
//! reassembly buffer on the host is bounded by `transport/link/rx/max_message_size`.
//!
//! # Copies
//! Host: the simulator renders into a pooled buffer that zenoh sends from (no copy of
//! ours); zenoh copies it into its transmission batches (64 KiB fragments). Agent: zenoh
//! reassembles the fragments into one buffer, which the agent keeps and reads in place; a
//! frame that arrives in several pieces is copied once into a pooled buffer.
//!
//! # Waking
//! Every callback (a batch, a token, a match) writes an `eventfd` that the host's (and
//! agent's) wait polls: no polling loop, and a host serving agents over several
//! transports waits for all of them at once (the eventfd is zenoh's
//! [`super::HostReadiness::activity_fd`]).

use std::os::fd::RawFd;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use crate::config::Config;

mod agent;
mod host;
mod host_state;
pub(crate) mod section;
mod tls_refusals;

pub use agent::*;
pub use host::*;
pub use host_state::ZenohHostStats;
pub use section::{DEFAULT_ZENOH_ENDPOINT, ZenohConfig, ZenohTls};
pub use tls_refusals::tls_refusal_layer;

/// Most batches that may wait per agent between two drains; more are dropped (a flood),
/// except batches with the stop flag, which may fill as many again.
pub const MAX_QUEUED_BATCHES: usize = 256;
/// Most batches handed to the sink per agent in one drain.
pub const MAX_BATCHES_PER_DRAIN: usize = 256;
/// The payload of the beat an agent sends once it saw `host/closed`: the host's clean
/// close waits for it (an ordinary beat is empty).
pub const CLOSED_BEAT: &[u8] = b"closed";
/// Bytes of a welcome reply body: protocol version, layout hash, largest frame, nonce.
pub const WELCOME_LEN: usize = 4 + 8 + 4 + 8;

/// First 4 bytes of a hello reply.
pub mod reply {
    /// Welcome: protocol version u32, layout hash u64, largest frame body u32, nonce u64.
    pub const WELCOME: u32 = 2;
    /// Refusal: the TCP transport's reject body ([`super::super::record::Reject`]).
    pub const REJECT: u32 = 3;
}

/// The key expressions of one session.
#[derive(Debug, Clone)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    /// The keys of `session`.
    pub fn new(session: &str) -> Self {
        Self {
            prefix: format!("vrsync/{session}"),
        }
    }

    /// `vrsync/<session>/hello`.
    pub fn hello(&self) -> String {
        format!("{}/hello", self.prefix)
    }

    /// `vrsync/<session>/host/alive`.
    pub fn host_alive(&self) -> String {
        format!("{}/host/alive", self.prefix)
    }

    /// `vrsync/<session>/host/closed`.
    pub fn host_closed(&self) -> String {
        format!("{}/host/closed", self.prefix)
    }

    /// `vrsync/<session>/host/*`.
    pub fn host_any(&self) -> String {
        format!("{}/host/*", self.prefix)
    }

    /// `vrsync/<session>/agent/<id>/sensors`.
    pub fn sensors(&self, id: u32) -> String {
        format!("{}/agent/{id}/sensors", self.prefix)
    }

    /// `vrsync/<session>/agent/<id>/motor`.
    pub fn motor(&self, id: u32) -> String {
        format!("{}/agent/{id}/motor", self.prefix)
    }

    /// `vrsync/<session>/agent/*/motor`.
    pub fn motor_any(&self) -> String {
        format!("{}/agent/*/motor", self.prefix)
    }

    /// `vrsync/<session>/agent/<id>/beat`.
    pub fn beat(&self, id: u32) -> String {
        format!("{}/agent/{id}/beat", self.prefix)
    }

    /// `vrsync/<session>/agent/*/beat`.
    pub fn beat_any(&self) -> String {
        format!("{}/agent/*/beat", self.prefix)
    }

    /// `vrsync/<session>/agent/<id>/alive/<nonce>`.
    pub fn agent_alive(&self, id: u32, nonce: u64) -> String {
        format!("{}/agent/{id}/alive/{nonce}", self.prefix)
    }

    /// `vrsync/<session>/agent/*/alive/*`.
    pub fn agent_alive_any(&self) -> String {
        format!("{}/agent/*/alive/*", self.prefix)
    }

    /// The agent id in `…/agent/<id>/<rest>` (and the nonce after `alive/`), if the key
    /// has that shape.
    pub fn parse_agent(&self, key: &str) -> Option<(u32, Option<u64>)> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix("/agent/")?;
        let mut parts = rest.split('/');
        let id = parse_decimal(parts.next()?)?;
        let id = u32::try_from(id).ok()?;
        let nonce = match (parts.next(), parts.next()) {
            (Some("alive"), Some(n)) => Some(parse_decimal(n)?),
            _ => None,
        };
        Some((id, nonce))
    }
}

/// A short decimal number (at most 20 digits), nothing else.
fn parse_decimal(s: &str) -> Option<u64> {
    if s.is_empty() || s.len() > 20 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// The zenoh session configuration of one side: peer mode, scouting as configured (off by
/// default), explicit endpoints, the lease, TLS certificates (the host's as the listen
/// side's, an agent's as the connect side's), and — on the host — a bound on what one
/// message may grow to while zenoh reassembles it.
///
/// # Errors
/// zenoh's message for a key it rejects.
pub(crate) fn session_config(
    config: &Config,
    listen: &[String],
    connect: &[String],
    max_rx_message: Option<usize>,
) -> Result<::zenoh::Config, String> {
    let z = &config.transport.zenoh;
    let mut c = ::zenoh::Config::default();
    let json = |v: &[String]| {
        let quoted: Vec<String> = v.iter().map(|e| format!("{e:?}")).collect();
        format!("[{}]", quoted.join(","))
    };
    let lease_ms = z.lease.as_millis().max(100);
    let mut set = |key: &str, value: String| {
        c.insert_json5(key, &value)
            .map_err(|e| format!("zenoh config {key} = {value}: {e}"))
    };
    set("mode", "\"peer\"".into())?;
    set("listen/endpoints", json(listen))?;
    set("connect/endpoints", json(connect))?;
    // Agents may start before their host: peers keep trying in the background
    // (zenoh's peer default), here quickly.
    set("connect/exit_on_failure", "false".into())?;
    set(
        "connect/retry",
        "{period_init_ms: 50, period_max_ms: 500, period_increase_factor: 2}".into(),
    )?;
    set("scouting/multicast/enabled", z.scouting.to_string())?;
    set("scouting/gossip/enabled", z.scouting.to_string())?;
    set("transport/link/tx/lease", lease_ms.to_string())?;
    // zenoh's default sends a keep-alive every lease / 4.
    set("transport/link/tx/keep_alive", "4".into())?;
    if let Some(max) = max_rx_message {
        set("transport/link/rx/max_message_size", max.to_string())?;
    }
    // Sync mode blocks a frame rather than dropping it: give up on a link that does not
    // drain only after the stop timeout (at least 1 s; zenoh counts microseconds).
    let block_us = config
        .sync
        .stop_timeout
        .max(Duration::from_secs(1))
        .as_micros();
    set(
        "transport/link/tx/queue/congestion_control/block/wait_before_close",
        block_us.to_string(),
    )?;
    // TLS (`tls/` endpoints): the host serves its certificate on the listen side, an
    // agent shows its own on the connect side (with mtls); both trust `tls_ca`. The host's
    // certificate must name the address agents connect to (zenoh checks the name).
    let t = &z.tls;
    let path = |p: &std::path::Path| {
        p.to_str()
            .map(|s| format!("{s:?}"))
            .ok_or_else(|| format!("TLS file path {} is not UTF-8", p.display()))
    };
    if let Some(ca) = &t.ca {
        set("transport/link/tls/root_ca_certificate", path(ca)?)?;
    }
    if let (Some(cert), Some(key)) = (&t.cert, &t.key) {
        let side = if listen.is_empty() {
            "connect"
        } else {
            "listen"
        };
        set(
            &format!("transport/link/tls/{side}_certificate"),
            path(cert)?,
        )?;
        set(
            &format!("transport/link/tls/{side}_private_key"),
            path(key)?,
        )?;
    }
    set("transport/link/tls/enable_mtls", t.mtls.to_string())?;
    Ok(c)
}

/// Starts the thread that puts an empty sample on `key` (an agent's beat) every `period`
/// (at least 25 ms) until the returned sender is dropped: the host tells from it a link
/// that went silent (nothing for half the lease before the agent's token vanished: held
/// for the resume window) from a connection closed while the agent was heard from (held
/// for the lease). `None` when no thread could be started (the host then holds a lost
/// link for the lease only).
pub(crate) fn start_beats(
    session: &::zenoh::Session,
    key: String,
    period: Duration,
) -> Option<std::sync::mpsc::Sender<()>> {
    let period = period.max(Duration::from_millis(25));
    let session = session.clone();
    let (stop_tx, stop_rx) = std::sync::mpsc::channel::<()>();
    let spawned = std::thread::Builder::new()
        .name("vrsync-zenoh-beat".into())
        .spawn(move || {
            // The timer is the wait for the end: it ends as soon as the owner drops the
            // sender.
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) = stop_rx.recv_timeout(period)
            {
                let put = session
                    .put(&key, Vec::<u8>::new())
                    .congestion_control(::zenoh::qos::CongestionControl::Drop);
                let _ = ::zenoh::Wait::wait(put);
            }
        });
    match spawned {
        Ok(_) => Some(stop_tx),
        Err(e) => {
            tracing::warn!("no thread for the zenoh beats: {e}");
            None
        }
    }
}

/// Locks a mutex, taking the data of a poisoned one (a panicking zenoh callback must not
/// take the host down with it).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

pub(crate) use super::wait::WakeFd;

/// An 8-byte aligned byte buffer of a fixed capacity (so headers and commands can be
/// viewed in place), reused through a pool.
#[derive(Debug, Default)]
pub(crate) struct AlignedBuf {
    words: Vec<u64>,
    len: usize,
}

impl AlignedBuf {
    pub(crate) fn with_capacity(bytes: usize) -> Self {
        Self {
            words: vec![0; bytes.div_ceil(8)],
            len: 0,
        }
    }

    pub(crate) fn capacity(&self) -> usize {
        self.words.len() * 8
    }

    /// Sets the length, growing only beyond the capacity.
    pub(crate) fn set_len(&mut self, len: usize) {
        if self.capacity() < len {
            self.words.resize(len.div_ceil(8), 0);
        }
        self.len = len;
    }

    pub(crate) fn bytes(&self) -> &[u8] {
        use zerocopy::IntoBytes;
        &self.words.as_bytes()[..self.len]
    }

    pub(crate) fn bytes_mut(&mut self) -> &mut [u8] {
        use zerocopy::IntoBytes;
        let len = self.len;
        &mut self.words.as_mut_bytes()[..len]
    }

    /// Copies a received payload in: `len` must be `payload.len()` and within the
    /// capacity (checked by the caller, so this never allocates).
    pub(crate) fn fill_from(&mut self, payload: &::zenoh::bytes::ZBytes) {
        let len = payload.len();
        self.set_len(len);
        let dst = self.bytes_mut();
        let mut at = 0;
        for s in payload.slices() {
            let n = s.len().min(dst.len() - at);
            dst[at..at + n].copy_from_slice(&s[..n]);
            at += n;
        }
    }
}

/// Log at the 1st, 2nd, 4th, 8th … occurrence: a misbehaving peer must not flood the log.
pub(crate) fn worth_logging(count: u64) -> bool {
    count.is_power_of_two()
}

#[cfg(test)]
mod tests;
