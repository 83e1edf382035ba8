//! Parked cars against the street they stand on. Where a sequence is one straight street (the camera
//! drives along it: KITTI odometry 06, frames 0-50), a car parked along the street stands along it
//! (parallel parking) or, rarely, across it; its heading is not labelled, but its angle to the street
//! is a check of a fit's orientation that needs no labels. The street's direction is the camera's
//! travel from the first to the last pose; a car is "along the street" when its centre lies within a
//! given distance of the camera's path (the parking lane next to the driving lane); the angle is that
//! of its longest horizontal axis ([`slam_quadric::metrics::longest_horizontal_axis`]) to the street's
//! direction, in `[0°, 90°]`.

use nalgebra::{Isometry3, Vector3};
use slam_core::geometry::Ellipsoid;

/// One object seen against the street.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreetObject {
    /// Object id.
    pub id: u64,
    /// Horizontal distance of its centre from the camera's path, metres.
    pub lateral_m: f64,
    /// Its position along the street from the first camera, metres.
    pub along_m: f64,
    /// Signed side: positive to the right of the direction of travel.
    pub side: f64,
    /// Angle of its longest horizontal axis to the street, degrees in `[0, 90]` (`None` when it has no
    /// longest horizontal axis: a round footprint).
    pub angle_deg: Option<f64>,
}

/// The street of `poses` (world from camera, the camera's y axis pointing down as in every KITTI
/// camera) and each object against it: the horizontal direction from the first to the last camera
/// position, each object's distance from the path (the polyline through the camera positions, in the
/// horizontal plane of the first camera) and its angle to the street. `None` when the camera did not
/// move (no direction).
pub fn against_street(poses: &[Isometry3<f64>], objects: &[(u64, Ellipsoid)]) -> Option<Vec<StreetObject>> {
    let (first, last) = (poses.first()?, poses.last()?);
    // the first camera's up (its -y): the ground plane the street lies in
    let up = first.rotation * -Vector3::y();
    let flat = |v: Vector3<f64>| v - up * up.dot(&v);
    let path: Vec<Vector3<f64>> = poses.iter().map(|p| flat(p.translation.vector)).collect();
    let direction = flat(last.translation.vector - first.translation.vector).try_normalize(1e-6)?;
    let right = direction.cross(&up);
    let origin = path[0];
    let out = objects
        .iter()
        .map(|(id, e)| {
            let c = flat(e.centre());
            let lateral_m = path
                .windows(2)
                .map(|w| distance_to_segment(&c, &w[0], &w[1]))
                .fold(path.iter().map(|p| (c - p).norm()).fold(f64::INFINITY, f64::min), f64::min);
            let angle_deg = slam_quadric::metrics::longest_horizontal_axis(e, &up)
                .map(|axis| axis.dot(&direction).abs().min(1.0).acos().to_degrees());
            StreetObject {
                id: *id,
                lateral_m,
                along_m: (c - origin).dot(&direction),
                side: (c - origin).dot(&right).signum(),
                angle_deg,
            }
        })
        .collect();
    Some(out)
}

/// Distance from `p` to the segment `a`-`b`.
fn distance_to_segment(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let ab = b - a;
    let t = if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
    (p - (a + ab * t)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn car(x: f64, z: f64, yaw_deg: f64) -> Ellipsoid {
        // a car's length along its own x; yaw about the camera's vertical (y)
        let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_deg.to_radians());
        Ellipsoid::new(Isometry3::from_parts(Translation3::new(x, 0.8, z), rot), Vector3::new(2.0, 0.75, 0.8))
    }

    #[test]
    fn cars_along_a_straight_street_are_measured_against_it() {
        // the camera drives 50 m along its optical axis (z), a little to the right on the way
        let poses: Vec<Isometry3<f64>> =
            (0..=50).map(|k| Isometry3::translation(0.02 * k as f64, 0.0, k as f64)).collect();
        let street_heading = (1.0f64 / 50.0).atan().to_degrees();
        let objects = vec![
            // parked along the street on the left (its length along z: the street), 4 m from the path
            (0, car(-4.0, 20.0, 90.0)),
            // on the right, turned by 10° from the street
            (1, car(4.5, 30.0, 90.0 - 10.0)),
            // a car in a lot 20 m to the left, across
            (2, car(-20.0, 25.0, 0.0)),
        ];
        let s = against_street(&poses, &objects).expect("the camera moved");
        assert!((s[0].lateral_m - (4.0 + 0.02 * 20.0)).abs() < 0.05, "{:?}", s[0]);
        assert!((s[0].angle_deg.unwrap() - street_heading).abs() < 0.01, "{:?}", s[0]);
        assert!(s[0].side < 0.0 && s[1].side > 0.0);
        assert!((s[1].angle_deg.unwrap() - (10.0 + street_heading)).abs() < 0.01, "{:?}", s[1]);
        assert!(
            (s[2].lateral_m - 20.5).abs() < 0.1 && (s[2].angle_deg.unwrap() - (90.0 - street_heading)).abs() < 0.01
        );
        assert!((s[1].along_m - 30.0).abs() < 0.2);
        // a camera that stood still has no street
        assert!(against_street(&poses[..1], &objects).is_none());
    }
}
