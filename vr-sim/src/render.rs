//! A cheap placeholder renderer: a pattern that depends on the cycle and the pose, written
//! straight into the loaned shared memory.

use vrsync_bridge::host::ImagesMut;
use vrsync_bridge::wire::{PixelFormat, Pose};

/// Fills every image with a pattern of (`cycle`, `pose`).
pub fn render_pattern(images: ImagesMut<'_>, cycle: u64, pose: &Pose) {
    let shift = (pose.position[0] * 16.0) as i64 as u8 ^ (pose.position[2] * 16.0) as i64 as u8;
    for (n, image) in images.enumerate() {
        let d = image.desc;
        let stride = d.stride_bytes as usize;
        let bpp = d
            .pixel_format()
            .unwrap_or(PixelFormat::Rgb8)
            .bytes_per_pixel();
        for (y, row) in image.data.chunks_exact_mut(stride).enumerate() {
            let base = (y as u8)
                .wrapping_add(cycle as u8)
                .wrapping_add(n as u8 * 64)
                ^ shift;
            for (x, px) in row[..d.width_px as usize * bpp]
                .chunks_exact_mut(bpp)
                .enumerate()
            {
                px.fill(base.wrapping_add(x as u8));
            }
        }
    }
}
