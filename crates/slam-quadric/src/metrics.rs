//! Accuracy metrics of Tian et al. §VI: IoU2D, e_trans, e_axe.
//!
//! * `e_trans = ‖t_gt − t_est‖` (metres, centre distance).
//! * `e_axe = min over axis permutations σ of ‖a_gt − σ(a_est)‖` (metres, semi-axes). An ellipsoid's
//!   axis labels are arbitrary (QuadricSLAM's constrain step returns them sorted, DQP in yaw order),
//!   so the semi-axes are compared in the order that matches best. [`e_axe_ordered`] compares them as
//!   given, for callers that know the axes correspond (e.g. length/height/width of a car).
//! * IoU2D: IoU of the projected ellipsoid's image-clipped box with a box, see [`projected_iou`].
//! * Box IoU2D (ours): IoU of the image-clipped bounds of the ellipsoid's own 3-D box (its circumscribed
//!   cuboid) projected, with a box, see [`box_iou`]: a ground-truth ellipsoid, inscribed in the labelled
//!   3-D box, scores 1 against that box's projection, where the paper's IoU2D cannot.
//! * `e_yaw` (ours, not the paper's): angle between the estimate's longest horizontal axis and the
//!   truth's heading (its own x axis), modulo 180°, see [`e_yaw`].

use nalgebra::Vector3;

use crate::ellipsoid::Ellipsoid;
pub use crate::{conic::projected_iou, cuboid::box_iou};

/// Centre distance, metres.
pub fn e_trans(estimate: &Ellipsoid, truth: &Ellipsoid) -> f64 {
    (estimate.centre() - truth.centre()).norm()
}

/// The six permutations of three axes.
const PERMUTATIONS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];

/// Semi-axis error in the best axis order, metres.
pub fn e_axe(estimate: &Ellipsoid, truth: &Ellipsoid) -> f64 {
    let a = &estimate.semi_axes;
    PERMUTATIONS
        .iter()
        .map(|p| (truth.semi_axes - Vector3::new(a[p[0]], a[p[1]], a[p[2]])).norm())
        .fold(f64::INFINITY, f64::min)
}

/// Semi-axis error with the axes compared in the order given, metres.
pub fn e_axe_ordered(estimate: &Ellipsoid, truth: &Ellipsoid) -> f64 {
    (estimate.semi_axes - truth.semi_axes).norm()
}

/// The longest horizontal direction of an ellipsoid: the major axis of its orthographic shadow on the
/// plane orthogonal to `up`, as a unit vector in that plane (world frame). `None` for a degenerate `up`.
pub fn longest_horizontal_axis(e: &Ellipsoid, up: &Vector3<f64>) -> Option<Vector3<f64>> {
    let (h1, h2) = horizontal_basis(up)?;
    let r = e.rotation();
    let s = r * nalgebra::Matrix3::from_diagonal(&e.semi_axes.map(|a| a * a)) * r.transpose();
    // the shadow of x' S⁻¹ x <= 1 on the plane spanned by (h1, h2) has the dual shape Pᵀ S P
    let b = nalgebra::Matrix2::new(h1.dot(&(s * h1)), h1.dot(&(s * h2)), h2.dot(&(s * h1)), h2.dot(&(s * h2)));
    let eig = nalgebra::SymmetricEigen::new(b);
    let k = if eig.eigenvalues[0] >= eig.eigenvalues[1] { 0 } else { 1 };
    let v = eig.eigenvectors.column(k);
    Some((h1 * v[0] + h2 * v[1]).normalize())
}

fn horizontal_basis(up: &Vector3<f64>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let u = up.try_normalize(1e-12)?;
    let seed = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::z() };
    let h1 = (seed - u * u.dot(&seed)).normalize();
    Some((h1, u.cross(&h1)))
}

/// Yaw error, degrees in `[0, 90]`: the angle between the estimate's longest horizontal axis and the
/// truth's heading (its own x axis, the length of a vehicle) projected on the horizontal plane, modulo
/// 180° (an ellipsoid has no front). `up` is the world's vertical (either sign). NaN when the truth's
/// heading is vertical or `up` degenerate.
pub fn e_yaw(estimate: &Ellipsoid, truth: &Ellipsoid, up: &Vector3<f64>) -> f64 {
    let Some(v) = longest_horizontal_axis(estimate, up) else { return f64::NAN };
    let Some(u) = up.try_normalize(1e-12) else { return f64::NAN };
    let heading = truth.rotation().column(0).into_owned();
    let Some(g) = (heading - u * u.dot(&heading)).try_normalize(1e-9) else { return f64::NAN };
    v.dot(&g).abs().min(1.0).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;

    #[test]
    fn axis_matching() {
        let t = Ellipsoid::new(Isometry3::translation(1.0, 2.0, 3.0), Vector3::new(2.0, 0.8, 0.9));
        let e = Ellipsoid::new(Isometry3::translation(1.0, 2.0, 7.0), Vector3::new(0.9, 2.0, 0.8));
        assert!((e_trans(&e, &t) - 4.0).abs() < 1e-15);
        assert!(e_axe(&e, &t) < 1e-15);
        assert!(e_axe_ordered(&e, &t) > 1.0);
    }

    #[test]
    fn yaw_error_is_the_horizontal_angle_modulo_180() {
        use nalgebra::{Translation3, UnitQuaternion};
        let up = Vector3::new(0.0, -1.0, 0.0);
        let turned = |deg: f64, axes: Vector3<f64>| {
            Ellipsoid::new(
                Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, 10.0),
                    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), deg.to_radians()),
                ),
                axes,
            )
        };
        let truth = turned(30.0, Vector3::new(2.0, 0.8, 0.9));
        // 20° off, and the same ellipsoid turned by 180° more: same error
        assert!((e_yaw(&turned(50.0, Vector3::new(2.0, 0.8, 0.9)), &truth, &up) - 20.0).abs() < 1e-9);
        assert!((e_yaw(&turned(230.0, Vector3::new(2.0, 0.8, 0.9)), &truth, &up) - 20.0).abs() < 1e-9);
        // axes labelled differently: the longest horizontal one (own z here) counts, whatever its label
        let relabelled = turned(30.0 + 90.0, Vector3::new(0.9, 0.8, 2.0));
        assert!(e_yaw(&relabelled, &truth, &up) < 1e-9);
        // across the truth: 90°
        assert!((e_yaw(&turned(120.0, Vector3::new(2.0, 0.8, 0.9)), &truth, &up) - 90.0).abs() < 1e-9);
        // a tall axis does not count as horizontal: the longest horizontal one is still the 0.9 m one
        let tall = turned(30.0, Vector3::new(0.5, 3.0, 0.9));
        assert!((e_yaw(&tall, &truth, &up) - 90.0).abs() < 1e-9);
    }
}
