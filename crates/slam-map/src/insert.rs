//! A new keyframe into the map: the points its keypoints were matched to gain its observations, and
//! its near stereo keypoints become new points at once. Farther stereo keypoints do not: their depth
//! is measured poorly (the disparity of a point 40 baselines away is 1/40 of the focal length, and a
//! pixel of it is 2.5 % of the depth, before any systematic error of the matching), so they become
//! points only when a second keyframe triangulates them with more parallax
//! ([`crate::triangulation`]), unless the view has too few near points to track by. The first keyframe
//! of a map segment is the exception: no other keyframe can triangulate its far keypoints yet, and the
//! next frames are tracked by its points alone (at 4.8 m a frame, the near ones have mostly left the
//! view one frame later), so all its stereo keypoints become points.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3};

use crate::{
    keyframe::{Features, Keyframe},
    map::{Map, MapError},
    KeyframeId, PointId,
};

/// A keyframe as the tracker hands it over.
#[derive(Debug, Clone, PartialEq)]
pub struct NewKeyframe {
    /// Its id: the map's [`Map::next_keyframe_id`].
    pub id: KeyframeId,
    /// The input frame it is made from.
    pub frame: usize,
    /// Its pose, world from camera.
    pub pose: Isometry3<f64>,
    /// The keyframe it was tracked against (none: it starts a new map segment).
    pub parent: Option<KeyframeId>,
    /// Its features.
    pub features: Arc<Features>,
    /// The map point each keypoint was matched to and kept by the pose refinement.
    pub matched: Vec<Option<PointId>>,
}

/// Which stereo keypoints of a new keyframe become map points at once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CreationPolicy {
    /// Stereo keypoints nearer than this many baselines become points (the front end's
    /// `far_baselines`: beyond it a disparity does not set the scale).
    pub near_baselines: f64,
    /// While fewer than this many of the nearest stereo keypoints have a point, farther ones become
    /// points too, nearest first: a view of open country must still leave tracking something to
    /// match in the next frames.
    pub min_points: usize,
}

impl Default for CreationPolicy {
    fn default() -> Self {
        Self { near_baselines: 40.0, min_points: 100 }
    }
}

/// What inserting a keyframe did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inserted {
    /// The keyframe.
    pub id: KeyframeId,
    /// Matched points that took the observation.
    pub observed: usize,
    /// New points made from its stereo keypoints.
    pub created: Vec<PointId>,
}

impl Map {
    /// Insert a new keyframe: its matched points observe it (a point matched to two keypoints keeps
    /// the first; a point no longer in the map is skipped), its stereo keypoints nearer than the
    /// policy's bound without a point become points, and farther ones, nearest first, while fewer than
    /// the policy's minimum have one (all of them for the first keyframe of a map segment, one without
    /// parent); every point it observes is refreshed.
    pub fn insert_keyframe(&mut self, kf: NewKeyframe, policy: &CreationPolicy) -> Result<Inserted, MapError> {
        if kf.matched.len() != kf.features.len() {
            return Err(MapError::Features { id: kf.id, keypoints: kf.features.len(), descriptors: kf.matched.len() });
        }
        let id = kf.id;
        self.add_keyframe(Keyframe::new(kf.id, kf.frame, kf.pose, kf.parent, kf.features.clone()))?;
        let mut observed = 0;
        for (i, m) in kf.matched.iter().enumerate() {
            if let Some(p) = m {
                observed += usize::from(self.observe(*p, id, i));
            }
        }
        let camera = *self.camera();
        let near = if kf.parent.is_none() { f64::INFINITY } else { policy.near_baselines * camera.baseline };
        let mut stereo: Vec<(f64, usize)> =
            kf.features.keypoints.iter().enumerate().filter_map(|(i, k)| k.depth(&camera).map(|z| (z, i))).collect();
        stereo.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut created = Vec::new();
        // the stereo keypoints are taken nearest first: `with_point` of them have a point already
        for (with_point, (z, i)) in stereo.into_iter().enumerate() {
            if z > near && with_point >= policy.min_points {
                break;
            }
            if self.keyframe(id).is_some_and(|k| k.points[i].is_some()) {
                continue;
            }
            let Some(c) = kf.features.keypoints[i].stereo_point(&camera) else { continue };
            let p = self.add_point((kf.pose * Point3::from(c)).coords, id);
            self.observe(p, id, i);
            created.push(p);
        }
        let all: Vec<PointId> =
            self.keyframe(id).map(|k| k.observations().map(|(_, p)| p).collect()).unwrap_or_default();
        for p in all {
            self.refresh(p);
        }
        Ok(Inserted { id, observed, created })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    /// A segment's first keyframe makes points of all its stereo keypoints; a later one of its near ones
    /// only, unless the near ones are too few; matched points take the observation; every point is
    /// refreshed (descriptor, direction, range).
    #[test]
    fn near_stereo_keypoints_become_points_and_far_ones_wait() {
        let mut street = synthetic::Street::new(3, 500);
        let cam = synthetic::camera();
        let (features, _, pose) = street.view(0.0, 80.0);
        let features = Arc::new(features);
        let n = features.len();
        let near = 40.0 * cam.baseline;
        let stereo = features.keypoints.iter().filter(|k| k.is_stereo()).count();
        let stereo_near = features.keypoints.iter().filter(|k| k.depth(&cam).is_some_and(|z| z <= near)).count();
        assert!(stereo_near > 100 && stereo_near < stereo, "{stereo_near} of {stereo}");
        let new = |id: u64, parent: Option<u64>, matched: Vec<Option<PointId>>| NewKeyframe {
            id,
            frame: id as usize,
            pose,
            parent,
            features: features.clone(),
            matched,
        };
        let mut map = synthetic::map();
        let first = map.insert_keyframe(new(0, None, vec![None; n]), &CreationPolicy::default()).expect("insert");
        assert_eq!(first.created.len(), stereo, "the segment's first keyframe: every stereo keypoint");
        // the same view again as a later keyframe that matched nothing: its near keypoints only
        let later = map.insert_keyframe(new(1, Some(0), vec![None; n]), &CreationPolicy::default()).expect("insert");
        assert_eq!(later.created.len(), stereo_near, "exactly the near ones");
        for p in later.created.iter().filter_map(|p| map.point(*p)) {
            assert!(p.position.z <= near + 1e-9);
            assert_ne!(p.descriptor, [0; 32], "refreshed");
            let d = p.position.norm();
            assert!(p.distance.0 <= d * 1.000001 && d <= p.distance.1 * 1.000001, "{:?} {d}", p.distance);
            assert!((p.normal - p.position.normalize()).norm() < 1e-9);
        }
        // a view with few near points: the nearest far ones fill up to the minimum
        let policy = CreationPolicy { near_baselines: 40.0, min_points: stereo_near + 50 };
        let sparse = map.insert_keyframe(new(2, Some(1), vec![None; n]), &policy).expect("insert");
        assert_eq!(sparse.created.len(), stereo_near + 50);
        // a keyframe matched to the first keyframe's points observes them and makes no duplicate
        let matched: Vec<Option<PointId>> = (0..n).map(|i| map.keyframe(0).and_then(|k| k.points[i])).collect();
        let again = map.insert_keyframe(new(3, Some(2), matched), &CreationPolicy::default()).expect("insert");
        assert_eq!((again.observed, again.created.len()), (stereo, 0));
        assert_eq!(map.covisibility().weight(0, 3), stereo as u32);
        map.check().expect("consistent");
        let stale = NewKeyframe {
            id: 9,
            frame: 9,
            pose,
            parent: Some(1),
            features: Arc::new(Features::default()),
            matched: Vec::new(),
        };
        assert_eq!(map.insert_keyframe(stale, &CreationPolicy::default()), Err(MapError::DuplicateKeyframe(9)));
    }
}
