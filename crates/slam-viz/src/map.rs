//! The top-down picture of a map: the frames' positions, ground truth when there is some, the map
//! points and each object's footprint.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix2, Vector2};
use slam_core::geometry::Ellipse2;
use slam_frontend::ellipse_outline;
use slam_pipeline::saved_map::{SavedMap, SavedObject};

use crate::{
    plot::{topdown_figure, MapShape, ObjectState, TopDown},
    VizError,
};

/// Top-view outline (x, z) of a stored object's ellipsoid: its orthographic projection along y.
pub fn footprint(o: &SavedObject) -> Vec<[f64; 2]> {
    let r = nalgebra::Matrix3::from_row_slice(&o.rotation);
    let a = nalgebra::Vector3::from(o.semi_axes);
    let s = r * nalgebra::Matrix3::from_diagonal(&a.map(|a| a * a)) * r.transpose();
    let shape = Matrix2::new(s[(0, 0)], s[(0, 2)], s[(2, 0)], s[(2, 2)]);
    ellipse_outline(&Ellipse2 { centre: Vector2::new(o.center[0], o.center[2]), shape }, 48)
}

/// The files [`map_picture`] writes into its folder.
pub const MAP_PICTURE_FILES: [&str; 2] = ["map.svg", "map.png"];

/// The top-down picture (`map.svg`, `map.png` in `dir`) of a map, its frame poses and ground truth.
pub fn map_picture(
    map: &SavedMap,
    poses: &[Isometry3<f64>],
    truth: Option<&[Isometry3<f64>]>,
    dir: &Path,
) -> Result<Vec<PathBuf>, VizError> {
    let xz = |p: &Isometry3<f64>| [p.translation.vector.x, p.translation.vector.z];
    let estimate: Vec<[f64; 2]> = poses.iter().map(xz).collect();
    let truth: Option<Vec<[f64; 2]>> = truth.map(|g| g.iter().take(poses.len()).map(xz).collect());
    let points: Vec<[f64; 2]> = map.points.values().map(|p| [p.position[0], p.position[2]]).collect();
    let objects: Vec<MapShape> = map
        .objects
        .iter()
        .map(|o| MapShape {
            outline: footprint(o),
            label: format!("#{} {}", o.id, slam_core::ClassId(o.class).name()),
            state: ObjectState::of(o.dynamic, o.moving),
        })
        .collect();
    topdown_figure(
        &TopDown { estimate: &estimate, truth: truth.as_deref(), points: &points, objects: &objects },
        dir,
        "map",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_quadric::Ellipsoid;

    #[test]
    fn footprint_of_a_turned_ellipsoid() {
        let e = Ellipsoid::new(
            nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(2.0, 1.0, 10.0),
                nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), std::f64::consts::FRAC_PI_2),
            ),
            nalgebra::Vector3::new(2.0, 0.8, 1.0),
        );
        let r = e.rotation();
        let f = footprint(&SavedObject {
            id: 1,
            class: 2,
            class_name: "car".into(),
            center: [e.centre().x, e.centre().y, e.centre().z],
            semi_axes: [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
            rotation: std::array::from_fn(|k| r[(k / 3, k % 3)]),
            frames: vec![0],
            dynamic: false,
            moving: false,
            points: Vec::new(),
            views: Vec::new(),
            earlier_views: 0,
        });
        // turned 90° about y: the length (2 m) now runs along z, the width (1 m) along x
        let (xs, zs): (Vec<f64>, Vec<f64>) = f.iter().map(|p| (p[0], p[1])).unzip();
        let span = |v: &[f64]| v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
        assert!((span(&xs) - 2.0).abs() < 0.01 && (span(&zs) - 4.0).abs() < 0.01, "{} {}", span(&xs), span(&zs));
    }
}
