//! Redundant keyframes. A keyframe whose near points are nearly all seen by at least three other
//! keyframes, at the same scale, a finer one or one level coarser (a factor of 1.2, within what a
//! descriptor matches across), adds no constraint those keyframes do not: it is culled (kept as an
//! anchor for the frames tracked against it). Driving the same road again or
//! standing still makes such keyframes; culling them keeps the map in proportion to the places seen,
//! not to the time spent there.

use crate::{map::Map, KeyframeId};

/// When a keyframe is redundant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyframeCulling {
    /// Share of its near points that must be seen elsewhere: nine in ten. A keyframe that alone sees one
    /// point in ten of its view still holds part of the map.
    pub redundant_share: f64,
    /// Other keyframes that must see such a point at the same level, a finer one or one coarser:
    /// three, so that the point stays triangulated and constrained from several views when this one is
    /// gone.
    pub observers: usize,
    /// Only stereo points nearer than this many baselines count (the front end's `far_baselines`): a
    /// far point constrains the pose little whoever sees it.
    pub near_baselines: f64,
}

impl Default for KeyframeCulling {
    fn default() -> Self {
        Self { redundant_share: 0.9, observers: 3, near_baselines: 40.0 }
    }
}

impl Map {
    /// Cull the redundant keyframes among `candidates` ([`KeyframeCulling`]); never `keep`, nor a
    /// keyframe that starts a map segment. The culled ids.
    pub fn cull_redundant_keyframes(
        &mut self,
        candidates: &[KeyframeId],
        keep: KeyframeId,
        config: &KeyframeCulling,
    ) -> Vec<KeyframeId> {
        let camera = *self.camera();
        let near = config.near_baselines * camera.baseline;
        let mut culled = Vec::new();
        for &id in candidates {
            if id == keep {
                continue;
            }
            let Some(k) = self.keyframe(id) else { continue };
            if k.parent.is_none() {
                continue;
            }
            let (mut counted, mut redundant) = (0usize, 0usize);
            for (i, p) in k.observations() {
                let kp = &k.features.keypoints[i];
                if kp.depth(&camera).is_none_or(|z| z > near) {
                    continue;
                }
                counted += 1;
                let Some(point) = self.point(p) else { continue };
                let others = point
                    .observations
                    .iter()
                    .filter(|o| o.keyframe != id && o.level <= kp.level + 1 && self.keyframe(o.keyframe).is_some())
                    .count();
                if others >= config.observers {
                    redundant += 1;
                }
            }
            if counted > 0 && redundant as f64 > config.redundant_share * counted as f64 && self.remove_keyframe(id) {
                culled.push(id);
            }
        }
        culled
    }
}

#[cfg(test)]
mod tests {
    use crate::{insert::CreationPolicy, keyframe_culling::KeyframeCulling, synthetic};

    /// Six keyframes 20 cm apart see the same points: the ones in the middle are redundant (every near
    /// point seen by at least three others) and culled down to what keeps each point seen by four; a
    /// keyframe 15 m on, which alone sees its near points, is kept.
    #[test]
    fn a_redundant_keyframe_is_culled_and_a_needed_one_kept() {
        let mut street = synthetic::Street::new(2, 400);
        let mut map = synthetic::map();
        let policy = CreationPolicy::default();
        let mut of = std::collections::BTreeMap::new();
        for (n, z) in [0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 16.0].into_iter().enumerate() {
            street.insert(&mut map, (n, z), &policy, &mut of);
        }
        let all: Vec<u64> = map.keyframes().map(|k| k.id).collect();
        let culled = map.cull_redundant_keyframes(&all, 6, &KeyframeCulling::default());
        assert!(!culled.is_empty(), "some of the six are redundant");
        assert!(!culled.contains(&0), "a segment's first keyframe stays");
        assert!(!culled.contains(&6), "the newest keyframe stays");
        assert!(map.keyframe(6).is_some());
        assert!(map.keyframe_count() >= 3, "points stay seen by several keyframes: {}", map.keyframe_count());
        // a keyframe that alone sees its near points is needed
        let far = map.cull_redundant_keyframes(&[6], 0, &KeyframeCulling::default());
        assert!(far.is_empty(), "the keyframe 15 m on sees what nobody else does");
        for id in &culled {
            assert!(map.keyframe_pose(*id).is_some(), "culled keyframe {id} kept as an anchor");
        }
        map.check().expect("consistent");
    }
}
