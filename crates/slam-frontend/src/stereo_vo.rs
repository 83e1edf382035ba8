//! Stereo visual odometry: ORB features on both images, stereo matching along rectified rows, guided
//! frame-to-frame matching under a constant-velocity prediction, PnP RANSAC, and a motion-only
//! refinement with the optimiser's reprojection factor (Huber).
//!
//! This is the tracking core of the front end; local bundle adjustment, keyframes and relocalisation
//! against a map build on it.

use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Vector3};
use opencv::{calib3d, core, features2d, prelude::*};
use slam_core::Image;
use slam_optim::{
    factors::{MonoReprojection, StereoReprojection},
    Graph, Huber, LevenbergMarquardt, LmParams, NoiseModel, Values, Var,
};
use slam_quadric::{se3, Intrinsics};

use crate::image_io::{image_to_mat, FrontendError};

/// A rectified stereo rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRig {
    /// Intrinsics of both (rectified) cameras.
    pub k: Intrinsics,
    /// Baseline, metres (right camera at +x of the left).
    pub baseline: f64,
}

/// Settings of [`StereoVo`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoConfig {
    /// ORB features per image.
    pub features: i32,
    /// Largest Hamming distance of a stereo match.
    pub stereo_hamming: u32,
    /// Row tolerance of stereo matching, pixels.
    pub row_tolerance: f64,
    /// Depth range kept, metres.
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
        }
    }
}

/// Tracking outcome of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackStatus {
    /// The first frame (the world origin).
    Initialised,
    /// Tracked against the current keyframe.
    Tracked {
        /// PnP inliers.
        inliers: usize,
    },
    /// Tracking failed; the pose is the constant-velocity prediction.
    Lost,
}

/// Result of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoFrame {
    /// Pose of the left camera (world = first frame's left camera).
    pub world_from_camera: Isometry3<f64>,
    /// What happened.
    pub status: TrackStatus,
    /// Stereo points of this frame.
    pub stereo_points: usize,
    /// This frame became the keyframe that the next frames are tracked against.
    pub keyframe: bool,
    /// Milliseconds spent in feature extraction, stereo matching, tracking (matching + PnP + refinement).
    pub timings_ms: [f64; 3],
}

struct Frame {
    points: Vec<Vector3<f64>>,
    desc: Vec<[u8; 32]>,
    /// Stereo observation `[u_l, v, u_r]` of each point.
    obs: Vec<[f64; 3]>,
    /// For each left keypoint, its stereo point (if any).
    of_keypoint: Vec<Option<usize>>,
}

/// Frame-to-frame stereo visual odometry.
pub struct StereoVo {
    orb: core::Ptr<features2d::ORB>,
    rig: StereoRig,
    config: VoConfig,
    /// The keyframe that frames are tracked against.
    prev: Option<Frame>,
    world_from_prev: Isometry3<f64>,
    /// Pose of the last processed frame in the keyframe.
    kf_from_last: Isometry3<f64>,
    /// Inliers of the first frame tracked against the keyframe.
    kf_inliers: Option<usize>,
    /// Frames tracked against the keyframe.
    since_kf: usize,
    /// `T_last←curr` of the last step (constant-velocity model).
    velocity: Isometry3<f64>,
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
    /// Odometry for a rig.
    pub fn new(rig: StereoRig, config: VoConfig) -> Result<Self, FrontendError> {
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
            prev: None,
            world_from_prev: Isometry3::identity(),
            kf_from_last: Isometry3::identity(),
            kf_inliers: None,
            since_kf: 0,
            velocity: Isometry3::identity(),
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
            let (mut best, mut second, mut arg) = (u32::MAX, u32::MAX, usize::MAX);
            for row in &by_row[lo..=hi] {
                for &j in row {
                    let (ur, vr) = right[j];
                    let d = u - ur;
                    if (vr - v).abs() > tol || d <= 0.0 || d > 300.0 {
                        continue;
                    }
                    let h = hamming(&ld[i], &rd[j]);
                    if h < best {
                        (second, best, arg) = (best, h, j);
                    } else if h < second {
                        second = h;
                    }
                }
            }
            if arg == usize::MAX
                || best > self.config.stereo_hamming
                || (second != u32::MAX && best as f64 > 0.9 * second as f64)
            {
                continue;
            }
            let disparity = refine_disparity(grey.0, grey.1, u, v, right[arg].0).unwrap_or(u - right[arg].0);
            let z = k.fx * self.rig.baseline / disparity;
            if z < self.config.depth_range.0 || z > self.config.depth_range.1 {
                continue;
            }
            of_keypoint[i] = Some(points.len());
            points.push(Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z));
            desc.push(ld[i]);
            obs.push([u, v, u - disparity]);
        }
        Frame { points, desc, obs, of_keypoint }
    }

    /// Match the previous frame's points into the current left keypoints around their predicted pixels.
    fn track(
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
            let c = curr_from_prev * nalgebra::Point3::from(*x);
            if c.z <= 0.1 {
                continue;
            }
            let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
            let (gx, gy) = ((u / cell) as i64, (v / cell) as i64);
            let (mut best, mut second, mut arg) = (u32::MAX, u32::MAX, usize::MAX);
            for dx in -r..=r {
                for dy in -r..=r {
                    let Some(cands) = grid.get(&(gx + dx, gy + dy)) else { continue };
                    for &j in cands {
                        let (uj, vj) = left[j];
                        if (uj - u).powi(2) + (vj - v).powi(2) > radius * radius {
                            continue;
                        }
                        let h = hamming(&prev.desc[pi], &ld[j]);
                        if h < best {
                            (second, best, arg) = (best, h, j);
                        } else if h < second {
                            second = h;
                        }
                    }
                }
            }
            if arg != usize::MAX
                && !used[arg]
                && best <= self.config.track_hamming
                && (second == u32::MAX || (best as f64) < 0.9 * second as f64)
            {
                used[arg] = true;
                out.push((pi, arg));
            }
        }
        out
    }

    /// Process one rectified stereo pair (grey or colour; colour is converted).
    pub fn process(&mut self, left: &Image, right: &Image) -> Result<VoFrame, FrontendError> {
        let t0 = Instant::now();
        let to_grey = |img: &Image| -> Result<Mat, FrontendError> {
            let m = image_to_mat(img)?;
            if m.channels() == 3 {
                let mut g = Mat::default();
                opencv::imgproc::cvt_color_def(&m, &mut g, opencv::imgproc::COLOR_BGR2GRAY)?;
                Ok(g)
            } else {
                Ok(m)
            }
        };
        let (lm, rm) = (to_grey(left)?, to_grey(right)?);
        let (lp, ld) = extract(&mut self.orb, &lm)?;
        let (rp, rd) = extract(&mut self.orb, &rm)?;
        let t1 = Instant::now();
        let (lg, rg) = (GreyView::of(&lm)?, GreyView::of(&rm)?);
        let frame = self.stereo(&lp, &ld, &rp, &rd, (&lg, &rg));
        let t2 = Instant::now();
        let stereo_points = frame.points.len();
        let Some(prev) = self.prev.take() else {
            self.prev = Some(frame);
            self.world_from_prev = Isometry3::identity();
            return Ok(VoFrame {
                world_from_camera: Isometry3::identity(),
                status: TrackStatus::Initialised,
                stereo_points,
                keyframe: true,
                timings_ms: [(t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3, 0.0],
            });
        };
        let predicted = (self.kf_from_last * self.velocity).inverse(); // curr ← keyframe
        let mut matches = self.track(&prev, &predicted, &lp, &ld, self.config.search_radius);
        if matches.len() < self.config.min_inliers {
            matches = self.track(&prev, &self.kf_from_last.inverse(), &lp, &ld, 4.0 * self.config.search_radius);
        }
        let solved = self.pnp(&prev, &frame, &lp, &matches, &predicted)?;
        let (curr_from_prev, status) = match solved {
            Some((pose, inliers)) => (pose, TrackStatus::Tracked { inliers }),
            None => (predicted, TrackStatus::Lost),
        };
        let kf_from_curr = curr_from_prev.inverse();
        let tracked = matches!(status, TrackStatus::Tracked { .. });
        if tracked {
            self.velocity = self.kf_from_last.inverse() * kf_from_curr;
        }
        let world_from_curr = self.world_from_prev * kf_from_curr;
        self.since_kf += 1;
        let want_keyframe = match status {
            TrackStatus::Tracked { inliers } => {
                let base = *self.kf_inliers.get_or_insert(inliers);
                (inliers as f64) < self.config.keyframe_inlier_ratio * base as f64
                    || self.since_kf >= self.config.keyframe_max_gap
            }
            _ => true,
        };
        // keep the old keyframe when this frame has too few points of its own (black frame, blur)
        let keyframe = want_keyframe && (frame.points.len() >= self.config.min_inliers || tracked);
        if keyframe {
            self.prev = Some(frame);
            self.world_from_prev = world_from_curr;
            self.kf_from_last = Isometry3::identity();
            self.kf_inliers = None;
            self.since_kf = 0;
        } else {
            self.prev = Some(prev);
            self.kf_from_last = kf_from_curr;
        }
        let t3 = Instant::now();
        Ok(VoFrame {
            world_from_camera: world_from_curr,
            status,
            stereo_points,
            keyframe,
            timings_ms: [(t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3, (t3 - t2).as_secs_f64() * 1e3],
        })
    }

    /// PnP RANSAC on the matches, then a motion-only Huber refinement on the inliers.
    fn pnp(
        &self,
        prev: &Frame,
        curr: &Frame,
        lp: &[(f64, f64)],
        matches: &[(usize, usize)],
        guess: &Isometry3<f64>,
    ) -> Result<Option<(Isometry3<f64>, usize)>, FrontendError> {
        if matches.len() < self.config.min_inliers {
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
            200,
            self.config.ransac_px,
            0.999,
            &mut inliers,
            calib3d::SOLVEPNP_EPNP,
        )?;
        if !ok || inliers.len() < self.config.min_inliers {
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
        let mut lm = LevenbergMarquardt::new(LmParams { max_iterations: 20, ..LmParams::default() });
        lm.fix(k_prev);
        let b = self.rig.baseline;
        for idx in inliers.iter() {
            let (p, c) = matches[idx as usize];
            let kx = values.add(Var::Point(prev.points[p]));
            lm.eliminate(kx);
            let _ = graph.add(
                StereoReprojection::new(k_prev, kx, *k, b, prev.obs[p]),
                NoiseModel::Isotropic(1.0),
                Huber(2.0),
            );
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
        if lm.solve(&graph, &mut values, None).is_ok() {
            if let Some(p) = values.pose(k_curr) {
                curr_from_prev = p.inverse();
            }
        }
        Ok(Some((curr_from_prev, inliers.len())))
    }
}
