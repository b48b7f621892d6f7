//! One host, agents on several transports: each agent's slot is routed to the transport
//! its config names (`[[agent]] transport`), and one wait covers them all.
//!
//! Each transport is created for its own agents only (a sub-config with those agents);
//! slots inside a transport are its own, this module maps them to the host's. Every
//! transport's readiness is one descriptor ([`HostReadiness::activity_fd`]); with more
//! than one transport they join one epoll set, and the host waits on it like on a single
//! transport's ([`super::wait_for_activity`]): bounded by the earliest of their deadlines,
//! then each transport's [`HostReadiness::after_wait`]. Whatever the mix, there is no case
//! per combination. A host with one transport uses that transport's own wait (shared
//! memory may spin before it blocks).
//!
//! Everything here that names a transport is generated from the transport registry
//! (`registry.rs`), by one small macro per concern: the loan enum and the create error
//! (`mixed_types!`), one part per transport in [`Parts`] (`mixed_parts!`), and the
//! `Parts` methods over them, each a `match` on the agent's transport (`mixed_routed!`)
//! or one `if let Some` per transport (`mixed_each!`, `mixed_first!`); no trait object on
//! the data path: see the registry's docs. [`Transports`], the `HostTransport` the host
//! drives, is ordinary code over [`Parts`], and the logic the parts share is in the
//! generic [`Part`].

use std::net::SocketAddr;
use std::os::fd::RawFd;
use std::time::{Duration, Instant};

use super::{
    BatchSink, FrameLoanMut, HostConnections, HostReadiness, HostTransport, HostTransportError,
    PeerRefusal,
};
use crate::wire::SensorHeader;
use vrsync_transport::SignalHandling;
use vrsync_transport::internal::EpollSet;
use vrsync_transport::{Config, TransportKind};

#[derive(Debug, Clone, Copy)]
struct Route {
    kind: TransportKind,
    /// The slot inside that transport.
    local: usize,
}

/// One transport of the mix, created for its own agents only.
struct Part<T> {
    host: T,
    /// The host slot of each of this transport's slots.
    slots: Vec<usize>,
}

impl<T: HostTransport> Part<T> {
    /// The part of `kind` if some agent of `config` uses it, created by `create` for a
    /// copy of `config` with only those agents.
    fn of<E>(
        config: &Config,
        kind: TransportKind,
        create: impl FnOnce(&Config) -> Result<T, E>,
    ) -> Result<Option<Self>, E> {
        let slots: Vec<usize> = (config.agents.iter().enumerate())
            .filter(|(_, a)| a.transport == kind)
            .map(|(slot, _)| slot)
            .collect();
        if slots.is_empty() {
            return Ok(None);
        }
        let mut sub = config.clone();
        sub.agents.retain(|a| a.transport == kind);
        Ok(Some(Self {
            host: create(&sub)?,
            slots,
        }))
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        let map = &self.slots;
        self.host.drain(&mut |local, header, commands| {
            if let Some(&slot) = map.get(local) {
                sink(slot, header, commands);
            }
        })
    }

    /// Adds the host slots of this transport's dead agents to `dead`.
    fn reap_dead_agents(&mut self, scratch: &mut Vec<usize>, dead: &mut Vec<usize>) {
        scratch.clear();
        self.host.reap_dead_agents(scratch);
        dead.extend(scratch.iter().filter_map(|&l| self.slots.get(l)));
    }
}

fn missing(kind: TransportKind) -> HostTransportError {
    HostTransportError::Send {
        what: format!("a frame over {}", kind.as_str()),
        reason: "that transport serves no agent".into(),
    }
}

/// An epoll set of `fds` (the `None`s skipped): readable whenever one of them is.
fn epoll_of(fds: &[Option<RawFd>]) -> std::io::Result<EpollSet> {
    let set = EpollSet::new(fds.len())?;
    for &fd in fds.iter().flatten() {
        set.add(fd, fd as u64)?;
    }
    Ok(set)
}

/// The registry's types the routing names, the create error and the loan of whichever
/// transport serves the agent.
macro_rules! mixed_types {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        use super::{$($module::{$host, $loan, $create_error}),*};

        /// Why the transports could not be created.
        #[derive(Debug, thiserror::Error)]
        #[non_exhaustive]
        pub enum TransportsCreateError {
            $(
                #[doc = concat!("The `", $name, "` transport failed.")]
                #[error(transparent)]
                $kind(#[from] $create_error),
            )*
            /// The epoll set of the transports' activity descriptors could not be made.
            #[error("cannot wait on several transports at once: epoll: {0}")]
            Wait(std::io::Error),
        }

        /// A loan of whichever transport serves the agent.
        #[derive(Debug)]
        pub enum AnyLoan {
            $(
                #[doc = concat!("A loan of the `", $name, "` transport.")]
                $kind($loan),
            )*
        }

        impl FrameLoanMut for AnyLoan {
            fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
                match self {
                    $(Self::$kind(l) => l.parts_mut(),)*
                }
            }

            fn header(&self) -> &SensorHeader {
                match self {
                    $(Self::$kind(l) => l.header(),)*
                }
            }
        }
    };
}

vrsync_transport::transports!(mixed_types);

/// [`Parts`]: one optional part per transport, created for its agents.
macro_rules! mixed_parts {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        /// One part per transport of the registry, `None` when no agent uses it.
        struct Parts {
            $($module: Option<Part<$host>>,)*
        }

        impl Parts {
            /// Creates the transports `config`'s agents use, each for its own agents.
            fn create(config: &Config, signals: SignalHandling) -> Result<Self, TransportsCreateError> {
                $(
                    let $module =
                        Part::of(config, TransportKind::$kind, |sub| $host::create(sub, signals))?;
                )*
                Ok(Self { $($module,)* })
            }

            /// Each transport's host slots, as `<module>_slots` fields of `d`.
            fn debug_slots(&self, d: &mut core::fmt::DebugStruct<'_, '_>) {
                $(d.field(
                    concat!(stringify!($module), "_slots"),
                    &self.$module.as_ref().map_or(&[][..], |p| &p.slots[..]),
                );)*
            }
        }
    };
}

vrsync_transport::transports!(mixed_parts);

/// The [`Parts`] methods for one agent: a `match` on the transport of its [`Route`].
macro_rules! mixed_routed {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        impl Parts {
            fn is_connected(&self, r: Route) -> bool {
                match r.kind {
                    $(TransportKind::$kind => {
                        self.$module.as_ref().is_some_and(|p| p.host.is_connected(r.local))
                    })*
                }
            }

            fn loan(&mut self, r: Route) -> Result<AnyLoan, HostTransportError> {
                match r.kind {
                    $(TransportKind::$kind => match &mut self.$module {
                        Some(p) => p.host.loan(r.local).map(AnyLoan::$kind),
                        None => Err(missing(r.kind)),
                    },)*
                }
            }

            /// Publishes `frame`, loaned for host slot `slot` (routed to `r`).
            fn publish(&mut self, slot: usize, r: Route, frame: AnyLoan) -> Result<bool, HostTransportError> {
                // A loan comes from `loan` of the same slot, so its kind is the route's.
                match (frame, r.kind) {
                    $((AnyLoan::$kind(l), TransportKind::$kind) => match &mut self.$module {
                        Some(p) => p.host.publish(r.local, l),
                        None => Err(missing(r.kind)),
                    },)*
                    #[allow(unreachable_patterns)] // with one transport in the registry
                    _ => Err(HostTransportError::Send {
                        what: format!("the sensor frame of slot {slot}"),
                        reason: "the frame was loaned for another agent".into(),
                    }),
                }
            }

            fn forget_connection(&mut self, r: Route) {
                match r.kind {
                    $(TransportKind::$kind => {
                        if let Some(p) = &mut self.$module {
                            p.host.forget_connection(r.local);
                        }
                    })*
                }
            }
        }
    };
}

vrsync_transport::transports!(mixed_routed);

/// The [`Parts`] methods that act on every transport: one `if let Some` per transport.
macro_rules! mixed_each {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        impl Parts {
            fn signal_start(&mut self) -> Result<(), HostTransportError> {
                $(if let Some(p) = &mut self.$module {
                    p.host.signal_start()?;
                })*
                Ok(())
            }

            fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
                $(if let Some(p) = &mut self.$module {
                    p.drain(sink)?;
                })*
                Ok(())
            }

            fn after_wait(&mut self) {
                $(if let Some(p) = &mut self.$module {
                    p.host.after_wait();
                })*
            }

            fn update_connections(&mut self) -> Result<(), HostTransportError> {
                $(if let Some(p) = &mut self.$module {
                    p.host.update_connections()?;
                })*
                Ok(())
            }

            fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
                let mut unkept = 0;
                $(if let Some(p) = &mut self.$module {
                    unkept += p.host.take_refusals(sink);
                })*
                unkept
            }

            fn take_resumes(&mut self) -> u64 {
                let mut resumes = 0;
                $(if let Some(p) = &mut self.$module {
                    resumes += p.host.take_resumes();
                })*
                resumes
            }

            fn reap_dead_agents(&mut self, scratch: &mut Vec<usize>, dead: &mut Vec<usize>) {
                $(if let Some(p) = &mut self.$module {
                    p.reap_dead_agents(scratch, dead);
                })*
            }
        }
    };
}

vrsync_transport::transports!(mixed_each);

/// The [`Parts`] methods that ask the transports in turn: the first that has an answer,
/// or all of them.
macro_rules! mixed_first {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        impl Parts {
            /// Each transport's activity descriptor, `None` for a transport no agent uses.
            fn activity_fds(&self) -> [Option<RawFd>; TransportKind::ALL.len()] {
                [$(self.$module.as_ref().map(|p| HostReadiness::activity_fd(&p.host)),)*]
            }

            /// The first transport's own wait (for a host with one transport).
            fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
                $(if let Some(p) = &mut self.$module {
                    return p.host.wait_activity(timeout);
                })*
                Ok(())
            }

            /// The first transport's activity descriptor, -1 without any.
            fn activity_fd(&self) -> RawFd {
                $(if let Some(p) = &self.$module {
                    return HostReadiness::activity_fd(&p.host);
                })*
                -1
            }

            fn next_deadline(&self) -> Option<Instant> {
                [$(self.$module.as_ref().and_then(|p| HostReadiness::next_deadline(&p.host)),)*]
                    .into_iter()
                    .flatten()
                    .min()
            }

            fn has_work(&self) -> bool {
                false $(|| self.$module.as_ref().is_some_and(|p| HostReadiness::has_work(&p.host)))*
            }

            fn local_addr(&self) -> Option<SocketAddr> {
                None $(.or_else(|| {
                    self.$module.as_ref().and_then(|p| HostConnections::local_addr(&p.host))
                }))*
            }
        }
    };
}

vrsync_transport::transports!(mixed_first);

/// Every transport a host's agents use, routed per agent.
pub struct Transports {
    parts: Parts,
    /// The transports' activity descriptors, when there are several.
    epoll: Option<EpollSet>,
    routes: Vec<Route>,
    scratch: Vec<usize>,
}

impl core::fmt::Debug for Transports {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mut d = f.debug_struct("Transports");
        self.parts.debug_slots(&mut d);
        d.finish()
    }
}

impl Transports {
    /// Creates the transports `config`'s agents use, each for its own agents.
    ///
    /// # Errors
    /// [`TransportsCreateError`].
    pub fn create(config: &Config, signals: SignalHandling) -> Result<Self, TransportsCreateError> {
        let mut counts = [0; TransportKind::ALL.len()];
        let routes = config
            .agents
            .iter()
            .map(|a| {
                let count = &mut counts[a.transport as usize];
                *count += 1;
                Route {
                    kind: a.transport,
                    local: *count - 1,
                }
            })
            .collect();
        let parts = Parts::create(config, signals)?;
        let fds = parts.activity_fds();
        let epoll = if fds.iter().flatten().count() > 1 {
            Some(epoll_of(&fds).map_err(TransportsCreateError::Wait)?)
        } else {
            None
        };
        Ok(Self {
            parts,
            epoll,
            routes,
            scratch: Vec::with_capacity(config.agents.len()),
        })
    }

    fn route(&self, slot: usize) -> Result<Route, HostTransportError> {
        self.routes
            .get(slot)
            .copied()
            .ok_or(HostTransportError::NoSuchSlot { slot })
    }
}

impl HostTransport for Transports {
    type Loan = AnyLoan;

    fn loan(&mut self, slot: usize) -> Result<AnyLoan, HostTransportError> {
        let r = self.route(slot)?;
        self.parts.loan(r)
    }

    fn publish(&mut self, slot: usize, frame: AnyLoan) -> Result<bool, HostTransportError> {
        let r = self.route(slot)?;
        self.parts.publish(slot, r, frame)
    }

    fn signal_start(&mut self) -> Result<(), HostTransportError> {
        self.parts.signal_start()
    }

    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
        self.parts.drain(sink)
    }
}

impl HostReadiness for Transports {
    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        if self.epoll.is_some() {
            return super::wait_for_activity(self, timeout);
        }
        // One transport: its own wait.
        self.parts.wait_activity(timeout)
    }

    fn activity_fd(&self) -> RawFd {
        if let Some(e) = &self.epoll {
            return e.raw();
        }
        self.parts.activity_fd()
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.parts.next_deadline()
    }

    fn has_work(&self) -> bool {
        self.parts.has_work()
    }

    fn after_wait(&mut self) {
        self.parts.after_wait();
    }
}

impl HostConnections for Transports {
    fn is_connected(&self, slot: usize) -> bool {
        let Some(&r) = self.routes.get(slot) else {
            return false;
        };
        self.parts.is_connected(r)
    }

    fn update_connections(&mut self) -> Result<(), HostTransportError> {
        self.parts.update_connections()
    }

    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        self.parts.take_refusals(sink)
    }

    fn take_resumes(&mut self) -> u64 {
        self.parts.take_resumes()
    }

    fn forget_connection(&mut self, slot: usize) {
        let Ok(r) = self.route(slot) else {
            return;
        };
        self.parts.forget_connection(r);
    }

    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        self.parts.reap_dead_agents(&mut self.scratch, dead);
    }

    /// The first transport's that has one (only TCP's listener does today).
    fn local_addr(&self) -> Option<SocketAddr> {
        self.parts.local_addr()
    }
}
