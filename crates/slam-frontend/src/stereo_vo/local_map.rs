//! The local map: the map points of the reference keyframe and of its covisible keyframes, in the
//! reference keyframe's frame, each with its observations in those keyframes. The tracker matches a
//! frame against it; its points' keyframe observations join the last refinement round.

use std::collections::HashMap;

use nalgebra::{Isometry3, Vector3};
use slam_core::PointId;

use super::keyframes::Reference;

/// Map points of the reference keyframe and its covisible keyframes, in the reference's frame.
#[derive(Default)]
pub(crate) struct LocalMap {
    pub(crate) ids: Vec<PointId>,
    pub(crate) points: Vec<Vector3<f64>>,
    pub(crate) desc: Vec<[u8; 32]>,
    pub(crate) octave: Vec<i32>,
    pub(crate) angle: Vec<f32>,
    /// Observations of each point: (keyframe slot, `[u_l, v, u_r]`).
    pub(crate) views: Vec<Vec<(usize, [f64; 3])>>,
    /// `reference_from_keyframe` of each slot (slot 0: the reference).
    pub(crate) poses: Vec<Isometry3<f64>>,
}

impl LocalMap {
    /// Adds keyframe `kf` (at `ref_from_kf` in the reference's frame) as the next slot: its valid
    /// points not yet in the map (`index`: map-point id → position in the map) join it, the others
    /// gain an observation.
    pub(crate) fn add_keyframe(
        &mut self,
        kf: &Reference,
        ref_from_kf: Isometry3<f64>,
        index: &mut HashMap<PointId, usize>,
    ) {
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
