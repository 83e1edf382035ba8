//! Keyframes: the reference keyframe and the older keyframes of the map segment kept for the local
//! map and relocalisation ([`Keyframes`]), the policy that decides when a frame becomes a keyframe
//! ([`KeyframePolicy`]), and the mapper's corrections applied to them.

use std::collections::{HashMap, HashSet, VecDeque};

use nalgebra::{Isometry3, Vector3};
use slam_core::{KeyframeCorrection, KeyframeData, KeyframeId, KeyframePoint, PointId, TrackState};

use super::config::VoConfig;
use super::frame::Frame;
use super::local_map::LocalMap;
use super::refine::{left_only_beyond, Refined};

/// A keyframe.
#[derive(Clone)]
pub(crate) struct Reference {
    pub(crate) frame: Frame,
    pub(crate) id: KeyframeId,
    pub(crate) world_from_kf: Isometry3<f64>,
    /// Parent keyframe and `parent_from_this`.
    pub(crate) parent: Option<(KeyframeId, Isometry3<f64>)>,
}

/// The keyframes the tracker works with: the reference keyframe, the older keyframes of its map
/// segment (newest first), and the next free keyframe and map-point ids.
#[derive(Default)]
pub(crate) struct Keyframes {
    pub(crate) reference: Option<Reference>,
    /// Older keyframes of the segment, newest first (local map and relocalisation).
    pub(crate) local: VecDeque<Reference>,
    next_keyframe: KeyframeId,
    next_point: PointId,
}

impl Keyframes {
    /// The local map: the reference keyframe's points and those of the older keyframes that share at
    /// least 10 map points with it (its covisible keyframes), up to `local_keyframes` of them.
    pub(crate) fn local_map(&self, local_keyframes: usize) -> LocalMap {
        let mut map = LocalMap::default();
        let Some(r) = &self.reference else { return map };
        let mut index = HashMap::new();
        map.add_keyframe(r, Isometry3::identity(), &mut index);
        let ref_ids: HashSet<PointId> = r.frame.ids.iter().copied().collect();
        let ref_from_world = r.world_from_kf.inverse();
        for kf in self.local.iter().take(local_keyframes) {
            let shared =
                kf.frame.ids.iter().zip(&kf.frame.valid).filter(|(id, ok)| **ok && ref_ids.contains(id)).count();
            if shared >= 10 {
                map.add_keyframe(kf, ref_from_world * kf.world_from_kf, &mut index);
            }
        }
        map
    }

    /// Make `frame` the reference keyframe at `world_from_kf` with `parent` (none: a new map segment,
    /// which forgets the older keyframes); ids of points matched to the old reference (`carried`:
    /// map-point id, keypoint) carry over, the others get new ids; `earlier` are the observations of
    /// its new triangulated points in an earlier keyframe. At most `keep` older keyframes stay. The
    /// observations handed over have no right-image column where the disparity is below
    /// `far_disparity` (the mapper's bundle adjustment uses them as the tracker does).
    pub(crate) fn insert(
        &mut self,
        mut frame: Frame,
        frame_index: usize,
        (world_from_kf, parent): (Isometry3<f64>, Option<(KeyframeId, Isometry3<f64>)>),
        carried: &[(PointId, usize)],
        earlier: &[(KeyframeId, usize, [f64; 3], Vector3<f64>)],
        (keep, far_disparity): (usize, f64),
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
                .map(|((x, o), &pid)| KeyframePoint {
                    id: pid,
                    camera_point: *x,
                    observation: left_only_beyond(*o, far_disparity),
                })
                .collect(),
            earlier: earlier
                .iter()
                .map(|&(kf, q, observation, camera_point)| {
                    (kf, KeyframePoint { id: frame.ids[q], camera_point, observation })
                })
                .collect(),
        };
        let kf = Reference { frame, id, world_from_kf, parent };
        let old = self.reference.replace(kf);
        match (old, parent) {
            (Some(old), Some(_)) => {
                self.local.push_front(old);
                self.local.truncate(keep);
            }
            // a new segment: the old keyframes' poses are not related to it
            _ => self.local.clear(),
        }
        data
    }

    /// Apply a mapper's correction to the keyframe it concerns, and to the reference's pose when the
    /// correction moved the reference's parent.
    pub(crate) fn correct(&mut self, c: &KeyframeCorrection) {
        for kf in self.local.iter_mut().filter(|k| k.id == c.id) {
            apply_correction(kf, c);
        }
        let Some(r) = self.reference.as_mut() else { return };
        if r.id == c.id {
            apply_correction(r, c);
        } else if let Some((parent, parent_from_ref)) = r.parent {
            if parent == c.id {
                r.world_from_kf = c.world_from_camera * parent_from_ref;
            }
        }
    }
}

/// When a frame becomes a keyframe: counts since the reference keyframe was taken.
#[derive(Debug, Default)]
pub(crate) struct KeyframePolicy {
    /// Tracked map points of the first frame tracked against the keyframe.
    kf_inliers: Option<usize>,
    /// Frames tracked against the keyframe.
    since_kf: usize,
}

impl KeyframePolicy {
    /// A keyframe was taken: counting starts again.
    pub(crate) fn reset(&mut self) {
        self.kf_inliers = None;
        self.since_kf = 0;
    }

    /// Whether the frame becomes a keyframe: a tracked frame when its tracked map points fell below
    /// `keyframe_inlier_ratio` of the keyframe's first frame's, after `keyframe_max_gap` frames if it
    /// moved, or when it shares less than `keyframe_overlap` of the reference keyframe's points
    /// (`reference_points`: its valid points; `map`: the local map whose slot 0 it is); a weak frame
    /// that moved; every relocalised frame; a frame lost for longer than `max_lost_s` (`since_measured`
    /// frames) that still has stereo points. Moved: the frame's tracked points (`keypoints`: the
    /// frame's) moved in the image since the reference keyframe saw them ([`crate::keyframe_motion`]),
    /// so a keyframe brings new information.
    pub(crate) fn wants(
        &mut self,
        config: &VoConfig,
        state: TrackState,
        refined: Option<&Refined>,
        (map, reference_points, keypoints): (&LocalMap, usize, &[(f64, f64)]),
        since_measured: usize,
        stereo_points: usize,
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
            of_reference as f64 / reference_points.max(1) as f64
        });
        self.since_kf += 1;
        let lost_too_long = refined.is_none()
            && since_measured as f64 * config.period() > config.max_lost_s
            && stereo_points >= config.min_inliers;
        match state {
            TrackState::Tracked { .. } => {
                let base = *self.kf_inliers.get_or_insert(tracked_map_points);
                (tracked_map_points as f64) < config.keyframe_inlier_ratio * base as f64
                    || (self.since_kf >= config.keyframe_max_gap && moved)
                    || overlap < config.keyframe_overlap
            }
            TrackState::Weak { .. } => moved,
            TrackState::Relocalised { .. } => true,
            _ => lost_too_long,
        }
    }
}

/// Apply a mapper's correction to a keyframe it concerns: pose, refined points, culled points.
pub(crate) fn apply_correction(kf: &mut Reference, c: &KeyframeCorrection) {
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
