//! A map rebuilt from what a map file keeps ([`Map::restore`]): its keyframes with their features and
//! the point each keypoint observes, and its points' positions. Everything derived is recomputed with
//! the map's own primitives: the observations on both sides, the covisibility weights, each point's
//! representative descriptor, viewing direction and distance range. Restored points count as born
//! before the first keyframe, so in a map of more keyframes than the probation lasts (3) they are
//! mature (young-point culling judges the points a run makes); new keyframes and points take ids
//! after the highest restored ones, so what a later run adds never collides with what was loaded.

use std::collections::BTreeSet;

use nalgebra::Vector3;

use crate::{
    camera::{ScalePyramid, StereoCamera},
    keyframe::Keyframe,
    map::Map,
    point::MapPoint,
    KeyframeId, PointId,
};

/// A point as a map file keeps it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SavedPoint {
    /// Its id.
    pub id: PointId,
    /// World position, metres.
    pub position: Vector3<f64>,
    /// The keyframe that made it (its reference view for the distance range).
    pub first_keyframe: KeyframeId,
}

/// Why a saved map cannot be rebuilt: the first inconsistency found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RestoreError {
    /// Two keyframes or two points with one id.
    #[error("{what} {id} appears twice")]
    Duplicate {
        /// `keyframe` or `point`.
        what: &'static str,
        /// The id.
        id: u64,
    },
    /// A keyframe whose features and point slots differ in length, or whose pose is not finite.
    #[error("keyframe {id}: {why}")]
    Keyframe {
        /// The keyframe.
        id: KeyframeId,
        /// What is wrong.
        why: String,
    },
    /// A keypoint observing a point that is not in the map, or a point observed twice by one keyframe.
    #[error("keyframe {keyframe} keypoint {keypoint}: {why}")]
    Observation {
        /// The keyframe.
        keyframe: KeyframeId,
        /// The keypoint.
        keypoint: usize,
        /// What is wrong.
        why: String,
    },
    /// A point with a non-finite position.
    #[error("point {0}: its position is not finite")]
    Position(PointId),
}

impl Map {
    /// Rebuild a map from saved keyframes (their `points` slots say which point each keypoint
    /// observes) and points. Points no keyframe observes are left out (a map keeps none); every
    /// other check failing is an error naming the keyframe, keypoint or point.
    pub fn restore(
        camera: StereoCamera,
        pyramid: ScalePyramid,
        keyframes: Vec<Keyframe>,
        points: &[SavedPoint],
    ) -> Result<Map, RestoreError> {
        let mut map = Map::new(camera, pyramid);
        let mut ids = BTreeSet::new();
        for p in points {
            if !ids.insert(p.id) {
                return Err(RestoreError::Duplicate { what: "point", id: p.id });
            }
            if !p.position.iter().all(|v| v.is_finite()) {
                return Err(RestoreError::Position(p.id));
            }
        }
        let mut keyframes = keyframes;
        keyframes.sort_by_key(|k| k.id);
        if let Some(w) = keyframes.windows(2).find(|w| w[0].id == w[1].id) {
            return Err(RestoreError::Duplicate { what: "keyframe", id: w[0].id });
        }
        let mut observations = Vec::new();
        for kf in keyframes {
            let slots = kf.points.clone();
            let id = kf.id;
            // the map hands out ids in order: the next one is this keyframe's
            map.set_next_keyframe(id);
            map.add_keyframe(kf).map_err(|e| RestoreError::Keyframe { id, why: e.to_string() })?;
            for (keypoint, p) in slots.into_iter().enumerate() {
                if let Some(p) = p {
                    if !ids.contains(&p) {
                        return Err(RestoreError::Observation {
                            keyframe: id,
                            keypoint,
                            why: format!("point {p} is not in the map"),
                        });
                    }
                    observations.push((p, id, keypoint));
                }
            }
        }
        for p in points {
            map.insert_point(p.id, MapPoint::new(p.position, p.first_keyframe, 0));
        }
        for (p, keyframe, keypoint) in observations {
            if !map.observe(p, keyframe, keypoint) {
                return Err(RestoreError::Observation {
                    keyframe,
                    keypoint,
                    why: format!("point {p} is observed twice by this keyframe"),
                });
            }
        }
        let unseen: Vec<PointId> = map.points().filter(|(_, p)| p.observations.is_empty()).map(|(id, _)| id).collect();
        if !unseen.is_empty() {
            tracing::debug!(points = unseen.len(), "restored points no keyframe observes left out");
        }
        for id in unseen {
            map.drop_point(id);
        }
        let all: Vec<PointId> = map.points().map(|(id, _)| id).collect();
        for id in all {
            map.refresh(id);
        }
        Ok(map)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::{insert::CreationPolicy, synthetic, triangulation::Triangulation};

    /// What a map file keeps of a map: its keyframes as they are and its points' positions.
    fn saved(m: &Map) -> (Vec<Keyframe>, Vec<SavedPoint>) {
        let kfs = m.keyframes().cloned().collect();
        let pts = m
            .points()
            .map(|(id, p)| SavedPoint { id, position: p.position, first_keyframe: p.first_keyframe })
            .collect();
        (kfs, pts)
    }

    /// A map of a few keyframes (a culled one among them) rebuilt from what is saved has the same
    /// observations, covisibility, descriptors, viewing directions and distance ranges; the next ids
    /// follow the highest restored ones.
    #[test]
    fn a_restored_map_equals_the_map_it_was_saved_from() {
        let mut street = synthetic::Street::new(11, 400);
        let mut live = synthetic::map();
        let policy = CreationPolicy::default();
        let mut of = BTreeMap::new();
        for (n, z) in [0.0, 2.0, 4.0, 6.0, 8.0].into_iter().enumerate() {
            street.insert(&mut live, (n, z), &policy, &mut of);
        }
        live.triangulate_new_points(4, &[3, 2], &Triangulation::default());
        assert!(live.remove_keyframe(2), "keyframe 2 culled");
        // the live map refreshes a point when its observations change; culling keyframe 2 left some
        // stale, which a restored map recomputes
        let ids: Vec<PointId> = live.points().map(|(id, _)| id).collect();
        ids.into_iter().for_each(|id| live.refresh(id));
        let (kfs, pts) = saved(&live);
        let back = Map::restore(*live.camera(), *live.pyramid(), kfs, &pts).expect("restores");
        back.check().expect("consistent");
        assert_eq!(back.covisibility(), live.covisibility());
        assert_eq!(back.point_count(), live.point_count());
        for (id, p) in live.points() {
            let q = back.point(id).expect("point kept");
            assert_eq!(q.observations, p.observations, "point {id}");
            assert_eq!(q.descriptor, p.descriptor, "point {id}");
            assert!((q.normal - p.normal).norm() < 1e-12, "point {id}");
            assert!((q.distance.0 - p.distance.0).abs() < 1e-9 && (q.distance.1 - p.distance.1).abs() < 1e-9);
        }
        assert_eq!(back.next_keyframe_id(), 5);
        let mut grown = back.clone();
        let next = grown.add_point(Vector3::new(0.0, 0.0, 30.0), 4);
        assert!(next > pts.iter().map(|p| p.id).max().expect("points"), "new point ids follow the restored ones");
    }

    #[test]
    fn a_damaged_saved_map_is_refused_with_what_is_wrong() {
        let mut street = synthetic::Street::new(12, 200);
        let mut live = synthetic::map();
        let mut of = BTreeMap::new();
        for (n, z) in [0.0, 2.0].into_iter().enumerate() {
            street.insert(&mut live, (n, z), &CreationPolicy::default(), &mut of);
        }
        let (kfs, pts) = saved(&live);
        let cam = *live.camera();
        let py = *live.pyramid();
        // a point observed but not kept
        let missing = pts[1..].to_vec();
        let gone = pts[0].id;
        let e = Map::restore(cam, py, kfs.clone(), &missing).expect_err("point missing");
        assert!(e.to_string().contains(&format!("point {gone} is not in the map")), "{e}");
        // a keyframe twice
        let twice = vec![kfs[0].clone(), kfs[0].clone()];
        let e = Map::restore(cam, py, twice, &pts).expect_err("duplicate");
        assert_eq!(e, RestoreError::Duplicate { what: "keyframe", id: 0 });
        // a point with a NaN position
        let mut nan = pts.clone();
        nan[3].position.x = f64::NAN;
        assert_eq!(Map::restore(cam, py, kfs.clone(), &nan).expect_err("nan"), RestoreError::Position(nan[3].id));
        // slots and features of different lengths
        let mut short = kfs.clone();
        short[1].points.pop();
        let e = Map::restore(cam, py, short, &pts).expect_err("slots");
        assert!(matches!(e, RestoreError::Keyframe { id: 1, .. }), "{e}");
        // a point given twice
        let mut dup = pts.clone();
        dup.push(pts[0]);
        assert!(matches!(Map::restore(cam, py, kfs, &dup), Err(RestoreError::Duplicate { what: "point", .. })));
    }
}
