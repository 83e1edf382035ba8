//! The local map: the map points of tracking's local keyframes (those observing the points the last
//! frame matched, and their best covisible neighbours: [`slam_map::Map::local_keyframes`]) in the
//! reference keyframe's frame, each with what the projection search needs (its representative
//! descriptor, mean viewing direction, detectable distance range) and its observations in those
//! keyframes (which join the last refinement round).

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use slam_core::{KeyframeId, PointId};
use slam_map::Map;

/// Map points of the local keyframes, in the reference keyframe's frame.
#[derive(Default)]
pub(crate) struct LocalMap {
    pub(crate) ids: Vec<PointId>,
    pub(crate) points: Vec<Vector3<f64>>,
    pub(crate) desc: Vec<[u8; 32]>,
    /// Orientation (degrees) of the point's keypoint in the first keyframe of the map observing it.
    pub(crate) angle: Vec<f32>,
    /// Pyramid level of that keypoint.
    pub(crate) level: Vec<u8>,
    /// Mean viewing direction (unit, reference frame).
    pub(crate) normal: Vec<Vector3<f64>>,
    /// Detectable distance range, metres.
    pub(crate) distance: Vec<(f64, f64)>,
    /// Observations of each point: (keyframe slot, `[u_l, v, u_r]`).
    pub(crate) views: Vec<Vec<(usize, [f64; 3])>>,
    /// `reference_from_keyframe` of each slot (slot 0: the reference).
    pub(crate) poses: Vec<Isometry3<f64>>,
    /// The keyframe of each slot.
    pub(crate) slots: Vec<KeyframeId>,
}

impl LocalMap {
    /// The points of `keyframes` (those in `map`) in the frame of `reference` (slot 0; its pose through
    /// its anchor if it was culled), in the order the keyframes come and their keypoints within each.
    pub(crate) fn of(map: &Map, reference: KeyframeId, keyframes: &[KeyframeId]) -> Self {
        let mut out = LocalMap::default();
        let Some(world_from_ref) = map.keyframe_pose(reference) else { return out };
        let ref_from_world = world_from_ref.inverse();
        let mut index: HashMap<PointId, usize> = HashMap::new();
        let order = std::iter::once(reference).chain(keyframes.iter().copied().filter(|&k| k != reference));
        for id in order {
            let Some(kf) = map.keyframe(id) else {
                if id == reference {
                    // a culled reference keeps slot 0 (its pose) without points
                    out.poses.push(Isometry3::identity());
                    out.slots.push(id);
                }
                continue;
            };
            let slot = out.poses.len();
            out.poses.push(ref_from_world * kf.pose);
            out.slots.push(id);
            for (kp, pid) in kf.observations() {
                let o = kf.features.keypoints[kp].observation();
                if let Some(&i) = index.get(&pid) {
                    out.views[i].push((slot, o));
                    continue;
                }
                let Some(p) = map.point(pid) else { continue };
                index.insert(pid, out.ids.len());
                out.ids.push(pid);
                out.points.push((ref_from_world * Point3::from(p.position)).coords);
                out.desc.push(p.descriptor);
                out.angle.push(kf.features.keypoints[kp].angle);
                out.level.push(kf.features.keypoints[kp].level);
                out.normal.push(ref_from_world.rotation * p.normal);
                out.distance.push(p.distance);
                out.views.push(vec![(slot, o)]);
            }
        }
        out
    }

    /// Number of points.
    pub(crate) fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether point `i`, at `c` in a camera whose centre is at `centre` (both in the reference frame),
    /// is seen within its distance range (widened by a quarter) and within 60° of its mean viewing
    /// direction: the distance when it is.
    pub(crate) fn viewable(&self, i: usize, centre: &Vector3<f64>) -> Option<f64> {
        let ray = self.points[i] - centre;
        let d = ray.norm();
        let (min, max) = self.distance[i];
        if d <= 0.0 || d < min / RANGE_SLACK || d > max * RANGE_SLACK {
            return None;
        }
        let n = &self.normal[i];
        (n.norm_squared() == 0.0 || ray.dot(n) >= MIN_VIEW_COS * d).then_some(d)
    }
}

/// Slack on a point's detectable distance range: a keypoint's scale is measured to about one pyramid
/// step (1.2), so a point a little beyond its range may still be found.
pub(crate) const RANGE_SLACK: f64 = 1.25;
/// Largest angle between a point's mean viewing direction and a view that may still find it, as a
/// cosine (60°): beyond it the patch looks too different for its descriptor to match.
pub(crate) const MIN_VIEW_COS: f64 = 0.5;
