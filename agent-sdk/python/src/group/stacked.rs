//! Zero-copy images of a group whose agents' payloads the host stacks (`[transport.shm]
//! stacked_images`): every camera's images of a step are one read-only `(N, H, W[, C])`
//! array over the cycle's stacked sample, agent `k`'s rows one block stride after agent
//! `k - 1`'s. The arrays hold the sample (their base is a `StackedSample`), so they stay
//! valid as long as they live; like a frame, it counts against the held-frame limit.

use std::rc::Rc;
use std::sync::Arc;

use pyo3::prelude::*;
use vrsync_agent::{Agent, Frame, StackSample};

use super::sink::ImageSink;
use crate::buffer::{Layout, array};
use crate::frame::{Graveyard, Owned};

/// The stacked payloads of one step's frames, kept until the step's images are made.
pub(crate) struct Held {
    /// Per agent: the stacked sample of its frame and its block's first byte there.
    blocks: Vec<Option<(Rc<StackSample>, usize)>>,
    /// Per camera: the image's offset in a block and its row stride, as the first frame
    /// of the step says; `uniform` turns false if another frame says otherwise.
    layout: Vec<(u64, usize)>,
    uniform: bool,
}

/// Where the images of a step are: one stacked sample at a uniform stride.
pub(super) struct Viewable {
    sample: Rc<StackSample>,
    first: usize,
    stride: usize,
}

impl Held {
    /// Room for `n` agents and `cameras` cameras (no allocation per step).
    pub(super) fn new(n: usize, cameras: usize) -> Self {
        Self {
            blocks: (0..n).map(|_| None).collect(),
            layout: Vec::with_capacity(cameras),
            uniform: true,
        }
    }

    /// Forgets the step's samples.
    pub(super) fn clear(&mut self) {
        self.blocks.iter_mut().for_each(|b| *b = None);
        self.layout.clear();
        self.uniform = true;
    }

    /// Keeps agent `k`'s frame's stacked sample (a frame with a payload of its own, copied
    /// into the group's arrays by the caller, makes the step not viewable).
    pub(super) fn note(&mut self, k: usize, frame: &Frame) {
        let Some(slot) = self.blocks.get_mut(k) else {
            return;
        };
        let Some((sample, range)) = Agent::stacked_payload(frame) else {
            self.uniform = false;
            return;
        };
        *slot = Some((Rc::clone(sample), range.start));
        let mut images = frame.images();
        if self.layout.is_empty() {
            self.layout
                .extend(images.map(|i| (i.desc().offset, i.stride())));
        } else if !self
            .layout
            .iter()
            .copied()
            .eq(images.by_ref().map(|i| (i.desc().offset, i.stride())))
        {
            self.uniform = false;
        }
    }

    /// The step's sample, if every agent's payload is in it at a uniform stride
    /// (`block_stride` for a group of one) with the same image layout.
    pub(super) fn viewable(&self, block_stride: usize) -> Option<Viewable> {
        if !self.uniform {
            return None;
        }
        let (sample, first) = self.blocks.first()?.as_ref()?;
        let stride = match self.blocks.get(1) {
            Some(Some((_, second))) => second.checked_sub(*first)?,
            Some(None) => return None,
            None => block_stride,
        };
        for (k, b) in self.blocks.iter().enumerate() {
            let (s, start) = b.as_ref()?;
            if !Rc::ptr_eq(s, sample) || *start != first + k * stride {
                return None;
            }
        }
        Some(Viewable {
            sample: Rc::clone(sample),
            first: *first,
            stride,
        })
    }

    /// Copies every agent's images from its kept sample into the group's arrays (a step
    /// whose payloads are not viewable: frames of different cycles, in async mode).
    ///
    /// # Safety
    /// As [`super::sink::Sink::write`]: the sinks point to the group's live arrays.
    pub(super) unsafe fn copy_into(&self, sinks: &[ImageSink]) {
        for (k, b) in self.blocks.iter().enumerate() {
            let Some((sample, start)) = b else {
                continue;
            };
            for (s, &(offset, stride)) in sinks.iter().zip(&self.layout) {
                let from = start + offset as usize;
                if let Some(data) = sample
                    .payload()
                    .get(from..from + stride * s.height as usize)
                {
                    // SAFETY: as the caller guarantees; `data` holds the image's rows.
                    unsafe { s.write(k, data, stride) };
                }
            }
        }
    }
}

/// A stacked sample held by Python arrays, dropped only on its group's thread (as a
/// frame; see `frame.rs`).
pub(crate) type OwnedStack = Owned<Rc<StackSample>>;

/// The memory of a group's zero-copy images: one stacked sample of shared memory.
#[pyclass(module = "vrsync._vrsync", name = "StackedSample", frozen)]
pub(crate) struct PyStackedSample {
    owned: OwnedStack,
}

#[pymethods]
impl PyStackedSample {
    /// The cycle of the frames whose payloads it holds.
    #[getter]
    fn cycle(&self) -> u64 {
        self.owned.get().cycle()
    }
}

/// The step's images as arrays over `v`'s sample, one per camera of `sinks`, into `out`
/// (empty; on an error it is left empty).
pub(super) fn views(
    py: Python<'_>,
    v: Viewable,
    sinks: &[ImageSink],
    layout: &Held,
    n: usize,
    graveyard: &Arc<Graveyard>,
    out: &mut Vec<Py<PyAny>>,
) -> PyResult<()> {
    let base = Bound::new(
        py,
        PyStackedSample {
            owned: OwnedStack::new(Rc::clone(&v.sample), Arc::clone(graveyard)),
        },
    )?;
    let payload = v.sample.payload();
    out.clear();
    for (s, &(offset, stride)) in sinks.iter().zip(&layout.layout) {
        let start = v.first + offset as usize;
        let last = (n.saturating_sub(1)) * v.stride + stride * s.height as usize;
        if payload.len() < start + last {
            out.clear();
            return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
                "camera {:?}: the stacked sample holds {} bytes, the images need {}",
                s.name,
                payload.len(),
                start + last
            )));
        }
        let layout = Layout::stacked_image(s.format, s.width, s.height, stride, n, v.stride);
        // SAFETY: the bytes the layout describes lie within the payload (checked above),
        // which the sample keeps valid as long as `base` (the array's base) lives; nobody
        // writes a sent sample. Read-only.
        let a = unsafe {
            array(
                base.clone().into_any(),
                payload.as_ptr().add(start).cast_mut(),
                &layout,
                false,
            )
        };
        match a {
            Ok(a) => out.push(a.unbind()),
            Err(e) => {
                out.clear();
                return Err(e);
            }
        }
    }
    Ok(())
}
