//! `[transport.shm]`: the shared-memory transport's config section — its typed form, what
//! serde reads, its checks and its text.

use serde::Deserialize;
use toml::Spanned;

use crate::config::ctx::Ctx;
use crate::config::error::ConfigLoadError;

/// `[transport.shm]` section.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ShmConfig {
    /// Every shared-memory agent's frame payload (images and vectors) comes in one sample
    /// of the session, agent after agent in id order (`stacked_images`; default false): a
    /// group that drives all of them in one process (`vrsync.AgentGroup`, `VrsyncVectorEnv`)
    /// reads their images as one `(N, H, W, C)` array without a copy. Every such agent then
    /// has the same cameras and vectors, and connects through a group (see
    /// [`crate::shm::ShmStack`]).
    pub stacked_images: bool,
}

impl ShmConfig {
    /// Checks `[transport.shm]` as read (`raw`), with its defaults.
    pub(crate) fn check(_ctx: &Ctx<'_>, raw: RawShm) -> Result<Self, ConfigLoadError> {
        Ok(Self {
            stacked_images: raw.stacked_images.is_some_and(|s| *s.get_ref()),
        })
    }

    /// The section has no secrets (for `TransportConfig::forget_secrets`).
    pub(crate) fn forget_secrets(&mut self) {}

    /// `[transport.shm]` as TOML, appended to `s`.
    pub(crate) fn write_toml(&self, s: &mut String) {
        use std::fmt::Write;
        let _ = writeln!(
            s,
            "\n[transport.shm]\nstacked_images = {}",
            self.stacked_images
        );
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawShm {
    pub(crate) stacked_images: Option<Spanned<bool>>,
}
