//! Accuracy metrics of Tian et al. §VI: IoU2D, e_trans, e_axe.
//!
//! * `e_trans = ‖t_gt − t_est‖` (metres, centre distance).
//! * `e_axe = min over axis permutations σ of ‖a_gt − σ(a_est)‖` (metres, semi-axes). An ellipsoid's
//!   axis labels are arbitrary (QuadricSLAM's constrain step returns them sorted, DQP in yaw order),
//!   so the semi-axes are compared in the order that matches best. [`e_axe_ordered`] compares them as
//!   given, for callers that know the axes correspond (e.g. length/height/width of a car).
//! * IoU2D: IoU of the projected ellipsoid's image-clipped box with a box, see [`projected_iou`].

use nalgebra::Vector3;

pub use crate::conic::projected_iou;
use crate::ellipsoid::Ellipsoid;

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
}
