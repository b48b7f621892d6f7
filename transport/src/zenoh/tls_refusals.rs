//! Peers that zenoh's TLS link drops in the handshake, counted as refused.
//!
//! A peer without a certificate of `tls_ca` (with `mtls`), with a certificate of another
//! CA, or speaking plain TCP to a `tls/` endpoint never reaches the hello: zenoh 1.10's
//! TLS listener drops it inside its accept loop and offers no callback for it. The only
//! trace it leaves is a `WARN` event of target `zenoh_link_tls::unicast` (the rustls
//! error, followed by zenoh's generic ". Hint: increase the system open file limit.").
//! [`tls_refusal_layer`] is a `tracing` layer that turns those events into
//! [`PeerRefusal`]s of kind [`RefusalKind::Tls`] for every zenoh host of the process
//! that listens on a `tls/` endpoint, and wakes their waits.
//!
//! A program that hosts over TLS adds the layer to its subscriber (`vr-sim` and the host
//! C ABI do); without it such peers are still dropped, only not counted. zenoh does not
//! say which listener or peer address an event is about, so with several TLS hosts in one
//! process each counts every TLS refusal of the process. zenoh is pinned (`=1.10.2`); a
//! unit test over a real handshake keeps this in step with it.

use std::sync::{Arc, Mutex, Weak};

use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::layer::Context;

use super::super::{PeerRefusal, RefusalKind};
use super::lock;

/// The module whose `WARN` events report a connection dropped in the TLS handshake.
const TLS_LINK_MODULE: &str = "zenoh_link_tls::unicast";

/// zenoh's suffix on every accept-loop error, meant for "too many open files".
const ACCEPT_HINT: &str = ". Hint: increase the system open file limit.";

/// What a registered host needs: where to put the refusal, and its endpoint for the text.
pub(super) trait TlsRefusalSink: Send + Sync {
    /// Records one refusal and wakes the host's wait.
    fn tls_refused(&self, refusal: PeerRefusal);
}

struct Listener {
    sink: Weak<dyn TlsRefusalSink>,
    endpoint: String,
}

static LISTENERS: Mutex<Vec<Listener>> = Mutex::new(Vec::new());

/// Registers a host listening on the `tls/` endpoint `endpoint`; it is forgotten once
/// `sink` is dropped.
pub(super) fn register(sink: &Arc<dyn TlsRefusalSink>, endpoint: String) {
    let mut listeners = lock(&LISTENERS);
    listeners.retain(|l| l.sink.strong_count() > 0);
    listeners.push(Listener {
        sink: Arc::downgrade(sink),
        endpoint,
    });
}

/// A `tracing` layer that counts the peers zenoh's TLS link drops in the handshake as
/// refused by the zenoh hosts of this process (zenoh offers no callback for them; the host
/// counts them only with this layer in its subscriber). It sees only
/// `WARN` and `ERROR` events of zenoh's TLS link, whatever the other layers' filters.
///
/// ```
/// use tracing_subscriber::layer::SubscriberExt;
/// let subscriber = tracing_subscriber::registry()
///     .with(vrsync_transport::zenoh::tls_refusal_layer());
/// # drop(subscriber);
/// ```
pub fn tls_refusal_layer<S>() -> impl Layer<S> + Send + Sync + 'static
where
    S: Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    TlsRefusals.with_filter(Targets::new().with_target(TLS_LINK_MODULE, Level::WARN))
}

struct TlsRefusals;

impl<S: Subscriber> Layer<S> for TlsRefusals {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        if event.metadata().target() != TLS_LINK_MODULE {
            return;
        }
        let mut message = Message(String::new());
        event.record(&mut message);
        if let Some(reason) = handshake_failure(&message.0) {
            refused(reason);
        }
    }
}

/// The reason of an accept-loop failure of zenoh's TLS listener, or `None` for its other
/// warnings (socket options on an accepted link).
fn handshake_failure(message: &str) -> Option<&str> {
    if let Some(reason) = message.strip_suffix(ACCEPT_HINT) {
        return Some(reason);
    }
    // An accepted connection whose client certificate cannot be read is dropped too.
    message
        .starts_with("Error getting client cert")
        .then_some(message)
}

fn refused(reason: &str) {
    let listeners: Vec<(Arc<dyn TlsRefusalSink>, String)> = lock(&LISTENERS)
        .iter()
        .filter_map(|l| Some((l.sink.upgrade()?, l.endpoint.clone())))
        .collect();
    for (sink, endpoint) in listeners {
        sink.tls_refused(PeerRefusal {
            kind: RefusalKind::Tls,
            agent: None,
            // zenoh's event does not name the peer's address.
            peer: format!("a peer of {endpoint}"),
            reason: format!("TLS handshake failed: {reason}"),
        });
    }
}

struct Message(String);

impl Visit for Message {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            value.clone_into(&mut self.0);
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn core::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_failures_are_told_from_other_warnings() {
        assert_eq!(
            handshake_failure(&format!(
                "invalid peer certificate: UnknownIssuer{ACCEPT_HINT}"
            )),
            Some("invalid peer certificate: UnknownIssuer")
        );
        assert_eq!(
            handshake_failure("Error getting client cert common name: x"),
            Some("Error getting client cert common name: x")
        );
        assert_eq!(
            handshake_failure("Unable to set NODEALY option on TLS link a => b: e"),
            None
        );
    }
}
