//! The pose search: finds a frame's pose against the local map. The local map's points are projected from
//! a guessed pose and matched to the frame's keypoints inside windows sized by the guess's
//! uncertainty ([`PoseSearch::search`]), PnP RANSAC solves the pose ([`PoseSearch::pnp_ransac`]), a second
//! search at that pose adds matches, and the refinement ([`PoseSearch::refine`], in `refine.rs`) gives the
//! final pose and its inliers. Descriptor matching without a guess ([`PoseSearch::match_all`]) serves
//! relocalisation.

use std::collections::HashSet;
use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Vector3};
use opencv::{calib3d, core, prelude::*};
use slam_core::KeyframeId;
use slam_map::{hamming, BestTwo, KeypointGrid, ScalePyramid};
use slam_optim::SharedOptimizer;
use slam_quadric::se3;

use super::config::{StereoRig, VoConfig};
use super::frame::Frame;
use super::local_map::LocalMap;
use super::refine::{Refined, Refiner};
use crate::image_io::FrontendError;

/// How a pose was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Route {
    /// Constant-velocity prediction (or the wider search around it).
    Motion,
    /// Relocalisation along the motion, `k` frame intervals ahead (dropped frames).
    Along(usize),
    /// By descriptors alone against the local map, without the motion model's prediction (the motion
    /// model broke: a reversal, a start after a standstill); accepted on its own support.
    Descriptors,
    /// Relocalisation against a keyframe retrieved from the keyframe index (any keyframe of the run,
    /// a revisit included); accepted on its own support, not the motion model.
    Retrieved(KeyframeId),
}

/// Ratio of the best to the second-best Hamming distance a match must stay below (that of every
/// matching of the front end: [`slam_map::BestTwo::winner`]).
const RATIO: f64 = 0.9;

/// A pose found by PnP RANSAC (`curr_from_ref`) and its inlier matches (local-map point, keypoint).
pub(crate) type Solved = (Isometry3<f64>, Vec<(usize, usize)>);

/// The pose search and refinement of one rig with its settings; `image_size` is that of the frames
/// being tracked (set by the first frame).
pub(crate) struct PoseSearch {
    pub(crate) rig: StereoRig,
    pub(crate) config: VoConfig,
    /// Solves the last refinement round (points free with their keyframe observations).
    pub(crate) optimizer: SharedOptimizer,
    /// Image size (width, height), pixels.
    pub(crate) image_size: (f64, f64),
}

/// Keeps the matches whose keypoint orientation changes agree with the bulk: a histogram of the
/// changes in 12° bins, matches in the three fullest bins kept (the second and third only when they
/// hold at least a tenth of the fullest). The image of a rigid scene turns as a whole.
pub(crate) fn orientation_filter(matches: Vec<(usize, usize, f32)>) -> Vec<(usize, usize)> {
    const BINS: usize = 30;
    let bin = |d: f32| (((d.rem_euclid(360.0)) / 360.0 * BINS as f32) as usize).min(BINS - 1);
    let mut hist = [0usize; BINS];
    for m in &matches {
        hist[bin(m.2)] += 1;
    }
    let mut order: Vec<usize> = (0..BINS).collect();
    order.sort_by(|a, b| hist[*b].cmp(&hist[*a]).then(a.cmp(b)));
    let max = hist[order[0]];
    let keep: Vec<usize> =
        order.iter().take(3).enumerate().filter(|(r, &b)| *r == 0 || hist[b] * 10 >= max).map(|(_, &b)| b).collect();
    matches.into_iter().filter(|m| keep.contains(&bin(m.2))).map(|m| (m.0, m.1)).collect()
}

impl PoseSearch {
    /// The refinement of this rig and settings.
    pub(crate) fn refiner(&self) -> Refiner<'_> {
        Refiner { rig: &self.rig, config: &self.config, optimizer: &self.optimizer }
    }

    /// Search window of a point at `c` (current camera frame) expected at pyramid level `level`, when
    /// the predicted pose may be off by `sigma_t` metres and `sigma_r` radians: the image motion those
    /// errors cause at that depth and offset from the axis, plus the keypoint's own scale.
    pub(crate) fn window(&self, c: &Vector3<f64>, level: u8, (sigma_t, sigma_r): (f64, f64)) -> f64 {
        let f = self.rig.k.fx;
        let off = (c.x.abs() + c.y.abs()) / c.z;
        let r = 3.0 * ScalePyramid::default().scale(level) + f * (sigma_r + sigma_t * (1.0 + off) / c.z);
        r.min(self.config.search_radius)
    }

    /// Where local-map point `i` is seen from `curr_from_ref`: its pixel, its camera-frame position and
    /// the pyramid level its distance predicts; `None` outside the image (with a cell's margin), behind
    /// the camera, or outside its distance range or viewing angle.
    pub(crate) fn projection(
        &self,
        map: &LocalMap,
        i: usize,
        curr_from_ref: &Isometry3<f64>,
        centre: &Vector3<f64>,
    ) -> Option<((f64, f64), Vector3<f64>, u8)> {
        let k = &self.rig.k;
        let margin = KeypointGrid::CELL;
        let c = curr_from_ref * nalgebra::Point3::from(map.points[i]);
        if c.z <= 0.1 {
            return None;
        }
        let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
        if u < -margin || v < -margin || u > self.image_size.0 + margin || v > self.image_size.1 + margin {
            return None;
        }
        let distance = map.viewable(i, centre)?;
        let level = ScalePyramid::default().predicted_level(map.distance[i].1, distance);
        Some(((u, v), c.coords, level))
    }

    /// Project the local map's points (not yet matched: `skip`) with `curr_from_ref` and match each to
    /// the keypoints (not yet `taken`) within its window and one level of the level its distance
    /// predicts: smallest Hamming distance under `track_hamming`, ratio test, each keypoint to its
    /// closest point, then the orientation check.
    pub(crate) fn search(
        &self,
        map: &LocalMap,
        curr_from_ref: &Isometry3<f64>,
        frame: &Frame,
        window: &dyn Fn(&Vector3<f64>, u8) -> f64,
        (skip, taken): (&[bool], &[bool]),
    ) -> Vec<(usize, usize)> {
        let centre = curr_from_ref.inverse().translation.vector;
        let mut found: Vec<(u32, usize, usize)> = Vec::new();
        let max_hamming = self.config.track_hamming;
        for (i, _) in skip.iter().enumerate().filter(|(_, s)| !**s) {
            let Some(((u, v), c, level)) = self.projection(map, i, curr_from_ref, &centre) else { continue };
            let radius = window(&c, level);
            // the two closest candidates (distance, keypoint)
            let (mut best, mut second) = ((u32::MAX, usize::MAX), (u32::MAX, usize::MAX));
            let d = &map.desc[i];
            frame.grid.for_each_near((u, v), radius, |j| {
                if taken[j] {
                    return;
                }
                let lj = frame.octave[j];
                if lj + 1 < level as i32 || lj > level as i32 + 1 {
                    return;
                }
                let (uj, vj) = frame.keypoints[j];
                if (uj - u).powi(2) + (vj - v).powi(2) <= radius * radius {
                    let h = hamming(d, &frame.keypoint_desc[j]);
                    if h < best.0 {
                        (second, best) = (best, (h, j));
                    } else if h < second.0 {
                        second = (h, j);
                    }
                }
            });
            if best.0 > max_hamming {
                continue;
            }
            // ratio test: the best clearly better than the second (a lone candidate passes)
            if second.0 != u32::MAX && best.0 as f64 >= RATIO * second.0 as f64 {
                continue;
            }
            found.push((best.0, i, best.1));
        }
        Self::assign(found, map, frame)
    }

    /// Each keypoint to the point closest in descriptor distance, then the orientation check.
    pub(crate) fn assign(mut found: Vec<(u32, usize, usize)>, map: &LocalMap, frame: &Frame) -> Vec<(usize, usize)> {
        found.sort_unstable();
        let mut used = HashSet::new();
        let kept: Vec<(usize, usize, f32)> = found
            .into_iter()
            .filter(|&(_, _, j)| used.insert(j))
            .map(|(_, i, j)| (i, j, frame.angle[j] - map.angle[i]))
            .collect();
        let mut out = orientation_filter(kept);
        out.sort_unstable();
        out
    }

    /// Brute-force descriptor matching of the map's points against all keypoints (Hamming ≤ 64, ratio
    /// test, orientation check): relocalisation when there is no usable prediction.
    pub(crate) fn match_all(&self, map: &LocalMap, frame: &Frame) -> Vec<(usize, usize)> {
        let mut found = Vec::new();
        for (i, d) in map.desc.iter().enumerate() {
            let mut two = BestTwo::new();
            for (j, e) in frame.keypoint_desc.iter().enumerate() {
                two.offer(hamming(d, e), j);
            }
            if let Some(j) = two.winner(64, false) {
                found.push((two.best, i, j));
            }
        }
        Self::assign(found, map, frame)
    }

    /// PnP RANSAC on the matches: `curr_from_ref` and the inlier matches.
    pub(crate) fn pnp_ransac(
        &self,
        map: &LocalMap,
        frame: &Frame,
        matches: &[(usize, usize)],
        (ransac_px, iterations, min_inliers): (f32, i32, usize),
    ) -> Result<Option<Solved>, FrontendError> {
        if matches.len() < min_inliers.max(6) {
            return Ok(None);
        }
        let obj: core::Vector<core::Point3f> = matches
            .iter()
            .map(|&(p, _)| {
                let x = map.points[p];
                core::Point3f::new(x.x as f32, x.y as f32, x.z as f32)
            })
            .collect();
        let img: core::Vector<core::Point2f> = matches
            .iter()
            .map(|&(_, c)| core::Point2f::new(frame.keypoints[c].0 as f32, frame.keypoints[c].1 as f32))
            .collect();
        let k = &self.rig.k;
        let kmat = Mat::from_slice_2d(&[[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]])?;
        let mut rvec = Mat::default();
        let mut tvec = Mat::default();
        let mut inliers = core::Vector::<i32>::new();
        let ok = calib3d::solve_pnp_ransac(
            &obj,
            &img,
            &kmat,
            &core::no_array(),
            &mut rvec,
            &mut tvec,
            false,
            iterations,
            ransac_px,
            0.999,
            &mut inliers,
            if iterations > 200 { calib3d::SOLVEPNP_AP3P } else { calib3d::SOLVEPNP_EPNP },
        )?;
        tracing::trace!(matches = matches.len(), inliers = inliers.len(), "PnP RANSAC");
        if !ok || inliers.len() < min_inliers {
            return Ok(None);
        }
        let mut rmat = Mat::default();
        calib3d::rodrigues(&rvec, &mut rmat, &mut core::no_array())?;
        let r = Matrix3::from_fn(|i, j| *rmat.at_2d::<f64>(i as i32, j as i32).unwrap_or(&0.0));
        let t = Vector3::new(*tvec.at::<f64>(0)?, *tvec.at::<f64>(1)?, *tvec.at::<f64>(2)?);
        let pose = se3::isometry_from_parts(&r, &t);
        if !pose.translation.vector.iter().all(|v| v.is_finite()) {
            return Ok(None);
        }
        Ok(Some((pose, inliers.iter().map(|i| matches[i as usize]).collect())))
    }

    /// Track against the local map from `guess` (`curr_from_ref`): search in windows sized by `bounds`
    /// (metres, radians), PnP RANSAC, a second search at the pose found, and the refinement
    /// (`last_measured`: the last measured frame's pose in the reference keyframe, the vehicle-motion
    /// prior's anchor). Returns the refined pose and the RANSAC inlier count.
    pub(crate) fn track_from(
        &self,
        map: &LocalMap,
        frame: &Frame,
        guess: &Isometry3<f64>,
        bounds: (f64, f64),
        last_measured: &Isometry3<f64>,
    ) -> Result<Option<(Refined, usize)>, FrontendError> {
        let t0 = Instant::now();
        let skip = vec![false; map.points.len()];
        let taken = vec![false; frame.keypoints.len()];
        let matches = self.search(map, guess, frame, &|c, o| self.window(c, o, bounds), (&skip, &taken));
        let t1 = Instant::now();
        let first = self.pnp_ransac(map, frame, &matches, (self.config.ransac_px, 200, self.config.weak_inliers))?;
        let t2 = Instant::now();
        tracing::debug!(
            matches = matches.len(),
            search_ms = (t1 - t0).as_secs_f64() * 1e3,
            pnp_ms = (t2 - t1).as_secs_f64() * 1e3,
            "local-map search"
        );
        let Some((pose, inliers)) = first else { return Ok(None) };
        Ok(self.extend_and_refine(map, frame, &pose, inliers, last_measured))
    }

    /// The second search (points not matched yet, small windows at `pose`) and the refinement.
    pub(crate) fn extend_and_refine(
        &self,
        map: &LocalMap,
        frame: &Frame,
        pose: &Isometry3<f64>,
        inliers: Vec<(usize, usize)>,
        last_measured: &Isometry3<f64>,
    ) -> Option<(Refined, usize)> {
        let t0 = Instant::now();
        let ransac_inliers = inliers.len();
        let mut skip = vec![false; map.points.len()];
        let mut taken = vec![false; frame.keypoints.len()];
        for &(i, c) in &inliers {
            skip[i] = true;
            taken[c] = true;
        }
        let radius = self.config.local_radius;
        let extra = self.search(map, pose, frame, &|_, l| radius * ScalePyramid::default().scale(l), (&skip, &taken));
        let mut all = inliers;
        all.extend(extra);
        all.sort_unstable();
        let t1 = Instant::now();
        let refined = self.refiner().refine(map, frame, &all, pose, last_measured);
        tracing::debug!(
            matches = all.len(),
            search_ms = (t1 - t0).as_secs_f64() * 1e3,
            refine_ms = t1.elapsed().as_secs_f64() * 1e3,
            "second search and refinement"
        );
        refined.map(|r| (r, ransac_inliers))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_check_drops_matches_that_turn_against_the_rest() {
        // most turn by 2°, some by −1° (the neighbouring bin across 0), four by 90°
        let mut m: Vec<(usize, usize, f32)> = (0..50).map(|i| (i, i, 2.0)).collect();
        m.extend((50..70).map(|i| (i, i, -1.0)));
        m.extend((70..74).map(|i| (i, i, 90.0)));
        let kept = orientation_filter(m);
        assert_eq!(kept.len(), 70, "{kept:?}");
        assert!(kept.iter().all(|&(i, _)| i < 70));
    }
}
