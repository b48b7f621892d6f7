//! The sensor frame a host loans for one agent, and its images.

use super::*;

/// One writable image of a loaned sensor frame.
#[derive(Debug)]
pub struct ImageMut<'a> {
    /// Where and what the image is.
    pub desc: ImageDesc,
    /// The pixels, in shared memory on the shm transport.
    pub data: &'a mut [u8],
}

/// Iterator over the writable images of a [`SensorFrameMut`].
#[derive(Debug)]
pub struct ImagesMut<'a> {
    pub(super) rest: &'a mut [u8],
    pub(super) consumed: usize,
    pub(super) descs: &'a [ImageDesc],
}

impl<'a> Iterator for ImagesMut<'a> {
    type Item = ImageMut<'a>;

    fn next(&mut self) -> Option<Self::Item> {
        let (desc, tail) = self.descs.split_first()?;
        self.descs = tail;
        let skip = (desc.offset as usize).checked_sub(self.consumed)?;
        let rest = core::mem::take(&mut self.rest);
        if rest.len() < skip + desc.len as usize {
            return None;
        }
        let (_, rest) = rest.split_at_mut(skip);
        let (data, rest) = rest.split_at_mut(desc.len as usize);
        self.rest = rest;
        self.consumed = desc.offset as usize + desc.len as usize;
        Some(ImageMut { desc: *desc, data })
    }
}

/// A sensor frame loaned for one agent: write the header and the images, then hand it to
/// [`Host::publish`]. Dropping it instead returns the memory unpublished.
#[derive(Debug)]
pub struct SensorFrameMut<L = AnyLoan> {
    pub(super) slot: usize,
    pub(super) agent_id: u32,
    pub(super) cycle: u64,
    pub(super) loan: L,
    pub(super) descs: [ImageDesc; MAX_CAMERAS],
    pub(super) image_count: usize,
    pub(super) vectors: [VectorDesc; MAX_VECTORS],
    pub(super) vector_count: usize,
}

impl<L: FrameLoanMut> SensorFrameMut<L> {
    /// The agent this frame is for.
    pub fn agent_id(&self) -> u32 {
        self.agent_id
    }

    /// The header (pre-filled with cycle, time, agent id and image table).
    pub fn header(&self) -> &SensorHeader {
        self.loan.header()
    }

    /// The header, writable: pose, sensors, statuses, collisions, reward.
    pub fn header_mut(&mut self) -> &mut SensorHeader {
        self.loan.parts_mut().0
    }

    /// The images, writable, in camera order.
    pub fn images_mut(&mut self) -> ImagesMut<'_> {
        self.parts_mut().1
    }

    /// The vector (`[[agent.vector]]`) called `name`, writable, straight in the frame's
    /// memory (shared memory on the shm transport); `None` if the agent has no such
    /// vector.
    pub fn vector_mut(&mut self, name: &str) -> Option<&mut [f32]> {
        let d = *self.vectors[..self.vector_count]
            .iter()
            .find(|d| d.name() == name)?;
        d.values_mut(self.loan.parts_mut().1)
    }

    /// The vector descriptions of this frame, in payload order.
    pub fn vector_descs(&self) -> &[VectorDesc] {
        &self.vectors[..self.vector_count]
    }

    /// Header and images at once (to render while reading the pose from the header).
    pub fn parts_mut(&mut self) -> (&mut SensorHeader, ImagesMut<'_>) {
        let (header, payload) = self.loan.parts_mut();
        (
            header,
            ImagesMut {
                rest: payload,
                consumed: 0,
                descs: &self.descs[..self.image_count],
            },
        )
    }
}
