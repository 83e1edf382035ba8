//! The rectified stereo camera the map is measured with, and the ORB scale pyramid its keypoints come
//! from.

use nalgebra::Vector3;
use slam_quadric::Intrinsics;

/// A rectified stereo rig: the left camera's intrinsics (the right camera's are the same) and the
/// baseline, metres (the right camera sits at +x of the left one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoCamera {
    /// Intrinsics of both rectified cameras.
    pub k: Intrinsics,
    /// Baseline, metres.
    pub baseline: f64,
}

impl StereoCamera {
    /// `fx · baseline`: disparity (pixels) times depth (metres).
    pub fn focal_baseline(&self) -> f64 {
        self.k.fx * self.baseline
    }

    /// The point (left camera frame) seen at left pixel `(u, v)` with `disparity` pixels.
    pub fn point(&self, u: f64, v: f64, disparity: f64) -> Vector3<f64> {
        let k = &self.k;
        let z = self.focal_baseline() / disparity;
        Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z)
    }

    /// Where a point (left camera frame) is seen in the left image, `(u, v)`; `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        (p.z > 0.0).then(|| (self.k.fx * p.x / p.z + self.k.cx, self.k.fy * p.y / p.z + self.k.cy))
    }

    /// Where a point (left camera frame, in front of it) is seen in both images: `[u_l, v, u_r]`.
    pub fn observe(&self, p: &Vector3<f64>) -> [f64; 3] {
        let k = &self.k;
        let u = k.fx * p.x / p.z + k.cx;
        [u, k.fy * p.y / p.z + k.cy, u - self.focal_baseline() / p.z]
    }

    /// The unit ray of left pixel `(u, v)` (left camera frame).
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let k = &self.k;
        Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0).normalize()
    }
}

/// The image pyramid ORB keypoints are detected on: `levels` levels, each `factor` times smaller than
/// the one before. A keypoint found at level `l` was measured on pixels `factor^l` times larger than
/// the image's, so its position is that much less certain and the patch it describes covers that much
/// more of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalePyramid {
    /// Number of levels.
    pub levels: u8,
    /// Scale between two neighbouring levels.
    pub factor: f64,
}

impl Default for ScalePyramid {
    /// ORB's usual pyramid (and the front end's): 8 levels, 1.2 apart.
    fn default() -> Self {
        Self { levels: 8, factor: 1.2 }
    }
}

impl ScalePyramid {
    /// `factor^level`.
    pub fn scale(&self, level: u8) -> f64 {
        self.factor.powi(level as i32)
    }

    /// The distance range over which a point seen at `distance` metres on level `level` can be
    /// detected: at `distance · factor^level` it would be found on level 0 (its patch as small as the
    /// finest level allows), at that over `factor^(levels − 1)` on the coarsest.
    pub fn distance_range(&self, distance: f64, level: u8) -> (f64, f64) {
        let max = distance * self.scale(level);
        (max / self.scale(self.levels.saturating_sub(1)), max)
    }

    /// The level a point whose detectable range ends at `max_distance` is expected on when seen from
    /// `distance`: `ceil(log_factor(max_distance / distance))`, within the pyramid.
    pub fn predicted_level(&self, max_distance: f64, distance: f64) -> u8 {
        let ratio = max_distance / distance.max(1e-9);
        // a hair below an integer is that integer (the ratio of a range to the distance it came from)
        let level = (ratio.ln() / self.factor.ln() - 1e-9).ceil();
        level.clamp(0.0, (self.levels.saturating_sub(1)) as f64) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_and_its_observation_agree_and_its_ray_points_at_it() {
        let cam = StereoCamera { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), baseline: 0.54 };
        let p = Vector3::new(2.0, -1.0, 14.0);
        let o = cam.observe(&p);
        let back = cam.point(o[0], o[1], o[0] - o[2]);
        assert!((back - p).norm() < 1e-9, "{back}");
        let (u, v) = cam.project(&p).expect("in front");
        assert!((u - o[0]).abs() < 1e-12 && (v - o[1]).abs() < 1e-12);
        assert!((cam.ray(u, v) - p.normalize()).norm() < 1e-12);
        assert!(cam.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn the_distance_range_brackets_the_distance_and_predicts_the_level_it_was_seen_on() {
        let s = ScalePyramid::default();
        for level in 0..8u8 {
            let (min, max) = s.distance_range(20.0, level);
            assert!(min <= 20.0 + 1e-9 && 20.0 <= max + 1e-9, "{level}: {min}..{max}");
            assert_eq!(s.predicted_level(max, 20.0), level, "seen again from where it was first seen");
            // twice as near: one level coarser per factor of 1.2 in distance, up to the last level
            assert!(s.predicted_level(max, 10.0) >= level);
        }
        assert_eq!(s.predicted_level(10.0, 1000.0), 0, "far beyond the range: the finest level");
        assert_eq!(s.predicted_level(1000.0, 1.0), 7, "far inside it: the coarsest");
    }
}
