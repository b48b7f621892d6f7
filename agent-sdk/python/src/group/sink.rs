//! The group's output arrays and the copy of a frame into row `k` of each.

use pyo3::prelude::*;
use vrsync_agent::{Frame, PixelFormat};
use vrsync_bridge::WireOutcome;

use super::channels::{VectorSink, check_vectors, write_vectors};
use super::out::Out;
use crate::agent::PyCamera;

/// Where one camera's images go: `(N, H, W[, C])`.
#[derive(Debug, Clone)]
pub(super) struct ImageSink {
    pub(super) name: String,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) format: PixelFormat,
    pub(super) row_bytes: usize,
    pub(super) ptr: usize,
}

/// An output array and its name.
pub(super) type NamedOut = (String, Out);

/// One stacked array per camera of `cameras`, `(n, ...)` for `n` agents (named by the
/// camera), and the sink that writes each agent's image into its row.
pub(super) fn image_outputs(
    py: Python<'_>,
    numpy: &Bound<'_, PyModule>,
    cameras: &[PyCamera],
    n: usize,
) -> PyResult<(Vec<NamedOut>, Vec<ImageSink>)> {
    let mut images = Vec::new();
    let mut image_sinks = Vec::new();
    for c in cameras {
        let format = match c.format.as_str() {
            "rgb8" => PixelFormat::Rgb8,
            "rgba8" => PixelFormat::Rgba8,
            "gray8" => PixelFormat::Gray8,
            _ => PixelFormat::Depth32f,
        };
        let mut shape = vec![n];
        shape.extend(c.shape().iter().map(|&d| d as usize));
        let out = Out::new(py, numpy, &shape, c.dtype())?;
        image_sinks.push(ImageSink {
            name: c.name.clone(),
            width: c.width,
            height: c.height,
            format,
            row_bytes: c.width as usize * format.bytes_per_pixel(),
            ptr: out.ptr,
        });
        images.push((c.name.clone(), out));
    }
    Ok((images, image_sinks))
}

/// Raw pointers into the output arrays, for writing with the GIL released.
#[derive(Debug, Clone)]
pub(super) struct Sink {
    pub(super) images: Vec<ImageSink>,
    pub(super) positions: usize,
    pub(super) rotations: usize,
    pub(super) rewards: usize,
    pub(super) sim_time_ns: usize,
    pub(super) cycles: usize,
    pub(super) collisions: usize,
    pub(super) outcomes: usize,
    pub(super) rejected: usize,
    pub(super) skipped: usize,
    pub(super) vectors: Vec<VectorSink>,
}

/// What one agent's frame must look like, checked before it is copied.
pub(super) fn check_frame(sink: &Sink, frame: &Frame) -> Result<(), String> {
    if frame.image_count() != sink.images.len() {
        return Err(format!(
            "the frame has {} images, the config {}",
            frame.image_count(),
            sink.images.len()
        ));
    }
    for (img, s) in frame.images().zip(&sink.images) {
        if img.width() != s.width || img.height() != s.height || img.format() != s.format {
            return Err(format!(
                "image {:?} is {}x{} {:?}, the config says {:?} {}x{} {:?}",
                img.name(),
                img.width(),
                img.height(),
                img.format(),
                s.name,
                s.width,
                s.height,
                s.format
            ));
        }
    }
    check_vectors(&sink.vectors, frame)
}

impl ImageSink {
    /// Copies one image (`data`, rows `stride` bytes apart) into row `k` of this camera's
    /// array.
    ///
    /// # Safety
    /// `ptr` points to the group's live `(N, H, W[, C])` array of this camera, `k` < N.
    pub(super) unsafe fn write(&self, k: usize, data: &[u8], stride: usize) {
        // SAFETY: row `k` of the array lies inside it (k < N, shape as built); the array
        // is C-contiguous; only bytes of `data` are read.
        unsafe {
            let dst = (self.ptr as *mut u8).add(k * self.row_bytes * self.height as usize);
            if stride == self.row_bytes {
                let n = self.row_bytes * self.height as usize;
                std::ptr::copy_nonoverlapping(data.as_ptr(), dst, n.min(data.len()));
            } else {
                for y in 0..self.height as usize {
                    if let Some(row) = data.get(y * stride..y * stride + self.row_bytes) {
                        std::ptr::copy_nonoverlapping(
                            row.as_ptr(),
                            dst.add(y * self.row_bytes),
                            self.row_bytes,
                        );
                    }
                }
            }
        }
    }
}

impl Sink {
    /// Copies agent `k`'s `frame` into row `k` of every output array (the images only
    /// with `images`: a group with zero-copy images leaves them in the frame's stacked
    /// sample).
    ///
    /// # Safety
    /// The pointers must point to the group's live output arrays (shapes as built in
    /// `AgentGroup::connect`), `k` < N, and `check_frame` must have passed.
    pub(super) unsafe fn write(&self, k: usize, frame: &Frame, skipped: u64, images: bool) {
        let h = frame.header();
        // SAFETY (whole block): row `k` of each array lies inside it (k < N, shapes as
        // built); the arrays are C-contiguous and aligned for their dtype (numpy).
        unsafe {
            if images {
                for (img, s) in frame.images().zip(&self.images) {
                    s.write(k, img.data(), img.stride());
                }
            }
            let pos = (self.positions as *mut f32).add(3 * k);
            for (i, v) in h.pose.position.iter().enumerate() {
                *pos.add(i) = *v;
            }
            let rot = (self.rotations as *mut f32).add(4 * k);
            for (i, v) in h.pose.rotation.iter().enumerate() {
                *rot.add(i) = v.clamp(-1.0, 1.0);
            }
            *(self.rewards as *mut f32).add(k) = h.reward;
            *(self.sim_time_ns as *mut u64).add(k) = h.sim_time_ns;
            *(self.cycles as *mut u64).add(k) = h.cycle;
            *(self.collisions as *mut u32).add(k) = frame.collisions().len() as u32;
            *(self.outcomes as *mut u8).add(k) = outcome_code(h.previous_outcome);
            *(self.rejected as *mut u32).add(k) = h.previous_rejected;
            *(self.skipped as *mut u64).add(k) = skipped;
            write_vectors(&self.vectors, k, frame);
        }
    }
}

/// `previous_outcome` as a small integer: 0 none, 1 stopped, 2 timed out.
pub(super) fn outcome_code(v: u32) -> u8 {
    match v {
        x if x == WireOutcome::Stopped as u32 => 1,
        x if x == WireOutcome::TimedOut as u32 => 2,
        _ => 0,
    }
}
