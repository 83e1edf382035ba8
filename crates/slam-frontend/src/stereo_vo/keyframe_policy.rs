//! The life of a keyframe, on the tracking side: when a tracked frame becomes one (the map needs it),
//! and the keyframe handed over (its features and the map points its keypoints matched). Inserting it,
//! making its near points and culling redundant keyframes is the map's work (`slam_map`).

use std::sync::Arc;

use nalgebra::Isometry3;
use slam_core::{KeyframeId, NewKeyframe, PointId};
use slam_map::Map;

use super::checks::Support;
use super::config::{StereoRig, VoConfig};
use super::frame::Frame;
use super::local_map::LocalMap;
use super::refine::Refined;

/// What the keyframe decision reads of a tracked frame.
pub(crate) struct View<'a> {
    /// The frame.
    pub(crate) frame: &'a Frame,
    /// Its local map (slot 0: the reference keyframe).
    pub(crate) map: &'a LocalMap,
    /// The accepted pose's inliers (local-map point, keypoint), when a pose was accepted.
    pub(crate) refined: Option<&'a Refined>,
    /// Where each local-map point is seen at the accepted pose, when it is in the view.
    pub(crate) seen: &'a [Option<(f64, f64)>],
}

/// When a frame becomes a keyframe: frames counted since the reference keyframe was made.
#[derive(Debug, Default)]
pub(crate) struct KeyframePolicy {
    since_kf: usize,
}

impl KeyframePolicy {
    /// A keyframe was made: counting starts again.
    pub(crate) fn reset(&mut self) {
        self.since_kf = 0;
    }

    /// Whether the frame becomes a keyframe. A frame whose accepted pose has full support (tracked or
    /// relocalised: `min_inliers` inliers spread over the image) does when the map needs it; a weak
    /// one never does (a keyframe's pose anchors every point it makes and every frame tracked from
    /// it, so it must be placed at least as well as a tracked frame is):
    /// - the view moved on: fewer than `keyframe_tracked_ratio` of the reference keyframe's established
    ///   points (seen by at least three keyframes; two while the map holds two or fewer) lie in it
    ///   (inside the image, within their distance range and viewing angle). This is geometry, not
    ///   matching: on mapped road or standing still the reference's points stay in view however many of
    ///   them one frame's matching misses;
    /// - the view holds near structure the map lacks: it tracks fewer than `keyframe_near_points.0` map
    ///   points nearer than the near bound, and more than `keyframe_near_points.1` of its near stereo
    ///   keypoints have no map point in view within the second search's radius of them.
    ///
    /// With `keyframe_max_gap` set, also every that many frames if the frame moved. A frame without a
    /// pose does only when it has been lost for longer than `max_lost_s` (`since_measured` frames) and
    /// has stereo points: a new map segment.
    pub(crate) fn wants(
        &mut self,
        config: &VoConfig,
        rig: &StereoRig,
        support: Support,
        view: &View<'_>,
        map: &Map,
        since_measured: usize,
    ) -> bool {
        self.since_kf += 1;
        let Some(r) = view.refined else {
            let lost_too_long = since_measured as f64 * config.period() > config.max_lost_s;
            return lost_too_long && view.frame.points.len() >= config.min_inliers;
        };
        if support != Support::Full {
            return false;
        }
        let tracked = r.inliers.len();
        let (established, in_view) = established_in_view(map, view);
        let near = config.far_baselines * rig.baseline;
        // a tracked map point nearer than the bound constrains the translation whether or not this
        // frame's stereo matched its keypoint
        let tracked_near =
            r.inliers.iter().filter(|&&(i, _)| (r.pose * nalgebra::Point3::from(view.map.points[i])).z < near).count();
        let unmapped_near = unmapped_near_keypoints(view, near, config.local_radius);
        let (min_near, new_near) = config.keyframe_near_points;
        let needs_near = tracked_near < min_near && unmapped_near > new_near;
        let moved_on = (in_view as f64) < config.keyframe_tracked_ratio * established as f64;
        let gap = config.keyframe_max_gap > 0 && self.since_kf >= config.keyframe_max_gap && moved(view, r);
        tracing::trace!(tracked, established, in_view, tracked_near, unmapped_near, "keyframe decision");
        (moved_on || needs_near || gap) && tracked > config.weak_inliers
    }
}

/// The reference keyframe's established points (seen by at least three keyframes; two while the map
/// holds two or fewer) and how many of them lie in the view.
fn established_in_view(map: &Map, view: &View<'_>) -> (usize, usize) {
    let least = if map.keyframe_count() <= 2 { 2 } else { 3 };
    let (mut established, mut in_view) = (0, 0);
    for (i, views) in view.map.views.iter().enumerate() {
        if !views.iter().any(|v| v.0 == 0) {
            continue;
        }
        if map.point(view.map.ids[i]).is_some_and(|p| p.seen_by() >= least) {
            established += 1;
            in_view += usize::from(view.seen.get(i).is_some_and(|s| s.is_some()));
        }
    }
    (established, in_view)
}

/// The frame's stereo keypoints nearer than `near` metres with no local-map point in view within the
/// second search's radius (`radius` pixels at level 0, times the keypoint's level scale): near
/// structure the map does not hold.
fn unmapped_near_keypoints(view: &View<'_>, near: f64, radius: f64) -> usize {
    let at: Vec<(f64, f64)> = view.seen.iter().filter_map(|s| *s).collect();
    let grid = slam_map::KeypointGrid::new(&at);
    let scale = slam_map::ScalePyramid::default();
    let f = view.frame;
    (0..f.keypoints.len())
        .filter(|&c| f.of_keypoint[c].is_some_and(|q| f.points[q].z < near))
        .filter(|&c| {
            let (u, v) = f.keypoints[c];
            let r = radius * scale.scale(f.octave[c].clamp(0, u8::MAX as i32) as u8);
            let mut mapped = false;
            grid.for_each_near((u, v), r, |j| {
                let (x, y) = at[j];
                mapped |= (x - u).powi(2) + (y - v).powi(2) <= r * r;
            });
            !mapped
        })
        .count()
}

/// Whether the frame's tracked points moved in the image since the reference keyframe saw them
/// ([`super::keyframe_motion`]).
fn moved(view: &View<'_>, r: &Refined) -> bool {
    super::keyframe_motion::moved(r.inliers.iter().filter_map(|&(i, c)| {
        let (_, o) = view.map.views[i].iter().find(|v| v.0 == 0)?;
        Some(((o[0], o[1]), *view.frame.keypoints.get(c)?))
    }))
}

/// The keyframe a frame becomes: id `id`, at `world_from_kf`, tracked from `parent` (none: a new map
/// segment), its keypoints' features (an image of `size`), and the map points its refined inliers
/// matched (`refined`'s indices into `map`).
pub(crate) fn new_keyframe(
    (id, frame_index): (KeyframeId, usize),
    frame: &Frame,
    size: (f64, f64),
    (world_from_kf, parent): (Isometry3<f64>, Option<KeyframeId>),
    matched: Option<(&Refined, &LocalMap)>,
) -> NewKeyframe {
    let mut points: Vec<Option<PointId>> = vec![None; frame.keypoints.len()];
    if let Some((r, map)) = matched {
        for &(i, c) in &r.inliers {
            points[c] = Some(map.ids[i]);
        }
    }
    NewKeyframe {
        id,
        frame: frame_index,
        pose: world_from_kf,
        parent,
        features: Arc::new(frame.map_features(size)),
        matched: points,
    }
}
