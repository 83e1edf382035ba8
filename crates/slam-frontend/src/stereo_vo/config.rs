//! The rig and the tracker's settings (the `[tracking]` table of `slam-app run --config`; their valid
//! ranges are in `stereo_vo::settings`).

/// A rectified stereo rig: the map's stereo camera ([`slam_map::StereoCamera`]: intrinsics of both
/// cameras, baseline in metres, the right camera at +x of the left one).
pub type StereoRig = slam_map::StereoCamera;

/// Settings of [`StereoVo`](super::StereoVo) (the `[tracking]` table of `slam-app run --config`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct VoConfig {
    /// ORB features per image.
    pub features: i32,
    /// Spread the features over the image: each pyramid level's share taken from a grid of cells of
    /// about one feature each, the best of every cell first (`stereo_vo/features.rs`). Off: OpenCV's
    /// choice, the highest corner scores wherever they are.
    pub spread_features: bool,
    /// Extract the left and the right image's features side by side, on two threads (the right one on a
    /// thread of its own for each frame). Default on: the same keypoints, and on two cores, with the
    /// detection and mapping threads running, 3–8 % more frames a second (docs/system.md, Measured).
    pub parallel_extraction: bool,
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
    /// Beyond this many baselines (disparity below `fx / far_baselines` pixels: 17.7 px at KITTI's
    /// 707 px focal length, 21.5 m), a stereo observation is used as a left-image observation only, in
    /// the pose refinement and in the keyframes handed to local bundle adjustment: the point still
    /// constrains the rotation and, through motion parallax, the translation, but its disparity does
    /// not set the scale. A point there moves its disparity by a pixel for every 6 % of depth, and the
    /// disparities of distant texture carry systematic errors of a tenth of a pixel to more than one
    /// (measured against the ground-truth motion with `slam-app depth-check --motion`, in both our
    /// stereo matching and ORB-SLAM2's; docs/system.md) that would otherwise lengthen the path. 40 is
    /// also where ORB-SLAM2 stops making map points from stereo depth (35–40 baselines). ∞: every
    /// disparity used.
    pub far_baselines: f64,
    /// Lost for longer than this (seconds): a new map segment starts. In a map loaded from an earlier
    /// run, frames not yet placed in it count as lost: a run that may extend the map starts a new
    /// segment after this long without being placed.
    pub max_lost_s: f64,
    /// A new keyframe is made when fewer than this share of the reference keyframe's established points
    /// (those seen by at least three keyframes, two while the map has two or fewer) lie in the frame's
    /// view (inside the image, within their distance range and viewing angle): a keyframe every time a
    /// quarter of the reference's map has left the view, so that each point is seen by about four
    /// keyframes while it is in view (triangulation needs two, keyframe culling three others).
    /// Geometry, not matching: standing still or driving over mapped road, the reference's points stay
    /// in view and no keyframe is made however many of them one frame's matching misses.
    pub keyframe_tracked_ratio: f64,
    /// ... or when it tracks fewer than `.0` map points nearer than `far_baselines` (the ones that set
    /// the scale) while more than `.1` of its near stereo keypoints have no map point in view within
    /// the second search's radius: the map lacks near structure the frame could give. 100 is the map's
    /// own least number of points made per keyframe (`mapping.min_new_points`); 70 is a third of the
    /// near stereo points of a typical street view, enough to be worth a keyframe.
    pub keyframe_near_points: (usize, usize),
    /// ... or, when not 0, after this many frames tracked against the reference keyframe if the frame
    /// moved (its tracked points' median image motion since the keyframe of at least a pixel). 0 (the
    /// default): keyframes only when the map needs them (the two rules above).
    pub keyframe_max_gap: usize,
    /// Most keypoints followed by optical flow per detection box (association cue).
    pub flow_points_per_region: usize,
    /// Most keyframes in tracking's local map: those observing the points the last frame matched, by
    /// how many each observes, then each one's best covisible neighbours. A view 40–80 m deep on a road
    /// with a keyframe every 2–3 m meets some 30 keyframes; the bound keeps the cost flat where a
    /// place has been mapped many times.
    pub local_keyframes: usize,
    /// Best covisible neighbours of each of those keyframes added to the local map (the parts of the
    /// map the next frames will see): ten, as many as new points are triangulated with.
    pub local_neighbours: usize,
    /// Search radius of the second search at the found pose, pixels at pyramid level 0.
    pub local_radius: f64,
    /// Added to every measured disparity, pixels: a correction of the rig's rectification (see
    /// [`crate::disparity`]; `slam-app stereo-check` estimates it from a sequence's images). Default 0.
    pub disparity_offset: f64,
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
    /// Localise only (`slam-app run --map FILE --localise-only`): no keyframe is made, so nothing is
    /// added to the map and no new segment is started. Not a settings-file key.
    #[serde(skip)]
    pub localise_only: bool,
    /// Frame pairs kept for [`StereoVo::disparity_pairs`](super::StereoVo::disparity_pairs) (offset self-calibration); 0 keeps none.
    /// Not a settings-file key: `slam-app stereo-check` sets it.
    #[serde(skip)]
    pub keep_disparity_pairs: usize,
}

impl VoConfig {
    /// The disparity below which a stereo observation is used as a left-image observation only
    /// ([`VoConfig::far_baselines`]), pixels, for focal length `fx`: `fx / far_baselines` (0 when
    /// `far_baselines` is infinite).
    pub fn far_disparity_px(&self, fx: f64) -> f64 {
        fx / self.far_baselines
    }

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
            spread_features: true,
            parallel_extraction: true,
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
            keyframe_tracked_ratio: 0.75,
            keyframe_near_points: (100, 70),
            keyframe_max_gap: 0,
            flow_points_per_region: 40,
            local_keyframes: 40,
            local_neighbours: 10,
            local_radius: 4.0,
            disparity_offset: 0.0,
            vehicle_slip_rad: 0.0,
            vehicle_lever_m: (1.35, 0.78),
            vehicle_height_m: 1.33,
            keep_disparity_pairs: 0,
            localise_only: false,
        }
    }
}
