//! The covisibility graph: two keyframes are linked when they observe map points in common, with the
//! number of those points as the link's weight. It is kept up to date observation by observation (an
//! observation added to a point seen by `n` keyframes adds one to `n` links), so it always equals what
//! counting the shared points would give.

use std::collections::BTreeMap;

use crate::KeyframeId;

/// Weighted links between keyframes that share map points.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Covisibility {
    links: BTreeMap<KeyframeId, BTreeMap<KeyframeId, u32>>,
}

impl Covisibility {
    /// Points shared by `a` and `b` (0 when unlinked).
    pub fn weight(&self, a: KeyframeId, b: KeyframeId) -> u32 {
        self.links.get(&a).and_then(|l| l.get(&b)).copied().unwrap_or(0)
    }

    /// `a` and `b` observe one more common point.
    pub fn link(&mut self, a: KeyframeId, b: KeyframeId) {
        if a == b {
            return;
        }
        *self.links.entry(a).or_default().entry(b).or_default() += 1;
        *self.links.entry(b).or_default().entry(a).or_default() += 1;
    }

    /// `a` and `b` observe one common point fewer.
    pub fn unlink(&mut self, a: KeyframeId, b: KeyframeId) {
        for (x, y) in [(a, b), (b, a)] {
            if let Some(l) = self.links.get_mut(&x) {
                if let Some(w) = l.get_mut(&y) {
                    *w = w.saturating_sub(1);
                    if *w == 0 {
                        l.remove(&y);
                    }
                }
                if l.is_empty() {
                    self.links.remove(&x);
                }
            }
        }
    }

    /// Forget keyframe `a` (its links must be gone already when its observations were removed; this
    /// drops whatever is left).
    pub fn remove(&mut self, a: KeyframeId) {
        if let Some(l) = self.links.remove(&a) {
            for b in l.keys() {
                if let Some(m) = self.links.get_mut(b) {
                    m.remove(&a);
                    if m.is_empty() {
                        self.links.remove(b);
                    }
                }
            }
        }
    }

    /// The keyframes linked to `a` with at least `min_weight` shared points, heaviest first (ties: the
    /// newer keyframe first).
    pub fn neighbours(&self, a: KeyframeId, min_weight: u32) -> Vec<(KeyframeId, u32)> {
        let mut out: Vec<(KeyframeId, u32)> = self
            .links
            .get(&a)
            .map(|l| l.iter().filter(|(_, &w)| w >= min_weight).map(|(&k, &w)| (k, w)).collect())
            .unwrap_or_default();
        out.sort_by(|x, y| y.1.cmp(&x.1).then(y.0.cmp(&x.0)));
        out
    }

    /// The `n` heaviest links of `a` (any weight).
    pub fn best(&self, a: KeyframeId, n: usize) -> Vec<KeyframeId> {
        self.neighbours(a, 1).into_iter().take(n).map(|(k, _)| k).collect()
    }

    /// Number of links (each counted once).
    pub fn edges(&self) -> usize {
        self.links.values().map(|l| l.len()).sum::<usize>() / 2
    }

    /// Every link `(a, b, weight)` with `a < b`, in order.
    pub fn iter(&self) -> impl Iterator<Item = (KeyframeId, KeyframeId, u32)> + '_ {
        self.links.iter().flat_map(|(&a, l)| l.iter().filter(move |(&b, _)| a < b).map(move |(&b, &w)| (a, b, w)))
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use nalgebra::{Isometry3, Vector3};

    use crate::{
        keyframe::{Features, Keyframe, Keypoint},
        synthetic, KeyframeId, Map,
    };

    /// A map of three keyframes of 10 keypoints each; points observed by hand-chosen keyframes.
    fn hand_built() -> (Map, Vec<u64>) {
        let mut map = synthetic::map();
        for id in 0..3u64 {
            let kps: Vec<Keypoint> = (0..10)
                .map(|i| Keypoint { u: 10.0 * i as f64, v: 5.0, u_right: f64::NAN, level: 0, angle: 0.0 })
                .collect();
            let f = Features::new(kps, vec![[id as u8; 32]; 10], synthetic::SIZE).expect("lengths");
            let kf = Keyframe::new(id, id as usize, Isometry3::identity(), id.checked_sub(1), Arc::new(f));
            map.add_keyframe(kf).expect("fresh id");
        }
        // points 0-5 seen by keyframes 0 and 1, points 6-7 by all three, point 8 by 1 and 2, point 9 by 0
        let seen: Vec<&[KeyframeId]> =
            vec![&[0, 1][..]; 6].into_iter().chain(vec![&[0, 1, 2][..]; 2]).chain([&[1, 2][..], &[0][..]]).collect();
        let mut ids = Vec::new();
        for (i, by) in seen.iter().enumerate() {
            let p = map.add_point(Vector3::new(0.0, 0.0, 10.0 + i as f64), by[0]);
            for &k in *by {
                assert!(map.observe(p, k, i));
            }
            ids.push(p);
        }
        (map, ids)
    }

    #[test]
    fn weights_count_shared_points_and_neighbours_come_heaviest_first() {
        let (mut map, ids) = hand_built();
        let c = map.covisibility();
        assert_eq!((c.weight(0, 1), c.weight(1, 0)), (8, 8));
        assert_eq!(c.weight(0, 2), 2);
        assert_eq!(c.weight(1, 2), 3);
        assert_eq!(c.neighbours(1, 1), vec![(0, 8), (2, 3)]);
        assert_eq!(c.neighbours(2, 3), vec![(1, 3)], "only links of at least 3 points");
        assert_eq!(c.best(0, 1), vec![1]);
        assert_eq!(c.edges(), 3);
        map.check().expect("consistent");
        // an observation removed lowers the weights of its links; a point nobody sees is removed
        assert!(map.unobserve(ids[6], 2));
        assert_eq!((map.covisibility().weight(0, 2), map.covisibility().weight(1, 2)), (1, 2));
        assert!(map.unobserve(ids[9], 0));
        assert!(map.point(ids[9]).is_none());
        map.check().expect("consistent");
        // a keyframe culled takes its links with it and stays as an anchor
        assert!(map.remove_keyframe(1));
        assert_eq!(map.covisibility().neighbours(0, 1), vec![(2, 1)]);
        assert!(map.point(ids[0]).is_some(), "still seen by keyframe 0");
        assert_eq!(map.keyframe(2).and_then(|k| k.parent), Some(0), "its child takes its parent");
        assert!(map.keyframe_pose(1).is_some());
        map.check().expect("consistent");
    }
}
