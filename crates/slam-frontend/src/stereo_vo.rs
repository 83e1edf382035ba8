//! Stereo visual odometry: ORB features on both images, stereo matching along rectified rows, guided
//! frame-to-frame matching under a constant-velocity prediction, PnP RANSAC, and a motion-only
//! refinement with the optimiser's reprojection factor (Huber).
//!
//! This is the tracking core of the front end; local bundle adjustment, keyframes and relocalisation
//! against a map build on it.

use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Vector3};
use opencv::{calib3d, core, features2d, prelude::*};
use slam_core::{
    geometry::BBox, Image, KeyframeCorrection, KeyframeData, KeyframeId, KeyframePoint, PointId, PointPair, StageTimes,
    StereoTracker, TrackError, TrackState, TrackedFrame,
};
use slam_optim::{
    factors::{MonoReprojection, StereoReprojection},
    Graph, Huber, NoiseModel, Options, SharedOptimizer, Values, Var,
};
use slam_quadric::{se3, Intrinsics};

use crate::disparity::DisparityPair;
use crate::image_io::{image_to_mat, FrontendError};

/// A rectified stereo rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRig {
    /// Intrinsics of both (rectified) cameras.
    pub k: Intrinsics,
    /// Baseline, metres (right camera at +x of the left).
    pub baseline: f64,
}

/// Settings of [`StereoVo`] (the `[tracking]` table of `slam-app run --config`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct VoConfig {
    /// ORB features per image.
    pub features: i32,
    /// Largest Hamming distance of a stereo match.
    pub stereo_hamming: u32,
    /// Row tolerance of stereo matching, pixels.
    pub row_tolerance: f64,
    /// Depth range kept, metres (nearest, farthest).
    pub depth_range: (f64, f64),
    /// Largest Hamming distance of a frame-to-frame match.
    pub track_hamming: u32,
    /// Search radius around the predicted position, pixels.
    pub search_radius: f64,
    /// PnP RANSAC reprojection threshold, pixels.
    pub ransac_px: f32,
    /// Fewest PnP inliers for a tracked frame.
    pub min_inliers: usize,
    /// A new keyframe is taken when the inliers against the current keyframe fall below this fraction of
    /// the inliers of the first frame tracked against it.
    pub keyframe_inlier_ratio: f64,
    /// ... or when this many frames have been tracked against it.
    pub keyframe_max_gap: usize,
    /// Most keypoints followed by optical flow per detection box (association cue).
    pub flow_points_per_region: usize,
    /// Older keyframes (besides the reference) whose points are searched in each tracked frame (the
    /// local map), so that a new keyframe's points keep the ids of the map points they re-observe
    /// (longer tracks for local BA). Default 0: on the shipped sequence it did not pay (docs/system.md).
    pub local_keyframes: usize,
    /// Search radius of local-map points around their projection, pixels.
    pub local_radius: f64,
    /// Added to every measured disparity, pixels: a correction of the rig's rectification (see
    /// [`crate::disparity`]; `slam-app stereo-check` estimates it from a sequence's images). Default 0.
    pub disparity_offset: f64,
    /// At a new keyframe, triangulate its keypoints without a stereo match against the previous
    /// keyframe's (epipolar search, ≥ `triangulate_parallax_deg` of parallax, ≤ 2 px reprojection error
    /// in both): new map points observed in the left images only. Default off: on the shipped sequence
    /// it did not pay (docs/system.md).
    pub triangulate: bool,
    /// Least angle between the two rays of a triangulated point, degrees.
    pub triangulate_parallax_deg: f64,
    /// Frame pairs kept for [`StereoVo::disparity_pairs`] (offset self-calibration); 0 keeps none.
    /// Not a settings-file key: `slam-app stereo-check` sets it.
    #[serde(skip)]
    pub keep_disparity_pairs: usize,
}

impl Default for VoConfig {
    fn default() -> Self {
        Self {
            features: 2000,
            stereo_hamming: 60,
            row_tolerance: 2.0,
            depth_range: (1.0, 80.0),
            track_hamming: 60,
            search_radius: 40.0,
            ransac_px: 2.0,
            min_inliers: 30,
            keyframe_inlier_ratio: 0.5,
            keyframe_max_gap: 4,
            flow_points_per_region: 40,
            local_keyframes: 0,
            local_radius: 8.0,
            disparity_offset: 0.0,
            triangulate: false,
            triangulate_parallax_deg: 3.0,
            keep_disparity_pairs: 0,
        }
    }
}

struct Frame {
    points: Vec<Vector3<f64>>,
    desc: Vec<[u8; 32]>,
    /// Stereo observation `[u_l, v, u_r]` of each point.
    obs: Vec<[f64; 3]>,
    /// For each left keypoint, its stereo point (if any).
    of_keypoint: Vec<Option<usize>>,
    /// Map-point id of each point (set when the frame becomes a keyframe).
    ids: Vec<PointId>,
    /// Points still usable (the mapper may cull some).
    valid: Vec<bool>,
    /// All left keypoints and their descriptors (triangulation of keypoints without a stereo match).
    keypoints: Vec<(f64, f64)>,
    keypoint_desc: Vec<[u8; 32]>,
}

/// The keyframe frames are tracked against.
struct Reference {
    frame: Frame,
    id: KeyframeId,
    world_from_kf: Isometry3<f64>,
    /// Parent keyframe and `parent_from_this`.
    parent: Option<(KeyframeId, Isometry3<f64>)>,
}

/// Stereo visual odometry against the last keyframe, with keyframe corrections from a mapper.
pub struct StereoVo {
    orb: core::Ptr<features2d::ORB>,
    rig: StereoRig,
    config: VoConfig,
    reference: Option<Reference>,
    /// Older keyframes of the segment, newest first (the local map).
    local: std::collections::VecDeque<Reference>,
    next_keyframe: KeyframeId,
    next_point: PointId,
    /// Pose of the last processed frame in the reference keyframe.
    kf_from_last: Isometry3<f64>,
    /// Inliers of the first frame tracked against the keyframe.
    kf_inliers: Option<usize>,
    /// Frames tracked against the keyframe.
    since_kf: usize,
    /// `T_last←curr` of the last step (constant-velocity model).
    velocity: Isometry3<f64>,
    /// Grey left images and left keypoints of the previous and current frame (optical flow).
    grey: [Option<Mat>; 2],
    keypoints: [Vec<(f64, f64)>; 2],
    /// Stereo correspondences of tracked frames with their keyframe (up to `keep_disparity_pairs`).
    pairs: Vec<DisparityPair>,
    /// Solves the two-frame stereo bundle adjustments.
    optimizer: SharedOptimizer,
}

/// A borrowed 8-bit grey image.
struct GreyView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
}

impl<'a> GreyView<'a> {
    fn of(m: &'a Mat) -> Result<Self, FrontendError> {
        Ok(Self { data: m.data_bytes()?, width: m.cols() as usize, height: m.rows() as usize })
    }

    fn at(&self, x: i64, y: i64) -> Option<i32> {
        (x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height)
            .then(|| self.data[y as usize * self.width + x as usize] as i32)
    }
}

/// Sub-pixel disparity by block matching along the row: SAD of an 11×11 patch at integer shifts
/// around the descriptor match, then a parabola through the best cost and its neighbours (as ORB-SLAM
/// does); `None` at image borders or when the minimum is at the search edge.
fn refine_disparity(left: &GreyView<'_>, right: &GreyView<'_>, ul: f64, v: f64, ur: f64) -> Option<f64> {
    const W: i64 = 5;
    const L: i64 = 3;
    let (xl, y, xr0) = (ul.round() as i64, v.round() as i64, ur.round() as i64);
    let mut costs = [0i64; (2 * L + 1) as usize];
    for (k, cost) in costs.iter_mut().enumerate() {
        let xr = xr0 + k as i64 - L;
        let mut sad = 0i64;
        for dy in -W..=W {
            for dx in -W..=W {
                let a = left.at(xl + dx, y + dy)?;
                let b = right.at(xr + dx, y + dy)?;
                sad += (a - b).abs() as i64;
            }
        }
        *cost = sad;
    }
    let (best, _) = costs.iter().enumerate().min_by_key(|(_, c)| **c)?;
    if best == 0 || best == costs.len() - 1 {
        return None;
    }
    let (c0, c1, c2) = (costs[best - 1] as f64, costs[best] as f64, costs[best + 1] as f64);
    let denom = c0 - 2.0 * c1 + c2;
    let delta = if denom > 0.0 { 0.5 * (c0 - c2) / denom } else { 0.0 };
    if delta.abs() > 1.0 {
        return None;
    }
    let xr = (xr0 + best as i64 - L) as f64 + delta;
    let d = xl as f64 - xr;
    (d > 0.0).then_some(d)
}

fn hamming(a: &[u8; 32], b: &[u8; 32]) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// The two smallest Hamming distances among the candidates offered, and the best candidate.
#[derive(Debug, Clone, Copy)]
struct BestTwo {
    best: u32,
    second: u32,
    arg: usize,
}

impl BestTwo {
    fn new() -> Self {
        Self { best: u32::MAX, second: u32::MAX, arg: usize::MAX }
    }

    fn offer(&mut self, h: u32, j: usize) {
        if h < self.best {
            (self.second, self.best, self.arg) = (self.best, h, j);
        } else if h < self.second {
            self.second = h;
        }
    }

    /// The best candidate when its distance is at most `max_hamming` and below 0.9 × the second best
    /// (at or below with `tie_ok`); a lone candidate passes the ratio test.
    fn winner(&self, max_hamming: u32, tie_ok: bool) -> Option<usize> {
        let limit = 0.9 * self.second as f64;
        let ratio = self.second == u32::MAX || (self.best as f64) < limit || (tie_ok && self.best as f64 == limit);
        (self.arg != usize::MAX && self.best <= max_hamming && ratio).then_some(self.arg)
    }
}

/// A solved pose (current from reference) and its inlier matches (reference point, current keypoint).
type Solved = (Isometry3<f64>, Vec<(usize, usize)>);

/// Keypoint positions and their 256-bit ORB descriptors.
type Features = (Vec<(f64, f64)>, Vec<[u8; 32]>);

fn extract(orb: &mut core::Ptr<features2d::ORB>, img: &Mat) -> Result<Features, FrontendError> {
    let mut kps = core::Vector::<core::KeyPoint>::new();
    let mut desc = Mat::default();
    orb.detect_and_compute(img, &core::no_array(), &mut kps, &mut desc, false)?;
    let mut pts = Vec::with_capacity(kps.len());
    let mut ds = Vec::with_capacity(kps.len());
    for (i, kp) in kps.iter().enumerate() {
        let row = desc.at_row::<u8>(i as i32)?;
        if row.len() != 32 {
            continue;
        }
        let mut d = [0u8; 32];
        d.copy_from_slice(row);
        pts.push((kp.pt().x as f64, kp.pt().y as f64));
        ds.push(d);
    }
    Ok((pts, ds))
}

impl StereoVo {
    /// Odometry for a rig; its two-frame bundle adjustments use `optimizer`.
    pub fn new(rig: StereoRig, config: VoConfig, optimizer: SharedOptimizer) -> Result<Self, FrontendError> {
        let orb = features2d::ORB::create(
            config.features,
            1.2,
            8,
            31,
            0,
            2,
            features2d::ORB_ScoreType::HARRIS_SCORE,
            31,
            20,
        )?;
        Ok(Self {
            orb,
            rig,
            config,
            reference: None,
            local: std::collections::VecDeque::new(),
            next_keyframe: 0,
            next_point: 0,
            kf_from_last: Isometry3::identity(),
            kf_inliers: None,
            since_kf: 0,
            velocity: Isometry3::identity(),
            grey: [None, None],
            keypoints: [Vec::new(), Vec::new()],
            pairs: Vec::new(),
            optimizer,
        })
    }

    /// Stereo points of the left keypoints: (left pixel, camera-frame point, descriptor).
    fn stereo(
        &self,
        left: &[(f64, f64)],
        ld: &[[u8; 32]],
        right: &[(f64, f64)],
        rd: &[[u8; 32]],
        grey: (&GreyView<'_>, &GreyView<'_>),
    ) -> Frame {
        let k = &self.rig.k;
        let rows = right.iter().map(|p| p.1 as usize).max().unwrap_or(0) + 1;
        let mut by_row: Vec<Vec<usize>> = vec![Vec::new(); rows + 3];
        for (i, p) in right.iter().enumerate() {
            by_row[p.1 as usize].push(i);
        }
        let tol = self.config.row_tolerance;
        let mut points = Vec::new();
        let mut desc = Vec::new();
        let mut obs = Vec::new();
        let mut of_keypoint = vec![None; left.len()];
        for (i, &(u, v)) in left.iter().enumerate() {
            let last = by_row.len() - 1;
            let (lo, hi) =
                ((((v - tol).floor().max(0.0)) as usize).min(last), ((v + tol).ceil().max(0.0) as usize).min(last));
            let mut two = BestTwo::new();
            for row in &by_row[lo..=hi] {
                for &j in row {
                    let (ur, vr) = right[j];
                    let d = u - ur;
                    if (vr - v).abs() > tol || d <= 0.0 || d > 300.0 {
                        continue;
                    }
                    two.offer(hamming(&ld[i], &rd[j]), j);
                }
            }
            let Some(arg) = two.winner(self.config.stereo_hamming, true) else { continue };
            let disparity = refine_disparity(grey.0, grey.1, u, v, right[arg].0).unwrap_or(u - right[arg].0)
                + self.config.disparity_offset;
            let z = k.fx * self.rig.baseline / disparity;
            if z < self.config.depth_range.0 || z > self.config.depth_range.1 {
                continue;
            }
            of_keypoint[i] = Some(points.len());
            points.push(Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z));
            desc.push(ld[i]);
            obs.push([u, v, u - disparity]);
        }
        let n = points.len();
        Frame {
            points,
            desc,
            obs,
            of_keypoint,
            ids: vec![0; n],
            valid: vec![true; n],
            keypoints: left.to_vec(),
            keypoint_desc: ld.to_vec(),
        }
    }

    /// Match the previous frame's points into the current left keypoints around their predicted pixels.
    fn guided_match(
        &self,
        prev: &Frame,
        curr_from_prev: &Isometry3<f64>,
        left: &[(f64, f64)],
        ld: &[[u8; 32]],
        radius: f64,
    ) -> Vec<(usize, usize)> {
        let k = &self.rig.k;
        let cell = 32.0;
        let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = std::collections::HashMap::new();
        for (i, p) in left.iter().enumerate() {
            grid.entry(((p.0 / cell) as i64, (p.1 / cell) as i64)).or_default().push(i);
        }
        let r = (radius / cell).ceil() as i64;
        let mut used = vec![false; left.len()];
        let mut out = Vec::new();
        for (pi, x) in prev.points.iter().enumerate() {
            if !prev.valid[pi] {
                continue;
            }
            let c = curr_from_prev * nalgebra::Point3::from(*x);
            if c.z <= 0.1 {
                continue;
            }
            let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
            let (gx, gy) = ((u / cell) as i64, (v / cell) as i64);
            let mut two = BestTwo::new();
            for dx in -r..=r {
                for dy in -r..=r {
                    let Some(cands) = grid.get(&(gx + dx, gy + dy)) else { continue };
                    for &j in cands {
                        let (uj, vj) = left[j];
                        if (uj - u).powi(2) + (vj - v).powi(2) > radius * radius {
                            continue;
                        }
                        two.offer(hamming(&prev.desc[pi], &ld[j]), j);
                    }
                }
            }
            if let Some(arg) = two.winner(self.config.track_hamming, false).filter(|&a| !used[a]) {
                used[arg] = true;
                out.push((pi, arg));
            }
        }
        out
    }

    /// Brute-force descriptor matching of the reference points against all keypoints (ratio test):
    /// relocalisation when the motion model gives no usable prediction.
    fn match_all(&self, prev: &Frame, ld: &[[u8; 32]]) -> Vec<(usize, usize)> {
        let mut used = vec![false; ld.len()];
        let mut out = Vec::new();
        for (pi, d) in prev.desc.iter().enumerate() {
            if !prev.valid[pi] {
                continue;
            }
            let mut two = BestTwo::new();
            for (j, e) in ld.iter().enumerate() {
                two.offer(hamming(d, e), j);
            }
            if let Some(arg) = two.winner(64, false).filter(|&a| !used[a]) {
                used[arg] = true;
                out.push((pi, arg));
            }
        }
        out
    }

    /// Make `frame` the reference keyframe; ids of points matched to the old reference carry over.
    fn take_keyframe(
        &mut self,
        mut frame: Frame,
        frame_index: usize,
        world_from_kf: Isometry3<f64>,
        parent: Option<(KeyframeId, Isometry3<f64>)>,
        carried: &[(PointId, usize)],
        earlier: &[(KeyframeId, usize, [f64; 3], Vector3<f64>)],
    ) -> KeyframeData {
        // keypoint → the map point it was matched to
        let from_keypoint: std::collections::HashMap<usize, PointId> = carried.iter().map(|&(id, c)| (c, id)).collect();
        let mut keypoint_of = vec![usize::MAX; frame.points.len()];
        for (kp, q) in frame.of_keypoint.iter().enumerate() {
            if let Some(q) = q {
                keypoint_of[*q] = kp;
            }
        }
        for (q, id) in frame.ids.iter_mut().enumerate() {
            *id = match from_keypoint.get(&keypoint_of[q]) {
                Some(&old) => old,
                None => {
                    self.next_point += 1;
                    self.next_point - 1
                }
            };
        }
        let id = self.next_keyframe;
        self.next_keyframe += 1;
        let data = KeyframeData {
            id,
            frame: frame_index,
            world_from_camera: world_from_kf,
            parent,
            points: frame
                .points
                .iter()
                .zip(&frame.obs)
                .zip(&frame.ids)
                .map(|((x, o), &pid)| KeyframePoint { id: pid, camera_point: *x, observation: *o })
                .collect(),
            earlier: earlier
                .iter()
                .map(|&(kf, q, observation, camera_point)| {
                    (kf, KeyframePoint { id: frame.ids[q], camera_point, observation })
                })
                .collect(),
        };
        let old = self.reference.replace(Reference { frame, id, world_from_kf, parent });
        match (old, parent) {
            (Some(old), Some(_)) => {
                self.local.push_front(old);
                self.local.truncate(self.config.local_keyframes);
            }
            // a new segment: the old keyframes' poses are not related to it
            _ => self.local.clear(),
        }
        self.kf_from_last = Isometry3::identity();
        self.kf_inliers = None;
        self.since_kf = 0;
        data
    }

    fn grey_of(img: &Image) -> Result<Mat, FrontendError> {
        let m = image_to_mat(img)?;
        if m.channels() == 3 {
            let mut g = Mat::default();
            opencv::imgproc::cvt_color_def(&m, &mut g, opencv::imgproc::COLOR_BGR2GRAY)?;
            Ok(g)
        } else {
            Ok(m)
        }
    }

    /// Stereo correspondences kept so far for offset self-calibration
    /// ([`crate::disparity::estimate_disparity_offset`]).
    pub fn disparity_pairs(&self) -> &[DisparityPair] {
        &self.pairs
    }

    /// Track one rectified stereo pair (grey or colour; colour is converted).
    pub fn process(
        &mut self,
        frame_index: usize,
        left: &Image,
        right: &Image,
        exclude: &[BBox],
    ) -> Result<TrackedFrame, FrontendError> {
        let t0 = Instant::now();
        let (lm, rm) = (Self::grey_of(left)?, Self::grey_of(right)?);
        let (mut lp, mut ld) = extract(&mut self.orb, &lm)?;
        if !exclude.is_empty() {
            let keep: Vec<bool> = lp.iter().map(|&(u, v)| !exclude.iter().any(|b| b.contains_point(u, v))).collect();
            let mut k = keep.iter();
            lp.retain(|_| *k.next().unwrap_or(&true));
            let mut k = keep.iter();
            ld.retain(|_| *k.next().unwrap_or(&true));
        }
        let (rp, rd) = extract(&mut self.orb, &rm)?;
        let t1 = Instant::now();
        let (lg, rg) = (GreyView::of(&lm)?, GreyView::of(&rm)?);
        let frame = self.stereo(&lp, &ld, &rp, &rd, (&lg, &rg));
        let t2 = Instant::now();
        self.grey.swap(0, 1);
        self.grey[1] = Some(lm);
        self.keypoints.swap(0, 1);
        self.keypoints[1] = lp.clone();
        let stereo_points = frame.points.len();
        let times = |t3: Instant| StageTimes {
            extraction: (t1 - t0).as_secs_f64() * 1e3,
            stereo: (t2 - t1).as_secs_f64() * 1e3,
            tracking: (t3 - t2).as_secs_f64() * 1e3,
        };
        let Some(reference) = self.reference.as_ref() else {
            let kf = self.take_keyframe(frame, frame_index, Isometry3::identity(), None, &[], &[]);
            return Ok(TrackedFrame {
                world_from_camera: Isometry3::identity(),
                reference: (kf.id, Isometry3::identity()),
                state: TrackState::Initialised,
                stereo_points,
                keyframe: Some(kf),
                times: times(Instant::now()),
            });
        };
        let prev = &reference.frame;
        let predicted = (self.kf_from_last * self.velocity).inverse(); // curr ← keyframe
        let mut matches = self.guided_match(prev, &predicted, &lp, &ld, self.config.search_radius);
        if matches.len() < self.config.min_inliers {
            matches = self.guided_match(prev, &self.kf_from_last.inverse(), &lp, &ld, 4.0 * self.config.search_radius);
        }
        let mut solved =
            self.pnp(prev, &frame, &lp, &matches, &predicted, (self.config.ransac_px, 200, self.config.min_inliers))?;
        let mut state = solved.as_ref().map(|s| TrackState::Tracked { inliers: s.1.len() });
        // best unverified relocalisation pose: where a new map segment starts if nothing better is found
        let mut fallback = None;
        if solved.is_none() {
            // relocalisation, first along the motion: dropped frames (a jump ahead) look like the motion
            // model applied several times
            for k in [2, 3, 5, 8, 12, 16] {
                let mut step = Isometry3::identity();
                for _ in 0..k {
                    step *= self.velocity;
                }
                let guess = (self.kf_from_last * step).inverse();
                let m = self.guided_match(prev, &guess, &lp, &ld, 2.0 * self.config.search_radius);
                tracing::trace!(steps = k, matches = m.len(), "relocalisation along the motion");
                if m.len() >= self.config.min_inliers {
                    solved =
                        self.pnp(prev, &frame, &lp, &m, &guess, (self.config.ransac_px, 200, self.config.min_inliers))?;
                    if solved.is_some() {
                        tracing::info!(frame = frame_index, steps = k, "relocalised along the motion");
                        break;
                    }
                }
            }
            if solved.is_none() {
                // then by descriptors alone, no motion prior, with a wider RANSAC threshold
                let all = self.match_all(prev, &ld);
                tracing::debug!(frame = frame_index, matches = all.len(), "relocalisation: descriptor matches");
                // (many outliers: a minimal 4-point solver and many more RANSAC rounds)
                let candidate =
                    self.pnp(prev, &frame, &lp, &all, &predicted, (2.0 * self.config.ransac_px, 5000, 12))?;
                // verify: the candidate pose must explain many guided matches
                if let Some((pose, _)) = candidate {
                    fallback = Some(pose);
                    let m = self.guided_match(prev, &pose, &lp, &ld, self.config.search_radius);
                    tracing::trace!(matches = m.len(), "relocalisation candidate check");
                    let need = (2 * self.config.min_inliers / 3).max(12);
                    solved = self.pnp(prev, &frame, &lp, &m, &pose, (self.config.ransac_px, 200, need))?;
                }
            }
            state = solved.as_ref().map(|s| TrackState::Relocalised { inliers: s.1.len() });
            if let Some(s) = &solved {
                tracing::info!(
                    frame = frame_index,
                    inliers = s.1.len(),
                    "relocalised against keyframe {}",
                    reference.id
                );
            }
        }
        let (ref_id, world_from_ref) = (reference.id, reference.world_from_kf);
        let (curr_from_prev, state, inliers) = match (solved, state) {
            (Some((pose, inl)), Some(state)) => (pose, state, inl),
            _ => (fallback.unwrap_or(predicted), TrackState::Lost, Vec::new()),
        };
        // matched map points: (id, keypoint)
        let mut carried: Vec<(PointId, usize)> = inliers.iter().map(|&(p, c)| (prev.ids[p], c)).collect();
        let kf_from_curr = curr_from_prev.inverse();
        let tracked = state != TrackState::Lost;
        if tracked {
            self.velocity = self.kf_from_last.inverse() * kf_from_curr;
        }
        if matches!(state, TrackState::Tracked { .. }) && self.pairs.len() < self.config.keep_disparity_pairs {
            let (a, b): (Vec<[f64; 3]>, Vec<[f64; 3]>) = inliers
                .iter()
                .filter(|&&(p, _)| prev.obs[p][2].is_finite())
                .filter_map(|&(p, c)| Some((prev.obs[p], frame.obs[frame.of_keypoint.get(c).copied().flatten()?])))
                .unzip();
            self.pairs.push(DisparityPair { keyframe: a, frame: b, frame_from_keyframe: curr_from_prev });
        }
        let world_from_curr = world_from_ref * kf_from_curr;
        self.since_kf += 1;
        let want_keyframe = match state {
            TrackState::Tracked { inliers } => {
                let base = *self.kf_inliers.get_or_insert(inliers);
                (inliers as f64) < self.config.keyframe_inlier_ratio * base as f64
                    || self.since_kf >= self.config.keyframe_max_gap
            }
            _ => true,
        };
        // keep the old keyframe when this frame has too few points of its own (black frame, blur)
        let keyframe = if want_keyframe && (frame.points.len() >= self.config.min_inliers || tracked) {
            if matches!(state, TrackState::Tracked { .. }) && !self.local.is_empty() {
                // the local map's points re-observed here keep their ids; the pose stays the two-frame
                // adjustment's (refining it against the older keyframes' points, held fixed, made it
                // worse: docs/system.md)
                if let Some(r) = self.reference.as_ref() {
                    let extra = self.search_local(&r.frame, r.world_from_kf, &curr_from_prev, &carried, &lp, &ld);
                    carried.extend(extra);
                }
            }
            // a lost frame starts a new map segment: no parent, no carried points
            let parent = tracked.then_some((ref_id, kf_from_curr));
            if !tracked {
                tracing::warn!(frame = frame_index, "tracking lost: new map segment from this frame");
            }
            let mut frame = frame;
            let earlier = match (tracked && self.config.triangulate, self.reference.as_ref()) {
                (true, Some(r)) => Self::triangulate(
                    &self.rig.k,
                    &r.frame,
                    &mut frame,
                    &curr_from_prev,
                    &carried,
                    self.config.triangulate_parallax_deg,
                )
                .into_iter()
                .map(|(q, obs, x)| (ref_id, q, obs, x))
                .collect(),
                _ => Vec::new(),
            };
            Some(self.take_keyframe(frame, frame_index, world_from_curr, parent, &carried, &earlier))
        } else {
            self.kf_from_last = kf_from_curr;
            None
        };
        Ok(TrackedFrame {
            world_from_camera: world_from_curr,
            reference: (ref_id, kf_from_curr),
            state,
            stereo_points,
            keyframe,
            times: times(Instant::now()),
        })
    }

    /// Triangulate the new keyframe's keypoints that have no stereo point and no carried map point
    /// against the reference keyframe's keypoints that have none either: a match lies within 1.5 px of
    /// the epipolar line, wins the best-two Hamming test, and its rays meet with `min_parallax_deg`,
    /// in front of both cameras and within 2 px of both keypoints. The points are appended to `frame`
    /// (left-only observations); returns `(point index in frame, observation in the reference, point in
    /// the reference frame)` for each.
    fn triangulate(
        k: &Intrinsics,
        reference: &Frame,
        frame: &mut Frame,
        curr_from_ref: &Isometry3<f64>,
        carried: &[(PointId, usize)],
        min_parallax_deg: f64,
    ) -> Vec<(usize, [f64; 3], Vector3<f64>)> {
        const BAND_PX: f64 = 1.5;
        const MAX_REPROJ_PX: f64 = 2.0;
        let min_cos = min_parallax_deg.to_radians().cos();
        let ref_from_curr = curr_from_ref.inverse();
        let (r, t) = (ref_from_curr.rotation.to_rotation_matrix().into_inner(), ref_from_curr.translation.vector);
        let kinv = k.matrix().try_inverse().unwrap_or_else(Matrix3::identity);
        // x_refᵀ E x_curr = 0 for normalised coordinates, E = [t]× R; F = K⁻ᵀ E K⁻¹
        let f = kinv.transpose() * t.cross_matrix() * r * kinv;
        let taken: std::collections::HashSet<usize> = carried.iter().map(|c| c.1).collect();
        let ref_free: Vec<usize> = (0..reference.keypoints.len())
            .filter(|&i| reference.of_keypoint.get(i).is_some_and(|q| q.is_none()))
            .collect();
        let mut ref_used = vec![false; reference.keypoints.len()];
        let project = |x: &Vector3<f64>| (k.fx * x.x / x.z + k.cx, k.fy * x.y / x.z + k.cy);
        let mut out = Vec::new();
        for c in 0..frame.keypoints.len() {
            if frame.of_keypoint[c].is_some() || taken.contains(&c) {
                continue;
            }
            let (uc, vc) = frame.keypoints[c];
            let line = f * Vector3::new(uc, vc, 1.0);
            let norm = (line.x * line.x + line.y * line.y).sqrt();
            if norm < 1e-12 {
                continue;
            }
            let mut two = BestTwo::new();
            for &p in &ref_free {
                let (ur, vr) = reference.keypoints[p];
                if (line.x * ur + line.y * vr + line.z).abs() / norm <= BAND_PX {
                    two.offer(hamming(&frame.keypoint_desc[c], &reference.keypoint_desc[p]), p);
                }
            }
            let Some(p) = two.winner(50, false).filter(|&p| !ref_used[p]) else { continue };
            // midpoint of the two rays, in the reference frame
            let (ur, vr) = reference.keypoints[p];
            let a = (kinv * Vector3::new(ur, vr, 1.0)).normalize();
            let b = (r * (kinv * Vector3::new(uc, vc, 1.0))).normalize();
            let cos = a.dot(&b);
            if cos > min_cos {
                continue;
            }
            // minimise |λa − (t + μb)|²
            let (ab, at, bt) = (cos, a.dot(&t), b.dot(&t));
            let den = 1.0 - ab * ab;
            let lambda = (at - ab * bt) / den;
            let mu = (ab * at - bt) / den;
            if lambda <= 0.0 || mu <= 0.0 {
                continue;
            }
            let x_ref = 0.5 * (lambda * a + t + mu * b);
            let x_cur = (curr_from_ref * nalgebra::Point3::from(x_ref)).coords;
            if x_ref.z <= 0.1 || x_cur.z <= 0.1 {
                continue;
            }
            let (pr, pc) = (project(&x_ref), project(&x_cur));
            if (pr.0 - ur).hypot(pr.1 - vr) > MAX_REPROJ_PX || (pc.0 - uc).hypot(pc.1 - vc) > MAX_REPROJ_PX {
                continue;
            }
            ref_used[p] = true;
            let q = frame.points.len();
            frame.points.push(x_cur);
            frame.desc.push(frame.keypoint_desc[c]);
            frame.obs.push([uc, vc, f64::NAN]);
            frame.of_keypoint[c] = Some(q);
            frame.ids.push(0);
            frame.valid.push(true);
            out.push((q, [ur, vr, f64::NAN], x_ref));
        }
        out
    }

    /// Points of the older keyframes (the local map) not matched yet, projected with the current pose and
    /// matched within `local_radius`: `(map point, keypoint)`.
    fn search_local(
        &self,
        reference: &Frame,
        world_from_ref: Isometry3<f64>,
        curr_from_ref: &Isometry3<f64>,
        matched: &[(PointId, usize)],
        lp: &[(f64, f64)],
        ld: &[[u8; 32]],
    ) -> Vec<(PointId, usize)> {
        let mut seen: std::collections::HashSet<PointId> = matched.iter().map(|m| m.0).collect();
        seen.extend(reference.ids.iter().copied());
        let used: std::collections::HashSet<usize> = matched.iter().map(|m| m.1).collect();
        let ref_from_world = world_from_ref.inverse();
        let mut candidates = Frame {
            points: Vec::new(),
            desc: Vec::new(),
            obs: Vec::new(),
            of_keypoint: Vec::new(),
            ids: Vec::new(),
            valid: Vec::new(),
            keypoints: Vec::new(),
            keypoint_desc: Vec::new(),
        };
        for kf in &self.local {
            let to_ref = ref_from_world * kf.world_from_kf;
            for (i, id) in kf.frame.ids.iter().enumerate() {
                if kf.frame.valid[i] && seen.insert(*id) {
                    candidates.points.push((to_ref * nalgebra::Point3::from(kf.frame.points[i])).coords);
                    candidates.desc.push(kf.frame.desc[i]);
                    candidates.ids.push(*id);
                    candidates.valid.push(true);
                }
            }
        }
        self.guided_match(&candidates, curr_from_ref, lp, ld, self.config.local_radius)
            .into_iter()
            .filter(|&(_, c)| !used.contains(&c))
            .map(|(i, c)| (candidates.ids[i], c))
            .collect()
    }

    /// Forward-backward Lucas-Kanade flow of the previous frame's keypoints inside `regions` into the
    /// current frame; pairs whose round trip misses by more than a pixel are dropped.
    pub fn optical_flow(&self, regions: &[BBox]) -> Result<Vec<PointPair>, FrontendError> {
        let ([Some(prev), Some(curr)], [kp, _]) = (&self.grey, &self.keypoints) else { return Ok(Vec::new()) };
        let mut pts = core::Vector::<core::Point2f>::new();
        for b in regions {
            let inside: Vec<&(f64, f64)> = kp.iter().filter(|&&(u, v)| b.contains_point(u, v)).collect();
            let step = inside.len().div_ceil(self.config.flow_points_per_region.max(1)).max(1);
            for p in inside.iter().step_by(step) {
                pts.push(core::Point2f::new(p.0 as f32, p.1 as f32));
            }
        }
        if pts.is_empty() {
            return Ok(Vec::new());
        }
        let lk = |a: &Mat, b: &Mat, from: &core::Vector<core::Point2f>| -> Result<_, FrontendError> {
            let mut to = core::Vector::<core::Point2f>::new();
            let mut status = core::Vector::<u8>::new();
            let mut err = core::Vector::<f32>::new();
            opencv::video::calc_optical_flow_pyr_lk(
                a,
                b,
                from,
                &mut to,
                &mut status,
                &mut err,
                core::Size::new(15, 15),
                2,
                core::TermCriteria::new(core::TermCriteria_COUNT + core::TermCriteria_EPS, 30, 0.01)?,
                0,
                1e-4,
            )?;
            Ok((to, status))
        };
        let (fwd, s1) = lk(prev, curr, &pts)?;
        let (back, s2) = lk(curr, prev, &fwd)?;
        let mut out = Vec::new();
        for i in 0..pts.len() {
            let (p, q, r) = (pts.get(i)?, fwd.get(i)?, back.get(i)?);
            if s1.get(i)? == 1 && s2.get(i)? == 1 && ((p.x - r.x).powi(2) + (p.y - r.y).powi(2)) < 1.0 {
                out.push(PointPair { reference: [p.x as f64, p.y as f64], current: [q.x as f64, q.y as f64] });
            }
        }
        Ok(out)
    }

    /// PnP RANSAC on the matches, then a two-frame stereo bundle adjustment on the inliers; returns the
    /// pose and the inlier matches.
    fn pnp(
        &self,
        prev: &Frame,
        curr: &Frame,
        lp: &[(f64, f64)],
        matches: &[(usize, usize)],
        guess: &Isometry3<f64>,
        (ransac_px, iterations, min_inliers): (f32, i32, usize),
    ) -> Result<Option<Solved>, FrontendError> {
        if matches.len() < min_inliers {
            return Ok(None);
        }
        let obj: core::Vector<core::Point3f> = matches
            .iter()
            .map(|&(p, _)| {
                let x = prev.points[p];
                core::Point3f::new(x.x as f32, x.y as f32, x.z as f32)
            })
            .collect();
        let img: core::Vector<core::Point2f> =
            matches.iter().map(|&(_, c)| core::Point2f::new(lp[c].0 as f32, lp[c].1 as f32)).collect();
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
        let mut curr_from_prev = se3::isometry_from_parts(&r, &t);
        if !curr_from_prev.translation.vector.iter().all(|v| v.is_finite()) {
            curr_from_prev = *guess;
        }
        // two-frame stereo bundle adjustment on the inliers: previous camera fixed (the gauge), current
        // camera free, points free (eliminated); stereo observations where a frame has them
        let mut values = Values::new();
        let k_prev = values.add(Var::Pose(Isometry3::identity()));
        let k_curr = values.add(Var::Pose(curr_from_prev.inverse()));
        let mut graph = Graph::new();
        graph.fix(k_prev);
        let b = self.rig.baseline;
        for idx in inliers.iter() {
            let (p, c) = matches[idx as usize];
            let kx = values.add(Var::Point(prev.points[p]));
            graph.eliminate(kx);
            let o = prev.obs[p];
            let _ = if o[2].is_nan() {
                graph.add(MonoReprojection::new(k_prev, kx, *k, [o[0], o[1]]), NoiseModel::Isotropic(1.0), Huber(2.0))
            } else {
                graph.add(StereoReprojection::new(k_prev, kx, *k, b, o), NoiseModel::Isotropic(1.0), Huber(2.0))
            };
            match curr.of_keypoint.get(c).copied().flatten() {
                Some(q) => {
                    let _ = graph.add(
                        StereoReprojection::new(k_curr, kx, *k, b, curr.obs[q]),
                        NoiseModel::Isotropic(1.0),
                        Huber(2.0),
                    );
                }
                None => {
                    let _ = graph.add(
                        MonoReprojection::new(k_curr, kx, *k, [lp[c].0, lp[c].1]),
                        NoiseModel::Isotropic(1.0),
                        Huber(2.0),
                    );
                }
            }
        }
        if self.optimizer.optimize(&graph, &mut values, &Options::with_max_iterations(20), None).is_ok() {
            if let Some(p) = values.pose(k_curr) {
                curr_from_prev = p.inverse();
            }
        }
        Ok(Some((curr_from_prev, inliers.iter().map(|i| matches[i as usize]).collect())))
    }
}

impl StereoTracker for StereoVo {
    fn track(
        &mut self,
        frame: usize,
        left: &Image,
        right: &Image,
        exclude: &[BBox],
    ) -> Result<TrackedFrame, TrackError> {
        self.process(frame, left, right, exclude).map_err(|e| TrackError(e.to_string()))
    }

    fn correct(&mut self, c: &KeyframeCorrection) {
        for kf in self.local.iter_mut().filter(|k| k.id == c.id) {
            kf.world_from_kf = c.world_from_camera;
        }
        let Some(r) = self.reference.as_mut() else { return };
        if r.id == c.id {
            r.world_from_kf = c.world_from_camera;
            let kf_from_world = c.world_from_camera.inverse();
            let refined: std::collections::HashMap<PointId, Vector3<f64>> = c.points.iter().copied().collect();
            let culled: std::collections::HashSet<PointId> = c.culled.iter().copied().collect();
            for (i, id) in r.frame.ids.iter().enumerate() {
                if culled.contains(id) {
                    r.frame.valid[i] = false;
                } else if let Some(x) = refined.get(id) {
                    r.frame.points[i] = (kf_from_world * nalgebra::Point3::from(*x)).coords;
                }
            }
        } else if let Some((parent, parent_from_ref)) = r.parent {
            if parent == c.id {
                r.world_from_kf = c.world_from_camera * parent_from_ref;
            }
        }
    }

    fn flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        self.optical_flow(regions).map_err(|e| TrackError(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::rng::SimRng;

    fn frame_of(keypoints: Vec<(f64, f64)>, desc: Vec<[u8; 32]>) -> Frame {
        let n = keypoints.len();
        Frame {
            points: Vec::new(),
            desc: Vec::new(),
            obs: Vec::new(),
            of_keypoint: vec![None; n],
            ids: Vec::new(),
            valid: Vec::new(),
            keypoints,
            keypoint_desc: desc,
        }
    }

    #[test]
    fn triangulation_recovers_points_with_parallax_and_skips_the_rest() {
        let k = Intrinsics::new(707.0, 707.0, 601.9, 183.1);
        // the camera moves 3 m forward and 0.5 m left, turning slightly
        let curr_from_ref = Isometry3::from_parts(
            nalgebra::Translation3::new(0.5, 0.0, -3.0),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.02, 0.0),
        );
        let mut rng = SimRng::new(7);
        let truth: Vec<Vector3<f64>> = (0..300)
            .map(|_| Vector3::new(rng.uniform(-15.0, 15.0), rng.uniform(-3.0, 2.0), rng.uniform(6.0, 60.0)))
            .collect();
        let project = |x: &Vector3<f64>| (k.fx * x.x / x.z + k.cx, k.fy * x.y / x.z + k.cy);
        let desc: Vec<[u8; 32]> = (0..truth.len())
            .map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8))
            .collect();
        let reference = frame_of(truth.iter().map(project).collect(), desc.clone());
        let in_curr: Vec<Vector3<f64>> =
            truth.iter().map(|x| (curr_from_ref * nalgebra::Point3::from(*x)).coords).collect();
        let mut frame = frame_of(in_curr.iter().map(project).collect(), desc);
        let out = StereoVo::triangulate(&k, &reference, &mut frame, &curr_from_ref, &[], 3.0);
        assert!(out.len() > 20, "{} points", out.len());
        for &(q, obs, x_ref) in &out {
            // which true point: the one whose reference keypoint was observed
            let i = reference.keypoints.iter().position(|p| p.0 == obs[0] && p.1 == obs[1]).expect("a keypoint");
            assert!((x_ref - truth[i]).norm() < 1e-6 * truth[i].norm(), "{x_ref} vs {}", truth[i]);
            assert!((frame.points[q] - in_curr[i]).norm() < 1e-6 * truth[i].norm());
            assert!(obs[2].is_nan() && frame.obs[q][2].is_nan());
            let a = truth[i].normalize();
            let b = (truth[i] - curr_from_ref.inverse().translation.vector).normalize();
            assert!(a.dot(&b) < 3f64.to_radians().cos(), "parallax below 3°");
        }
        // points with enough parallax that were left out are few (descriptor ties, band edges)
        let eligible = truth
            .iter()
            .filter(|x| {
                let a = x.normalize();
                let b = (*x - curr_from_ref.inverse().translation.vector).normalize();
                a.dot(&b) < 3.2f64.to_radians().cos()
            })
            .count();
        assert!(out.len() * 10 >= eligible * 9, "{} of {eligible}", out.len());
        // carried keypoints are never triangulated again
        let mut again = frame_of(frame.keypoints.clone(), frame.keypoint_desc.clone());
        let carried: Vec<(PointId, usize)> = (0..again.keypoints.len()).map(|c| (c as PointId, c)).collect();
        assert!(StereoVo::triangulate(&k, &reference, &mut again, &curr_from_ref, &carried, 3.0).is_empty());
    }
}
