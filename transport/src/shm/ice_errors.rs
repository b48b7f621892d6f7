//! What the shared-memory transport needs to know of an iceoryx2 error, read from its
//! variant (never from its `Debug` text, which a new iceoryx2 version may change).

use iceoryx2::port::listener::ListenerCreateError;
use iceoryx2::port::notifier::NotifierCreateError;
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::service::builder::event::{EventCreateError, EventOpenError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeCreateError, PublishSubscribeOpenError,
};

/// The kinds of iceoryx2 errors the transport answers differently; every other error is
/// reported with its `Debug` text.
pub(super) trait IceError: core::fmt::Debug {
    /// Opening: the service does not exist (yet, or for this id).
    fn does_not_exist(&self) -> bool {
        false
    }
    /// Creating: the service exists already (another host of the session).
    fn already_exists(&self) -> bool {
        false
    }
    /// Creating a port: the service's limit for this port kind is reached (another
    /// connection of the same agent id holds it).
    fn port_limit_reached(&self) -> bool {
        false
    }
}

impl IceError for PublishSubscribeOpenError {
    fn does_not_exist(&self) -> bool {
        matches!(self, Self::DoesNotExist)
    }
}

impl IceError for EventOpenError {
    fn does_not_exist(&self) -> bool {
        matches!(self, Self::DoesNotExist)
    }
}

impl IceError for PublishSubscribeCreateError {
    fn already_exists(&self) -> bool {
        matches!(self, Self::AlreadyExists)
    }
}

impl IceError for EventCreateError {
    fn already_exists(&self) -> bool {
        matches!(self, Self::AlreadyExists)
    }
}

impl IceError for NotifierCreateError {
    fn port_limit_reached(&self) -> bool {
        matches!(self, Self::ExceedsMaxSupportedNotifiers)
    }
}

impl IceError for ListenerCreateError {
    fn port_limit_reached(&self) -> bool {
        matches!(self, Self::ExceedsMaxSupportedListeners)
    }
}

impl IceError for PublisherCreateError {
    fn port_limit_reached(&self) -> bool {
        matches!(self, Self::ExceedsMaxSupportedPublishers)
    }
}

impl IceError for SubscriberCreateError {
    fn port_limit_reached(&self) -> bool {
        // Not BufferSizeExceedsMaxSupportedBufferSizeOfService: a layout error, not an id
        // in use (the old text match took both).
        matches!(self, Self::ExceedsMaxSupportedSubscribers)
    }
}
