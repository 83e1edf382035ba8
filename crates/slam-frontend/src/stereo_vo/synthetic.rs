//! Synthetic drives for the tracker: a street of known points seen by a KITTI-like rig, observed with
//! Gaussian pixel noise of a chosen size, fed to [`StereoVo`] as prepared frames (no images, no ORB),
//! so that what the tracker makes of noisy stereo can be measured against the truth: the path length
//! (scale), the steps.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_core::rng::SimRng;
use slam_quadric::Intrinsics;

use super::frame::Frame;
use super::{StereoRig, StereoVo, VoConfig};
use crate::matching::KeypointGrid;

/// KITTI's rectified rig (odometry 06: fx 707.09 px, baseline 0.537 m) and image size.
pub(crate) const RIG: StereoRig =
    StereoRig { k: Intrinsics { fx: 707.0912, fy: 707.0912, cx: 601.8873, cy: 183.1104, skew: 0.0 }, baseline: 0.5372 };
pub(crate) const SIZE: (f64, f64) = (1226.0, 370.0);

/// A street: road points, two facades and trees along it, with random 256-bit descriptors (unique
/// with overwhelming probability, so matching is decided by projection alone).
pub(crate) struct Street {
    pub(crate) points: Vec<Vector3<f64>>,
    pub(crate) desc: Vec<[u8; 32]>,
}

impl Street {
    /// `n` points along `length` metres of street ahead of the origin (camera frame at the start: x
    /// right, y down, z ahead): a fifth on the road 1.65 m below the camera, the rest on facades 6–15 m
    /// to either side up to 8 m above the road.
    pub(crate) fn new(n: usize, length: f64, rng: &mut SimRng) -> Self {
        let mut points = Vec::with_capacity(n);
        for i in 0..n {
            let z = rng.uniform(0.0, length);
            let p = if i % 5 == 0 {
                Vector3::new(rng.uniform(-7.0, 7.0), 1.65, z)
            } else {
                let side = if i % 2 == 0 { -1.0 } else { 1.0 };
                Vector3::new(side * rng.uniform(6.0, 15.0), rng.uniform(-6.3, 1.6), z)
            };
            points.push(p);
        }
        let desc = (0..n).map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8)).collect();
        Self { points, desc }
    }

    /// The frame seen from `world_from_camera`: every point 1–80 m ahead inside the image, its left
    /// keypoint and right column observed with independent Gaussian noise of `sigma_px`, and its stereo
    /// point triangulated from the noisy observation as the stereo matcher does.
    pub(crate) fn frame(&self, world_from_camera: &Isometry3<f64>, sigma_px: f64, rng: &mut SimRng) -> Frame {
        let camera_from_world = world_from_camera.inverse();
        let (mut keypoints, mut keypoint_desc, mut points, mut obs, mut desc, mut of_keypoint) =
            (vec![], vec![], vec![], vec![], vec![], vec![]);
        for (x, d) in self.points.iter().zip(&self.desc) {
            let c = camera_from_world * Point3::from(*x);
            if c.z < 1.0 || c.z > 80.0 {
                continue;
            }
            let [u, v, ur] = RIG.observe(&c.coords);
            if u < 0.0 || v < 0.0 || u >= SIZE.0 || v >= SIZE.1 || ur < 0.0 {
                continue;
            }
            let (u, v, ur) = (u + sigma_px * rng.normal(), v + sigma_px * rng.normal(), ur + sigma_px * rng.normal());
            let p = RIG.point(u, v, u - ur);
            if !(1.0..=80.0).contains(&p.z) {
                keypoints.push((u, v));
                keypoint_desc.push(*d);
                of_keypoint.push(None);
                continue;
            }
            of_keypoint.push(Some(points.len()));
            keypoints.push((u, v));
            keypoint_desc.push(*d);
            points.push(p);
            obs.push([u, v, ur]);
            desc.push(*d);
        }
        let (n, m) = (points.len(), keypoints.len());
        Frame {
            points,
            desc,
            obs,
            of_keypoint,
            ids: vec![0; n],
            valid: vec![true; n],
            grid: KeypointGrid::new(&keypoints),
            keypoints,
            keypoint_desc,
            octave: vec![0; m],
            angle: vec![0.0; m],
        }
    }
}

/// A drive of `frames` poses along the street: `step` metres per frame, turning by `yaw_per_frame`
/// radians per frame (a constant-curvature road), camera frame at the start = world.
pub(crate) fn drive(frames: usize, step: f64, yaw_per_frame: f64) -> Vec<Isometry3<f64>> {
    let mut pose = Isometry3::identity();
    let mut out = vec![pose];
    let delta = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, step),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_per_frame),
    );
    for _ in 1..frames {
        pose *= delta;
        out.push(pose);
    }
    out
}

/// The tracker's poses (world from camera) on a synthetic drive with observation noise `sigma_px`, and
/// the keyframes it handed to the mapper.
pub(crate) fn track_keyframes(
    config: VoConfig,
    street: &Street,
    truth: &[Isometry3<f64>],
    sigma_px: f64,
    seed: u64,
) -> (Vec<Isometry3<f64>>, Vec<slam_core::KeyframeData>) {
    let optimizer = std::sync::Arc::new(slam_lm::LevenbergMarquardt::default());
    let mut vo = StereoVo::new(RIG, config, optimizer).expect("ORB");
    vo.tracker.image_size = SIZE;
    let mut rng = SimRng::new(seed);
    let mut keyframes = Vec::new();
    let poses = truth
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let frame = street.frame(pose, sigma_px, &mut rng);
            let t = vo.track_frame(i, frame, (Vec::new(), Vec::new()), (0.0, 0.0)).expect("tracks");
            keyframes.extend(t.keyframe);
            t.world_from_camera
        })
        .collect();
    (poses, keyframes)
}

/// The tracker's poses on a synthetic drive ([`track_keyframes`]).
pub(crate) fn track(
    config: VoConfig,
    street: &Street,
    truth: &[Isometry3<f64>],
    sigma_px: f64,
    seed: u64,
) -> Vec<Isometry3<f64>> {
    track_keyframes(config, street, truth, sigma_px, seed).0
}

/// Path length, metres.
pub(crate) fn path_length(poses: &[Isometry3<f64>]) -> f64 {
    poses.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tracker's path error (estimated path length over the true one, minus one) on synthetic
    /// streets with 0.5 px of observation noise, mean over seeds: unbiased within 0.2 %.
    #[test]
    fn noisy_stereo_gives_an_unbiased_path() {
        let truth = drive(40, 1.0, 0.002);
        let mut errors = Vec::new();
        for seed in 0..4u64 {
            let street = Street::new(6000, 130.0, &mut SimRng::new(100 + seed));
            let est = track(VoConfig::default(), &street, &truth, 0.5, seed);
            errors.push(100.0 * (path_length(&est) / path_length(&truth) - 1.0));
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        eprintln!("path errors % {errors:?}, mean {mean:+.3}");
        assert!(mean.abs() < 0.2, "mean path error {mean:+.3} % ({errors:?})");
    }

    /// The keyframes handed to the mapper observe points beyond `far_baselines` in the left image only,
    /// and nearer ones in both; without the limit every stereo observation keeps its right column.
    #[test]
    fn far_points_reach_the_mapper_as_left_only_observations() {
        let truth = drive(6, 1.0, 0.0);
        let street = Street::new(3000, 100.0, &mut SimRng::new(5));
        let limit = VoConfig::default().far_disparity_px(RIG.k.fx);
        let (_, kfs) = track_keyframes(VoConfig::default(), &street, &truth, 0.3, 1);
        let obs: Vec<[f64; 3]> = kfs.iter().flat_map(|k| k.points.iter().map(|p| p.observation)).collect();
        let far = obs.iter().filter(|o| o[2].is_nan()).count();
        assert!(far > 100 && obs.len() - far > 100, "{far} far of {}", obs.len());
        for o in obs.iter().filter(|o| o[2].is_finite()) {
            assert!(o[0] - o[2] >= limit, "a stereo observation of disparity {}", o[0] - o[2]);
        }
        let all = VoConfig { far_baselines: f64::INFINITY, ..VoConfig::default() };
        let (_, kfs) = track_keyframes(all, &street, &truth, 0.3, 1);
        assert!(kfs.iter().flat_map(|k| &k.points).all(|p| p.observation[2].is_finite()));
    }
}
