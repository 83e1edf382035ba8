//! Stereo visual odometry against a local map: ORB features on both images, stereo matching along
//! rectified rows (mutual best, sub-pixel), the map points of the reference keyframe and its covisible
//! keyframes projected with a constant-velocity prediction into windows sized by the prediction's
//! uncertainty, PnP RANSAC, a second search at the found pose, and a robust pose refinement with staged
//! outlier rejection (keyframes fixed, points free with their keyframe observations). Every pose is
//! checked for support and for consistency with a vehicle's motion before it is accepted
//! ([`TrackState`]); relocalisation against the keyframes when tracking fails.
//!
//! The thresholds and why they hold beyond one sequence are in `docs/system.md` ("Tracking").

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::time::Instant;

use nalgebra::{DMatrix, Isometry3, Matrix3, Vector3};
use opencv::{calib3d, core, features2d, prelude::*};
use slam_core::{
    geometry::BBox, FramePoint, Image, KeyframeCorrection, KeyframeData, KeyframeId, KeyframePoint, MovingRegion,
    PointId, PointPair, StageTimes, StereoTracker, TrackError, TrackState, TrackedFrame,
};
use slam_optim::{
    factors::{MonoReprojection, PosePrior, StereoReprojection},
    Graph, Huber, Key, NoiseModel, Options, SharedOptimizer, Values, Var, L2,
};
use slam_quadric::{se3, Intrinsics};

use crate::disparity::DisparityPair;
use crate::image_io::{image_to_mat, FrontendError};
use crate::keyframe_index::KeyframeIndex;
use crate::matching::{hamming, KeypointGrid};
use crate::pose_only;

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
    /// Largest Hamming distance of a map-point match.
    pub track_hamming: u32,
    /// Largest search window around a predicted position, pixels (the window of each point is sized by
    /// the prediction's uncertainty, [`VoConfig::max_acceleration`] and below, up to this).
    pub search_radius: f64,
    /// PnP RANSAC reprojection threshold, pixels.
    pub ransac_px: f32,
    /// Fewest inliers of a tracked frame.
    pub min_inliers: usize,
    /// Fewest inliers of an accepted pose: between this and `min_inliers` the frame is weak.
    pub weak_inliers: usize,
    /// Fewest cells of a 4 × 4 grid over the image holding inliers for a tracked frame (fewer but at
    /// least 3: weak; fewer than 3: the pose is rejected).
    pub min_spread_cells: usize,
    /// Largest RMS reprojection error of the inliers of an accepted pose, pixels.
    pub max_rms_px: f64,
    /// Time between input frames, seconds; 0: 0.1 s, KITTI's rate (`slam-app run` sets it from the
    /// sequence's time stamps when the settings leave it at 0).
    pub frame_period_s: f64,
    /// Largest acceleration of the vehicle, m/s² (tyre grip: about 1 g).
    pub max_acceleration: f64,
    /// Largest angular acceleration of the vehicle, rad/s².
    pub max_angular_acceleration: f64,
    /// Largest speed, m/s (used while the velocity is unknown: the first step of a map segment).
    pub max_speed: f64,
    /// Allowed error of the velocity estimate, metres per frame (two per-step error budgets).
    pub step_tolerance_m: f64,
    /// Allowed error of the angular-velocity estimate, radians per frame.
    pub rotation_tolerance_rad: f64,
    /// Points farther than this many baselines have their disparity (right-image) residual
    /// down-weighted in proportion to depth.
    pub far_baselines: f64,
    /// Lost for longer than this (seconds): a new map segment starts.
    pub max_lost_s: f64,
    /// A new keyframe is taken when the tracked map points fall below this fraction of those tracked
    /// in the first frame after the current keyframe.
    pub keyframe_inlier_ratio: f64,
    /// ... or when this many frames have been tracked against it.
    pub keyframe_max_gap: usize,
    /// ... or when fewer than this share of the reference keyframe's points are tracked (its overlap
    /// with the frame; in fast motion it falls by half or more per frame).
    pub keyframe_overlap: f64,
    /// Most keypoints followed by optical flow per detection box (association cue).
    pub flow_points_per_region: usize,
    /// Keyframes before the reference whose map points form the local map (those sharing at least
    /// 10 map points with the reference: its covisible keyframes).
    pub local_keyframes: usize,
    /// Search radius of the second search at the found pose, pixels at pyramid level 0.
    pub local_radius: f64,
    /// Keyframes kept for relocalisation (newest first).
    pub relocalisation_keyframes: usize,
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
    /// σ of the slip angle at the rear axle, radians, of the vehicle-motion prior (0: no prior). A road
    /// vehicle's rear axle does not slide sideways: without tyre slip its velocity points along the
    /// car, so a step's sideways part at the camera is the yaw times the camera's lever arm (and the
    /// roll times its height); the pose refinement holds the rest near zero with this σ times the step
    /// length. Slip angles of a car in normal driving (lateral acceleration below 0.4 g) stay below
    /// about 1–2° (0.02–0.035 rad): 0.03 is a car's value. Default 0 (off): on the dev drives it moved
    /// two objects' box misfit over the dynamic limit (docs/system.md, "The vehicle-motion prior").
    pub vehicle_slip_rad: f64,
    /// Camera ahead of the rear axle, metres, and its σ: 1.35 ± 0.78 m is a camera anywhere between the
    /// axles of a car of 2.7 m wheelbase (KITTI's VW Passat B6: 2.71 m; uniform over it: σ = 2.71/√12).
    pub vehicle_lever_m: (f64, f64),
    /// Camera above the rear axle, metres: KITTI's cameras are 1.65 m above the road, the axle one wheel
    /// radius (about 0.32 m) above it.
    pub vehicle_height_m: f64,
    /// Frame pairs kept for [`StereoVo::disparity_pairs`] (offset self-calibration); 0 keeps none.
    /// Not a settings-file key: `slam-app stereo-check` sets it.
    #[serde(skip)]
    pub keep_disparity_pairs: usize,
}

impl VoConfig {
    /// The time between frames, seconds ([`VoConfig::frame_period_s`], or 0.1 s when that is 0).
    pub fn period(&self) -> f64 {
        if self.frame_period_s > 0.0 {
            self.frame_period_s
        } else {
            0.1
        }
    }
}

impl Default for VoConfig {
    fn default() -> Self {
        Self {
            features: 2000,
            stereo_hamming: 60,
            row_tolerance: 2.0,
            depth_range: (1.0, 80.0),
            track_hamming: 60,
            search_radius: 160.0,
            ransac_px: 2.0,
            min_inliers: 30,
            weak_inliers: 15,
            min_spread_cells: 5,
            max_rms_px: 2.0,
            frame_period_s: 0.0,
            max_acceleration: 10.0,
            max_angular_acceleration: 2.0,
            max_speed: 50.0,
            step_tolerance_m: 0.3,
            rotation_tolerance_rad: 0.02,
            far_baselines: 40.0,
            max_lost_s: 0.5,
            keyframe_inlier_ratio: 0.5,
            keyframe_max_gap: 4,
            keyframe_overlap: 0.3,
            flow_points_per_region: 40,
            local_keyframes: 4,
            local_radius: 4.0,
            relocalisation_keyframes: 8,
            disparity_offset: 0.0,
            triangulate: false,
            triangulate_parallax_deg: 3.0,
            vehicle_slip_rad: 0.0,
            vehicle_lever_m: (1.35, 0.78),
            vehicle_height_m: 1.33,
            keep_disparity_pairs: 0,
        }
    }
}

#[derive(Clone)]
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
    /// Pyramid level and orientation (degrees) of each left keypoint.
    octave: Vec<i32>,
    angle: Vec<f32>,
    /// The left keypoints in cells (projection searches).
    grid: KeypointGrid,
}

impl Frame {
    /// The stereo points as the pipeline sees them.
    fn stereo_points(&self) -> Vec<FramePoint> {
        self.points.iter().zip(&self.obs).map(|(p, o)| FramePoint { camera_point: *p, observation: *o }).collect()
    }

    /// The frame without the keypoints `keep` marks false, nor their stereo points (order kept).
    fn retain_keypoints(&self, keep: &[bool]) -> Frame {
        let mut new_point = vec![None; self.points.len()];
        let (mut points, mut desc, mut obs, mut ids, mut valid) = (vec![], vec![], vec![], vec![], vec![]);
        for (q, &kp) in self.point_keypoints().iter().enumerate() {
            if keep.get(kp).copied().unwrap_or(false) {
                new_point[q] = Some(points.len());
                points.push(self.points[q]);
                desc.push(self.desc[q]);
                obs.push(self.obs[q]);
                ids.push(self.ids[q]);
                valid.push(self.valid[q]);
            }
        }
        let kept: Vec<usize> = (0..self.keypoints.len()).filter(|&i| keep.get(i).copied().unwrap_or(false)).collect();
        let keypoints: Vec<(f64, f64)> = kept.iter().map(|&i| self.keypoints[i]).collect();
        Frame {
            points,
            desc,
            obs,
            of_keypoint: kept.iter().map(|&i| self.of_keypoint[i].and_then(|q| new_point[q])).collect(),
            ids,
            valid,
            keypoint_desc: kept.iter().map(|&i| self.keypoint_desc[i]).collect(),
            octave: kept.iter().map(|&i| self.octave[i]).collect(),
            angle: kept.iter().map(|&i| self.angle[i]).collect(),
            grid: KeypointGrid::new(&keypoints),
            keypoints,
        }
    }

    /// The keypoint of each point.
    fn point_keypoints(&self) -> Vec<usize> {
        let mut of = vec![usize::MAX; self.points.len()];
        for (kp, q) in self.of_keypoint.iter().enumerate() {
            if let Some(q) = q {
                of[*q] = kp;
            }
        }
        of
    }
}

/// A keyframe.
#[derive(Clone)]
struct Reference {
    frame: Frame,
    id: KeyframeId,
    world_from_kf: Isometry3<f64>,
    /// Parent keyframe and `parent_from_this`.
    parent: Option<(KeyframeId, Isometry3<f64>)>,
}

/// Map points of the reference keyframe and its covisible keyframes, in the reference's frame.
#[derive(Default)]
struct LocalMap {
    ids: Vec<PointId>,
    points: Vec<Vector3<f64>>,
    desc: Vec<[u8; 32]>,
    octave: Vec<i32>,
    angle: Vec<f32>,
    /// Observations of each point: (keyframe slot, `[u_l, v, u_r]`).
    views: Vec<Vec<(usize, [f64; 3])>>,
    /// `reference_from_keyframe` of each slot (slot 0: the reference).
    poses: Vec<Isometry3<f64>>,
}

impl LocalMap {
    fn add_keyframe(&mut self, kf: &Reference, ref_from_kf: Isometry3<f64>, index: &mut HashMap<PointId, usize>) {
        let slot = self.poses.len();
        self.poses.push(ref_from_kf);
        let kps = kf.frame.point_keypoints();
        for (q, &id) in kf.frame.ids.iter().enumerate() {
            if !kf.frame.valid[q] {
                continue;
            }
            let o = kf.frame.obs[q];
            if let Some(&i) = index.get(&id) {
                self.views[i].push((slot, o));
                continue;
            }
            index.insert(id, self.ids.len());
            self.ids.push(id);
            self.points.push((ref_from_kf * nalgebra::Point3::from(kf.frame.points[q])).coords);
            self.desc.push(kf.frame.desc[q]);
            let kp = kps[q];
            self.octave.push(kf.frame.octave.get(kp).copied().unwrap_or(0));
            self.angle.push(kf.frame.angle.get(kp).copied().unwrap_or(0.0));
            self.views.push(vec![(slot, o)]);
        }
    }
}

/// How a pose was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// Constant-velocity prediction (or the wider search around it).
    Motion,
    /// Relocalisation along the motion, `k` frame intervals ahead (dropped frames).
    Along(usize),
    /// Relocalisation by descriptors alone.
    Descriptors,
    /// Relocalisation against a keyframe retrieved from the keyframe index (any keyframe of the run,
    /// a revisit included); accepted on its own support, not the motion model.
    Retrieved(KeyframeId),
}

/// A pose found by PnP RANSAC (`curr_from_ref`) and its inlier matches (local-map point, keypoint).
type Solved = (Isometry3<f64>, Vec<(usize, usize)>);

/// What relocalisation found: the accepted candidate (refined pose, RANSAC inliers, route), the
/// first candidate pose whether accepted or not, and for a retrieved keyframe, the map its inliers
/// index (that keyframe's points in the reference keyframe's frame).
type Relocalisation = (Option<(Refined, usize, Route)>, Option<Isometry3<f64>>, Option<LocalMap>);

/// Keyframes tried by retrieval ([`StereoVo::retrieve`]): the best few by votes, since the keyframes
/// just before and after a place share most of its descriptors and the votes rank the right one near
/// the top, not always first; each costs one brute-force matching and PnP RANSAC, on a lost frame only.
const RETRIEVAL_CANDIDATES: usize = 3;

/// 95 % bounds of χ² with 3 (stereo) and 2 (left image only) degrees of freedom, σ = 1 px.
/// σ floor of the vehicle-motion prior's sideways step, metres: the camera's sway on the body's
/// suspension within one frame (body roll of a car: a few degrees at most, about a centimetre at roof
/// height over 0.1 s of normal driving).
const VEHICLE_SWAY_M: f64 = 0.01;
const CHI2_STEREO: f64 = 7.815;
const CHI2_MONO: f64 = 5.991;

/// One refinement round's problem ([`StereoVo::round_problem`]): the graph, its values, the current
/// pose's key, and each match's point key and current factor (`usize::MAX`: set aside).
struct RoundProblem {
    graph: Graph,
    values: Values,
    pose: Key,
    per_match: Vec<(Key, usize)>,
}

/// A refined pose: `curr_from_ref`, inlier matches (local-map point, keypoint), RMS reprojection error.
struct Refined {
    pose: Isometry3<f64>,
    inliers: Vec<(usize, usize)>,
    rms: f64,
}

/// Support of a pose: what [`StereoVo::support`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Support {
    /// Enough inliers, spread over the image, small reprojection error.
    Full,
    /// Accepted, but weaker.
    Weak,
    /// Not enough to accept the pose.
    Rejected,
}

/// The motion-model limits of a frame's pose: how far (metres, radians) it may lie from the
/// constant-velocity prediction after `frames` frame periods of `period_s`, for a vehicle whose
/// acceleration is at most `max_acceleration` and angular acceleration `max_angular_acceleration`,
/// with the velocity estimate off by up to `step_tolerance_m` / `rotation_tolerance_rad` per frame.
pub fn motion_limits(config: &VoConfig, frames: f64) -> (f64, f64) {
    let n = frames.max(1.0);
    let t = n * config.period();
    (
        0.5 * config.max_acceleration * t * t + n * config.step_tolerance_m,
        0.5 * config.max_angular_acceleration * t * t + n * config.rotation_tolerance_rad,
    )
}

/// Whether `pose` (any frame's pose in a common frame) is consistent with `predicted` after `frames`
/// frame periods ([`motion_limits`]); with `velocity_known` false only the speed limit applies to the
/// step from `last` (the last measured pose).
pub fn motion_consistent(
    config: &VoConfig,
    pose: &Isometry3<f64>,
    predicted: &Isometry3<f64>,
    last: &Isometry3<f64>,
    frames: f64,
    velocity_known: bool,
) -> bool {
    if velocity_known {
        let (t_lim, r_lim) = motion_limits(config, frames);
        let d = predicted.inverse() * pose;
        d.translation.vector.norm() <= t_lim && d.rotation.angle() <= r_lim
    } else {
        let t = frames.max(1.0) * config.period();
        let d = last.inverse() * pose;
        d.translation.vector.norm() <= config.max_speed * t
    }
}

/// Stereo visual odometry against a local map, with keyframe corrections from a mapper.
pub struct StereoVo {
    orb: core::Ptr<features2d::ORB>,
    rig: StereoRig,
    config: VoConfig,
    reference: Option<Reference>,
    /// Older keyframes of the segment, newest first (local map and relocalisation).
    local: VecDeque<Reference>,
    next_keyframe: KeyframeId,
    next_point: PointId,
    /// Pose of the last processed frame in the reference keyframe (measured or predicted).
    kf_from_last: Isometry3<f64>,
    /// Pose of the last frame with a measured pose, in the reference keyframe.
    kf_from_measured: Isometry3<f64>,
    /// Frames since the last measured pose (1: the previous frame was measured).
    since_measured: usize,
    /// Frame-id steps the velocity was measured over (2 when every 2nd frame is played).
    velocity_gap: usize,
    /// Frame intervals between the last processed frame and the current one (frames the pipeline
    /// could not read count).
    gap: usize,
    /// Index of the last processed frame and of the last frame with a measured pose.
    last_index: usize,
    measured_index: usize,
    /// Whether a frame failed (lost or predicted) since the last measured pose.
    failed: bool,
    /// Whether `velocity` was measured (two consecutive measured frames in this segment).
    velocity_known: bool,
    /// Tracked map points of the first frame tracked against the keyframe.
    kf_inliers: Option<usize>,
    /// Frames tracked against the keyframe.
    since_kf: usize,
    /// `T_last←curr` of the last step (constant-velocity model).
    velocity: Isometry3<f64>,
    /// Image size (width, height), pixels.
    image_size: (f64, f64),
    /// Grey left images and left keypoints of the previous and current frame (optical flow).
    grey: [Option<Mat>; 2],
    keypoints: [Vec<(f64, f64)>; 2],
    /// The stereo keypoints of the last two frames, those on moving regions included (the scene flow's).
    flow_keypoints: [Vec<(f64, f64)>; 2],
    /// Stereo correspondences of tracked frames with their keyframe (up to `keep_disparity_pairs`).
    pairs: Vec<DisparityPair>,
    /// Solves the two-frame stereo bundle adjustments.
    optimizer: SharedOptimizer,
    /// The descriptors of every keyframe of the run (relocalisation by retrieval), and the keyframes
    /// themselves by id (their map points; keypoints dropped).
    index: KeyframeIndex,
    archive: BTreeMap<KeyframeId, Reference>,
}

/// What [`StereoVo::prepare`] makes of a stereo pair: the frame, its stereo points, the stereo points
/// on the moving regions (kept out of the frame), and the extraction and stereo times, ms.
type Prepared = (Frame, Vec<FramePoint>, Vec<FramePoint>, (f64, f64));

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

/// Keypoints: positions, 256-bit ORB descriptors, pyramid levels, orientations (degrees).
struct Features {
    points: Vec<(f64, f64)>,
    desc: Vec<[u8; 32]>,
    octave: Vec<i32>,
    angle: Vec<f32>,
}

fn extract(orb: &mut core::Ptr<features2d::ORB>, img: &Mat) -> Result<Features, FrontendError> {
    let mut kps = core::Vector::<core::KeyPoint>::new();
    let mut desc = Mat::default();
    orb.detect_and_compute(img, &core::no_array(), &mut kps, &mut desc, false)?;
    let mut f = Features {
        points: Vec::with_capacity(kps.len()),
        desc: Vec::with_capacity(kps.len()),
        octave: Vec::with_capacity(kps.len()),
        angle: Vec::with_capacity(kps.len()),
    };
    for (i, kp) in kps.iter().enumerate() {
        let row = desc.at_row::<u8>(i as i32)?;
        if row.len() != 32 {
            continue;
        }
        let mut d = [0u8; 32];
        d.copy_from_slice(row);
        f.points.push((kp.pt().x as f64, kp.pt().y as f64));
        f.desc.push(d);
        f.octave.push(kp.octave());
        f.angle.push(kp.angle());
    }
    Ok(f)
}

/// `step` applied `r` times (a fraction of it for the fractional part).
fn scaled(step: &Isometry3<f64>, r: f64) -> Isometry3<f64> {
    let whole = r.max(0.0).floor();
    repeat(step, whole as usize) * Isometry3::identity().lerp_slerp(step, r.max(0.0) - whole)
}

/// `step` applied `k` times: one product after another up to [`REPEAT_FOLD`] steps, by repeated
/// squaring beyond (a gap of 10⁸ frame ids costs 27 products, not 10⁸).
fn repeat(step: &Isometry3<f64>, k: usize) -> Isometry3<f64> {
    if k <= REPEAT_FOLD {
        return (0..k).fold(Isometry3::identity(), |acc, _| acc * step);
    }
    let (mut out, mut base, mut k) = (Isometry3::identity(), *step, k);
    while k > 0 {
        if k & 1 == 1 {
            out *= base;
        }
        base *= base;
        k >>= 1;
    }
    out
}

/// Steps up to which [`repeat`] multiplies one step after another (every gap a drive's recording
/// drops, so the tracker's predictions stay as they were); longer gaps are squared.
const REPEAT_FOLD: usize = 64;

/// Keeps the matches whose keypoint orientation changes agree with the bulk: a histogram of the
/// changes in 12° bins, matches in the three fullest bins kept (the second and third only when they
/// hold at least a tenth of the fullest). The image of a rigid scene turns as a whole.
fn orientation_filter(matches: Vec<(usize, usize, f32)>) -> Vec<(usize, usize)> {
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

/// Occupied cells of a 4 × 4 grid over a `width` × `height` image.
fn spread_cells(points: impl Iterator<Item = (f64, f64)>, (width, height): (f64, f64)) -> usize {
    let mut cells = [false; 16];
    for (u, v) in points {
        let i = ((u / width * 4.0).floor().clamp(0.0, 3.0)) as usize;
        let j = ((v / height * 4.0).floor().clamp(0.0, 3.0)) as usize;
        cells[4 * j + i] = true;
    }
    cells.iter().filter(|c| **c).count()
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
            local: VecDeque::new(),
            next_keyframe: 0,
            next_point: 0,
            kf_from_last: Isometry3::identity(),
            kf_from_measured: Isometry3::identity(),
            since_measured: 1,
            velocity_gap: 1,
            gap: 1,
            last_index: 0,
            measured_index: 0,
            failed: false,
            velocity_known: false,
            kf_inliers: None,
            since_kf: 0,
            velocity: Isometry3::identity(),
            image_size: (1.0, 1.0),
            grey: [None, None],
            keypoints: [Vec::new(), Vec::new()],
            flow_keypoints: [Vec::new(), Vec::new()],
            pairs: Vec::new(),
            optimizer,
            index: KeyframeIndex::default(),
            archive: BTreeMap::new(),
        })
    }

    /// Stereo points of the left keypoints: each left keypoint is matched along its row, kept when the
    /// right keypoint's best left match along the row is that keypoint too (left-right consistency),
    /// and its disparity is refined to sub-pixel by block matching.
    fn stereo(&self, left: &Features, right: &Features, grey: (&GreyView<'_>, &GreyView<'_>)) -> Frame {
        let k = &self.rig.k;
        let rows = right.points.iter().map(|p| p.1.max(0.0) as usize).max().unwrap_or(0) + 1;
        let mut by_row: Vec<Vec<usize>> = vec![Vec::new(); rows + 3];
        for (i, p) in right.points.iter().enumerate() {
            by_row[p.1.max(0.0) as usize].push(i);
        }
        let tol = self.config.row_tolerance;
        // best left keypoint of each right keypoint: (distance, left index)
        let mut right_best = vec![(u32::MAX, usize::MAX); right.points.len()];
        let mut winners = Vec::new();
        for (i, &(u, v)) in left.points.iter().enumerate() {
            let last = by_row.len() - 1;
            let (lo, hi) =
                ((((v - tol).floor().max(0.0)) as usize).min(last), ((v + tol).ceil().max(0.0) as usize).min(last));
            let mut two = BestTwo::new();
            for row in &by_row[lo..=hi] {
                for &j in row {
                    let (ur, vr) = right.points[j];
                    let d = u - ur;
                    if (vr - v).abs() > tol || d <= 0.0 || d > 300.0 {
                        continue;
                    }
                    let h = hamming(&left.desc[i], &right.desc[j]);
                    two.offer(h, j);
                    if h < right_best[j].0 {
                        right_best[j] = (h, i);
                    }
                }
            }
            if let Some(arg) = two.winner(self.config.stereo_hamming, true) {
                winners.push((i, arg));
            }
        }
        let mut points = Vec::new();
        let mut desc = Vec::new();
        let mut obs = Vec::new();
        let mut of_keypoint = vec![None; left.points.len()];
        for (i, arg) in winners {
            if right_best[arg].1 != i {
                continue;
            }
            let (u, v) = left.points[i];
            let disparity = refine_disparity(grey.0, grey.1, u, v, right.points[arg].0)
                .unwrap_or(u - right.points[arg].0)
                + self.config.disparity_offset;
            let z = k.fx * self.rig.baseline / disparity;
            if z < self.config.depth_range.0 || z > self.config.depth_range.1 {
                continue;
            }
            of_keypoint[i] = Some(points.len());
            points.push(Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z));
            desc.push(left.desc[i]);
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
            keypoints: left.points.clone(),
            keypoint_desc: left.desc.clone(),
            octave: left.octave.clone(),
            angle: left.angle.clone(),
            grid: KeypointGrid::new(&left.points),
        }
    }

    /// The local map: the reference keyframe's points and those of the older keyframes that share at
    /// least 10 map points with it (its covisible keyframes), up to `local_keyframes` of them.
    fn local_map(&self) -> LocalMap {
        let mut map = LocalMap::default();
        let Some(r) = &self.reference else { return map };
        let mut index = HashMap::new();
        map.add_keyframe(r, Isometry3::identity(), &mut index);
        let ref_ids: HashSet<PointId> = r.frame.ids.iter().copied().collect();
        let ref_from_world = r.world_from_kf.inverse();
        for kf in self.local.iter().take(self.config.local_keyframes) {
            let shared =
                kf.frame.ids.iter().zip(&kf.frame.valid).filter(|(id, ok)| **ok && ref_ids.contains(id)).count();
            if shared >= 10 {
                map.add_keyframe(kf, ref_from_world * kf.world_from_kf, &mut index);
            }
        }
        map
    }

    /// Search window of a point at `c` (current camera frame) of pyramid level `octave`, when the
    /// predicted pose may be off by `sigma_t` metres and `sigma_r` radians: the image motion those
    /// errors cause at that depth and offset from the axis, plus the keypoint's own scale.
    fn window(&self, c: &Vector3<f64>, octave: i32, (sigma_t, sigma_r): (f64, f64)) -> f64 {
        let f = self.rig.k.fx;
        let off = (c.x.abs() + c.y.abs()) / c.z;
        let r = 3.0 * 1.2f64.powi(octave) + f * (sigma_r + sigma_t * (1.0 + off) / c.z);
        r.min(self.config.search_radius)
    }

    /// Project the local map's points (not yet matched: `skip`) with `curr_from_ref` and match each to
    /// the keypoints (not yet `taken`) within its window: smallest Hamming distance under
    /// `track_hamming`, ratio test, each keypoint to its closest point, then the orientation check.
    fn search(
        &self,
        map: &LocalMap,
        curr_from_ref: &Isometry3<f64>,
        frame: &Frame,
        window: &dyn Fn(&Vector3<f64>, i32) -> f64,
        skip: &[bool],
        taken: &[bool],
    ) -> Vec<(usize, usize)> {
        let k = &self.rig.k;
        let margin = KeypointGrid::CELL;
        let mut found: Vec<(u32, usize, usize)> = Vec::new();
        for (i, x) in map.points.iter().enumerate() {
            if skip[i] {
                continue;
            }
            let c = curr_from_ref * nalgebra::Point3::from(*x);
            if c.z <= 0.1 {
                continue;
            }
            let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
            if u < -margin || v < -margin || u > self.image_size.0 + margin || v > self.image_size.1 + margin {
                continue;
            }
            let radius = window(&c.coords, map.octave[i]);
            let mut two = BestTwo::new();
            let d = &map.desc[i];
            frame.grid.for_each_near((u, v), radius, |j| {
                if taken[j] {
                    return;
                }
                let (uj, vj) = frame.keypoints[j];
                if (uj - u).powi(2) + (vj - v).powi(2) <= radius * radius {
                    two.offer(hamming(d, &frame.keypoint_desc[j]), j);
                }
            });
            if let Some(j) = two.winner(self.config.track_hamming, false) {
                found.push((two.best, i, j));
            }
        }
        Self::assign(found, map, frame)
    }

    /// Each keypoint to the point closest in descriptor distance, then the orientation check.
    fn assign(mut found: Vec<(u32, usize, usize)>, map: &LocalMap, frame: &Frame) -> Vec<(usize, usize)> {
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
    fn match_all(&self, map: &LocalMap, frame: &Frame) -> Vec<(usize, usize)> {
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
    fn pnp_ransac(
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

    /// Noise of an observation `[u_l, v, u_r]`: 1 px, and for a stereo observation of a point farther
    /// than `far_baselines` baselines, a right-image σ growing in proportion to its depth (its
    /// disparity, a few pixels, says little about depth and is the most exposed to rectification error).
    fn noise(&self, o: &[f64; 3]) -> NoiseModel {
        let sigma = self.sigma(o);
        if sigma[2] != 1.0 {
            NoiseModel::Diagonal(sigma.to_vec())
        } else {
            NoiseModel::Isotropic(1.0)
        }
    }

    /// The σ of each component of an observation ([`StereoVo::noise`]).
    fn sigma(&self, o: &[f64; 3]) -> [f64; 3] {
        let d = o[0] - o[2];
        let far = self.config.far_baselines * self.rig.baseline;
        let z = self.rig.k.fx * self.rig.baseline / d.max(1e-6);
        if o[2].is_finite() && z > far {
            [1.0, 1.0, z / far]
        } else {
            [1.0; 3]
        }
    }

    /// The current frame's observation of keypoint `c`: stereo `[u_l, v, u_r]` where it has a stereo
    /// point, else `[u, v, NaN]`.
    fn observation(frame: &Frame, c: usize) -> [f64; 3] {
        match frame.of_keypoint.get(c).copied().flatten() {
            Some(q) => frame.obs[q],
            None => [frame.keypoints[c].0, frame.keypoints[c].1, f64::NAN],
        }
    }

    /// Adds the reprojection factor of observation `o` (stereo when `o[2]` is finite) of `point` from
    /// `pose`, with Huber (at the 95 % stereo χ² bound) when `robust`; its index in the graph.
    fn add_observation(
        &self,
        graph: &mut Graph,
        (pose, point): (Key, Key),
        o: [f64; 3],
        robust: bool,
    ) -> Option<usize> {
        let (k, b) = (self.rig.k, self.rig.baseline);
        let f: Box<dyn slam_optim::Factor> = if o[2].is_finite() {
            Box::new(StereoReprojection::new(pose, point, k, b, o))
        } else {
            Box::new(MonoReprojection::new(pose, point, k, [o[0], o[1]]))
        };
        let kernel: Box<dyn slam_optim::RobustKernel> =
            if robust { Box::new(Huber(CHI2_STEREO.sqrt())) } else { Box::new(slam_optim::L2) };
        graph
            .add_boxed(f, self.noise(&o), kernel)
            .map_err(|e| tracing::warn!("pose refinement: observation left out: {e}"))
            .ok()
    }

    /// The last refinement round's problem from `pose` (`curr_from_ref`): the matched points free
    /// (eliminated) with all their keyframe observations (keyframes fixed, Huber) and the current
    /// observations of the `active` matches (least squares). Every match gets its point's key; its
    /// current factor is `usize::MAX` when set aside.
    fn round_problem(
        &self,
        map: &LocalMap,
        frame: &Frame,
        matches: &[(usize, usize)],
        (active, pose): (&[bool], &Isometry3<f64>),
    ) -> RoundProblem {
        let mut values = Values::new();
        let mut graph = Graph::new();
        let pose_key = values.add(Var::Pose(pose.inverse()));
        let mut slots: HashMap<usize, Key> = HashMap::new();
        let mut per_match = Vec::with_capacity(matches.len());
        for (m, &(i, c)) in matches.iter().enumerate() {
            let kx = values.add(Var::Point(map.points[i]));
            graph.eliminate(kx);
            for &(slot, o) in &map.views[i] {
                let ks = *slots.entry(slot).or_insert_with(|| values.add(Var::Pose(map.poses[slot])));
                graph.fix(ks);
                self.add_observation(&mut graph, (ks, kx), o, true);
            }
            let f = if active[m] {
                self.add_observation(&mut graph, (pose_key, kx), Self::observation(frame, c), false)
            } else {
                None
            };
            per_match.push((kx, f.unwrap_or(usize::MAX)));
        }
        RoundProblem { graph, values, pose: pose_key, per_match }
    }

    /// χ² of every observation at `pose` with its point fixed, each within its bound or not, and the
    /// sum and count of squared left-image errors of those within.
    fn classify_fixed(
        rig: &pose_only::Rig,
        obs: &[pose_only::PoseObservation],
        pose: &Isometry3<f64>,
    ) -> (Vec<bool>, f64, usize) {
        let (mut active, mut sq_sum, mut sq_n) = (Vec::with_capacity(obs.len()), 0.0, 0usize);
        for o in obs {
            let bound = if o.observed[2].is_finite() { CHI2_STEREO } else { CHI2_MONO };
            let ok = rig.residual(pose, o).filter(|(r, _)| r.norm_squared() <= bound);
            if let Some((r, _)) = &ok {
                sq_sum += (r.x * o.sigma[0]).powi(2) + (r.y * o.sigma[1]).powi(2);
                sq_n += 1;
            }
            active.push(ok.is_some());
        }
        (active, sq_sum, sq_n)
    }

    /// χ² of every match's current observation at the solved round's pose (the set-aside ones against
    /// their point as the round left it), and with `rms`, the sum and count of squared left-image
    /// errors of the matches within the bound.
    fn classify(
        &self,
        frame: &Frame,
        matches: &[(usize, usize)],
        p: &RoundProblem,
        pose: &Isometry3<f64>,
    ) -> (Vec<bool>, f64, usize) {
        let k = self.rig.k;
        let mut probe_values = Values::new();
        let probe_pose = probe_values.add(Var::Pose(pose.inverse()));
        let (mut active, mut sq_sum, mut sq_n) = (Vec::with_capacity(matches.len()), 0.0, 0usize);
        for (&(_, c), &(kx, f)) in matches.iter().zip(&p.per_match) {
            let o = Self::observation(frame, c);
            let chi2 = if f != usize::MAX {
                p.graph.whitened_residual(f, &p.values).and_then(|r| r.ok()).map(|r| r.norm_squared())
            } else {
                let probe_point = probe_values.add(Var::Point(p.values.point(kx).copied().unwrap_or_default()));
                let mut g = Graph::new();
                self.add_observation(&mut g, (probe_pose, probe_point), o, false)
                    .and_then(|fi| g.whitened_residual(fi, &probe_values))
                    .and_then(|r| r.ok())
                    .map(|r| r.norm_squared())
            };
            let bound = if o[2].is_finite() { CHI2_STEREO } else { CHI2_MONO };
            let ok = chi2.is_some_and(|c| c <= bound);
            active.push(ok);
            if ok && f != usize::MAX {
                // left-image error at the pose, the point where the round put it
                if let Some(x) = p.values.point(kx) {
                    let q = pose * nalgebra::Point3::from(*x);
                    let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
                    sq_sum += (u - o[0]).powi(2) + (v - o[1]).powi(2);
                    sq_n += 1;
                }
            }
        }
        (active, sq_sum, sq_n)
    }

    /// Refine `curr_from_ref` on the matches, the current frame's observations stereo where it has a
    /// stereo point. Four rounds: after each, the current observations above the χ² bound (95 %: 7.815
    /// stereo, 5.991 left only, σ = 1 px) are set aside for the next round and the set-aside ones are
    /// checked again; Huber in the first two rounds, plain least squares after. The first three rounds
    /// move the pose alone, the points held where their keyframes put them ([`pose_only::solve`]); the
    /// fourth frees the matched points with all their keyframe observations (keyframes fixed). Round 1
    /// is skipped when round 0 kept every match (it would solve the same problem again). The RMS error
    /// is that of the last round's inliers.
    fn refine(
        &self,
        map: &LocalMap,
        frame: &Frame,
        matches: &[(usize, usize)],
        guess: &Isometry3<f64>,
    ) -> Option<Refined> {
        let enough = self.config.weak_inliers.max(6);
        let mut pose = *guess;
        let mut active = vec![true; matches.len()];
        let mut rms = f64::NAN;
        let mut changed = true;
        let rig = pose_only::Rig { k: self.rig.k, baseline: self.rig.baseline };
        let prior = self.motion_prior(guess);
        let fixed: Vec<pose_only::PoseObservation> = matches
            .iter()
            .map(|&(i, c)| {
                let observed = Self::observation(frame, c);
                pose_only::PoseObservation { point: map.points[i], observed, sigma: self.sigma(&observed) }
            })
            .collect();
        for round in 0..4 {
            if active.iter().filter(|a| **a).count() < enough {
                return None;
            }
            if round == 1 && !changed {
                continue; // round 0's problem again (Huber, pose only, the same inliers)
            }
            let (now, sq_sum, sq_n) = if round < 3 {
                let used: Vec<pose_only::PoseObservation> =
                    fixed.iter().zip(&active).filter(|(_, a)| **a).map(|(o, _)| *o).collect();
                let huber = (round < 2).then(|| CHI2_STEREO.sqrt());
                pose = pose_only::solve(&rig, &used, &pose, huber, prior.as_ref(), 10)?;
                Self::classify_fixed(&rig, &fixed, &pose)
            } else {
                let mut p = self.round_problem(map, frame, matches, (&active, &pose));
                if let Some(m) = &prior {
                    let mut w = DMatrix::zeros(6, 6);
                    w.row_mut(0).copy_from_slice((m.row / m.sigma).as_slice());
                    p.graph.add(PosePrior::new(p.pose, m.base), NoiseModel::SqrtInformation(w), L2).ok()?;
                }
                self.optimizer.optimize(&p.graph, &mut p.values, &Options::with_max_iterations(10), None).ok()?;
                pose = p.values.pose(p.pose)?.inverse();
                self.classify(frame, matches, &p, &pose)
            };
            changed = now != active;
            active = now;
            rms = (sq_sum / sq_n.max(1) as f64).sqrt();
        }
        let inliers: Vec<(usize, usize)> = matches.iter().zip(&active).filter(|(_, a)| **a).map(|(m, _)| *m).collect();
        if inliers.len() < enough {
            return None;
        }
        Some(Refined { pose, inliers, rms })
    }

    /// The vehicle-motion prior on the step from the last measured frame, its σ set at the step to
    /// `guess` (`curr_from_ref`); `None` when `vehicle_slip_rad` is 0.
    fn motion_prior(&self, guess: &Isometry3<f64>) -> Option<pose_only::MotionPrior> {
        let c = &self.config;
        if c.vehicle_slip_rad <= 0.0 {
            return None;
        }
        let model = pose_only::VehicleModel {
            lever: c.vehicle_lever_m,
            height: c.vehicle_height_m,
            slip: c.vehicle_slip_rad,
            floor: VEHICLE_SWAY_M,
        };
        let step = self.kf_from_measured.inverse() * guess.inverse();
        Some(pose_only::MotionPrior::new(self.kf_from_measured, &step, &model))
    }

    /// Support of a refined pose: [`Support::Full`] with at least `min_inliers` inliers over at least
    /// `min_spread_cells` cells of a 4 × 4 grid; [`Support::Weak`] with at least `weak_inliers` over at
    /// least 3 cells; else rejected, as is any pose whose inliers' RMS error exceeds `max_rms_px`.
    pub fn support(config: &VoConfig, inliers: usize, cells: usize, rms_px: f64) -> Support {
        if rms_px.is_nan() || rms_px > config.max_rms_px || inliers < config.weak_inliers || cells < 3 {
            Support::Rejected
        } else if inliers >= config.min_inliers && cells >= config.min_spread_cells {
            Support::Full
        } else {
            Support::Weak
        }
    }

    /// Track against the local map from `guess` (`curr_from_ref`): search in windows sized by `bounds`
    /// (metres, radians), PnP RANSAC, a second search at the pose found, and the refinement.
    /// Returns the refined pose and the RANSAC inlier count.
    fn track_from(
        &self,
        map: &LocalMap,
        frame: &Frame,
        guess: &Isometry3<f64>,
        bounds: (f64, f64),
    ) -> Result<Option<(Refined, usize)>, FrontendError> {
        let t0 = Instant::now();
        let skip = vec![false; map.points.len()];
        let taken = vec![false; frame.keypoints.len()];
        let matches = self.search(map, guess, frame, &|c, o| self.window(c, o, bounds), &skip, &taken);
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
        Ok(self.extend_and_refine(map, frame, &pose, inliers))
    }

    /// The second search (points not matched yet, small windows at `pose`) and the refinement.
    fn extend_and_refine(
        &self,
        map: &LocalMap,
        frame: &Frame,
        pose: &Isometry3<f64>,
        inliers: Vec<(usize, usize)>,
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
        let extra = self.search(map, pose, frame, &|_, o| radius * 1.2f64.powi(o), &skip, &taken);
        let mut all = inliers;
        all.extend(extra);
        all.sort_unstable();
        let t1 = Instant::now();
        let refined = self.refine(map, frame, &all, pose);
        tracing::debug!(
            matches = all.len(),
            search_ms = (t1 - t0).as_secs_f64() * 1e3,
            refine_ms = t1.elapsed().as_secs_f64() * 1e3,
            "second search and refinement"
        );
        refined.map(|r| (r, ransac_inliers))
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
        let from_keypoint: HashMap<usize, PointId> = carried.iter().map(|&(id, c)| (c, id)).collect();
        let keypoint_of = frame.point_keypoints();
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
        let kf = Reference { frame, id, world_from_kf, parent };
        self.archive_keyframe(&kf);
        let old = self.reference.replace(kf);
        match (old, parent) {
            (Some(old), Some(_)) => {
                self.local.push_front(old);
                self.local.truncate(self.config.local_keyframes.max(self.config.relocalisation_keyframes));
            }
            // a new segment: the old keyframes' poses are not related to it
            _ => self.local.clear(),
        }
        self.kf_from_last = Isometry3::identity();
        self.kf_from_measured = Isometry3::identity();
        self.kf_inliers = None;
        self.since_kf = 0;
        data
    }

    /// Keep a keyframe for retrieval: all its keypoints' descriptors in the index and its map points
    /// in the archive.
    fn archive_keyframe(&mut self, kf: &Reference) {
        let t0 = Instant::now();
        self.index.insert(kf.id, &kf.frame.keypoint_desc);
        let mut kept = kf.clone();
        kept.frame.keypoints = Vec::new();
        kept.frame.keypoint_desc = Vec::new();
        kept.frame.grid = KeypointGrid::default();
        self.archive.insert(kf.id, kept);
        tracing::debug!(keyframe = kf.id, ms = t0.elapsed().as_secs_f64() * 1e3, "keyframe indexed");
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

    /// Relocalisation: along the motion (the motion model applied 2 to 16 times: frames dropped by the
    /// recorder look like that), then by descriptors alone against the local map and
    /// then against each older keyframe (4-point solver, 5000 RANSAC rounds, 2 × the RANSAC threshold,
    /// ≥ 12 inliers), each candidate verified by a second search and the refinement.
    /// Returns the first candidate `accept` takes, and the pose of the first one found (accepted or
    /// not: where a new map segment starts when nothing better is found).
    fn relocalise(
        &self,
        map: &LocalMap,
        frame: &Frame,
        accept: &dyn Fn(&Refined, Route) -> bool,
    ) -> Result<Relocalisation, FrontendError> {
        let mut first = None;
        // each hypothesis of k − 1 dropped frames covers half a step either side of its prediction
        let (t1, r1) = motion_limits(&self.step_config(), 1.0);
        let bounds = (t1 + 0.5 * self.velocity.translation.vector.norm(), r1 + 0.5 * self.velocity.rotation.angle());
        for k in 2usize..=16 {
            let guess = (self.kf_from_last * scaled(&self.velocity, self.steps(self.gap) - 1.0 + k as f64)).inverse();
            if let Some((r, n)) = self.track_from(map, frame, &guess, bounds)? {
                tracing::debug!(steps = k, inliers = r.inliers.len(), "relocalisation along the motion");
                first.get_or_insert(r.pose);
                if accept(&r, Route::Along(k)) {
                    return Ok((Some((r, n, Route::Along(k))), first, None));
                }
            }
        }
        let Some(reference) = &self.reference else { return Ok((None, first, None)) };
        let ref_from_world = reference.world_from_kf.inverse();
        let mut maps = vec![None];
        for kf in self.local.iter().skip(self.config.local_keyframes) {
            let mut single = LocalMap::default();
            single.add_keyframe(kf, ref_from_world * kf.world_from_kf, &mut HashMap::new());
            maps.push(Some(single));
        }
        for candidate in &maps {
            let m = candidate.as_ref().unwrap_or(map);
            let all = self.match_all(m, frame);
            let Some((pose, _)) = self.pnp_ransac(m, frame, &all, (2.0 * self.config.ransac_px, 5000, 12))? else {
                continue;
            };
            first.get_or_insert(pose);
            // verify against the local map at the candidate pose
            let skip = vec![false; map.points.len()];
            let taken = vec![false; frame.keypoints.len()];
            let radius = 2.0 * self.config.local_radius;
            let matches = self.search(map, &pose, frame, &|_, o| radius * 1.2f64.powi(o), &skip, &taken);
            let Some((pose, inliers)) =
                self.pnp_ransac(map, frame, &matches, (self.config.ransac_px, 200, self.config.weak_inliers))?
            else {
                continue;
            };
            if let Some((r, n)) = self.extend_and_refine(map, frame, &pose, inliers) {
                tracing::debug!(inliers = r.inliers.len(), "relocalisation by descriptors");
                first.get_or_insert(r.pose);
                if accept(&r, Route::Descriptors) {
                    return Ok((Some((r, n, Route::Descriptors)), first, None));
                }
            }
        }
        let (found, retrieved) =
            self.retrieve(frame)?.map_or((None, None), |(r, n, id, m)| (Some((r, n, Route::Retrieved(id))), Some(m)));
        Ok((found, first, retrieved))
    }

    /// Relocalisation by retrieval: the [`RETRIEVAL_CANDIDATES`] keyframes of the whole run that the
    /// descriptor index ([`crate::keyframe_index`]) ranks best for the frame's descriptors, each tried alone (its map points matched by descriptors, PnP RANSAC
    /// as in [`StereoVo::relocalise`], a second search at the pose found, the refinement) and accepted
    /// only with full support ([`Support::Full`]: inliers, their spread, their error). The motion
    /// model is not consulted: a revisit or a long gap breaks it legitimately. Returns the refined
    /// pose as `curr_from_ref`, the RANSAC inliers, the keyframe's id and the map the inliers index.
    fn retrieve(&self, frame: &Frame) -> Result<Option<(Refined, usize, KeyframeId, LocalMap)>, FrontendError> {
        let Some(reference) = &self.reference else { return Ok(None) };
        if frame.points.len() < self.config.min_inliers {
            return Ok(None);
        }
        let ref_from_world = reference.world_from_kf.inverse();
        for (id, score) in self.index.query(&frame.keypoint_desc, RETRIEVAL_CANDIDATES) {
            let Some(kf) = self.archive.get(&id) else { continue };
            let ref_from_kf = ref_from_world * kf.world_from_kf;
            let mut map = LocalMap::default();
            map.add_keyframe(kf, ref_from_kf, &mut HashMap::new());
            let all = self.match_all(&map, frame);
            let Some((pose, _)) = self.pnp_ransac(&map, frame, &all, (2.0 * self.config.ransac_px, 5000, 12))? else {
                tracing::debug!(keyframe = id, score, matches = all.len(), "retrieved keyframe: no PnP pose");
                continue;
            };
            let skip = vec![false; map.points.len()];
            let taken = vec![false; frame.keypoints.len()];
            let radius = 2.0 * self.config.local_radius;
            let matches = self.search(&map, &pose, frame, &|_, o| radius * 1.2f64.powi(o), &skip, &taken);
            let Some((pose, inliers)) =
                self.pnp_ransac(&map, frame, &matches, (self.config.ransac_px, 200, self.config.weak_inliers))?
            else {
                continue;
            };
            let Some((r, n)) = self.extend_and_refine(&map, frame, &pose, inliers) else { continue };
            let support = self.judge(&r, Route::Retrieved(id), frame);
            tracing::debug!(keyframe = id, score, inliers = r.inliers.len(), ?support, "retrieved keyframe");
            if support == Support::Full {
                return Ok(Some((r, n, id, map)));
            }
        }
        Ok(None)
    }

    /// Frame-id steps as velocity steps (the velocity was measured over `velocity_gap` ids), at least 1.
    fn steps(&self, ids: usize) -> f64 {
        ids.max(1) as f64 / self.velocity_gap.max(1) as f64
    }

    /// The settings with the frame period of one velocity step.
    fn step_config(&self) -> VoConfig {
        VoConfig { frame_period_s: self.config.period() * self.velocity_gap.max(1) as f64, ..self.config }
    }

    /// Whether a refined pose (`curr_from_ref`) found by `route` is accepted: its support, and its
    /// consistency with the motion model over the frames since the last measured pose.
    fn judge(&self, r: &Refined, route: Route, frame: &Frame) -> Support {
        let cells = spread_cells(r.inliers.iter().map(|&(_, c)| frame.keypoints[c]), self.image_size);
        let support = Self::support(&self.config, r.inliers.len(), cells, r.rms);
        if let Route::Retrieved(_) = route {
            return if support == Support::Full { support } else { Support::Rejected };
        }
        if support == Support::Rejected {
            tracing::debug!(inliers = r.inliers.len(), cells, rms = r.rms, "pose rejected: support");
            return support;
        }
        let (steps, frames) = match route {
            Route::Along(k) => {
                (self.steps(self.gap) - 1.0 + k as f64, self.steps(self.since_measured) - 1.0 + k as f64)
            }
            _ => (self.steps(self.gap), self.steps(self.since_measured)),
        };
        let predicted = self.kf_from_last * scaled(&self.velocity, steps);
        let pose = r.pose.inverse();
        if motion_consistent(
            &self.step_config(),
            &pose,
            &predicted,
            &self.kf_from_measured,
            frames,
            self.velocity_known,
        ) {
            support
        } else {
            let d = predicted.inverse() * pose;
            tracing::debug!(
                metres = d.translation.vector.norm(),
                degrees = d.rotation.angle().to_degrees(),
                frames,
                "pose rejected: inconsistent with the motion model"
            );
            Support::Rejected
        }
    }

    /// Track one rectified stereo pair (grey or colour; colour is converted): features and stereo
    /// points ([`StereoVo::prepare`]), the pose ([`StereoVo::find_pose`]) and its state
    /// ([`StereoVo::decide`]), the motion model ([`StereoVo::record`]), and a keyframe when one is due
    /// ([`StereoVo::wants_keyframe`], [`StereoVo::new_keyframe`]).
    pub fn process(
        &mut self,
        frame_index: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
    ) -> Result<TrackedFrame, FrontendError> {
        let (frame, points, masked_points, (extraction, stereo)) = self.prepare(left, right, exclude)?;
        let t2 = Instant::now();
        let times = |t3: Instant| StageTimes { extraction, stereo, tracking: (t3 - t2).as_secs_f64() * 1e3 };
        let stereo_points = frame.points.len();
        let Some(reference) = self.reference.as_ref() else {
            let mut tf = self.initialise(frame, frame_index);
            tf.times = times(Instant::now());
            tf.points = points;
            tf.masked_points = masked_points;
            return Ok(tf);
        };
        let (ref_id, world_from_ref) = (reference.id, reference.world_from_kf);
        let map = self.local_map();
        // frame intervals since the last processed and the last measured frame (unreadable frames
        // between them count)
        self.gap = frame_index.saturating_sub(self.last_index).max(1);
        self.since_measured = frame_index.saturating_sub(self.measured_index).max(1);
        self.last_index = frame_index;
        let predicted = (self.kf_from_last * scaled(&self.velocity, self.steps(self.gap))).inverse(); // curr ← keyframe
        let (found, fallback, retrieved) = self.find_pose(&map, &frame, &predicted)?;
        // the map the inliers index: a retrieved keyframe's, else the local map
        let map = retrieved.unwrap_or(map);
        let route = found.as_ref().map(|f| f.2);
        let (state, curr_from_ref, refined) = self.decide(frame_index, found, &frame, predicted);
        let kf_from_curr = curr_from_ref.inverse();
        let measured = refined.is_some();
        // matched map points: (id, keypoint)
        let carried: Vec<(PointId, usize)> =
            refined.as_ref().map(|r| r.inliers.iter().map(|&(i, c)| (map.ids[i], c)).collect()).unwrap_or_default();
        self.record(frame_index, state, refined.as_ref(), (&map, &frame), &curr_from_ref);
        let tracked_map_points = refined.as_ref().map_or(0, |r| r.inliers.len());
        let rms = refined.as_ref().map_or(f64::NAN, |r| r.rms);
        let world_from_curr = world_from_ref * kf_from_curr;
        // retrieval does not consult the motion model (a revisit or a long gap breaks it legitimately):
        // the velocity is unknown until two measured frames give it again
        if measured && matches!(route, Some(Route::Retrieved(_))) {
            self.velocity_known = false;
        }
        let keyframe = if self.wants_keyframe(state, refined.as_ref(), &map, (stereo_points, &frame.keypoints)) {
            // a frame lost for too long starts a new map segment: no parent, no carried points, at the
            // first unverified candidate pose when there was one, else at the motion prediction
            let (parent, world_from_kf) = if let (true, Some(Route::Retrieved(id))) = (measured, route) {
                // the pose was measured against the retrieved keyframe: it is the parent
                let world_from_parent = self.archive.get(&id).map_or(world_from_ref, |k| k.world_from_kf);
                (Some((id, world_from_parent.inverse() * world_from_curr)), world_from_curr)
            } else if measured {
                ((Some((ref_id, kf_from_curr))), world_from_curr)
            } else {
                tracing::warn!(frame = frame_index, "tracking lost: new map segment from this frame");
                (None, world_from_ref * fallback.unwrap_or(curr_from_ref).inverse())
            };
            let triangulate = measured && !matches!(route, Some(Route::Retrieved(_)));
            Some(self.new_keyframe(
                frame,
                frame_index,
                (world_from_kf, parent),
                (&carried, &curr_from_ref),
                triangulate,
            ))
        } else {
            self.kf_from_last = kf_from_curr;
            None
        };
        // a keyframe is its own reference: its pose in the trajectory is the keyframe's, which local
        // bundle adjustment then refines together with the frames that follow it
        let (reference, world_from_camera) = match &keyframe {
            Some(kf) => ((kf.id, Isometry3::identity()), kf.world_from_camera),
            None => ((ref_id, kf_from_curr), world_from_curr),
        };
        Ok(TrackedFrame {
            world_from_camera,
            reference,
            state,
            stereo_points,
            points,
            masked_points,
            tracked_map_points,
            reprojection_rms_px: rms,
            keyframe,
            times: times(Instant::now()),
        })
    }

    /// ORB features of both images, the stereo points (as the pipeline sees them), the stereo points
    /// on the `exclude` regions apart, and the grey image and keypoints kept for optical flow; with the
    /// extraction and stereo times, ms. Keypoints on an `exclude` region ([`MovingRegion::covers`]) are
    /// dropped after stereo matching (their depth decides), so neither tracking, the map, the optical
    /// flow of association nor the pipeline's object points see them; their stereo points are handed
    /// over apart (`TrackedFrame::masked_points`) and the stereo points' optical flow (the scene flow)
    /// still starts from them.
    fn prepare(&mut self, left: &Image, right: &Image, exclude: &[MovingRegion]) -> Result<Prepared, FrontendError> {
        let t0 = Instant::now();
        let (lm, rm) = (Self::grey_of(left)?, Self::grey_of(right)?);
        self.image_size = (lm.cols().max(1) as f64, lm.rows().max(1) as f64);
        let lf = extract(&mut self.orb, &lm)?;
        let rf = extract(&mut self.orb, &rm)?;
        let t1 = Instant::now();
        let (lg, rg) = (GreyView::of(&lm)?, GreyView::of(&rm)?);
        let all = self.stereo(&lf, &rf, (&lg, &rg));
        // every stereo keypoint, masked or not, is followed by the scene flow
        let flow_keypoints: Vec<(f64, f64)> =
            all.keypoints.iter().zip(&all.of_keypoint).filter(|(_, q)| q.is_some()).map(|(k, _)| *k).collect();
        let (frame, masked) = if exclude.is_empty() {
            (all, Vec::new())
        } else {
            let keep: Vec<bool> = lf
                .points
                .iter()
                .zip(&all.of_keypoint)
                .map(|(&(u, v), q)| {
                    let z = q.map(|q| all.points[q].z);
                    !exclude.iter().any(|r| r.covers(u, v, z))
                })
                .collect();
            let masked: Vec<FramePoint> = all
                .of_keypoint
                .iter()
                .zip(&keep)
                .filter_map(|(q, &k)| q.filter(|_| !k))
                .map(|q| FramePoint { camera_point: all.points[q], observation: all.obs[q] })
                .collect();
            (all.retain_keypoints(&keep), masked)
        };
        let points = frame.stereo_points();
        let t2 = Instant::now();
        self.grey.swap(0, 1);
        self.grey[1] = Some(lm);
        self.keypoints.swap(0, 1);
        self.keypoints[1] = frame.keypoints.clone();
        self.flow_keypoints.swap(0, 1);
        self.flow_keypoints[1] = flow_keypoints;
        Ok((frame, points, masked, ((t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3)))
    }

    /// The first frame of the run: the first keyframe, at the origin (times left at zero).
    fn initialise(&mut self, frame: Frame, frame_index: usize) -> TrackedFrame {
        let stereo_points = frame.points.len();
        let kf = self.take_keyframe(frame, frame_index, Isometry3::identity(), None, &[], &[]);
        self.since_measured = 1;
        (self.last_index, self.measured_index, self.failed) = (frame_index, frame_index, false);
        self.velocity_known = false;
        self.velocity = Isometry3::identity();
        self.velocity_gap = 1;
        TrackedFrame {
            world_from_camera: Isometry3::identity(),
            reference: (kf.id, Isometry3::identity()),
            state: TrackState::Initialised,
            stereo_points,
            points: Vec::new(),
            masked_points: Vec::new(),
            tracked_map_points: 0,
            reprojection_rms_px: f64::NAN,
            keyframe: Some(kf),
            times: StageTimes::default(),
        }
    }

    /// The frame's pose: 1. the local map searched from the constant-velocity prediction
    /// (`predicted`, `curr_from_ref`) in windows of the motion limits; 2. wider, around the last pose;
    /// 3. relocalisation ([`StereoVo::relocalise`]). Returns what relocalisation returns, the first
    /// candidate pose of any stage as the fallback.
    fn find_pose(
        &self,
        map: &LocalMap,
        frame: &Frame,
        predicted: &Isometry3<f64>,
    ) -> Result<Relocalisation, FrontendError> {
        let n = self.since_measured;
        let bounds = if self.velocity_known {
            motion_limits(&self.step_config(), self.steps(n))
        } else {
            (self.config.max_speed * n as f64 * self.config.period(), 0.1)
        };
        let accept = |r: &Refined, route: Route| self.judge(r, route, frame) != Support::Rejected;
        let mut fallback = None;
        let wider = (bounds.0 + self.velocity.translation.vector.norm(), bounds.1 + self.velocity.rotation.angle());
        for (guess, b) in [(*predicted, bounds), (self.kf_from_last.inverse(), wider)] {
            if let Some((r, ransac)) = self.track_from(map, frame, &guess, b)? {
                fallback.get_or_insert(r.pose);
                if accept(&r, Route::Motion) {
                    return Ok((Some((r, ransac, Route::Motion)), fallback, None));
                }
            }
        }
        let (found, first, retrieved) = self.relocalise(map, frame, &accept)?;
        Ok((found, fallback.or(first), retrieved))
    }

    /// The state of a frame from what [`StereoVo::find_pose`] found: tracked or weak by its support,
    /// relocalised after a failed frame or by a relocalisation route; lost (the first failed frame)
    /// or predicted (the next ones) at the prediction when nothing was accepted. Returns the state,
    /// `curr_from_ref` and the refined pose when one was accepted.
    fn decide(
        &self,
        frame_index: usize,
        found: Option<(Refined, usize, Route)>,
        frame: &Frame,
        predicted: Isometry3<f64>,
    ) -> (TrackState, Isometry3<f64>, Option<Refined>) {
        let support = found.as_ref().map(|(r, _, route)| self.judge(r, *route, frame));
        let was_measured = !self.failed;
        match (found, support) {
            (Some((r, ransac, route)), Some(s)) if s != Support::Rejected => {
                let state = if !was_measured || route != Route::Motion {
                    tracing::info!(frame = frame_index, inliers = r.inliers.len(), ?route, "relocalised");
                    TrackState::Relocalised { inliers: ransac }
                } else if s == Support::Full {
                    TrackState::Tracked { inliers: ransac }
                } else {
                    TrackState::Weak { inliers: ransac }
                };
                (state, r.pose, Some(r))
            }
            _ => (if was_measured { TrackState::Lost } else { TrackState::Predicted }, predicted, None),
        }
    }

    /// After a frame's state is decided: the velocity (from a tracked or weak frame right after a
    /// measured one), the disparity pairs kept for self-calibration, and the last measured pose; or
    /// the failure when no pose was accepted.
    fn record(
        &mut self,
        frame_index: usize,
        state: TrackState,
        refined: Option<&Refined>,
        (map, frame): (&LocalMap, &Frame),
        curr_from_ref: &Isometry3<f64>,
    ) {
        let kf_from_curr = curr_from_ref.inverse();
        let Some(r) = refined else {
            self.failed = true;
            let stereo_points = frame.points.len();
            tracing::warn!(frame = frame_index, stereo_points, state = state.name(), "no pose accepted");
            return;
        };
        if matches!(state, TrackState::Tracked { .. } | TrackState::Weak { .. }) && self.since_measured == self.gap {
            self.velocity = self.kf_from_last.inverse() * kf_from_curr;
            self.velocity_known = true;
            self.velocity_gap = self.gap;
        }
        if matches!(state, TrackState::Tracked { .. }) && self.pairs.len() < self.config.keep_disparity_pairs {
            let (a, b): (Vec<[f64; 3]>, Vec<[f64; 3]>) = r
                .inliers
                .iter()
                .filter_map(|&(i, c)| {
                    let (_, o) = map.views[i].iter().find(|(slot, o)| *slot == 0 && o[2].is_finite())?;
                    Some((*o, frame.obs[frame.of_keypoint.get(c).copied().flatten()?]))
                })
                .unzip();
            self.pairs.push(DisparityPair { keyframe: a, frame: b, frame_from_keyframe: *curr_from_ref });
        }
        self.kf_from_measured = kf_from_curr;
        (self.measured_index, self.failed) = (frame_index, false);
    }

    /// Whether the frame becomes a keyframe: a tracked frame when its tracked map points fell below
    /// `keyframe_inlier_ratio` of the keyframe's first frame's, after `keyframe_max_gap` frames if it
    /// moved, or when it shares less than `keyframe_overlap` of the reference keyframe's points; a weak
    /// frame that moved; every relocalised frame; a frame lost for longer than `max_lost_s` that still
    /// has stereo points. Moved: its tracked points moved in the image since the reference keyframe
    /// ([`crate::keyframe_motion`]), so a keyframe brings new information.
    fn wants_keyframe(
        &mut self,
        state: TrackState,
        refined: Option<&Refined>,
        map: &LocalMap,
        (stereo_points, keypoints): (usize, &[(f64, f64)]),
    ) -> bool {
        let moved = refined.is_none_or(|r| {
            crate::keyframe_motion::moved(r.inliers.iter().filter_map(|&(i, c)| {
                let (_, o) = map.views[i].iter().find(|v| v.0 == 0)?;
                Some(((o[0], o[1]), *keypoints.get(c)?))
            }))
        });
        let tracked_map_points = refined.map_or(0, |r| r.inliers.len());
        // share of the reference keyframe's points tracked in this frame (its overlap with the keyframe)
        let overlap = refined.map_or(0.0, |r| {
            let of_reference = r.inliers.iter().filter(|&&(i, _)| map.views[i].iter().any(|v| v.0 == 0)).count();
            let total = self.reference.as_ref().map_or(0, |k| k.frame.valid.iter().filter(|v| **v).count());
            of_reference as f64 / total.max(1) as f64
        });
        self.since_kf += 1;
        let lost_too_long = refined.is_none()
            && self.since_measured as f64 * self.config.period() > self.config.max_lost_s
            && stereo_points >= self.config.min_inliers;
        match state {
            TrackState::Tracked { .. } => {
                let base = *self.kf_inliers.get_or_insert(tracked_map_points);
                (tracked_map_points as f64) < self.config.keyframe_inlier_ratio * base as f64
                    || (self.since_kf >= self.config.keyframe_max_gap && moved)
                    || overlap < self.config.keyframe_overlap
            }
            TrackState::Weak { .. } => moved,
            TrackState::Relocalised { .. } => true,
            _ => lost_too_long,
        }
    }

    /// Make the frame a keyframe at `world_from_kf` with `parent` (none: a new map segment, which
    /// also restarts the motion model), carrying the matched map points' ids, and with `triangulate`
    /// (and the setting on) the points triangulated against the reference keyframe at `curr_from_ref`.
    fn new_keyframe(
        &mut self,
        mut frame: Frame,
        frame_index: usize,
        (world_from_kf, parent): (Isometry3<f64>, Option<(KeyframeId, Isometry3<f64>)>),
        (carried, curr_from_ref): (&[(PointId, usize)], &Isometry3<f64>),
        triangulate: bool,
    ) -> KeyframeData {
        let earlier = match (triangulate && self.config.triangulate, self.reference.as_ref()) {
            (true, Some(r)) => Self::triangulate(
                &self.rig.k,
                &r.frame,
                &mut frame,
                curr_from_ref,
                carried,
                self.config.triangulate_parallax_deg,
            )
            .into_iter()
            .map(|(q, obs, x)| (r.id, q, obs, x))
            .collect(),
            _ => Vec::new(),
        };
        let kf = self.take_keyframe(frame, frame_index, world_from_kf, parent, carried, &earlier);
        if parent.is_none() {
            (self.measured_index, self.failed) = (frame_index, false);
            self.velocity_known = false;
        }
        kf
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

    /// Forward-backward Lucas-Kanade flow of the previous frame's keypoints inside `regions` into the
    /// current frame (with `stereo_only`, the keypoints with a stereo point, those the frame's moving
    /// regions kept out of tracking included), up to `flow_points_per_region` per region evenly spaced;
    /// pairs whose round trip misses by more than a pixel are dropped.
    pub fn optical_flow(&self, regions: &[BBox], stereo_only: bool) -> Result<Vec<PointPair>, FrontendError> {
        let [Some(prev), Some(curr)] = &self.grey else {
            return Ok(Vec::new());
        };
        // the stereo points' flow starts from every stereo keypoint of the frame before, those on
        // moving regions too (the scene flow measures the objects the tracking leaves out)
        let kp = if stereo_only { &self.flow_keypoints[0] } else { &self.keypoints[0] };
        let mut pts = core::Vector::<core::Point2f>::new();
        for b in regions {
            let inside: Vec<usize> = (0..kp.len()).filter(|&i| b.contains_point(kp[i].0, kp[i].1)).collect();
            let step = inside.len().div_ceil(self.config.flow_points_per_region.max(1)).max(1);
            for &i in inside.iter().step_by(step) {
                pts.push(core::Point2f::new(kp[i].0 as f32, kp[i].1 as f32));
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
}

/// Apply a mapper's correction to a keyframe it concerns: pose, refined points, culled points.
fn apply_correction(kf: &mut Reference, c: &KeyframeCorrection) {
    kf.world_from_kf = c.world_from_camera;
    let kf_from_world = c.world_from_camera.inverse();
    let refined: HashMap<PointId, Vector3<f64>> = c.points.iter().copied().collect();
    let culled: HashSet<PointId> = c.culled.iter().copied().collect();
    for (i, id) in kf.frame.ids.iter().enumerate() {
        if culled.contains(id) {
            kf.frame.valid[i] = false;
        } else if let Some(x) = refined.get(id) {
            kf.frame.points[i] = (kf_from_world * nalgebra::Point3::from(*x)).coords;
        }
    }
}

impl StereoTracker for StereoVo {
    fn track(
        &mut self,
        frame: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
    ) -> Result<TrackedFrame, TrackError> {
        self.process(frame, left, right, exclude).map_err(TrackError::backend)
    }

    fn correct(&mut self, c: &KeyframeCorrection) {
        for kf in self.local.iter_mut().filter(|k| k.id == c.id) {
            apply_correction(kf, c);
        }
        if let Some(kf) = self.archive.get_mut(&c.id) {
            apply_correction(kf, c);
        }
        let Some(r) = self.reference.as_mut() else { return };
        if r.id == c.id {
            apply_correction(r, c);
        } else if let Some((parent, parent_from_ref)) = r.parent {
            if parent == c.id {
                r.world_from_kf = c.world_from_camera * parent_from_ref;
                if let Some(kf) = self.archive.get_mut(&r.id) {
                    kf.world_from_kf = r.world_from_kf;
                }
            }
        }
    }

    fn flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        self.optical_flow(regions, false).map_err(TrackError::backend)
    }

    fn stereo_flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        self.optical_flow(regions, true).map_err(TrackError::backend)
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
            octave: vec![0; n],
            angle: vec![0.0; n],
            grid: KeypointGrid::new(&keypoints),
            keypoints,
            keypoint_desc: desc,
        }
    }

    /// Dropping keypoints keeps every kept keypoint with its own stereo point, descriptor, level and
    /// angle (indices rebuilt), and drops the stereo points of the dropped ones.
    #[test]
    fn retaining_keypoints_keeps_each_with_its_own_stereo_point() {
        let n = 6;
        let keypoints: Vec<(f64, f64)> = (0..n).map(|i| (10.0 * i as f64, 5.0 * i as f64)).collect();
        let desc: Vec<[u8; 32]> = (0..n).map(|i| [i as u8; 32]).collect();
        let mut f = frame_of(keypoints.clone(), desc);
        f.octave = (0..n as i32).collect();
        f.angle = (0..n).map(|i| i as f32).collect();
        // keypoints 1, 2, 4 and 5 have stereo points (in that order), their depth 10 + keypoint index
        for i in [1usize, 2, 4, 5] {
            f.of_keypoint[i] = Some(f.points.len());
            f.points.push(Vector3::new(0.0, 0.0, 10.0 + i as f64));
            f.desc.push([i as u8; 32]);
            f.obs.push([keypoints[i].0, keypoints[i].1, keypoints[i].0 - 3.0]);
            f.ids.push(100 + i as u64);
            f.valid.push(true);
        }
        let keep = [true, false, true, true, false, true];
        let r = f.retain_keypoints(&keep);
        let kept: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
        assert_eq!(r.keypoints.len(), kept.len());
        assert_eq!(r.points.len(), 2, "the stereo points of keypoints 2 and 5");
        for (new, &old) in kept.iter().enumerate() {
            assert_eq!(r.keypoints[new], keypoints[old]);
            assert_eq!(r.keypoint_desc[new], [old as u8; 32]);
            assert_eq!((r.octave[new], r.angle[new]), (old as i32, old as f32));
            match r.of_keypoint[new] {
                Some(q) => {
                    assert_eq!(r.points[q].z, 10.0 + old as f64);
                    assert_eq!(
                        (r.ids[q], r.desc[q], r.obs[q][0]),
                        (100 + old as u64, [old as u8; 32], keypoints[old].0)
                    );
                }
                None => assert!(f.of_keypoint[old].is_none(), "keypoint {old} lost its stereo point"),
            }
        }
        assert_eq!(r.point_keypoints(), vec![1, 3], "each point knows its keypoint");
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

    /// A synthetic keyframe: stereo observations of `points` (camera frame) with these ids.
    fn keyframe_of(k: &Intrinsics, b: f64, points: &[Vector3<f64>], ids: &[PointId], desc: &[[u8; 32]]) -> Frame {
        let obs: Vec<[f64; 3]> = points
            .iter()
            .map(|x| {
                let (u, v) = (k.fx * x.x / x.z + k.cx, k.fy * x.y / x.z + k.cy);
                [u, v, u - k.fx * b / x.z]
            })
            .collect();
        let n = points.len();
        Frame {
            points: points.to_vec(),
            desc: desc.to_vec(),
            obs: obs.clone(),
            of_keypoint: (0..n).map(Some).collect(),
            ids: ids.to_vec(),
            valid: vec![true; n],
            keypoints: obs.iter().map(|o| (o[0], o[1])).collect(),
            keypoint_desc: desc.to_vec(),
            octave: vec![0; n],
            angle: vec![10.0; n],
            grid: KeypointGrid::new(&obs.iter().map(|o| (o[0], o[1])).collect::<Vec<_>>()),
        }
    }

    /// The local-map scene: 240 random points (inside the view of every camera below, the nearest
    /// 5.6 m away) with random descriptors; keyframe 0 at the origin sees them all, keyframe 1 (the
    /// reference), 1.2 m ahead, misses the last 30.
    struct Scene {
        k: Intrinsics,
        b: f64,
        world: Vec<Vector3<f64>>,
        desc: Vec<[u8; 32]>,
        ids: Vec<PointId>,
        seen: usize,
    }

    fn scene() -> Scene {
        let mut rng = SimRng::new(11);
        let world: Vec<Vector3<f64>> = (0..240)
            .map(|_| {
                let z = rng.uniform(8.0, 40.0);
                Vector3::new(rng.uniform(-0.4, 0.4) * z, rng.uniform(-0.15, 0.15) * z, z)
            })
            .collect();
        let desc: Vec<[u8; 32]> = (0..world.len())
            .map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8))
            .collect();
        let ids: Vec<PointId> = (0..world.len() as PointId).collect();
        let seen = world.len() - 30;
        Scene { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), b: 0.54, world, desc, ids, seen }
    }

    /// `pts` (world) in the camera at `world_from_camera`.
    fn in_camera(world_from_camera: &Isometry3<f64>, pts: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        pts.iter().map(|x| (world_from_camera.inverse() * nalgebra::Point3::from(*x)).coords).collect()
    }

    /// A tracker holding the scene's two keyframes, with `local_keyframes` older keyframes in its
    /// local map.
    fn tracker_of(s: &Scene, local_keyframes: usize) -> StereoVo {
        let world_from = |z: f64| Isometry3::translation(0.0, 0.0, z);
        let config = VoConfig { local_keyframes, ..VoConfig::default() };
        let optimizer = std::sync::Arc::new(slam_lm::LevenbergMarquardt::default());
        let mut vo = StereoVo::new(StereoRig { k: s.k, baseline: s.b }, config, optimizer).expect("ORB");
        vo.image_size = (1241.0, 376.0);
        let (seen, desc) = (&s.world[..s.seen], &s.desc[..s.seen]);
        vo.reference = Some(Reference {
            frame: keyframe_of(&s.k, s.b, &in_camera(&world_from(1.2), seen), &s.ids[..s.seen], desc),
            id: 1,
            world_from_kf: world_from(1.2),
            parent: Some((0, world_from(1.2))),
        });
        vo.local.push_front(Reference {
            frame: keyframe_of(&s.k, s.b, &in_camera(&world_from(0.0), &s.world), &s.ids, &s.desc),
            id: 0,
            world_from_kf: world_from(0.0),
            parent: None,
        });
        vo
    }

    /// Local-map tracking: points the reference keyframe did not see (lost in that frame) are found
    /// again from an older covisible keyframe, and the refinement recovers the pose; the motion guard
    /// accepts the true pose and rejects it moved by 5 m.
    #[test]
    fn local_map_recovers_points_lost_for_one_frame_and_the_guard_rejects_a_5m_jump() {
        let s = scene();
        // the current frame, 2.4 m from the origin, sees every point
        let truth = Isometry3::translation(0.0, 0.0, 2.4);
        let frame = keyframe_of(&s.k, s.b, &in_camera(&truth, &s.world), &vec![0; s.world.len()], &s.desc);
        let curr_from_ref = truth.inverse() * Isometry3::translation(0.0, 0.0, 1.2);
        for (local_keyframes, expect_recovered) in [(0, false), (4, true)] {
            let vo = tracker_of(&s, local_keyframes);
            let map = vo.local_map();
            let skip = vec![false; map.points.len()];
            let taken = vec![false; frame.keypoints.len()];
            // the prediction is off by 0.3 m and a little turn
            let guess = Isometry3::new(Vector3::new(0.1, 0.0, 0.3), Vector3::new(0.0, 0.01, 0.0)) * curr_from_ref;
            let matches = vo.search(&map, &guess, &frame, &|c, o| vo.window(c, o, (0.35, 0.03)), &skip, &taken);
            let recovered: Vec<PointId> =
                matches.iter().map(|&(i, _)| map.ids[i]).filter(|&id| id >= s.seen as PointId).collect();
            assert_eq!(!recovered.is_empty(), expect_recovered, "{local_keyframes} keyframes: {recovered:?}");
            for &(i, c) in &matches {
                assert_eq!(map.ids[i] as usize, c, "every match is right");
            }
            if !expect_recovered {
                continue;
            }
            assert_eq!(recovered.len(), 30, "all the points the reference missed");
            let r = vo.refine(&map, &frame, &matches, &guess).expect("refined");
            let err = r.pose * curr_from_ref.inverse();
            assert!(err.translation.vector.norm() < 1e-3 && err.rotation.angle() < 1e-5, "{err:?}");
            assert_eq!(r.inliers.len(), s.world.len(), "all inliers");
            assert!(r.rms < 1e-3, "rms {}", r.rms);
            // the motion guard: the camera moves 1.2 m per frame and the last frame was the reference
            let mut vo = vo;
            vo.velocity = Isometry3::translation(0.0, 0.0, 1.2);
            vo.velocity_known = true;
            assert_eq!(vo.judge(&r, Route::Motion, &frame), Support::Full);
            let jump = Refined {
                pose: Isometry3::translation(3.0, 0.0, -4.0) * r.pose,
                inliers: r.inliers.clone(),
                rms: r.rms,
            };
            assert_eq!(vo.judge(&jump, Route::Motion, &frame), Support::Rejected, "a 5 m jump");
        }
    }

    /// The keyframe index on real frames: after tracking odometry 06 frames 0-30, every frame's own
    /// descriptors (keyframe or not) retrieve, as the best candidate, a keyframe taken within a few
    /// frames of it, never one of the far end of the run.
    #[test]
    fn the_index_retrieves_a_nearby_keyframe_for_real_frames() {
        let root =
            std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_odom_06/sequences/06"));
        let read = |cam: &str, i: usize| {
            crate::read_image(root.join(cam).join(format!("{i:06}.png")), false).expect("fixture image")
        };
        let k = Intrinsics::new(707.0912, 707.0912, 601.8873, 183.1104);
        let rig = StereoRig { k, baseline: 379.8145 / 707.0912 };
        let mut vo =
            StereoVo::new(rig, VoConfig::default(), std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()))
                .expect("ORB");
        let mut keyframe_at: HashMap<KeyframeId, usize> = HashMap::new();
        let frames = 31;
        for i in 0..frames {
            let t = vo.process(i, &read("image_0", i), &read("image_1", i), &[]).expect("tracks");
            if let Some(kf) = t.keyframe {
                keyframe_at.insert(kf.id, kf.frame);
            }
        }
        assert!(keyframe_at.len() >= 6, "{keyframe_at:?}");
        assert_eq!(vo.index.len(), keyframe_at.len(), "every keyframe indexed");
        for i in (1..frames).step_by(3) {
            let grey = StereoVo::grey_of(&read("image_0", i)).expect("grey");
            let f = extract(&mut vo.orb, &grey).expect("ORB");
            let best = vo.index.query(&f.desc, 3);
            let at = keyframe_at[&best[0].0];
            assert!(at.abs_diff(i) <= 4, "frame {i}: best keyframe at frame {at}: {best:?}");
        }
    }

    #[test]
    fn a_step_repeated_over_a_long_gap_is_squared_and_agrees_with_the_product() {
        let step = Isometry3::new(Vector3::new(0.01, 0.0, 0.9), Vector3::new(0.0, 0.001, 0.0));
        let fold = |k: usize| (0..k).fold(Isometry3::identity(), |acc, _| acc * step);
        for k in [0, 1, 2, 16, REPEAT_FOLD] {
            assert_eq!(repeat(&step, k), fold(k), "k = {k}: the product itself");
        }
        for k in [REPEAT_FOLD + 1, 100, 1000] {
            let d = repeat(&step, k).inverse() * fold(k);
            assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-12, "k = {k}: {d:?}");
        }
        // 10¹² steps: squared (a fold would not finish); a pure rotation stays one
        let turn = Isometry3::rotation(Vector3::new(0.0, 1e-6, 0.0));
        assert!(repeat(&turn, 1_000_000_000_000).translation.vector.norm() < 1e-9);
    }

    #[test]
    fn motion_limits_follow_the_frame_period_and_vehicle_physics() {
        for period in [0.1, 0.2, 0.3, 0.4] {
            let config = VoConfig { frame_period_s: period, ..VoConfig::default() };
            let last = Isometry3::translation(0.0, 0.0, 100.0);
            let predicted = last * Isometry3::translation(0.0, 0.0, 15.0 * period);
            // hard braking (0.9 g) during the frame: accepted
            let braking = predicted * Isometry3::translation(0.0, 0.0, -0.5 * 9.0 * period * period);
            assert!(motion_consistent(&config, &braking, &predicted, &last, 1.0, true), "{period}");
            // a 5 m jump in any direction: rejected
            for d in [Vector3::new(0.0, 0.0, 5.0), Vector3::new(5.0, 0.0, 0.0), Vector3::new(3.0, 0.0, -4.0)] {
                let jump = Isometry3::translation(d.x, d.y, d.z) * predicted;
                assert!(!motion_consistent(&config, &jump, &predicted, &last, 1.0, true), "{period} {d}");
            }
            // a 20° turn within one frame: rejected
            let turn = predicted * Isometry3::rotation(Vector3::new(0.0, 20f64.to_radians(), 0.0));
            assert!(!motion_consistent(&config, &turn, &predicted, &last, 1.0, true), "{period}");
            // while the velocity is unknown only the speed limit (50 m/s) applies
            let fast = last * Isometry3::translation(0.0, 0.0, 40.0 * period);
            let too_fast = last * Isometry3::translation(0.0, 0.0, 60.0 * period);
            assert!(motion_consistent(&config, &fast, &last, &last, 1.0, false));
            assert!(!motion_consistent(&config, &too_fast, &last, &last, 1.0, false));
        }
        // the limits grow with the frames since the last measured pose
        let c = VoConfig::default();
        assert!(
            motion_limits(&c, 3.0).0 > motion_limits(&c, 1.0).0 && motion_limits(&c, 3.0).1 > motion_limits(&c, 1.0).1
        );
    }

    #[test]
    fn support_needs_inliers_spread_and_small_error() {
        let c = VoConfig::default();
        assert_eq!(StereoVo::support(&c, 200, 10, 0.8), Support::Full);
        assert_eq!(StereoVo::support(&c, 20, 10, 0.8), Support::Weak);
        assert_eq!(StereoVo::support(&c, 200, 4, 0.8), Support::Weak);
        assert_eq!(StereoVo::support(&c, 200, 2, 0.8), Support::Rejected);
        assert_eq!(StereoVo::support(&c, 10, 10, 0.8), Support::Rejected);
        assert_eq!(StereoVo::support(&c, 200, 10, 2.5), Support::Rejected);
        assert_eq!(StereoVo::support(&c, 200, 10, f64::NAN), Support::Rejected);
        assert_eq!(spread_cells([(1.0, 1.0), (1240.0, 375.0), (620.0, 10.0)].into_iter(), (1241.0, 376.0)), 3);
    }

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
