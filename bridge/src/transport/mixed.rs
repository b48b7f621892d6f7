//! One host, agents on several transports: each agent's slot is routed to the transport
//! its config names (`[[agent]] transport`), and one wait covers them all.
//!
//! Each transport is created for its own agents only (a sub-config with those agents);
//! slots inside a transport are its own, this module maps them to the host's. Every
//! transport's readiness is one descriptor ([`HostTransport::activity_fd`]); with more
//! than one transport they join one epoll set, and the host waits on it like on a single
//! transport's ([`super::wait_for_activity`]): bounded by the earliest of their deadlines,
//! then each transport's [`HostTransport::after_wait`]. Whatever the mix, there is no case
//! per combination. A host with one transport uses that transport's own wait (shared
//! memory may spin before it blocks).

use std::time::Duration;

use super::legacy::{LegacyFrameLoan, LegacyHost, LegacyHostCreateError};
use super::shm::{ShmFrameLoan, ShmHost, ShmHostCreateError};
use super::tcp::{TcpFrameLoan, TcpHost, TcpHostCreateError};
use super::wait::EpollSet;
use super::zenoh::{ZenohFrameLoan, ZenohHost, ZenohHostCreateError};
use super::{BatchSink, FrameLoanMut, HostTransport, HostTransportError, PeerRefusal};
use crate::config::{Config, TransportKind};
use crate::signal::SignalHandling;
use crate::wire::SensorHeader;

/// Why the transports could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TransportsCreateError {
    /// The shared-memory transport failed.
    #[error(transparent)]
    Shm(#[from] ShmHostCreateError),
    /// The TCP transport failed.
    #[error(transparent)]
    Tcp(#[from] TcpHostCreateError),
    /// The legacy transport failed.
    #[error(transparent)]
    Legacy(#[from] LegacyHostCreateError),
    /// The zenoh transport failed.
    #[error(transparent)]
    Zenoh(#[from] ZenohHostCreateError),
    /// The epoll set of the transports' activity descriptors could not be made.
    #[error("cannot wait on several transports at once: epoll: {0}")]
    Wait(std::io::Error),
}

/// A loan of whichever transport serves the agent.
#[derive(Debug)]
pub enum AnyLoan {
    /// Shared memory.
    Shm(ShmFrameLoan),
    /// TCP.
    Tcp(TcpFrameLoan),
    /// The original protocol.
    Legacy(LegacyFrameLoan),
    /// zenoh.
    Zenoh(ZenohFrameLoan),
}

impl FrameLoanMut for AnyLoan {
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        match self {
            Self::Shm(l) => l.parts_mut(),
            Self::Tcp(l) => l.parts_mut(),
            Self::Legacy(l) => l.parts_mut(),
            Self::Zenoh(l) => l.parts_mut(),
        }
    }

    fn header(&self) -> &SensorHeader {
        match self {
            Self::Shm(l) => l.header(),
            Self::Tcp(l) => l.header(),
            Self::Legacy(l) => l.header(),
            Self::Zenoh(l) => l.header(),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Route {
    kind: TransportKind,
    /// The slot inside that transport.
    local: usize,
}

/// Every transport a host's agents use, routed per agent.
pub struct Transports {
    shm: Option<ShmHost>,
    tcp: Option<TcpHost>,
    legacy: Option<LegacyHost>,
    zenoh: Option<ZenohHost>,
    /// The transports' activity descriptors, when there are several.
    epoll: Option<EpollSet>,
    routes: Vec<Route>,
    /// Host slot of each shm slot / tcp slot.
    shm_slots: Vec<usize>,
    tcp_slots: Vec<usize>,
    legacy_slots: Vec<usize>,
    zenoh_slots: Vec<usize>,
    scratch: Vec<usize>,
    signals: SignalHandling,
}

impl core::fmt::Debug for Transports {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Transports")
            .field("shm_slots", &self.shm_slots)
            .field("tcp_slots", &self.tcp_slots)
            .field("legacy_slots", &self.legacy_slots)
            .field("zenoh_slots", &self.zenoh_slots)
            .finish()
    }
}

impl Transports {
    /// Creates the transports `config`'s agents use, each for its own agents.
    ///
    /// # Errors
    /// [`TransportsCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, TransportsCreateError> {
        let mut routes = Vec::with_capacity(config.agents.len());
        let (mut shm_slots, mut tcp_slots, mut legacy_slots, mut zenoh_slots) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (slot, a) in config.agents.iter().enumerate() {
            let list = match a.transport {
                TransportKind::Shm => &mut shm_slots,
                TransportKind::Tcp => &mut tcp_slots,
                TransportKind::Legacy => &mut legacy_slots,
                TransportKind::Zenoh => &mut zenoh_slots,
            };
            routes.push(Route {
                kind: a.transport,
                local: list.len(),
            });
            list.push(slot);
        }
        let only = |kind: TransportKind| {
            let mut sub = config.clone();
            sub.agents.retain(|a| a.transport == kind);
            sub
        };
        let shm = if shm_slots.is_empty() {
            None
        } else {
            Some(ShmHost::create(&only(TransportKind::Shm), signals)?)
        };
        let tcp = if tcp_slots.is_empty() {
            None
        } else {
            Some(TcpHost::create(&only(TransportKind::Tcp), signals)?)
        };
        let legacy = if legacy_slots.is_empty() {
            None
        } else {
            Some(LegacyHost::create(&only(TransportKind::Legacy), signals)?)
        };
        let zenoh = if zenoh_slots.is_empty() {
            None
        } else {
            Some(ZenohHost::create(&only(TransportKind::Zenoh), signals)?)
        };
        let fds = [
            shm.as_ref().map(HostTransport::activity_fd),
            tcp.as_ref().map(HostTransport::activity_fd),
            legacy.as_ref().map(HostTransport::activity_fd),
            zenoh.as_ref().map(HostTransport::activity_fd),
        ];
        let epoll = if fds.iter().flatten().count() > 1 {
            Some(epoll_of(&fds).map_err(TransportsCreateError::Wait)?)
        } else {
            None
        };
        Ok(Self {
            shm,
            tcp,
            legacy,
            zenoh,
            epoll,
            routes,
            scratch: Vec::with_capacity(
                shm_slots
                    .len()
                    .max(tcp_slots.len())
                    .max(legacy_slots.len())
                    .max(zenoh_slots.len()),
            ),
            shm_slots,
            tcp_slots,
            legacy_slots,
            zenoh_slots,
            signals,
        })
    }

    fn route(&self, slot: usize) -> Result<Route, HostTransportError> {
        self.routes
            .get(slot)
            .copied()
            .ok_or(HostTransportError::NoSuchSlot { slot })
    }

    fn missing(kind: TransportKind) -> HostTransportError {
        HostTransportError::Send {
            what: format!("a frame over {}", kind.as_str()),
            reason: "that transport serves no agent".into(),
        }
    }
}

impl HostTransport for Transports {
    type Loan = AnyLoan;

    fn is_connected(&self, slot: usize) -> bool {
        let Some(r) = self.routes.get(slot) else {
            return false;
        };
        match r.kind {
            TransportKind::Shm => self.shm.as_ref().is_some_and(|t| t.is_connected(r.local)),
            TransportKind::Tcp => self.tcp.as_ref().is_some_and(|t| t.is_connected(r.local)),
            TransportKind::Legacy => self
                .legacy
                .as_ref()
                .is_some_and(|t| t.is_connected(r.local)),
            TransportKind::Zenoh => self.zenoh.as_ref().is_some_and(|t| t.is_connected(r.local)),
        }
    }

    fn loan(&mut self, slot: usize) -> Result<AnyLoan, HostTransportError> {
        let r = self.route(slot)?;
        match r.kind {
            TransportKind::Shm => match &mut self.shm {
                Some(t) => t.loan(r.local).map(AnyLoan::Shm),
                None => Err(Self::missing(r.kind)),
            },
            TransportKind::Tcp => match &mut self.tcp {
                Some(t) => t.loan(r.local).map(AnyLoan::Tcp),
                None => Err(Self::missing(r.kind)),
            },
            TransportKind::Legacy => match &mut self.legacy {
                Some(t) => t.loan(r.local).map(AnyLoan::Legacy),
                None => Err(Self::missing(r.kind)),
            },
            TransportKind::Zenoh => match &mut self.zenoh {
                Some(t) => t.loan(r.local).map(AnyLoan::Zenoh),
                None => Err(Self::missing(r.kind)),
            },
        }
    }

    fn publish(&mut self, slot: usize, frame: AnyLoan) -> Result<bool, HostTransportError> {
        let r = self.route(slot)?;
        // A loan comes from `loan` of the same slot, so its kind is the route's.
        match (frame, &mut self.shm, &mut self.tcp, &mut self.legacy) {
            (AnyLoan::Shm(l), Some(t), _, _) if r.kind == TransportKind::Shm => {
                t.publish(r.local, l)
            }
            (AnyLoan::Tcp(l), _, Some(t), _) if r.kind == TransportKind::Tcp => {
                t.publish(r.local, l)
            }
            (AnyLoan::Legacy(l), _, _, Some(t)) if r.kind == TransportKind::Legacy => {
                t.publish(r.local, l)
            }
            (AnyLoan::Zenoh(l), _, _, _) if r.kind == TransportKind::Zenoh => {
                match &mut self.zenoh {
                    Some(t) => t.publish(r.local, l),
                    None => Err(Self::missing(r.kind)),
                }
            }
            _ => Err(HostTransportError::Send {
                what: format!("the sensor frame of slot {slot}"),
                reason: "the frame was loaned for another agent".into(),
            }),
        }
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        if let Some(t) = &mut self.shm {
            t.signal_start()?;
        }
        if let Some(t) = &mut self.tcp {
            t.signal_start()?;
        }
        if let Some(t) = &mut self.legacy {
            t.signal_start()?;
        }
        if let Some(t) = &mut self.zenoh {
            t.signal_start()?;
        }
        Ok(())
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        if let Some(t) = &mut self.shm {
            let map = &self.shm_slots;
            t.drain(&mut |local, header, commands| {
                if let Some(&slot) = map.get(local) {
                    sink(slot, header, commands);
                }
            })?;
        }
        if let Some(t) = &mut self.tcp {
            let map = &self.tcp_slots;
            t.drain(&mut |local, header, commands| {
                if let Some(&slot) = map.get(local) {
                    sink(slot, header, commands);
                }
            })?;
        }
        if let Some(t) = &mut self.legacy {
            let map = &self.legacy_slots;
            t.drain(&mut |local, header, commands| {
                if let Some(&slot) = map.get(local) {
                    sink(slot, header, commands);
                }
            })?;
        }
        if let Some(t) = &mut self.zenoh {
            let map = &self.zenoh_slots;
            t.drain(&mut |local, header, commands| {
                if let Some(&slot) = map.get(local) {
                    sink(slot, header, commands);
                }
            })?;
        }
        Ok(())
    }

    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        if self.epoll.is_some() {
            return super::wait_for_activity(self, timeout);
        }
        // One transport: its own wait.
        match (
            &mut self.shm,
            &mut self.tcp,
            &mut self.legacy,
            &mut self.zenoh,
        ) {
            (Some(t), _, _, _) => t.wait_activity(timeout),
            (_, Some(t), _, _) => t.wait_activity(timeout),
            (_, _, Some(t), _) => t.wait_activity(timeout),
            (_, _, _, Some(t)) => t.wait_activity(timeout),
            (None, None, None, None) => Ok(()),
        }
    }

    fn activity_fd(&self) -> std::os::fd::RawFd {
        match (&self.epoll, &self.shm, &self.tcp, &self.legacy, &self.zenoh) {
            (Some(e), ..) => e.raw(),
            (None, Some(t), ..) => t.activity_fd(),
            (None, _, Some(t), ..) => t.activity_fd(),
            (None, _, _, Some(t), _) => t.activity_fd(),
            (None, _, _, _, Some(t)) => t.activity_fd(),
            (None, None, None, None, None) => -1,
        }
    }

    fn next_deadline(&self) -> Option<std::time::Instant> {
        [
            self.shm.as_ref().and_then(HostTransport::next_deadline),
            self.tcp.as_ref().and_then(HostTransport::next_deadline),
            self.legacy.as_ref().and_then(HostTransport::next_deadline),
            self.zenoh.as_ref().and_then(HostTransport::next_deadline),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn has_work(&self) -> bool {
        self.shm.as_ref().is_some_and(HostTransport::has_work)
            || self.tcp.as_ref().is_some_and(HostTransport::has_work)
            || self.legacy.as_ref().is_some_and(HostTransport::has_work)
            || self.zenoh.as_ref().is_some_and(HostTransport::has_work)
    }

    fn after_wait(&mut self) {
        if let Some(t) = &mut self.shm {
            t.after_wait();
        }
        if let Some(t) = &mut self.tcp {
            t.after_wait();
        }
        if let Some(t) = &mut self.legacy {
            t.after_wait();
        }
        if let Some(t) = &mut self.zenoh {
            t.after_wait();
        }
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        if let Some(t) = &mut self.shm {
            t.update_connections()?;
        }
        if let Some(t) = &mut self.tcp {
            t.update_connections()?;
        }
        if let Some(t) = &mut self.legacy {
            t.update_connections()?;
        }
        if let Some(t) = &mut self.zenoh {
            t.update_connections()?;
        }
        Ok(())
    }

    fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        let mut unkept = 0;
        if let Some(t) = &mut self.shm {
            unkept += t.take_refusals(sink);
        }
        if let Some(t) = &mut self.tcp {
            unkept += t.take_refusals(sink);
        }
        if let Some(t) = &mut self.legacy {
            unkept += t.take_refusals(sink);
        }
        if let Some(t) = &mut self.zenoh {
            unkept += t.take_refusals(sink);
        }
        unkept
    }

    fn forget_connection(&mut self, slot: usize) {
        let Ok(r) = self.route(slot) else {
            return;
        };
        match r.kind {
            TransportKind::Shm => {
                if let Some(t) = &mut self.shm {
                    t.forget_connection(r.local);
                }
            }
            TransportKind::Tcp => {
                if let Some(t) = &mut self.tcp {
                    t.forget_connection(r.local);
                }
            }
            TransportKind::Legacy => {
                if let Some(t) = &mut self.legacy {
                    t.forget_connection(r.local);
                }
            }
            TransportKind::Zenoh => {
                if let Some(t) = &mut self.zenoh {
                    t.forget_connection(r.local);
                }
            }
        }
    }

    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        if let Some(t) = &mut self.shm {
            self.scratch.clear();
            t.reap_dead_agents(&mut self.scratch);
            dead.extend(self.scratch.iter().filter_map(|&l| self.shm_slots.get(l)));
        }
        if let Some(t) = &mut self.tcp {
            self.scratch.clear();
            t.reap_dead_agents(&mut self.scratch);
            dead.extend(self.scratch.iter().filter_map(|&l| self.tcp_slots.get(l)));
        }
        if let Some(t) = &mut self.legacy {
            self.scratch.clear();
            t.reap_dead_agents(&mut self.scratch);
            dead.extend(
                self.scratch
                    .iter()
                    .filter_map(|&l| self.legacy_slots.get(l)),
            );
        }
        if let Some(t) = &mut self.zenoh {
            self.scratch.clear();
            t.reap_dead_agents(&mut self.scratch);
            dead.extend(self.scratch.iter().filter_map(|&l| self.zenoh_slots.get(l)));
        }
    }

    fn local_addr(&self) -> Option<std::net::SocketAddr> {
        self.tcp.as_ref().and_then(HostTransport::local_addr)
    }
}

/// An epoll set of `fds` (the `None`s skipped): readable whenever one of them is.
fn epoll_of(fds: &[Option<std::os::fd::RawFd>]) -> std::io::Result<EpollSet> {
    let set = EpollSet::new(fds.len())?;
    for &fd in fds.iter().flatten() {
        set.add(fd, fd as u64)?;
    }
    Ok(set)
}
