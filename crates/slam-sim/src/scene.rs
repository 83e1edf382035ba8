//! Scenes and noise.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use slam_core::rng::SimRng;
use slam_quadric::{init::BoxView, project, se3, BBox, Camera, Ellipsoid, ImageSize, Intrinsics};

/// KITTI colour-camera intrinsics used by the study.
pub const KITTI_K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };
/// KITTI image size.
pub const IMAGE: ImageSize = ImageSize::new(1242.0, 375.0);

/// Camera configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Geometry {
    /// The paper's five cameras on an 18° arc.
    Arc,
    /// A straight drive past a parked car.
    DriveBy,
}

impl Geometry {
    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            Geometry::Arc => "arc",
            Geometry::DriveBy => "drive-by",
        }
    }
}

/// Which quantity is perturbed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum NoiseKind {
    /// Camera translation.
    Translation,
    /// Camera rotation.
    Rotation,
    /// Box coordinates.
    Box,
}

impl NoiseKind {
    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            NoiseKind::Translation => "translation",
            NoiseKind::Rotation => "rotation",
            NoiseKind::Box => "box",
        }
    }

    /// The noise levels swept, in per cent.
    pub fn levels(&self) -> &'static [f64] {
        match self {
            NoiseKind::Translation | NoiseKind::Rotation => &[0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 30.0],
            NoiseKind::Box => &[0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        }
    }
}

/// A noise-free scene: the true ellipsoid, true cameras and their exact clipped boxes.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Geometry.
    pub geometry: Geometry,
    /// True ellipsoid (world = reference camera frame).
    pub truth: Ellipsoid,
    /// True cameras; the first is the reference.
    pub cameras: Vec<Camera>,
    /// Exact clipped boxes of the truth in each camera.
    pub boxes: Vec<BBox>,
}

fn yaw(angle: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angle)
}

impl Scene {
    /// Draw the object of trial `object` and build the scene.
    pub fn new(geometry: Geometry, master_seed: u64, object: u64) -> Self {
        let mut rng = SimRng::derive(master_seed, &[1, object]);
        let axes = Vector3::new(rng.uniform(1.8, 2.4), rng.uniform(0.7, 0.9), rng.uniform(0.75, 0.95));
        let dyaw = rng.uniform(-5.0, 5.0).to_radians();
        let (truth, poses) = match geometry {
            Geometry::Arc => {
                let centre = Vector3::new(0.0, 0.9, 15.0);
                let truth = Ellipsoid::new(Isometry3::from_parts(Translation3::from(centre), yaw(dyaw)), axes);
                let poses: Vec<Isometry3<f64>> = (0..5)
                    .map(|i| {
                        let phi = (4.5 * i as f64).to_radians();
                        let c = Vector3::new(centre.x - 15.0 * phi.sin(), 0.0, centre.z - 15.0 * phi.cos());
                        Isometry3::from_parts(Translation3::from(c), yaw(phi))
                    })
                    .collect();
                (truth, poses)
            }
            Geometry::DriveBy => {
                // parked parallel to the road: its length (own x) along +z
                let centre = Vector3::new(6.0, 0.9, 25.0);
                let truth = Ellipsoid::new(
                    Isometry3::from_parts(Translation3::from(centre), yaw(-std::f64::consts::FRAC_PI_2 + dyaw)),
                    axes,
                );
                let mut poses = Vec::new();
                let mut k = 0;
                loop {
                    let z = k as f64;
                    let off_axis = (centre.x).atan2(centre.z - z).to_degrees();
                    if off_axis > 40.0 {
                        break;
                    }
                    if k % 3 == 0 {
                        poses.push(Isometry3::translation(0.0, 0.0, z));
                    }
                    k += 1;
                }
                (truth, poses)
            }
        };
        let mut cameras = Vec::new();
        let mut boxes = Vec::new();
        for p in poses {
            let cam = Camera::new(KITTI_K, p);
            if let Ok(b) = project(&truth, &cam).and_then(|c| c.clipped_bounds(&IMAGE)) {
                cameras.push(cam);
                boxes.push(b);
            }
        }
        Self { geometry, truth, cameras, boxes }
    }
}

/// The views a method sees: noisy cameras and boxes for noise `kind` at `level` per cent, drawn from
/// the stream of (`object`, `seed`, `kind`). The same standard normals are used at every level, so a
/// sweep varies only the scale (common random numbers).
pub fn perturb(scene: &Scene, kind: NoiseKind, level: f64, master_seed: u64, object: u64, seed: u64) -> Vec<BoxView> {
    let mut rng = SimRng::derive(master_seed, &[2, object, seed, kind as u64]);
    let p = level / 100.0;
    let reference = scene.cameras[0].world_from_camera;
    scene
        .cameras
        .iter()
        .zip(&scene.boxes)
        .enumerate()
        .map(|(i, (cam, b))| {
            let draws: [f64; 4] = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
            let mut pose = cam.world_from_camera;
            let mut bbox = *b;
            if i > 0 {
                match kind {
                    NoiseKind::Translation => {
                        let len = (pose.translation.vector - reference.translation.vector).norm();
                        pose.translation.vector += p * len * Vector3::new(draws[0], draws[1], draws[2]);
                    }
                    NoiseKind::Rotation => {
                        let angle = (reference.rotation.inverse() * pose.rotation).angle();
                        let scale = if angle > 1e-9 { angle } else { 1f64.to_radians() };
                        let w = p * scale * Vector3::new(draws[0], draws[1], draws[2]);
                        let r: Matrix3<f64> = pose.rotation.to_rotation_matrix().into_inner()
                            * nalgebra::Rotation3::from_scaled_axis(w).into_inner();
                        pose = se3::isometry_from_parts(&r, &pose.translation.vector);
                    }
                    NoiseKind::Box => {
                        let (w, h) = (b.width(), b.height());
                        bbox = BBox::new(
                            b.xmin + p * w * draws[0],
                            b.ymin + p * h * draws[1],
                            b.xmax + p * w * draws[2],
                            b.ymax + p * h * draws[3],
                        );
                        if bbox.validated().is_err() {
                            bbox = *b;
                        }
                    }
                }
            }
            BoxView::new(Camera::new(cam.intrinsics, pose), bbox)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometries() {
        let arc = Scene::new(Geometry::Arc, 1, 0);
        assert_eq!(arc.cameras.len(), 5);
        let c0 = arc.cameras[0].centre();
        assert!(c0.norm() < 1e-12, "reference camera at the origin");
        for c in &arc.cameras {
            assert!(((c.centre() - arc.truth.centre()).xz().norm() - 15.0).abs() < 1e-9);
        }
        let drive = Scene::new(Geometry::DriveBy, 1, 0);
        assert_eq!(drive.cameras.len(), 6);
        // reference noise-free: the first view never changes
        let v = perturb(&drive, NoiseKind::Translation, 30.0, 1, 0, 0);
        assert_eq!(v[0].camera, drive.cameras[0]);
        assert_ne!(v[1].camera, drive.cameras[1]);
        let v0 = perturb(&drive, NoiseKind::Box, 0.0, 1, 0, 0);
        assert_eq!(v0[3].bbox, drive.boxes[3]);
    }
}
