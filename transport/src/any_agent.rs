//! The agent side over whichever transport the config names: the SDK's `Agent` drives this
//! one [`AgentTransport`] and knows no transport by name (the host side's counterpart is
//! `mixed.rs`). Generated from the transport registry (`registry.rs`): one variant per
//! transport (`any_types!`), each method a `match` that calls the transport's own
//! (`any_agent_connect!`, `any_agent_methods!`, expanded inside the `AgentTransport`
//! impl); no trait object: see the registry's docs.

use std::time::Duration;

use super::{
    AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError, AgentTransport, HostLiveness,
};
use crate::config::{Config, TransportKind};
use crate::signal::SignalHandling;
use crate::wire::{MotorCommand, MotorHeader, SensorHeader};

/// The registry's agent types, [`AnyFrame`] and [`AnyAgent`].
macro_rules! any_types {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        use super::{$($module::{$agent, $frame}),*};

        /// A frame of whichever transport brought it.
        // The TCP variant carries its 784-byte header by value (a frame is moved once, from
        // the transport to the caller); boxing it would allocate every cycle.
        #[allow(clippy::large_enum_variant)]
        #[derive(Debug)]
        pub enum AnyFrame {
            $(
                #[doc = concat!("A frame of the `", $name, "` transport.")]
                $kind($frame),
            )*
        }

        impl AgentFrame for AnyFrame {
            fn header(&self) -> &SensorHeader {
                match self {
                    $(Self::$kind(f) => AgentFrame::header(f),)*
                }
            }

            fn payload(&self) -> &[u8] {
                match self {
                    $(Self::$kind(f) => AgentFrame::payload(f),)*
                }
            }
        }

        /// An agent connection over the transport its config names (`[[agent]] transport`,
        /// else `[transport] kind`).
        #[derive(Debug)]
        pub enum AnyAgent {
            $(
                #[doc = concat!("Over the `", $name, "` transport (boxed: the variants differ \
                                 much in size, and it is made once per connection).")]
                $kind(Box<$agent>),
            )*
        }
    };
}

crate::transports!(any_types);

/// [`AgentTransport::connect`] of [`AnyAgent`] (inside its impl).
macro_rules! any_agent_connect {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        /// Connects over agent `id`'s transport. A transport without an agent side in
        /// this SDK (the original protocol's, which serves programs written for the
        /// original system) gives a clear error.
        fn connect(
            config: &Config,
            id: u32,
            timeout: Duration,
            signals: SignalHandling,
        ) -> Result<Self, AgentConnectError> {
            let kind = config
                .agent(id)
                .map_or(config.transport.kind, |a| a.transport);
            Ok(match kind {
                $(TransportKind::$kind => {
                    Self::$kind(Box::new($agent::connect(config, id, timeout, signals)?))
                })*
            })
        }
    };
}

/// The other [`AgentTransport`] methods of [`AnyAgent`] (inside its impl): the variant's
/// own.
macro_rules! any_agent_methods {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            $props:tt;
    )*) => {
        fn try_receive_newest(&mut self) -> Result<Option<AnyFrame>, AgentReceiveError> {
            Ok(match self {
                $(Self::$kind(t) => t.try_receive_newest()?.map(AnyFrame::$kind),)*
            })
        }

        fn wait_readable(&mut self, timeout: Duration) {
            match self {
                $(Self::$kind(t) => t.wait_readable(timeout),)*
            }
        }

        fn discard_wakeups(&mut self) {
            match self {
                $(Self::$kind(t) => t.discard_wakeups(),)*
            }
        }

        fn host_liveness(&mut self, check_process: bool) -> HostLiveness {
            match self {
                $(Self::$kind(t) => t.host_liveness(check_process),)*
            }
        }

        fn begin_close(&mut self) {
            match self {
                $(Self::$kind(t) => t.begin_close(),)*
            }
        }

        fn send_batch(
            &mut self,
            header: &MotorHeader,
            commands: &[MotorCommand],
        ) -> Result<(), AgentSendError> {
            match self {
                $(Self::$kind(t) => t.send_batch(header, commands),)*
            }
        }

        fn termination_requested(&self) -> bool {
            match self {
                $(Self::$kind(t) => t.termination_requested(),)*
            }
        }
    };
}

impl AgentTransport for AnyAgent {
    type Frame = AnyFrame;

    crate::transports!(any_agent_connect);
    crate::transports!(any_agent_methods);
}
