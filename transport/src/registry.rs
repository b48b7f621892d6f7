//! The list of transports: each transport is named here once, and everything that
//! enumerates transports is generated from this list.
//!
//! [`transports!`] hands the list to a macro of the caller's (the "x-macro" pattern), one
//! entry per transport: its [`TransportKind`](crate::TransportKind) variant (with that
//! variant's docs), its config spelling (`[transport] kind`, `[[agent]] transport`, and
//! its section `[transport.<name>]` where it has one), its module (a folder of this crate,
//! or for the original protocol's host the `vrsync-legacy` crate), and the types of that
//! module the rest of vrsync needs: host, loan, host-create error, agent, agent frame.
//! Each caller resolves the module as `crate::<module>` (this crate) or
//! `crate::transport::<module>` (`vrsync-bridge`). From it come:
//!
//! - `TransportKind` with `ALL` and `as_str` (`config/mod.rs`; serde reads it by the same
//!   names);
//! - the transports' sections of `[transport]`, fields of `TransportConfig`
//!   (`config/transport.rs`);
//! - the host's routing per agent (`vrsync-bridge`'s `transport/mixed.rs`): `AnyLoan` and
//!   its `FrameLoanMut`, one part per transport in `Parts` (inside `Transports`) and every
//!   `HostTransport` method over them, and the create error `TransportsCreateError` (also
//!   the public `HostCreateError`);
//! - the agent side (`any_agent.rs`): `AnyAgent`, `AnyFrame` and their contract methods.
//!
//! The C ABI and C# constants (`vrs_host_transport_t`, `Native.cs`, the C side of the C#
//! layout check) are not generated (cbindgen reads source, not macro output): a test of the
//! host FFI checks them against `TransportKind::ALL`. The multi-process suites check their
//! transport list against it too (`tests/util.rs`).
//!
//! Adding a transport: its folder in this crate (host and agent side; a transport without
//! an agent side, like legacy, gives an uninhabited agent whose `connect` says why:
//! `absent.rs`'s `absent_agent!`), one entry here, its config section if it has keys
//! (`section.rs` in its folder: the typed and raw forms with `check`, `write_toml` and
//! `forget_secrets`; named in its entry's `section:`), and its line in the conformance
//! suite. A transport behind a cargo feature (zenoh, legacy) keeps its entry in every
//! build: without the feature its types are stand-ins (`absent_host!`, `absent_agent!`)
//! whose constructors fail naming the feature.
//!
//! # Why a macro and not trait objects
//!
//! A mix of transports could also be a `Vec<Box<dyn HostTransport>>`. It is not, because:
//!
//! - [`HostTransport::Loan`](super::HostTransport::Loan) is an associated type: each
//!   transport loans its own memory (an iceoryx2 sample, a TCP or zenoh buffer), the host
//!   writes the frame into it and hands that same loan back to `publish` (zero copy). A
//!   `dyn HostTransport` must fix `Loan` to one type, so the loan would become a
//!   `Box<dyn FrameLoanMut>` (an allocation per agent per cycle, and a run-time downcast
//!   in every `publish` to get the transport's own type back), or a copy into a common
//!   buffer: both are what the data path must not do. The generated `AnyLoan` enum keeps
//!   each transport's loan by value and `publish` matches it to its transport statically.
//! - On the hot loop (loan, publish, start, drain, wait, once per agent or transport per
//!   cycle) the generated code is a `match` on a small enum or an `if let Some` per
//!   transport: calls the compiler sees and can inline, no vtable, no allocation. The
//!   same holds on the agent side (`AnyAgent::try_receive_newest` returns its transport's
//!   frame by value).
//! - `connect`/`create` are constructors (`-> Self`), which trait objects cannot express
//!   without a factory table next to them: a second list.
//!
//! The cost is that the routing is written inside `macro_rules!` bodies, which rustfmt
//! does not format; they are kept short and mechanical (one line per method and
//! transport; several small macros per file, each under 60 lines, rather than one), with
//! the logic in ordinary generic functions (`mixed.rs`'s `Part<T>`).

/// Calls `$then! { … }` with every transport, in the order of
/// [`TransportKind::ALL`](crate::TransportKind::ALL). Each entry:
///
/// ```text
/// /// docs of the TransportKind variant
/// #[default]   (on one entry: the default `[transport] kind`)
/// Kind "config-name" module: Host, Loan, HostCreateError, Agent, Frame
///     [channels: bool, wait_for_stop: WaitForStop variant
///      (, section: Config Raw)?];
/// ```
///
/// The bracket holds what the config needs to know of the transport: whether its agents
/// can have channels, the `wait_for_stop` its agents get by default
/// (`TransportKind::carries_channels`, `TransportKind::default_wait_for_stop`), and for a
/// transport with a `[transport.<name>]` section the typed and raw forms of it, types of
/// its module's `section` (`config/transport.rs` makes the section a field of
/// `TransportConfig` named after the module, read, checked and written by those types).
///
/// The types are those of the caller's `<module>` (see the module docs).
#[doc(hidden)]
#[macro_export]
macro_rules! transports {
    ($then:ident) => {
        $then! {
            /// iceoryx2 shared memory (default; `[transport.shm]`).
            #[default]
            Shm "shm" shm: ShmHost, ShmFrameLoan, ShmHostCreateError, ShmAgent, ShmFrame
                [channels: true, wait_for_stop: Alive, section: ShmConfig RawShm];
            /// TCP, the measured baseline.
            Tcp "tcp" tcp: TcpHost, TcpFrameLoan, TcpHostCreateError, TcpAgent, TcpFrame
                [channels: true, wait_for_stop: Alive];
            /// The original system's protobuf/TCP protocol, for agents written for it
            /// (`[transport.legacy]`; see [`crate::legacy`]). Its clients may block on a
            /// final status, so they are waited for up to the stop timeout only.
            Legacy "legacy" legacy:
                LegacyHost, LegacyFrameLoan, LegacyHostCreateError, LegacyAgent, LegacyFrame
                [channels: false, wait_for_stop: Timeout, section: LegacyConfig RawLegacy];
            /// zenoh, for agents on other machines (`[transport.zenoh]`).
            Zenoh "zenoh" zenoh:
                ZenohHost, ZenohFrameLoan, ZenohHostCreateError, ZenohAgent, ZenohFrame
                [channels: true, wait_for_stop: Alive, section: ZenohConfig RawZenoh];
        }
    };
}
