//! Stand-ins for a transport side that does not exist: the registry ([`super::registry`])
//! names five types per transport, and a side that is not there still needs them.
//!
//! - [`absent_agent!`]: an agent side that never connects (the legacy transport has no
//!   vrsync agent; zenoh's is missing without its cargo feature). `connect` fails with the
//!   given detail.
//! - [`absent_host!`]: a host side compiled out with its cargo feature (`legacy`, `zenoh`);
//!   `create` fails with an error naming the feature.
//!
//! The types are uninhabited: no value of them exists, so every method but the
//! constructors is unreachable by construction, and the generic routing over the registry
//! (`mixed.rs`, `any_agent.rs`) compiles unchanged.

/// Declares the uninhabited frame `$frame` of the absent agent `$agent`.
#[doc(hidden)]
#[macro_export]
macro_rules! absent_frame {
    ($agent:ident, $frame:ident) => {
        #[doc = concat!("The frame of a [`", stringify!($agent), "`]. Uninhabited.")]
        #[derive(Debug)]
        pub enum $frame {}

        impl $crate::AgentFrame for $frame {
            fn header(&self) -> &$crate::internal::wire::SensorHeader {
                match *self {}
            }

            fn payload(&self) -> &[u8] {
                match *self {}
            }
        }
    };
}

/// Declares the uninhabited agent `$agent` and its frame `$frame`; `connect` fails with
/// `AgentConnectError::Transport` and `$detail` (an expression of type `String`).
#[doc(hidden)]
#[macro_export]
macro_rules! absent_agent {
    ($(#[$doc:meta])* $agent:ident, $frame:ident, $detail:expr) => {
        $(#[$doc])*
        #[derive(Debug)]
        pub enum $agent {}

        $crate::absent_frame!($agent, $frame);

        impl $crate::AgentTransport for $agent {
            type Frame = $frame;

            /// Always fails, saying why.
            fn connect(
                config: &$crate::Config,
                id: u32,
                _timeout: ::std::time::Duration,
                _signals: $crate::SignalHandling,
            ) -> Result<Self, $crate::AgentConnectError> {
                Err($crate::AgentConnectError::Transport {
                    session: config.session.clone(),
                    agent: id,
                    detail: $detail,
                })
            }

            fn try_receive_newest(
                &mut self,
            ) -> Result<Option<$frame>, $crate::AgentReceiveError> {
                match *self {}
            }

            fn wait_readable(&mut self, _timeout: ::std::time::Duration) {
                match *self {}
            }

            fn discard_wakeups(&mut self) {
                match *self {}
            }

            fn host_liveness(&mut self, _check_process: bool) -> $crate::HostLiveness {
                match *self {}
            }

            fn send_batch(
                &mut self,
                _header: &$crate::internal::wire::MotorHeader,
                _commands: &[$crate::internal::wire::MotorCommand],
            ) -> Result<(), $crate::AgentSendError> {
                match *self {}
            }

            fn termination_requested(&self) -> bool {
                match *self {}
            }
        }
    };
}

/// Declares the uninhabited host `$host` of the transport `$name`, its loan `$loan` and
/// its create error `$error`, whose only variant `NotBuilt` names the cargo feature
/// `$feature` of vrsync-bridge. (Unused in a build with every transport feature.)
#[doc(hidden)]
#[macro_export]
macro_rules! absent_host {
    ($host:ident, $loan:ident, $error:ident, $name:literal, $feature:literal) => {
        #[doc = concat!(
                    "Why the ", $name, " host could not be created: in this build, always [`",
                    stringify!($error), "::NotBuilt`]."
                )]
        #[derive(Debug, thiserror::Error)]
        #[non_exhaustive]
        pub enum $error {
            /// The config gives agents this transport, which this build does not have.
            #[error(
                "the config gives agents the {} transport, but this build has none (it was \
                 compiled without the `{}` cargo feature of vrsync-bridge)",
                $name,
                $feature
            )]
            NotBuilt,
        }

        #[doc = concat!(
                    "The ", $name, " host of a build without the `", $feature,
                    "` feature: `create` says why there is none. Uninhabited."
                )]
        #[derive(Debug)]
        pub enum $host {}

        #[doc = concat!("The loan of a [`", stringify!($host), "`]. Uninhabited.")]
        #[derive(Debug)]
        pub enum $loan {}

        impl $host {
            /// Always fails: this build does not have the transport.
            ///
            /// # Errors
            #[doc = concat!("[`", stringify!($error), "::NotBuilt`].")]
            pub fn create(
                _config: &$crate::Config,
                _signals: $crate::SignalHandling,
            ) -> Result<Self, $error> {
                Err($error::NotBuilt)
            }
        }

        $crate::absent_host_transport!($host, $loan);
    };
}

/// The [`HostTransport`](super::HostTransport) impl of the uninhabited host `$host` and the
/// [`FrameLoanMut`](super::FrameLoanMut) impl of its loan `$loan`: every method unreachable.
#[doc(hidden)]
#[macro_export]
macro_rules! absent_host_transport {
    ($host:ident, $loan:ident) => {
        impl $crate::FrameLoanMut for $loan {
            fn parts_mut(&mut self) -> (&mut $crate::internal::wire::SensorHeader, &mut [u8]) {
                match *self {}
            }

            fn header(&self) -> &$crate::internal::wire::SensorHeader {
                match *self {}
            }
        }

        impl $crate::HostTransport for $host {
            type Loan = $loan;

            fn loan(&mut self, _slot: usize) -> Result<$loan, $crate::HostTransportError> {
                match *self {}
            }

            fn publish(
                &mut self,
                _slot: usize,
                frame: $loan,
            ) -> Result<bool, $crate::HostTransportError> {
                match frame {}
            }

            fn signal_start(&mut self) -> Result<(), $crate::HostTransportError> {
                match *self {}
            }

            fn drain(
                &mut self,
                _sink: &mut $crate::BatchSink<'_>,
            ) -> Result<(), $crate::HostTransportError> {
                match *self {}
            }
        }

        impl $crate::HostReadiness for $host {
            fn activity_fd(&self) -> ::std::os::fd::RawFd {
                match *self {}
            }
        }

        impl $crate::HostConnections for $host {
            fn is_connected(&self, _slot: usize) -> bool {
                match *self {}
            }

            fn update_connections(&mut self) -> Result<(), $crate::HostTransportError> {
                match *self {}
            }
        }
    };
}
