//! Pinhole camera: intrinsics `K`, a world-from-camera pose, and the projection matrix `P`.
//!
//! Camera frame: x right, y down, z forward (the OpenCV / gtsam optical frame).
//! `P = K [I | 0] T_cw` with `T_cw = (world_from_camera)⁻¹`, so a world point `X` maps to the pixel
//! `P X` (homogeneous).

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Matrix4, Point3, Vector2, Vector3};

/// Pinhole intrinsics `K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`, in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Skew (zero for KITTI and most modern cameras).
    pub skew: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics without skew.
    pub const fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { fx, fy, skew: 0.0, cx, cy }
    }

    /// The 3×3 calibration matrix `K`.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, self.skew, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// True when all entries are finite and the focal lengths are positive.
    pub fn is_valid(&self) -> bool {
        [self.fx, self.fy, self.skew, self.cx, self.cy].iter().all(|v| v.is_finite()) && self.fx > 0.0 && self.fy > 0.0
    }
}

/// A calibrated camera at a pose.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Camera {
    /// Calibration.
    pub intrinsics: Intrinsics,
    /// Pose of the camera in the world: maps camera-frame points to world points (`T_wc`).
    pub world_from_camera: Isometry3<f64>,
}

impl Camera {
    /// A camera from intrinsics and its world-from-camera pose.
    pub const fn new(intrinsics: Intrinsics, world_from_camera: Isometry3<f64>) -> Self {
        Self { intrinsics, world_from_camera }
    }

    /// `T_cw`, mapping world points into the camera frame.
    pub fn camera_from_world(&self) -> Isometry3<f64> {
        self.world_from_camera.inverse()
    }

    /// The camera centre in world coordinates.
    pub fn centre(&self) -> Vector3<f64> {
        self.world_from_camera.translation.vector
    }

    /// The 3×4 projection matrix `P = K [I|0] T_cw`.
    pub fn projection_matrix(&self) -> Matrix3x4<f64> {
        projection_matrix(&self.intrinsics.matrix(), &self.camera_from_world().to_homogeneous())
    }

    /// Pixel of a world point, or `None` when the point is not in front of the camera.
    pub fn project_point(&self, world: &Point3<f64>) -> Option<Vector2<f64>> {
        let pc = self.camera_from_world() * world;
        if pc.z <= 0.0 {
            return None;
        }
        let k = &self.intrinsics;
        Some(Vector2::new(k.fx * pc.x / pc.z + k.skew * pc.y / pc.z + k.cx, k.fy * pc.y / pc.z + k.cy))
    }

    /// Unit direction (world frame) of the ray through a pixel.
    pub fn ray_direction(&self, u: f64, v: f64) -> Vector3<f64> {
        let k = &self.intrinsics;
        let y = (v - k.cy) / k.fy;
        let x = (u - k.cx - k.skew * y) / k.fx;
        (self.world_from_camera.rotation * Vector3::new(x, y, 1.0)).normalize()
    }
}

/// `K [I|0] T` for a 4×4 camera-from-world matrix `T`.
pub fn projection_matrix(k: &Matrix3<f64>, camera_from_world: &Matrix4<f64>) -> Matrix3x4<f64> {
    k * camera_from_world.fixed_view::<3, 4>(0, 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn projection_matrix_matches_point_projection() {
        let k = Intrinsics::new(700.0, 710.0, 600.0, 180.0);
        let pose =
            Isometry3::from_parts(Translation3::new(1.0, -0.5, 2.0), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3));
        let cam = Camera::new(k, pose);
        let x = Point3::new(3.0, 1.0, 12.0);
        let p = cam.projection_matrix() * x.to_homogeneous();
        let uv = cam.project_point(&x).expect("in front");
        assert!((p.x / p.z - uv.x).abs() < 1e-9 && (p.y / p.z - uv.y).abs() < 1e-9);
        // the ray through that pixel passes through x
        let d = cam.ray_direction(uv.x, uv.y);
        let w = x.coords - cam.centre();
        assert!((w.normalize() - d).norm() < 1e-9);
    }
}
