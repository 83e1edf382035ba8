//! Pose refinement: the matches of a frame against the local map solved for the frame's pose in four
//! rounds with staged outlier rejection (pose alone with Huber, then least squares, then the matched
//! points freed with their keyframe observations), each observation in the stereo image coordinates
//! `[u_l, v, u_r]` it was measured in.

use std::collections::HashMap;

use nalgebra::{DMatrix, Isometry3};
use slam_optim::{
    factors::{MonoReprojection, PosePrior, StereoReprojection},
    Graph, Huber, Key, NoiseModel, Options, Values, Var, L2,
};

use super::config::{StereoRig, VoConfig};
use super::frame::Frame;
use super::local_map::LocalMap;
use super::pose_only;

/// σ floor of the vehicle-motion prior's sideways step, metres: the camera's sway on the body's
/// suspension within one frame (body roll of a car: a few degrees at most, about a centimetre at roof
/// height over 0.1 s of normal driving).
const VEHICLE_SWAY_M: f64 = 0.01;
/// `o` without its right-image column when its disparity is below `min_disparity` pixels (a point
/// farther than the stereo depth is trusted for; see [`VoConfig::far_baselines`](super::config::VoConfig::far_baselines)); other observations
/// unchanged.
pub(crate) fn left_only_beyond(o: [f64; 3], min_disparity: f64) -> [f64; 3] {
    if o[2].is_finite() && o[0] - o[2] < min_disparity {
        [o[0], o[1], f64::NAN]
    } else {
        o
    }
}

/// Least depth of a point in a camera observing it, metres (the reprojection factors' own bound).
const MIN_DEPTH_M: f64 = 0.1;

/// 95 % bounds of χ² with 3 (stereo) and 2 (left image only) degrees of freedom, σ = 1 px.
pub(crate) const CHI2_STEREO: f64 = 7.815;
const CHI2_MONO: f64 = 5.991;

/// One refinement round's problem ([`Refiner::round_problem`]): the graph, its values, the current
/// pose's key, and each match's point key and current factor (`usize::MAX`: set aside).
pub(crate) struct RoundProblem {
    graph: Graph,
    values: Values,
    pose: Key,
    per_match: Vec<(Key, usize)>,
}

/// A refined pose: `curr_from_ref`, inlier matches (local-map point, keypoint), RMS reprojection error.
pub(crate) struct Refined {
    pub(crate) pose: Isometry3<f64>,
    pub(crate) inliers: Vec<(usize, usize)>,
    pub(crate) rms: f64,
}

/// What the refinement reads: the rig, the settings and the optimiser of the joint round.
pub(crate) struct Refiner<'a> {
    pub(crate) rig: &'a StereoRig,
    pub(crate) config: &'a VoConfig,
    pub(crate) optimizer: &'a slam_optim::SharedOptimizer,
}

impl Refiner<'_> {
    /// An observation as the estimation uses it: a stereo observation of a point beyond
    /// `far_baselines` baselines (disparity below [`VoConfig::far_disparity_px`](super::config::VoConfig::far_disparity_px)) without its
    /// right-image column ([`left_only_beyond`]).
    pub(crate) fn usable(&self, o: [f64; 3]) -> [f64; 3] {
        left_only_beyond(o, self.config.far_disparity_px(self.rig.k.fx))
    }

    /// The current frame's observation of keypoint `c` as the estimation uses it: stereo
    /// `[u_l, v, u_r]` where it has a stereo point that is not far ([`Refiner::usable`]), else
    /// `[u, v, NaN]`.
    pub(crate) fn observation(&self, frame: &Frame, c: usize) -> [f64; 3] {
        match frame.of_keypoint.get(c).copied().flatten() {
            Some(q) => self.usable(frame.obs[q]),
            None => [frame.keypoints[c].0, frame.keypoints[c].1, f64::NAN],
        }
    }

    /// Adds the reprojection factor of observation `o` (stereo when `o[2]` is finite) of `point` from
    /// `pose`, with Huber (at the 95 % stereo χ² bound) when `robust`; its index in the graph.
    pub(crate) fn add_observation(
        &self,
        graph: &mut Graph,
        (pose, point): (Key, Key),
        o: [f64; 3],
        robust: bool,
    ) -> Option<usize> {
        let (k, b) = (self.rig.k, self.rig.baseline);
        let f: Box<dyn slam_optim::Factor> = if o[2].is_finite() {
            Box::new(StereoReprojection::new(pose, point, k, b, o))
        } else {
            Box::new(MonoReprojection::new(pose, point, k, [o[0], o[1]]))
        };
        let kernel: Box<dyn slam_optim::RobustKernel> =
            if robust { Box::new(Huber(CHI2_STEREO.sqrt())) } else { Box::new(slam_optim::L2) };
        graph
            .add_boxed(f, NoiseModel::Isotropic(1.0), kernel)
            .map_err(|e| tracing::warn!("pose refinement: observation left out: {e}"))
            .ok()
    }

    /// The last refinement round's problem from `pose` (`curr_from_ref`): the matched points free
    /// (eliminated) with all their keyframe observations (keyframes fixed, Huber) and the current
    /// observations of the `active` matches (least squares). Every match gets its point's key; its
    /// current factor is `usize::MAX` when set aside.
    pub(crate) fn round_problem(
        &self,
        map: &LocalMap,
        frame: &Frame,
        matches: &[(usize, usize)],
        (active, pose): (&[bool], &Isometry3<f64>),
    ) -> RoundProblem {
        let mut values = Values::new();
        let mut graph = Graph::new();
        let pose_key = values.add(Var::Pose(pose.inverse()));
        let mut slots: HashMap<usize, Key> = HashMap::new();
        let mut per_match = Vec::with_capacity(matches.len());
        for (m, &(i, c)) in matches.iter().enumerate() {
            let kx = values.add(Var::Point(map.points[i]));
            graph.eliminate(kx);
            for &(slot, o) in &map.views[i] {
                // an observation from a keyframe the point now lies behind (local mapping moved one of
                // the two since) is no measurement of it: left out, as local mapping will cull it
                if (map.poses[slot].inverse() * nalgebra::Point3::from(map.points[i])).z <= MIN_DEPTH_M {
                    continue;
                }
                let ks = *slots.entry(slot).or_insert_with(|| values.add(Var::Pose(map.poses[slot])));
                graph.fix(ks);
                self.add_observation(&mut graph, (ks, kx), self.usable(o), true);
            }
            let f = if active[m] {
                self.add_observation(&mut graph, (pose_key, kx), self.observation(frame, c), false)
            } else {
                None
            };
            per_match.push((kx, f.unwrap_or(usize::MAX)));
        }
        RoundProblem { graph, values, pose: pose_key, per_match }
    }

    /// χ² of every observation at `pose` with its point fixed, each within its bound or not, and the
    /// sum and count of squared left-image errors of those within.
    pub(crate) fn classify_fixed(
        rig: &pose_only::Rig,
        obs: &[pose_only::PoseObservation],
        pose: &Isometry3<f64>,
    ) -> (Vec<bool>, f64, usize) {
        let (mut active, mut sq_sum, mut sq_n) = (Vec::with_capacity(obs.len()), 0.0, 0usize);
        for o in obs {
            let bound = if o.observed[2].is_finite() { CHI2_STEREO } else { CHI2_MONO };
            let ok = rig.residual(pose, o).filter(|(r, _)| r.norm_squared() <= bound);
            if let Some((r, _)) = &ok {
                sq_sum += (r.x * o.sigma[0]).powi(2) + (r.y * o.sigma[1]).powi(2);
                sq_n += 1;
            }
            active.push(ok.is_some());
        }
        (active, sq_sum, sq_n)
    }

    /// χ² of every match's current observation at the solved round's pose (the set-aside ones against
    /// their point as the round left it), and with `rms`, the sum and count of squared left-image
    /// errors of the matches within the bound.
    pub(crate) fn classify(
        &self,
        frame: &Frame,
        matches: &[(usize, usize)],
        p: &RoundProblem,
        pose: &Isometry3<f64>,
    ) -> (Vec<bool>, f64, usize) {
        let k = self.rig.k;
        let mut probe_values = Values::new();
        let probe_pose = probe_values.add(Var::Pose(pose.inverse()));
        let (mut active, mut sq_sum, mut sq_n) = (Vec::with_capacity(matches.len()), 0.0, 0usize);
        for (&(_, c), &(kx, f)) in matches.iter().zip(&p.per_match) {
            let o = self.observation(frame, c);
            let chi2 = if f != usize::MAX {
                p.graph.whitened_residual(f, &p.values).and_then(|r| r.ok()).map(|r| r.norm_squared())
            } else {
                let probe_point = probe_values.add(Var::Point(p.values.point(kx).copied().unwrap_or_default()));
                let mut g = Graph::new();
                self.add_observation(&mut g, (probe_pose, probe_point), o, false)
                    .and_then(|fi| g.whitened_residual(fi, &probe_values))
                    .and_then(|r| r.ok())
                    .map(|r| r.norm_squared())
            };
            let bound = if o[2].is_finite() { CHI2_STEREO } else { CHI2_MONO };
            let ok = chi2.is_some_and(|c| c <= bound);
            active.push(ok);
            if ok && f != usize::MAX {
                // left-image error at the pose, the point where the round put it
                if let Some(x) = p.values.point(kx) {
                    let q = pose * nalgebra::Point3::from(*x);
                    let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
                    sq_sum += (u - o[0]).powi(2) + (v - o[1]).powi(2);
                    sq_n += 1;
                }
            }
        }
        (active, sq_sum, sq_n)
    }

    /// Refine `curr_from_ref` on the matches, the current frame's observations stereo where it has a
    /// stereo point. Four rounds: after each, the current observations above the χ² bound (95 %: 7.815
    /// stereo, 5.991 left only, σ = 1 px) are set aside for the next round and the set-aside ones are
    /// checked again; Huber in the first two rounds, plain least squares after. The first three rounds
    /// move the pose alone, the points held where their keyframes put them ([`pose_only::solve`]); the
    /// fourth frees the matched points with all their keyframe observations (keyframes fixed). Round 1
    /// is skipped when round 0 kept every match (it would solve the same problem again). The RMS error
    /// is that of the last round's inliers.
    pub(crate) fn refine(
        &self,
        map: &LocalMap,
        frame: &Frame,
        matches: &[(usize, usize)],
        guess: &Isometry3<f64>,
        last_measured: &Isometry3<f64>,
    ) -> Option<Refined> {
        let enough = self.config.weak_inliers.max(6);
        let mut pose = *guess;
        let mut active = vec![true; matches.len()];
        let mut rms = f64::NAN;
        let mut changed = true;
        let rig = pose_only::Rig { k: self.rig.k, baseline: self.rig.baseline };
        let prior = self.motion_prior(guess, last_measured);
        let fixed: Vec<pose_only::PoseObservation> = matches
            .iter()
            .map(|&(i, c)| {
                let observed = self.observation(frame, c);
                pose_only::PoseObservation { point: map.points[i], observed, sigma: [1.0; 3] }
            })
            .collect();
        for round in 0..4 {
            if active.iter().filter(|a| **a).count() < enough {
                return None;
            }
            if round == 1 && !changed {
                continue; // round 0's problem again (Huber, pose only, the same inliers)
            }
            let (now, sq_sum, sq_n) = if round < 3 {
                let used: Vec<pose_only::PoseObservation> =
                    fixed.iter().zip(&active).filter(|(_, a)| **a).map(|(o, _)| *o).collect();
                let huber = (round < 2).then(|| CHI2_STEREO.sqrt());
                pose = pose_only::solve(&rig, &used, &pose, huber, prior.as_ref(), 10)?;
                Self::classify_fixed(&rig, &fixed, &pose)
            } else {
                let mut p = self.round_problem(map, frame, matches, (&active, &pose));
                if let Some(m) = &prior {
                    let mut w = DMatrix::zeros(6, 6);
                    w.row_mut(0).copy_from_slice((m.row / m.sigma).as_slice());
                    p.graph.add(PosePrior::new(p.pose, m.base), NoiseModel::SqrtInformation(w), L2).ok()?;
                }
                if let Err(e) =
                    self.optimizer.optimize(&p.graph, &mut p.values, &Options::with_max_iterations(10), None)
                {
                    tracing::debug!("pose refinement, joint round: {e}");
                    return None;
                }
                pose = p.values.pose(p.pose)?.inverse();
                self.classify(frame, matches, &p, &pose)
            };
            changed = now != active;
            active = now;
            rms = (sq_sum / sq_n.max(1) as f64).sqrt();
        }
        let inliers: Vec<(usize, usize)> = matches.iter().zip(&active).filter(|(_, a)| **a).map(|(m, _)| *m).collect();
        if inliers.len() < enough {
            return None;
        }
        Some(Refined { pose, inliers, rms })
    }

    /// The vehicle-motion prior on the step from the last measured frame (`last_measured`, its pose in
    /// the reference keyframe), its σ set at the step to `guess` (`curr_from_ref`); `None` when
    /// `vehicle_slip_rad` is 0.
    pub(crate) fn motion_prior(
        &self,
        guess: &Isometry3<f64>,
        last_measured: &Isometry3<f64>,
    ) -> Option<pose_only::MotionPrior> {
        let c = &self.config;
        if c.vehicle_slip_rad <= 0.0 {
            return None;
        }
        let model = pose_only::VehicleModel {
            lever: c.vehicle_lever_m,
            height: c.vehicle_height_m,
            slip: c.vehicle_slip_rad,
            floor: VEHICLE_SWAY_M,
        };
        let step = last_measured.inverse() * guess.inverse();
        Some(pose_only::MotionPrior::new(*last_measured, &step, &model))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stereo observation below the far disparity loses its right-image column; a nearer one, a
    /// left-only one, and every observation when nothing is far (disparity 0) stay as they are.
    #[test]
    fn far_observations_become_left_only() {
        let near = [600.0, 180.0, 570.0]; // disparity 30 px
        let far = [600.0, 180.0, 590.0]; // 10 px
        assert_eq!(left_only_beyond(near, 17.7), near);
        let l = left_only_beyond(far, 17.7);
        assert_eq!((l[0], l[1]), (600.0, 180.0));
        assert!(l[2].is_nan());
        let mono = [1.0, 2.0, f64::NAN];
        assert!(left_only_beyond(mono, 17.7)[2].is_nan());
        assert_eq!(left_only_beyond(far, 0.0), far, "infinitely many baselines: every disparity used");
    }
}
