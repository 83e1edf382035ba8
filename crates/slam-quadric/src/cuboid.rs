//! The box an ellipsoid's circumscribed cuboid projects to.
//!
//! A labelled or detected box bounds the whole object, and a car is closer to a cuboid than to the
//! ellipsoid inscribed in it: that ellipsoid projects to a box smaller than the object's (by up to
//! 1/√3 per side, less when a face is seen head-on) and, seen obliquely, shifted towards the far
//! corner. Fitting ellipse bounds to object boxes therefore pulls the ellipsoid nearer or makes it
//! larger; fitting the cuboid's projected box (this module) does not.

use nalgebra::{Point3, Vector3};

use crate::{BBox, Camera, Ellipsoid};

/// The corner signs of a cuboid in its own frame: corner `i` is `s_i ⊙ semi_axes` with `s_i ∈ {±1}³`
/// (bit 0 of `i` → x, bit 1 → y, bit 2 → z).
pub fn cuboid_signs() -> [Vector3<f64>; 8] {
    let sign = |bit: usize| if bit == 0 { -1.0 } else { 1.0 };
    std::array::from_fn(|i| Vector3::new(sign(i & 1), sign(i & 2), sign(i & 4)))
}

/// The eight corners (world frame) of the cuboid circumscribing `e`: centre ± its semi-axes along its
/// own axes, in the order of [`cuboid_signs`].
pub fn cuboid_corners(e: &Ellipsoid) -> [Point3<f64>; 8] {
    let r = e.rotation();
    let c = e.centre();
    cuboid_signs().map(|s| Point3::from(c + r * s.component_mul(&e.semi_axes)))
}

/// Axis-aligned bounds of the projected corners of `e`'s circumscribed cuboid (not clipped to the
/// image); `None` when a corner is not in front of the camera.
pub fn cuboid_bounds(e: &Ellipsoid, camera: &Camera) -> Option<BBox> {
    let mut b = BBox { xmin: f64::INFINITY, ymin: f64::INFINITY, xmax: f64::NEG_INFINITY, ymax: f64::NEG_INFINITY };
    for p in cuboid_corners(e) {
        let uv = camera.project_point(&p)?;
        b.xmin = b.xmin.min(uv.x);
        b.ymin = b.ymin.min(uv.y);
        b.xmax = b.xmax.max(uv.x);
        b.ymax = b.ymax.max(uv.y);
    }
    b.to_vector().iter().all(|v| v.is_finite()).then_some(b)
}

/// **Box IoU2D**: the IoU of `bbox` (a labelled or detected box) with the image-clipped bounds of the
/// projected corners of `e`'s circumscribed cuboid, its own 3-D box. An object's ground-truth ellipsoid
/// is the one inscribed in its labelled 3-D box, so on the projected label box it scores 1, where the
/// paper's IoU2D ([`crate::metrics::projected_iou`], the bounds of the projected ellipsoid) scores less
/// (e.g. `(z − c) / (z + c)` for a box seen face-on, centred, its face at depth `z − c`). 0 when a corner
/// lies behind the camera or nothing of the box is in the image.
pub fn box_iou(e: &Ellipsoid, camera: &Camera, image: &crate::ImageSize, bbox: &BBox) -> f64 {
    cuboid_bounds(e, camera).and_then(|b| b.clipped(image)).map_or(0.0, |b| b.iou(bbox))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{predict_box, BoundsModel, Intrinsics};
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    const K: Intrinsics = Intrinsics::new(700.0, 700.0, 600.0, 180.0);

    #[test]
    fn a_cuboid_seen_face_on_spans_its_front_face_and_contains_the_ellipse() {
        // a 4 × 1.5 × 2 m car, 20 m ahead, axis-aligned: the nearest face (z = 19) spans the box
        let e = Ellipsoid::new(
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 20.0), UnitQuaternion::identity()),
            Vector3::new(2.0, 0.75, 1.0),
        );
        let cam = Camera::new(K, Isometry3::identity());
        let b = cuboid_bounds(&e, &cam).unwrap();
        let expect = [
            600.0 - 700.0 * 2.0 / 19.0,
            180.0 - 700.0 * 0.75 / 19.0,
            600.0 + 700.0 * 2.0 / 19.0,
            180.0 + 700.0 * 0.75 / 19.0,
        ];
        for (got, want) in b.to_vector().iter().zip(expect) {
            assert!((got - want).abs() < 1e-9, "{b:?}");
        }
        let ellipse = predict_box(&e, &cam, &BoundsModel::Full).unwrap().bbox;
        assert!(b.contains(&ellipse) && ellipse.area() < b.area());
    }

    #[test]
    fn an_oblique_cuboid_box_is_wider_than_the_ellipse_box_by_up_to_root_three() {
        let e = Ellipsoid::new(
            Isometry3::from_parts(Translation3::new(-4.0, 0.0, 25.0), UnitQuaternion::from_euler_angles(0.0, 0.7, 0.0)),
            Vector3::new(2.0, 0.75, 0.9),
        );
        let cam = Camera::new(K, Isometry3::identity());
        let b = cuboid_bounds(&e, &cam).unwrap();
        let ellipse = predict_box(&e, &cam, &BoundsModel::Full).unwrap().bbox;
        let ratio = b.width() / ellipse.width();
        assert!(ratio > 1.05 && ratio < 3f64.sqrt() + 0.05, "{ratio}");
        // behind the camera: no box
        let behind = Camera::new(K, Isometry3::translation(0.0, 0.0, 40.0));
        assert!(cuboid_bounds(&e, &behind).is_none());
    }

    /// A ground-truth ellipsoid (inscribed in a 4 × 1.5 × 2 m box) seen face-on, centred, 20 m ahead: its
    /// box IoU2D against the box's own projection is 1 and against that box shifted by d px sideways
    /// (W − d) / (W + d); its paper IoU2D against the unshifted box is (z − c) / (z + c) = 19 / 21: the
    /// ellipse's bounds are f a / √(z² − c²) wide against the face's f a / (z − c).
    #[test]
    fn box_iou_of_a_ground_truth_ellipsoid_against_its_own_box_is_analytic() {
        let (z, c) = (20.0, 1.0);
        let e = Ellipsoid::new(Isometry3::translation(0.0, 0.0, z), Vector3::new(2.0, 0.75, c));
        let cam = Camera::new(K, Isometry3::identity());
        let image = crate::ImageSize::new(1242.0, 375.0);
        let own = BBox::new(
            600.0 - 700.0 * 2.0 / (z - c),
            180.0 - 700.0 * 0.75 / (z - c),
            600.0 + 700.0 * 2.0 / (z - c),
            180.0 + 700.0 * 0.75 / (z - c),
        );
        assert!((box_iou(&e, &cam, &image, &own) - 1.0).abs() < 1e-12);
        let d = 10.0;
        let shifted = BBox::new(own.xmin + d, own.ymin, own.xmax + d, own.ymax);
        let want = (own.width() - d) / (own.width() + d);
        assert!((box_iou(&e, &cam, &image, &shifted) - want).abs() < 1e-12);
        let paper = crate::metrics::projected_iou(&e, &cam, &image, &own);
        assert!((paper - (z - c) / (z + c)).abs() < 1e-9, "{paper}");
        // behind the camera: 0
        assert_eq!(box_iou(&e, &Camera::new(K, Isometry3::translation(0.0, 0.0, 40.0)), &image, &own), 0.0);
    }
}
