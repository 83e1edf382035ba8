//! Self-calibration of a constant disparity offset of a rectified stereo rig.
//!
//! A small rotation of the right camera about its vertical axis that the rectification missed (0.3 mrad
//! is enough) shifts every measured disparity by the same amount, `ε ≈ f·δ` pixels. Depth `f·b/d` then
//! errs most for far points, and the odometry's scale errs with it (about 1 % on KITTI odometry 06 for
//! ε ≈ 0.2 px, docs/system.md). The offset is observable from motion: with the wrong offset the stereo
//! points of two frames are a projective, not a rigid, copy of each other, so the lateral image motion
//! of far and near points disagrees with their stereo depths. [`estimate_disparity_offset`] scans
//! candidate offsets, re-solves each frame pair's two-view stereo adjustment with the disparities shifted,
//! and keeps the offset of least total robust cost (refined by a parabola through the best three).

use nalgebra::Isometry3;
use slam_optim::{factors::StereoReprojection, Graph, Huber, NoiseModel, Optimizer, Options, Values, Var};

use slam_map::StereoCamera as StereoRig;

/// Stereo observations `[u_l, v, u_r]` of the same points in a keyframe and a later frame, with the
/// frame's pose relative to the keyframe from tracking (the starting point of each re-solve).
#[derive(Debug, Clone, PartialEq)]
pub struct DisparityPair {
    /// Observations in the keyframe.
    pub keyframe: Vec<[f64; 3]>,
    /// Observations of the same points in the frame.
    pub frame: Vec<[f64; 3]>,
    /// `T_frame←keyframe` as tracked.
    pub frame_from_keyframe: Isometry3<f64>,
}

/// Result of [`estimate_disparity_offset`].
#[derive(Debug, Clone, PartialEq)]
pub struct OffsetEstimate {
    /// Offset to add to every measured disparity, pixels.
    pub offset: f64,
    /// Frame pairs and point observations used.
    pub pairs: usize,
    /// Point correspondences used.
    pub points: usize,
    /// Total robust cost at each candidate offset (offset, cost).
    pub curve: Vec<(f64, f64)>,
    /// Whether the least cost lay inside the scanned range (not at an end).
    pub interior: bool,
    /// Standard error of `offset`, pixels: the jackknife over the frame pairs (each left out once, the
    /// offset found again from the others), so it measures how much the answer depends on which frames
    /// were seen. NaN with fewer than two pairs.
    pub standard_error: f64,
}

/// Fewest frame pairs an offset is estimated from: a spread estimated from `n` pairs is itself
/// uncertain by about 1/√(2(n − 1)) of its value, a quarter at ten pairs; fewer leave the offset's own
/// confidence unknown.
pub const MIN_OFFSET_PAIRS: usize = 10;

/// The least point of a cost curve sampled every `step`: the best sample refined by a parabola through it
/// and its neighbours; and whether it lay inside the curve (not at an end).
fn least(curve: &[(f64, f64)], step: f64) -> Option<(f64, bool)> {
    let n = curve.len();
    let best = (0..n).min_by(|&a, &b| curve[a].1.total_cmp(&curve[b].1))?;
    let interior = best > 0 && best + 1 < n;
    let mut offset = curve[best].0;
    if interior {
        let (c0, c1, c2) = (curve[best - 1].1, curve[best].1, curve[best + 1].1);
        let den = c0 - 2.0 * c1 + c2;
        if den > 0.0 {
            offset += 0.5 * step * (c0 - c2) / den;
        }
    }
    Some((offset, interior))
}

/// Robust cost of one pair's two-view adjustment with `offset` added to every disparity; an error when
/// its graph cannot be built or solved.
fn pair_cost(
    rig: &StereoRig,
    pair: &DisparityPair,
    offset: f64,
    optimizer: &dyn Optimizer,
) -> Result<f64, slam_optim::OptimError> {
    let shift = |o: &[f64; 3]| [o[0], o[1], o[2] - offset];
    let mut values = Values::new();
    let kf = values.add(Var::Pose(Isometry3::identity()));
    let fr = values.add(Var::Pose(pair.frame_from_keyframe.inverse()));
    let mut graph = Graph::new();
    graph.fix(kf);
    for (a, b) in pair.keyframe.iter().zip(&pair.frame) {
        let a = shift(a);
        let d = a[0] - a[2];
        if d <= 0.0 {
            continue;
        }
        let p = rig.point(a[0], a[1], d);
        let x = values.add(Var::Point(p));
        graph.eliminate(x);
        for (pose, obs) in [(kf, a), (fr, shift(b))] {
            graph.add(
                StereoReprojection::new(pose, x, rig.k, rig.baseline, obs),
                NoiseModel::Isotropic(1.0),
                Huber(2.0),
            )?;
        }
    }
    Ok(optimizer.optimize(&graph, &mut values, &Options::with_max_iterations(15), None)?.final_cost)
}

/// Estimate the disparity offset from frame pairs by scanning `range` (pixels) in steps of `step`,
/// re-solving each pair with `optimizer`. `None` without pairs or with a degenerate range.
///
/// A pair whose adjustment fails at any candidate offset is left out at every offset (a sum over fewer
/// pairs would look cheaper and win the scan); such pairs are counted and logged, and
/// [`OffsetEstimate::pairs`] counts only the pairs used. `None` too when no pair is left.
pub fn estimate_disparity_offset(
    rig: &StereoRig,
    pairs: &[DisparityPair],
    range: (f64, f64),
    step: f64,
    optimizer: &dyn Optimizer,
) -> Option<OffsetEstimate> {
    let usable = step > 0.0 && range.1 > range.0 && step.is_finite() && range.0.is_finite() && range.1.is_finite();
    if pairs.is_empty() || !usable {
        return None;
    }
    let n = ((range.1 - range.0) / step).round() as usize + 1;
    let offsets: Vec<f64> = (0..n).map(|i| range.0 + i as f64 * step).collect();
    // costs[pair][offset]
    let costs: Vec<Vec<Result<f64, slam_optim::OptimError>>> =
        pairs.iter().map(|p| offsets.iter().map(|&e| pair_cost(rig, p, e, optimizer)).collect()).collect();
    let used: Vec<usize> = (0..pairs.len()).filter(|&i| costs[i].iter().all(Result::is_ok)).collect();
    if used.len() < pairs.len() {
        let first = costs.iter().flatten().find_map(|c| c.as_ref().err());
        tracing::warn!(
            skipped = pairs.len() - used.len(),
            pairs = pairs.len(),
            "disparity offset: frame pairs left out, their adjustment failed at some offset (first: {})",
            first.map_or_else(String::new, ToString::to_string)
        );
    }
    if used.is_empty() {
        return None;
    }
    let curve: Vec<(f64, f64)> = offsets
        .iter()
        .enumerate()
        .map(|(j, &e)| (e, used.iter().map(|&i| costs[i][j].as_ref().map_or(0.0, |c| *c)).sum()))
        .collect();
    let (offset, interior) = least(&curve, step)?;
    // jackknife: the offset of the curve without each pair in turn
    let cost = |i: usize, j: usize| costs[i][j].as_ref().map_or(0.0, |c| *c);
    let leave_out: Vec<f64> = used
        .iter()
        .filter_map(|&i| {
            let without: Vec<(f64, f64)> = curve.iter().enumerate().map(|(j, &(e, c))| (e, c - cost(i, j))).collect();
            least(&without, step).map(|l| l.0)
        })
        .collect();
    let m = leave_out.len() as f64;
    let standard_error = if leave_out.len() < 2 {
        f64::NAN
    } else {
        let mean = leave_out.iter().sum::<f64>() / m;
        ((m - 1.0) / m * leave_out.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt()
    };
    Some(OffsetEstimate {
        offset,
        pairs: used.len(),
        points: used.iter().map(|&i| pairs[i].keyframe.len()).sum(),
        curve,
        interior,
        standard_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The optimiser of these tests (the project's Levenberg–Marquardt).
    fn lm() -> slam_lm::LevenbergMarquardt {
        slam_lm::LevenbergMarquardt::default()
    }
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use slam_core::rng::SimRng;
    use slam_quadric::Intrinsics;

    fn rig() -> StereoRig {
        StereoRig { k: Intrinsics::new(718.9, 718.9, 607.2, 185.2), baseline: 0.537 }
    }

    /// Frame pairs of a forward drive whose measured disparities are `true − bias` (+ noise).
    fn pairs(bias: f64, noise: f64, seed: u64) -> Vec<DisparityPair> {
        let r = rig();
        let mut rng = SimRng::new(seed);
        let observe = |p: &Vector3<f64>, rng: &mut SimRng| {
            let u = r.k.fx * p.x / p.z + r.k.cx + noise * rng.normal();
            let v = r.k.fy * p.y / p.z + r.k.cy + noise * rng.normal();
            let d = r.k.fx * r.baseline / p.z - bias + noise * rng.normal();
            [u, v, u - d]
        };
        (0..6)
            .map(|i| {
                let yaw = 0.01 * (i as f64 - 2.5);
                let pose = nalgebra::Isometry3::from_parts(
                    Translation3::new(0.05 * i as f64, 0.0, -4.0 - 0.3 * i as f64),
                    UnitQuaternion::from_euler_angles(0.0, yaw, 0.0),
                );
                let (mut a, mut b) = (Vec::new(), Vec::new());
                while a.len() < 250 {
                    let p = Vector3::new(rng.uniform(-12.0, 12.0), rng.uniform(-3.0, 1.5), rng.uniform(6.0, 60.0));
                    let q = pose * nalgebra::Point3::from(p);
                    let (u, v) = (r.k.fx * q.x / q.z + r.k.cx, r.k.fy * q.y / q.z + r.k.cy);
                    if q.z < 2.0 || !(0.0..1240.0).contains(&u) || !(0.0..375.0).contains(&v) {
                        continue;
                    }
                    a.push(observe(&p, &mut rng));
                    b.push(observe(&q.coords, &mut rng));
                }
                // tracking's pose: what a solve with the biased disparities gives, roughly (start point)
                DisparityPair { keyframe: a, frame: b, frame_from_keyframe: pose }
            })
            .collect()
    }

    #[test]
    fn recovers_an_injected_offset() {
        for (bias, seed) in [(0.3, 1), (0.0, 2), (-0.2, 3), (-1.0, 6)] {
            let e = estimate_disparity_offset(&rig(), &pairs(bias, 0.15, seed), (-1.5, 1.5), 0.05, &lm()).unwrap();
            assert!(e.interior, "{e:?}");
            assert!((e.offset - bias).abs() < 0.05, "bias {bias}: estimated {}", e.offset);
            assert_eq!((e.pairs, e.points), (6, 1500));
        }
    }

    /// The jackknife's standard error is near the spread of offsets over independent draws of the same
    /// rig (6 pairs each), and shrinks with less disparity noise.
    #[test]
    fn the_standard_error_measures_the_spread_over_frames() {
        let (range, step) = ((-0.6, 1.0), 0.1);
        let noisy: Vec<OffsetEstimate> = (10..15)
            .map(|seed| {
                estimate_disparity_offset(&rig(), &pairs(0.2, 0.5, seed), range, step, &lm()).expect("estimate")
            })
            .collect();
        let offsets: Vec<f64> = noisy.iter().map(|e| e.offset).collect();
        let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
        let spread = (offsets.iter().map(|o| (o - mean).powi(2)).sum::<f64>() / (offsets.len() - 1) as f64).sqrt();
        let se = noisy.iter().map(|e| e.standard_error).sum::<f64>() / noisy.len() as f64;
        assert!(se > 0.3 * spread && se < 3.0 * spread, "standard error {se:.4} vs spread over draws {spread:.4}");
        let quiet = estimate_disparity_offset(&rig(), &pairs(0.2, 0.05, 10), range, step, &lm()).expect("estimate");
        assert!(quiet.standard_error < 0.5 * se, "{} vs {se}", quiet.standard_error);
        let one = estimate_disparity_offset(&rig(), &pairs(0.2, 0.1, 10)[..1], range, step, &lm()).expect("estimate");
        assert!(one.standard_error.is_nan(), "one pair: no spread");
    }

    #[test]
    fn reports_an_offset_outside_the_range_as_such() {
        let e = estimate_disparity_offset(&rig(), &pairs(0.9, 0.1, 4), (-0.3, 0.3), 0.1, &lm()).unwrap();
        assert!(!e.interior);
        assert!((e.offset - 0.3).abs() < 1e-9);
        assert!(estimate_disparity_offset(&rig(), &[], (-0.3, 0.3), 0.1, &lm()).is_none());
        assert!(estimate_disparity_offset(&rig(), &pairs(0.0, 0.1, 5), (0.3, -0.3), 0.1, &lm()).is_none());
    }

    #[test]
    fn a_pair_that_cannot_be_solved_is_left_out_at_every_offset() {
        let good = pairs(0.3, 0.15, 7);
        let mut with_bad = good.clone();
        let mut bad = good[0].clone();
        bad.frame[0][0] = f64::NAN; // its initial cost is not finite: the optimiser refuses it
        with_bad.insert(2, bad);
        let clean = estimate_disparity_offset(&rig(), &good, (-1.0, 1.0), 0.1, &lm()).unwrap();
        let e = estimate_disparity_offset(&rig(), &with_bad, (-1.0, 1.0), 0.1, &lm()).unwrap();
        assert_eq!(e, clean, "the unsolvable pair changed the estimate");
        assert_eq!((e.pairs, e.points), (6, 1500));
        let only_bad = vec![with_bad[2].clone()];
        assert!(estimate_disparity_offset(&rig(), &only_bad, (-1.0, 1.0), 0.1, &lm()).is_none());
    }
}
