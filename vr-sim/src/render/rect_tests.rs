//! The screen rectangles and depth bounds the renderer lists primitives by are
//! conservative: every pixel whose ray hits a primitive (computed exactly as the renderer
//! computes it) is in the primitive's rectangle, at no less than its depth bound. A pixel
//! left out would show what is behind the primitive.

use glam::Vec3;
use proptest::prelude::*;

use super::{
    BoxLanes, LANES, PrimKind, Rays, RowRays, clipped_rect, clipped_rects_lanes,
    hit_cylinder_lanes, hit_prim,
};
use crate::geometry::{Camera, recip};

/// A primitive and the axis-aligned box the renderer bounds it with.
fn prim(kind: u8, center: Vec3, size: Vec3) -> (PrimKind, Vec3, Vec3) {
    match kind {
        0 => {
            let radius = size.x;
            (
                PrimKind::Sphere { center, radius },
                center - Vec3::splat(radius),
                center + Vec3::splat(radius),
            )
        }
        1 => (
            PrimKind::Box {
                min: center - size,
                max: center + size,
            },
            center - size,
            center + size,
        ),
        _ => {
            let (radius, height) = (size.x, 2.0 * size.y);
            let base = center - Vec3::new(0.0, size.y, 0.0);
            (
                PrimKind::Body {
                    base,
                    radius,
                    height,
                },
                base - Vec3::new(radius, 0.0, radius),
                base + Vec3::new(radius, height, radius),
            )
        }
    }
}

/// Where pixel (`x`, `y`)'s ray hits the primitive, as the row shader tests it.
fn hit(cam: &Camera, kind: PrimKind, x: u32, y: u32) -> Option<f32> {
    let d = RowRays::of(cam, y).dir(cam.right, x);
    let t = match kind {
        PrimKind::Body {
            base,
            radius,
            height,
        } => {
            let rays = Rays {
                dx: [d.x; LANES],
                dy: [d.y; LANES],
                dz: [d.z; LANES],
            };
            hit_cylinder_lanes(cam.origin, &rays, base, radius, height)[0]
        }
        _ => {
            let p = super::Prim {
                kind,
                color: Vec3::ZERO,
                x0: 0,
                x1: 0,
                y0: 0,
                y1: 0,
                near: 0.0,
                index: 0,
            };
            hit_prim(&p, cam.origin, d, recip(d)).unwrap_or(f32::INFINITY)
        }
    };
    t.is_finite().then_some(t)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn every_pixel_that_sees_a_primitive_is_in_its_rectangle(
        (yaw, pitch) in (0.0f32..360.0, -80.0f32..80.0),
        (fov_h, fov_v) in (20.0f32..160.0, 20.0f32..140.0),
        (width, height) in (1u32..72, 1u32..56),
        kind in 0u8..3,
        // Around the camera, in front, beside and behind it, some reaching behind the
        // near plane or holding the camera.
        center in (-4.0f32..4.0, -2.0f32..2.0, -4.0f32..4.0),
        size in (0.01f32..1.5, 0.01f32..1.5, 0.01f32..1.5),
    ) {
        let cam = Camera::new(Vec3::new(0.3, 1.6, -0.2), yaw, pitch, fov_h, fov_v, width, height);
        let center = cam.origin + Vec3::new(center.0, center.1, center.2);
        let (kind, min, max) = prim(kind, center, Vec3::new(size.0, size.1, size.2));
        let rect = clipped_rect(&cam, min, max);
        for y in 0..height {
            for x in 0..width {
                let Some(t) = hit(&cam, kind, x, y) else { continue };
                let Some(((x0, x1, y0, y1), near)) = rect else {
                    panic!("pixel ({x}, {y}) hits {kind:?} at {t}, which has no rectangle");
                };
                prop_assert!(
                    (x0..=x1).contains(&x) && (y0..=y1).contains(&y),
                    "pixel ({x}, {y}) hits {kind:?} at {t}, outside its rectangle {:?}",
                    (x0, x1, y0, y1)
                );
                prop_assert!(t >= near, "pixel ({x}, {y}) hits {kind:?} at {t} < bound {near}");
            }
        }
    }

    #[test]
    fn the_rectangles_of_boxes_in_lanes_are_each_boxs_own(
        (yaw, pitch) in (0.0f32..360.0, -80.0f32..80.0),
        (fov_h, fov_v) in (20.0f32..160.0, 20.0f32..140.0),
        (width, height) in (1u32..72, 1u32..56),
        n in 1usize..=LANES,
        // Around the camera, in front, beside and behind it, some reaching behind the
        // near plane or holding the camera.
        boxes in prop::collection::vec(
            ((-4.0f32..4.0, -2.0f32..2.0, -4.0f32..4.0), (0.01f32..1.5, 0.01f32..1.5, 0.01f32..1.5)),
            LANES,
        ),
    ) {
        let cam = Camera::new(Vec3::new(0.3, 1.6, -0.2), yaw, pitch, fov_h, fov_v, width, height);
        let mut lanes = BoxLanes::default();
        let mut each = Vec::new();
        for (k, (c, h)) in boxes.into_iter().enumerate() {
            let (c, h) = (cam.origin + Vec3::new(c.0, c.1, c.2), Vec3::new(h.0, h.1, h.2));
            lanes.set(k, c - h, c + h);
            each.push(clipped_rect(&cam, c - h, c + h));
        }
        let got = clipped_rects_lanes(&cam, &lanes, n);
        for k in 0..LANES {
            let want = if k < n { each[k] } else { None };
            // Bounds compared by their bits.
            let bits = |r: Option<(super::Rect, f32)>| r.map(|(r, near)| (r, near.to_bits()));
            prop_assert_eq!(bits(got[k]), bits(want), "box {}", k);
        }
    }
}
