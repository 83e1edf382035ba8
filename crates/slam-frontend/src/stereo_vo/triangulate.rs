//! Triangulation of keypoints without a stereo match against the previous keyframe (optional:
//! `VoConfig::triangulate`): new map points observed in the left images only.

use std::collections::HashSet;

use nalgebra::{Isometry3, Matrix3, Vector3};
use slam_core::PointId;
use slam_quadric::Intrinsics;

use super::frame::Frame;
use crate::matching::{hamming, BestTwo};

/// Triangulate the new keyframe's keypoints that have no stereo point and no carried map point
/// against the reference keyframe's keypoints that have none either: a match lies within 1.5 px of
/// the epipolar line, wins the best-two Hamming test, and its rays meet with `min_parallax_deg`,
/// in front of both cameras and within 2 px of both keypoints. The points are appended to `frame`
/// (left-only observations); returns `(point index in frame, observation in the reference, point in
/// the reference frame)` for each.
pub(crate) fn triangulate(
    k: &Intrinsics,
    reference: &Frame,
    frame: &mut Frame,
    curr_from_ref: &Isometry3<f64>,
    carried: &[(PointId, usize)],
    min_parallax_deg: f64,
) -> Vec<(usize, [f64; 3], Vector3<f64>)> {
    const BAND_PX: f64 = 1.5;
    const MAX_REPROJ_PX: f64 = 2.0;
    let min_cos = min_parallax_deg.to_radians().cos();
    let ref_from_curr = curr_from_ref.inverse();
    let (r, t) = (ref_from_curr.rotation.to_rotation_matrix().into_inner(), ref_from_curr.translation.vector);
    let kinv = k.matrix().try_inverse().unwrap_or_else(Matrix3::identity);
    // x_refᵀ E x_curr = 0 for normalised coordinates, E = [t]× R; F = K⁻ᵀ E K⁻¹
    let f = kinv.transpose() * t.cross_matrix() * r * kinv;
    let taken: HashSet<usize> = carried.iter().map(|c| c.1).collect();
    let ref_free: Vec<usize> =
        (0..reference.keypoints.len()).filter(|&i| reference.of_keypoint.get(i).is_some_and(|q| q.is_none())).collect();
    let mut ref_used = vec![false; reference.keypoints.len()];
    let project = |x: &Vector3<f64>| (k.fx * x.x / x.z + k.cx, k.fy * x.y / x.z + k.cy);
    let mut out = Vec::new();
    for c in 0..frame.keypoints.len() {
        if frame.of_keypoint[c].is_some() || taken.contains(&c) {
            continue;
        }
        let (uc, vc) = frame.keypoints[c];
        let line = f * Vector3::new(uc, vc, 1.0);
        let norm = (line.x * line.x + line.y * line.y).sqrt();
        if norm < 1e-12 {
            continue;
        }
        let mut two = BestTwo::new();
        for &p in &ref_free {
            let (ur, vr) = reference.keypoints[p];
            if (line.x * ur + line.y * vr + line.z).abs() / norm <= BAND_PX {
                two.offer(hamming(&frame.keypoint_desc[c], &reference.keypoint_desc[p]), p);
            }
        }
        let Some(p) = two.winner(50, false).filter(|&p| !ref_used[p]) else { continue };
        // midpoint of the two rays, in the reference frame
        let (ur, vr) = reference.keypoints[p];
        let a = (kinv * Vector3::new(ur, vr, 1.0)).normalize();
        let b = (r * (kinv * Vector3::new(uc, vc, 1.0))).normalize();
        let cos = a.dot(&b);
        if cos > min_cos {
            continue;
        }
        // minimise |λa − (t + μb)|²
        let (ab, at, bt) = (cos, a.dot(&t), b.dot(&t));
        let den = 1.0 - ab * ab;
        let lambda = (at - ab * bt) / den;
        let mu = (ab * at - bt) / den;
        if lambda <= 0.0 || mu <= 0.0 {
            continue;
        }
        let x_ref = 0.5 * (lambda * a + t + mu * b);
        let x_cur = (curr_from_ref * nalgebra::Point3::from(x_ref)).coords;
        if x_ref.z <= 0.1 || x_cur.z <= 0.1 {
            continue;
        }
        let (pr, pc) = (project(&x_ref), project(&x_cur));
        if (pr.0 - ur).hypot(pr.1 - vr) > MAX_REPROJ_PX || (pc.0 - uc).hypot(pc.1 - vc) > MAX_REPROJ_PX {
            continue;
        }
        ref_used[p] = true;
        let q = frame.points.len();
        frame.points.push(x_cur);
        frame.desc.push(frame.keypoint_desc[c]);
        frame.obs.push([uc, vc, f64::NAN]);
        frame.of_keypoint[c] = Some(q);
        frame.ids.push(0);
        frame.valid.push(true);
        out.push((q, [ur, vr, f64::NAN], x_ref));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::rng::SimRng;

    #[test]
    fn triangulation_recovers_points_with_parallax_and_skips_the_rest() {
        let k = Intrinsics::new(707.0, 707.0, 601.9, 183.1);
        // the camera moves 3 m forward and 0.5 m left, turning slightly
        let curr_from_ref = Isometry3::from_parts(
            nalgebra::Translation3::new(0.5, 0.0, -3.0),
            nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.02, 0.0),
        );
        let mut rng = SimRng::new(7);
        let truth: Vec<Vector3<f64>> = (0..300)
            .map(|_| Vector3::new(rng.uniform(-15.0, 15.0), rng.uniform(-3.0, 2.0), rng.uniform(6.0, 60.0)))
            .collect();
        let project = |x: &Vector3<f64>| (k.fx * x.x / x.z + k.cx, k.fy * x.y / x.z + k.cy);
        let desc: Vec<[u8; 32]> = (0..truth.len())
            .map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8))
            .collect();
        let reference = Frame::of_keypoints(truth.iter().map(project).collect(), desc.clone());
        let in_curr: Vec<Vector3<f64>> =
            truth.iter().map(|x| (curr_from_ref * nalgebra::Point3::from(*x)).coords).collect();
        let mut frame = Frame::of_keypoints(in_curr.iter().map(project).collect(), desc);
        let out = triangulate(&k, &reference, &mut frame, &curr_from_ref, &[], 3.0);
        assert!(out.len() > 20, "{} points", out.len());
        for &(q, obs, x_ref) in &out {
            // which true point: the one whose reference keypoint was observed
            let i = reference.keypoints.iter().position(|p| p.0 == obs[0] && p.1 == obs[1]).expect("a keypoint");
            assert!((x_ref - truth[i]).norm() < 1e-6 * truth[i].norm(), "{x_ref} vs {}", truth[i]);
            assert!((frame.points[q] - in_curr[i]).norm() < 1e-6 * truth[i].norm());
            assert!(obs[2].is_nan() && frame.obs[q][2].is_nan());
            let a = truth[i].normalize();
            let b = (truth[i] - curr_from_ref.inverse().translation.vector).normalize();
            assert!(a.dot(&b) < 3f64.to_radians().cos(), "parallax below 3°");
        }
        // points with enough parallax that were left out are few (descriptor ties, band edges)
        let eligible = truth
            .iter()
            .filter(|x| {
                let a = x.normalize();
                let b = (*x - curr_from_ref.inverse().translation.vector).normalize();
                a.dot(&b) < 3.2f64.to_radians().cos()
            })
            .count();
        assert!(out.len() * 10 >= eligible * 9, "{} of {eligible}", out.len());
        // carried keypoints are never triangulated again
        let mut again = Frame::of_keypoints(frame.keypoints.clone(), frame.keypoint_desc.clone());
        let carried: Vec<(PointId, usize)> = (0..again.keypoints.len()).map(|c| (c as PointId, c)).collect();
        assert!(triangulate(&k, &reference, &mut again, &curr_from_ref, &carried, 3.0).is_empty());
    }
}
