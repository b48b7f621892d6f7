//! The Rerun logger of a vr-sim built without the `rerun` feature: it cannot be opened.

use super::{CycleData, RerunOptions, RerunUnavailable};

/// The logger of a vr-sim built without the `rerun` feature: never opened.
#[derive(Debug)]
pub enum RerunLog {}

impl RerunLog {
    /// Always fails: built without the `rerun` feature.
    ///
    /// # Errors
    /// [`RerunUnavailable`].
    pub fn open(
        _opts: &RerunOptions,
        _config: &vrsync_bridge::Config,
        _world: &crate::world::World,
    ) -> Result<Self, RerunUnavailable> {
        Err(RerunUnavailable)
    }

    /// Never called (no value exists).
    pub fn wants_images(&self, _cycle: u64) -> bool {
        match *self {}
    }

    /// Never called (no value exists).
    pub fn log_image(
        &mut self,
        _cycle: u64,
        _agent: u32,
        _image: &vrsync_bridge::ImageMut<'_>,
    ) -> Result<(), RerunUnavailable> {
        match *self {}
    }

    /// Never called (no value exists).
    pub fn log_cycle(&mut self, _cycle: &CycleData<'_>) -> Result<(), RerunUnavailable> {
        match *self {}
    }

    /// Never called (no value exists).
    pub fn finish(self) -> Result<(), RerunUnavailable> {
        match self {}
    }
}
