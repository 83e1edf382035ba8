//! Fusion: a place seen from two keyframes may have become two points (each keyframe made its own,
//! or tracking missed the match); projecting a keyframe's points into its neighbours finds the
//! keypoint each should be seen at, and a point found at a keypoint that observes another point is
//! the same point: the two are merged (the one observed by fewer keyframes into the other). A point
//! found at a free keypoint gains that observation.

use nalgebra::Point3;

use crate::{descriptor::hamming, map::Map, KeyframeId, PointId};

/// The search of fusion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fusion {
    /// Search radius around the projection, pixels at level 0, times the predicted level's scale
    /// (three pixels: the 95 % bound of a 1 px keypoint error in two coordinates is 2.45 px).
    pub radius_px: f64,
    /// Largest Hamming distance of a match (as triangulation's).
    pub max_hamming: u32,
    /// Bounds of the squared reprojection error in the level's variance (χ², 95 %: 2 and 3 degrees of
    /// freedom).
    pub chi2_mono: f64,
    /// See `chi2_mono`.
    pub chi2_stereo: f64,
    /// Largest angle between a point's mean viewing direction and the view, as a cosine: 0.5 (60°).
    /// A patch seen from more than 60° off its usual direction looks different enough that its
    /// descriptor no longer matches.
    pub min_view_cos: f64,
    /// Slack on a point's detectable distance range (0.8 to 1.2 times it).
    pub range_slack: f64,
}

impl Default for Fusion {
    fn default() -> Self {
        Self {
            radius_px: 3.0,
            max_hamming: 50,
            chi2_mono: 5.991,
            chi2_stereo: 7.815,
            min_view_cos: 0.5,
            range_slack: 1.25,
        }
    }
}

/// What fusion did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Fused {
    /// Points merged into another.
    pub merged: usize,
    /// Observations added.
    pub observed: usize,
}

impl Map {
    /// Fuse keyframe `kf`'s points into each of `targets`, then the targets' points into `kf`.
    pub fn fuse(&mut self, kf: KeyframeId, targets: &[KeyframeId], config: &Fusion) -> Fused {
        let mut out = Fused::default();
        for &t in targets.iter().filter(|&&t| t != kf) {
            let points: Vec<PointId> =
                self.keyframe(kf).map(|k| k.observations().map(|(_, p)| p).collect()).unwrap_or_default();
            self.fuse_into(&points, t, config, &mut out);
        }
        let mut theirs: Vec<PointId> =
            targets.iter().filter_map(|t| self.keyframe(*t)).flat_map(|k| k.observations().map(|(_, p)| p)).collect();
        theirs.sort_unstable();
        theirs.dedup();
        self.fuse_into(&theirs, kf, config, &mut out);
        out
    }

    /// Each of `points` projected into keyframe `target`: merged with the point its best keypoint
    /// observes, or observed there.
    fn fuse_into(&mut self, points: &[PointId], target: KeyframeId, config: &Fusion, out: &mut Fused) {
        for &p in points {
            let Some(best) = self.fusion_match(p, target, config) else { continue };
            let Some(k) = self.keyframe(target) else { return };
            match k.points[best] {
                Some(q) if q == p => {}
                Some(q) => {
                    let seen = |id: PointId| self.point(id).map_or(0, |x| x.seen_by());
                    let (from, into) = if seen(p) > seen(q) { (q, p) } else { (p, q) };
                    // the same place only if the kept point is where every view of the other one saw it
                    if self.explains(into, from, config) {
                        self.merge(from, into);
                        self.refresh(into);
                        out.merged += 1;
                    }
                }
                None => {
                    if self.observe(p, target, best) {
                        self.refresh(p);
                        out.observed += 1;
                    }
                }
            }
        }
    }

    /// Whether point `into`'s position is seen, from every keyframe here that observes point `from`, in
    /// front of it and within the reprojection bound of the keypoint that observes `from` there.
    fn explains(&self, into: PointId, from: PointId, config: &Fusion) -> bool {
        let (Some(x), Some(f)) = (self.position(into), self.point(from)) else { return false };
        let pyr = self.pyramid();
        f.observations.iter().all(|o| {
            let Some(k) = self.keyframe(o.keyframe) else { return true };
            let c = (k.pose.inverse() * Point3::from(x)).coords;
            if c.z <= 0.0 {
                return false;
            }
            let p = self.camera().observe(&c);
            let kp = &k.features.keypoints[o.keypoint as usize];
            let mut e2 = (p[0] - kp.u).powi(2) + (p[1] - kp.v).powi(2);
            let bound = if kp.is_stereo() {
                e2 += (p[2] - kp.u_right).powi(2);
                config.chi2_stereo
            } else {
                config.chi2_mono
            };
            e2 <= bound * pyr.scale(kp.level).powi(2)
        })
    }

    /// The keypoint of `target` at which point `p` is found: inside the image, within the point's
    /// distance range and viewing angle, within the search radius of its projection at a level close to
    /// the predicted one, within the reprojection bound, best in Hamming distance under the bound.
    fn fusion_match(&self, p: PointId, target: KeyframeId, config: &Fusion) -> Option<usize> {
        let (point, k) = (self.point(p)?, self.keyframe(target)?);
        if point.observation(target).is_some() {
            return None;
        }
        let centre = k.centre();
        let distance = point.viewable_from(&centre, config.range_slack, config.min_view_cos)?;
        let cam = self.camera();
        let c = (k.pose.inverse() * Point3::from(point.position)).coords;
        if c.z <= 0.0 {
            return None;
        }
        let o = cam.observe(&c);
        if !k.features.in_image(o[0], o[1]) {
            return None;
        }
        let pyr = self.pyramid();
        let level = pyr.predicted_level(point.distance.1, distance);
        let radius = config.radius_px * pyr.scale(level);
        let mut best: Option<(u32, usize)> = None;
        k.features.grid.for_each_near((o[0], o[1]), radius, |j| {
            let kp = &k.features.keypoints[j];
            if kp.level + 1 < level || kp.level > level {
                return;
            }
            let sigma2 = pyr.scale(kp.level).powi(2);
            let mut e2 = (o[0] - kp.u).powi(2) + (o[1] - kp.v).powi(2);
            let bound = if kp.is_stereo() {
                e2 += (o[2] - kp.u_right).powi(2);
                config.chi2_stereo
            } else {
                config.chi2_mono
            };
            if e2 > bound * sigma2 {
                return;
            }
            let h = hamming(&point.descriptor, &k.features.descriptors[j]);
            if h <= config.max_hamming && best.is_none_or(|b| (h, j) < b) {
                best = Some((h, j));
            }
        });
        best.map(|b| b.1)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::{insert::CreationPolicy, synthetic};

    /// Two keyframes 1 m apart inserted without matching each other: each made its own points for the
    /// same places. Fusion merges each pair (same descriptor, same place) into one point seen by both,
    /// and keeps two points that differ in descriptor.
    #[test]
    fn fusion_merges_a_place_found_twice_and_keeps_points_that_differ() {
        let mut street = synthetic::Street::new(4, 300);
        let mut map = synthetic::map();
        let policy = CreationPolicy::default();
        let (a, ia) = street.keyframe(&map, 0, 0.0, &|_| None);
        map.insert_keyframe(a, &policy).expect("insert");
        let (mut b, ib) = street.keyframe(&map, 1, 1.0, &|_| None);
        // places both keyframes make a point for (near in both)
        let made_by_a: std::collections::BTreeSet<usize> =
            map.keyframe(0).expect("kf").observations().map(|(kp, _)| ia[kp]).collect();
        let in_both: Vec<usize> = ib
            .iter()
            .enumerate()
            .filter(|(kp, w)| made_by_a.contains(w) && b.features.keypoints[*kp].is_stereo())
            .map(|(_, &w)| w)
            .collect();
        assert!(in_both.len() > 50, "{} places made twice", in_both.len());
        // the second keyframe sees another corner at one of them: its descriptor differs
        let different = in_both[0];
        let kp_b = ib.iter().position(|&w| w == different).expect("seen");
        let features = Arc::make_mut(&mut b.features);
        features.descriptors[kp_b].iter_mut().for_each(|x| *x = !*x);
        map.insert_keyframe(b, &policy).expect("insert");
        let before = map.point_count();
        let out = map.fuse(1, &[0], &Fusion::default());
        assert_eq!(out.merged, in_both.len() - 1, "every place made twice but the odd one");
        assert_eq!(map.point_count(), before - out.merged);
        let kp_a = ia.iter().position(|&w| w == different).expect("seen");
        let pa = map.keyframe(0).and_then(|k| k.points[kp_a]).expect("point");
        let pb = map.keyframe(1).and_then(|k| k.points[kp_b]).expect("point");
        assert!(pa != pb, "the two that differ stay two");
        for &w in &in_both[1..] {
            let kp = ib.iter().position(|&x| x == w).expect("seen");
            let p = map.keyframe(1).and_then(|k| k.points[kp]).expect("point");
            assert_eq!(map.point(p).expect("point").seen_by(), 2, "place {w} is one point seen by both");
        }
        map.check().expect("consistent");
    }
}
