//! New map points from two keyframes: keypoints of a new keyframe and of one of its covisible
//! neighbours that observe no point yet are matched along the epipolar line and triangulated. The two
//! views' rays meet at an angle (the parallax) that sets the depth's precision: a pixel's error is an
//! angle of 1/f radians, so the depth is known to about (1/f)/parallax. Where the keyframes' motion gives
//! more parallax than the stereo baseline does, the rays are used; where it gives less, the keypoint's
//! own stereo depth (the nearer of the two, with more stereo parallax) is.

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Vector3};

use crate::{
    descriptor::{hamming, BestTwo},
    keyframe::Keypoint,
    map::Map,
    KeyframeId, PointId,
};

/// The checks of a triangulated point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangulation {
    /// Largest cosine of the parallax of two rays with no stereo depth to fall back on: 0.9998 is
    /// 1.15°, where a pixel's error at KITTI's 707 px focal length (0.08°) is 7 % of the depth, as much
    /// as a stereo depth has at 35 baselines.
    pub max_parallax_cos: f64,
    /// Largest Hamming distance of a match (the 50 of keyframe retrieval: ten standard deviations below
    /// the 128 bits unrelated descriptors differ by).
    pub max_hamming: u32,
    /// Bound of the squared distance of a keypoint from the epipolar line, in units of its level's
    /// variance: 3.84, the 95 % point of χ² with one degree of freedom.
    pub epipolar_chi2: f64,
    /// Bounds of the squared reprojection error in the level's variance: 5.991 for a left-image
    /// observation (χ², 2 degrees of freedom, 95 %), 7.815 for a stereo one (3).
    pub chi2_mono: f64,
    /// See `chi2_mono`.
    pub chi2_stereo: f64,
    /// The ratio of the point's distances from the two cameras must match the ratio of the two
    /// keypoints' scales within this factor times the pyramid's step: a keypoint seen twice as near is
    /// found a level or so coarser, and a match whose scales disagree with its distances is not one.
    pub scale_slack: f64,
    /// Farthest depth, metres, of a point searched for (the epipolar segment ends there).
    pub max_depth: f64,
}

impl Default for Triangulation {
    fn default() -> Self {
        Self {
            max_parallax_cos: 0.9998,
            max_hamming: 50,
            epipolar_chi2: 3.84,
            chi2_mono: 5.991,
            chi2_stereo: 7.815,
            scale_slack: 1.5,
            max_depth: 80.0,
        }
    }
}

/// The point seen by two cameras (`a_from_world`, `b_from_world`, normalised image coordinates of
/// each ray) by the linear method: the null vector of the four equations the two projections give.
pub fn triangulate_rays(
    a_from_world: &Isometry3<f64>,
    b_from_world: &Isometry3<f64>,
    a: (f64, f64),
    b: (f64, f64),
) -> Option<Vector3<f64>> {
    let pa = a_from_world.to_homogeneous();
    let pb = b_from_world.to_homogeneous();
    let mut m = Matrix4::zeros();
    for (row, (p, (x, y))) in [(pa, a), (pb, b)].into_iter().enumerate() {
        m.set_row(2 * row, &(x * p.row(2) - p.row(0)));
        m.set_row(2 * row + 1, &(y * p.row(2) - p.row(1)));
    }
    let svd = m.svd(false, true);
    let v_t = svd.v_t?;
    let (i, _) = svd.singular_values.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    let h = v_t.row(i);
    (h[3].abs() > 1e-12).then(|| Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]))
}

impl Map {
    /// Triangulate new points between keyframe `kf` and each of `neighbours` ([`Triangulation`]);
    /// the new points' ids. A neighbour nearer to `kf` than the stereo baseline is skipped: its
    /// parallax is smaller than stereo's own.
    pub fn triangulate_new_points(
        &mut self,
        kf: KeyframeId,
        neighbours: &[KeyframeId],
        config: &Triangulation,
    ) -> Vec<PointId> {
        let mut made = Vec::new();
        for &n in neighbours {
            if n == kf {
                continue;
            }
            let (Some(a), Some(b)) = (self.keyframe(kf), self.keyframe(n)) else { continue };
            if (a.centre() - b.centre()).norm() < self.camera().baseline {
                continue;
            }
            let pairs = self.epipolar_matches(kf, n, config);
            for (i, j) in pairs {
                if let Some(x) = self.triangulated(kf, i, n, j, config) {
                    let p = self.add_point(x, kf);
                    self.observe(p, kf, i);
                    self.observe(p, n, j);
                    self.refresh(p);
                    made.push(p);
                }
            }
        }
        made
    }

    /// Matches between the keypoints of `a` and `b` that observe no point: within the epipolar band
    /// of the segment of depths up to `max_depth`, smallest Hamming distance with the ratio test, each
    /// keypoint of `b` to one of `a`.
    fn epipolar_matches(&self, a: KeyframeId, b: KeyframeId, config: &Triangulation) -> Vec<(usize, usize)> {
        let (Some(ka), Some(kb)) = (self.keyframe(a), self.keyframe(b)) else { return Vec::new() };
        let cam = *self.camera();
        let pyr = *self.pyramid();
        let b_from_a = kb.pose.inverse() * ka.pose;
        let r = b_from_a.rotation.to_rotation_matrix().into_inner();
        let t = b_from_a.translation.vector;
        let kinv = cam.k.matrix().try_inverse().unwrap_or_else(Matrix3::identity);
        // x_bᵀ F x_a = 0 with F = K⁻ᵀ [t]× R K⁻¹
        let f = kinv.transpose() * t.cross_matrix() * r * kinv;
        let free_b: Vec<usize> = (0..kb.points.len()).filter(|&j| kb.points[j].is_none()).collect();
        // cells of about twice the widest band: a band's cells hold few keypoints beside it
        let grid = crate::KeypointGrid::with_cell(
            &free_b.iter().map(|&j| (kb.features.keypoints[j].u, kb.features.keypoints[j].v)).collect::<Vec<_>>(),
            16.0,
        );
        // each level's band, and the widest of any candidate: a candidate passes the box test below (within
        // its band of the segment's bounding box) and the line test, so its offsets in u and in v from some
        // point of the segment are both within the widest band: the grid's square neighbourhood holds it
        let bands: Vec<f64> = (0..=u8::MAX).map(|l| (config.epipolar_chi2 * pyr.scale(l).powi(2)).sqrt()).collect();
        let band_of = |level: u8| bands[level as usize];
        let widest = free_b.iter().map(|&j| band_of(kb.features.keypoints[j].level)).fold(0.0, f64::max);
        let near = 1.0f64.max(cam.baseline);
        let mut found: Vec<(u32, usize, usize)> = Vec::new();
        for i in (0..ka.points.len()).filter(|&i| ka.points[i].is_none()) {
            let kp = &ka.features.keypoints[i];
            let ray = cam.ray(kp.u, kp.v);
            let ray = ray / ray.z;
            // the segment the point's image in b can lie on: depths `near` to `max_depth`
            let ends: Vec<(f64, f64)> = [near, config.max_depth]
                .iter()
                .filter_map(|&z| cam.project(&(b_from_a * Point3::from(ray * z)).coords))
                .collect();
            if ends.len() < 2 {
                continue;
            }
            let line = f * Vector3::new(kp.u, kp.v, 1.0);
            let norm = line.x.hypot(line.y);
            if norm < 1e-12 {
                continue;
            }
            let (lo_u, hi_u) = (ends[0].0.min(ends[1].0), ends[0].0.max(ends[1].0));
            let (lo_v, hi_v) = (ends[0].1.min(ends[1].1), ends[0].1.max(ends[1].1));
            let d = &ka.features.descriptors[i];
            let mut two = BestTwo::new();
            // the order of the offers does not matter: ties fail the ratio test whichever comes first
            grid.for_each_near_segment(ends[0], ends[1], widest, |c| {
                let j = free_b[c];
                let q = &kb.features.keypoints[j];
                let band = band_of(q.level);
                if q.u < lo_u - band || q.u > hi_u + band || q.v < lo_v - band || q.v > hi_v + band {
                    return;
                }
                let dist = (line.x * q.u + line.y * q.v + line.z).abs() / norm;
                if dist > band {
                    return;
                }
                two.offer(hamming(d, &kb.features.descriptors[j]), j);
            });
            if let Some(j) = two.winner(config.max_hamming, false) {
                found.push((two.best, i, j));
            }
        }
        found.sort_unstable();
        let mut used = vec![false; kb.points.len()];
        found.into_iter().filter(|&(_, _, j)| !std::mem::replace(&mut used[j], true)).map(|(_, i, j)| (i, j)).collect()
    }

    /// The point of keypoint `i` of `a` and keypoint `j` of `b` when it passes the checks.
    fn triangulated(
        &self,
        a: KeyframeId,
        i: usize,
        b: KeyframeId,
        j: usize,
        config: &Triangulation,
    ) -> Option<Vector3<f64>> {
        let (ka, kb) = (self.keyframe(a)?, self.keyframe(b)?);
        let cam = *self.camera();
        let (p, q) = (&ka.features.keypoints[i], &kb.features.keypoints[j]);
        let (ray_a, ray_b) = (ka.pose.rotation * cam.ray(p.u, p.v), kb.pose.rotation * cam.ray(q.u, q.v));
        let cos_rays = ray_a.dot(&ray_b);
        let stereo_cos = |k: &Keypoint| k.depth(&cam).map_or(2.0, |z| (2.0 * (cam.baseline / 2.0).atan2(z)).cos());
        let (cos_a, cos_b) = (stereo_cos(p), stereo_cos(q));
        let stereo = p.is_stereo() || q.is_stereo();
        let x = if cos_rays > 0.0 && cos_rays < cos_a.min(cos_b) && (stereo || cos_rays < config.max_parallax_cos) {
            let norm = |k: &Keypoint| ((k.u - cam.k.cx) / cam.k.fx, (k.v - cam.k.cy) / cam.k.fy);
            triangulate_rays(&ka.pose.inverse(), &kb.pose.inverse(), norm(p), norm(q))?
        } else if p.is_stereo() && cos_a < cos_b {
            (ka.pose * Point3::from(p.stereo_point(&cam)?)).coords
        } else if q.is_stereo() && cos_b < cos_a {
            (kb.pose * Point3::from(q.stereo_point(&cam)?)).coords
        } else {
            return None;
        };
        let pyr = *self.pyramid();
        // in front of both, seen where the keypoints are, at distances matching their scales
        let mut distances = [0.0; 2];
        for (slot, (k, kp)) in [(ka, p), (kb, q)].into_iter().enumerate() {
            let c = (k.pose.inverse() * Point3::from(x)).coords;
            if c.z <= 0.0 {
                return None;
            }
            let o = cam.observe(&c);
            let sigma2 = pyr.scale(kp.level).powi(2);
            let mut e2 = (o[0] - kp.u).powi(2) + (o[1] - kp.v).powi(2);
            let bound = if kp.is_stereo() {
                e2 += (o[2] - kp.u_right).powi(2);
                config.chi2_stereo
            } else {
                config.chi2_mono
            };
            if e2 > bound * sigma2 {
                return None;
            }
            distances[slot] = (x - k.centre()).norm();
        }
        if distances[0] <= 0.0 || distances[1] <= 0.0 {
            return None;
        }
        let ratio_dist = distances[1] / distances[0];
        let ratio_scale = pyr.scale(p.level) / pyr.scale(q.level);
        let slack = config.scale_slack * pyr.factor;
        if ratio_dist * slack < ratio_scale || ratio_dist > ratio_scale * slack {
            return None;
        }
        Some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{insert::CreationPolicy, synthetic};

    /// Two keyframes 3 m apart whose far keypoints have no stereo depth: the far places are
    /// triangulated from the two views, each within a fraction of its depth's expected error of the
    /// truth, observed by both; the near ones already had points and are not made twice.
    #[test]
    fn far_keypoints_are_triangulated_between_two_keyframes() {
        let mut street = synthetic::Street::new(5, 600);
        let mut map = synthetic::map();
        let policy = CreationPolicy { near_baselines: 40.0, min_points: 0 };
        let mut made = std::collections::BTreeMap::new();
        street.insert(&mut map, (0, 0.0), &policy, &mut made);
        let (b, ib) = street.keyframe(&map, 1, 3.0, &|w| made.get(&w).copied());
        map.insert_keyframe(b, &policy).expect("insert");
        let before = map.point_count();
        let new = map.triangulate_new_points(1, &[0], &Triangulation::default());
        assert!(new.len() > 30, "{} new points", new.len());
        assert_eq!(map.point_count(), before + new.len());
        for p in &new {
            let point = map.point(*p).expect("point");
            assert_eq!(point.seen_by(), 2);
            let o = point.observation(1).expect("seen by the new keyframe");
            let truth = street.points[ib[o.keypoint as usize]];
            assert!((point.position - truth).norm() < 1e-6 * truth.norm(), "{} vs {truth}", point.position);
            assert!(truth.z > 40.0 * 0.54, "a far place: {truth}");
        }
        map.check().expect("consistent");
        // a neighbour nearer than the stereo baseline gives no new point
        let (c, _) = street.keyframe(&map, 2, 3.3, &|_| None);
        map.insert_keyframe(c, &policy).expect("insert");
        assert!(map.triangulate_new_points(2, &[1], &Triangulation::default()).is_empty());
    }

    #[test]
    fn linear_triangulation_recovers_a_point() {
        let x = Vector3::new(1.5, -0.7, 25.0);
        let a = Isometry3::identity();
        let b = Isometry3::translation(0.3, 0.0, 2.0);
        let n = |pose: &Isometry3<f64>| {
            let c = pose.inverse() * Point3::from(x);
            (c.x / c.z, c.y / c.z)
        };
        let got = triangulate_rays(&a.inverse(), &b.inverse(), n(&a), n(&b)).expect("point");
        assert!((got - x).norm() < 1e-9, "{got}");
    }
}
