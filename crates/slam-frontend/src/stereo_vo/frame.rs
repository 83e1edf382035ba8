//! The stereo frame: stereo matching of the two images' ORB features along rectified rows (mutual best,
//! sub-pixel by block matching), and the frame the tracker works on (its keypoints, their stereo
//! points and observations; as a keyframe, its features in the map's form).

use nalgebra::Vector3;
use slam_core::FramePoint;
use slam_map::{hamming, BestTwo, Keypoint, KeypointGrid};

use super::config::{StereoRig, VoConfig};
use super::features::Features;
use super::grey::GreyView;

/// A stereo frame: its left keypoints and the stereo points matched among them.
#[derive(Clone)]
pub(crate) struct Frame {
    pub(crate) points: Vec<Vector3<f64>>,
    pub(crate) desc: Vec<[u8; 32]>,
    /// Stereo observation `[u_l, v, u_r]` of each point.
    pub(crate) obs: Vec<[f64; 3]>,
    /// For each left keypoint, its stereo point (if any).
    pub(crate) of_keypoint: Vec<Option<usize>>,
    /// All left keypoints and their descriptors.
    pub(crate) keypoints: Vec<(f64, f64)>,
    pub(crate) keypoint_desc: Vec<[u8; 32]>,
    /// Pyramid level and orientation (degrees) of each left keypoint.
    pub(crate) octave: Vec<i32>,
    pub(crate) angle: Vec<f32>,
    /// The left keypoints in cells (projection searches).
    pub(crate) grid: KeypointGrid,
}

impl Frame {
    /// The stereo points as the pipeline sees them.
    pub(crate) fn stereo_points(&self) -> Vec<FramePoint> {
        self.points.iter().zip(&self.obs).map(|(p, o)| FramePoint { camera_point: *p, observation: *o }).collect()
    }

    /// The frame without the keypoints `keep` marks false, nor their stereo points (order kept).
    pub(crate) fn retain_keypoints(&self, keep: &[bool]) -> Frame {
        let mut new_point = vec![None; self.points.len()];
        let (mut points, mut desc, mut obs) = (vec![], vec![], vec![]);
        for (q, &kp) in self.point_keypoints().iter().enumerate() {
            if keep.get(kp).copied().unwrap_or(false) {
                new_point[q] = Some(points.len());
                points.push(self.points[q]);
                desc.push(self.desc[q]);
                obs.push(self.obs[q]);
            }
        }
        let kept: Vec<usize> = (0..self.keypoints.len()).filter(|&i| keep.get(i).copied().unwrap_or(false)).collect();
        let keypoints: Vec<(f64, f64)> = kept.iter().map(|&i| self.keypoints[i]).collect();
        Frame {
            points,
            desc,
            obs,
            of_keypoint: kept.iter().map(|&i| self.of_keypoint[i].and_then(|q| new_point[q])).collect(),
            keypoint_desc: kept.iter().map(|&i| self.keypoint_desc[i]).collect(),
            octave: kept.iter().map(|&i| self.octave[i]).collect(),
            angle: kept.iter().map(|&i| self.angle[i]).collect(),
            grid: KeypointGrid::new(&keypoints),
            keypoints,
        }
    }

    /// The frame's keypoints in the map's form, for an image of `size` (width, height): each with its
    /// stereo match's right column where it has one.
    pub(crate) fn map_features(&self, size: (f64, f64)) -> slam_map::Features {
        let keypoints: Vec<Keypoint> = self
            .keypoints
            .iter()
            .enumerate()
            .map(|(i, &(u, v))| Keypoint {
                u,
                v,
                u_right: self.of_keypoint[i].map_or(f64::NAN, |q| self.obs[q][2]),
                level: self.octave[i].clamp(0, u8::MAX as i32) as u8,
                angle: self.angle[i],
            })
            .collect();
        slam_map::Features::new(keypoints, self.keypoint_desc.clone(), size).unwrap_or_default()
    }

    /// The keypoint of each point.
    pub(crate) fn point_keypoints(&self) -> Vec<usize> {
        let mut of = vec![usize::MAX; self.points.len()];
        for (kp, q) in self.of_keypoint.iter().enumerate() {
            if let Some(q) = q {
                of[*q] = kp;
            }
        }
        of
    }
}

/// Sub-pixel disparity by block matching along the row: SAD of an 11×11 patch at integer shifts
/// around the descriptor match, then a parabola through the best cost and its neighbours (as ORB-SLAM
/// does); `None` at image borders or when the minimum is at the search edge.
fn refine_disparity(left: &GreyView<'_>, right: &GreyView<'_>, ul: f64, v: f64, ur: f64) -> Option<f64> {
    const W: i64 = 5;
    const L: i64 = 3;
    let (xl, y, xr0) = (ul.round() as i64, v.round() as i64, ur.round() as i64);
    let mut costs = [0i64; (2 * L + 1) as usize];
    for (k, cost) in costs.iter_mut().enumerate() {
        let xr = xr0 + k as i64 - L;
        let mut sad = 0i64;
        for dy in -W..=W {
            for dx in -W..=W {
                let a = left.at(xl + dx, y + dy)?;
                let b = right.at(xr + dx, y + dy)?;
                sad += (a - b).abs() as i64;
            }
        }
        *cost = sad;
    }
    let (best, _) = costs.iter().enumerate().min_by_key(|(_, c)| **c)?;
    if best == 0 || best == costs.len() - 1 {
        return None;
    }
    let (c0, c1, c2) = (costs[best - 1] as f64, costs[best] as f64, costs[best + 1] as f64);
    let denom = c0 - 2.0 * c1 + c2;
    let delta = if denom > 0.0 { 0.5 * (c0 - c2) / denom } else { 0.0 };
    if delta.abs() > 1.0 {
        return None;
    }
    let xr = (xr0 + best as i64 - L) as f64 + delta;
    let d = xl as f64 - xr;
    (d > 0.0).then_some(d)
}

/// A left keypoint with a stereo match, as the tracker measures it (see [`super::stereo_keypoints`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoKeypoint {
    /// Column and row of the left keypoint, pixels (level-0 coordinates).
    pub u: f64,
    /// Row.
    pub v: f64,
    /// Disparity, pixels: `u − u_right` after the sub-pixel refinement and the rig's
    /// `disparity_offset`.
    pub disparity: f64,
    /// ORB pyramid level the keypoint was detected at (0: full resolution; level `l` is scaled by
    /// `1.2^-l`).
    pub level: i32,
    /// The keypoint's 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
}

impl Frame {
    /// The frame's stereo keypoints (left keypoints with a stereo point).
    pub(crate) fn stereo_keypoints(&self) -> Vec<StereoKeypoint> {
        self.of_keypoint
            .iter()
            .enumerate()
            .filter_map(|(i, q)| {
                let o = self.obs[(*q)?];
                Some(StereoKeypoint {
                    u: self.keypoints[i].0,
                    v: self.keypoints[i].1,
                    disparity: o[0] - o[2],
                    level: self.octave[i],
                    descriptor: self.keypoint_desc[i],
                })
            })
            .collect()
    }
}

/// Stereo matching of a rectified rig: the settings of [`StereoMatcher::frame`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct StereoMatcher {
    pub(crate) rig: StereoRig,
    /// Row tolerance, pixels; largest Hamming distance; depth range kept, metres; disparity offset, pixels.
    pub(crate) row_tolerance: f64,
    pub(crate) stereo_hamming: u32,
    pub(crate) depth_range: (f64, f64),
    pub(crate) disparity_offset: f64,
}

impl StereoMatcher {
    /// The stereo matching `config` sets for `rig`.
    pub(crate) fn new(rig: StereoRig, config: &VoConfig) -> Self {
        Self {
            rig,
            row_tolerance: config.row_tolerance,
            stereo_hamming: config.stereo_hamming,
            depth_range: config.depth_range,
            disparity_offset: config.disparity_offset,
        }
    }

    /// Stereo points of the left keypoints: each left keypoint is matched along its row, kept when the
    /// right keypoint's best left match along the row is that keypoint too (left-right consistency),
    /// and its disparity is refined to sub-pixel by block matching.
    pub(crate) fn frame(&self, left: &Features, right: &Features, grey: (&GreyView<'_>, &GreyView<'_>)) -> Frame {
        let rows = right.points.iter().map(|p| p.1.max(0.0) as usize).max().unwrap_or(0) + 1;
        let mut by_row: Vec<Vec<usize>> = vec![Vec::new(); rows + 3];
        for (i, p) in right.points.iter().enumerate() {
            by_row[p.1.max(0.0) as usize].push(i);
        }
        let tol = self.row_tolerance;
        // best left keypoint of each right keypoint: (distance, left index)
        let mut right_best = vec![(u32::MAX, usize::MAX); right.points.len()];
        let mut winners = Vec::new();
        for (i, &(u, v)) in left.points.iter().enumerate() {
            let last = by_row.len() - 1;
            let (lo, hi) =
                ((((v - tol).floor().max(0.0)) as usize).min(last), ((v + tol).ceil().max(0.0) as usize).min(last));
            let mut two = BestTwo::new();
            for row in &by_row[lo..=hi] {
                for &j in row {
                    let (ur, vr) = right.points[j];
                    let d = u - ur;
                    if (vr - v).abs() > tol || d <= 0.0 || d > 300.0 {
                        continue;
                    }
                    let h = hamming(&left.desc[i], &right.desc[j]);
                    two.offer(h, j);
                    if h < right_best[j].0 {
                        right_best[j] = (h, i);
                    }
                }
            }
            if let Some(arg) = two.winner(self.stereo_hamming, true) {
                winners.push((i, arg));
            }
        }
        let mut points = Vec::new();
        let mut desc = Vec::new();
        let mut obs = Vec::new();
        let mut of_keypoint = vec![None; left.points.len()];
        for (i, arg) in winners {
            if right_best[arg].1 != i {
                continue;
            }
            let (u, v) = left.points[i];
            let disparity = refine_disparity(grey.0, grey.1, u, v, right.points[arg].0)
                .unwrap_or(u - right.points[arg].0)
                + self.disparity_offset;
            let p = self.rig.point(u, v, disparity);
            if p.z < self.depth_range.0 || p.z > self.depth_range.1 {
                continue;
            }
            of_keypoint[i] = Some(points.len());
            points.push(p);
            desc.push(left.desc[i]);
            obs.push([u, v, u - disparity]);
        }
        Frame {
            points,
            desc,
            obs,
            of_keypoint,
            keypoints: left.points.clone(),
            keypoint_desc: left.desc.clone(),
            octave: left.octave.clone(),
            angle: left.angle.clone(),
            grid: KeypointGrid::new(&left.points),
        }
    }
}

#[cfg(test)]
impl Frame {
    /// A frame of keypoints alone (no stereo points), level 0, orientation 0.
    pub(crate) fn of_keypoints(keypoints: Vec<(f64, f64)>, desc: Vec<[u8; 32]>) -> Frame {
        let n = keypoints.len();
        Frame {
            points: Vec::new(),
            desc: Vec::new(),
            obs: Vec::new(),
            of_keypoint: vec![None; n],
            octave: vec![0; n],
            angle: vec![0.0; n],
            grid: KeypointGrid::new(&keypoints),
            keypoints,
            keypoint_desc: desc,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dropping keypoints keeps every kept keypoint with its own stereo point, descriptor, level and
    /// angle (indices rebuilt), and drops the stereo points of the dropped ones.
    #[test]
    fn retaining_keypoints_keeps_each_with_its_own_stereo_point() {
        let n = 6;
        let keypoints: Vec<(f64, f64)> = (0..n).map(|i| (10.0 * i as f64, 5.0 * i as f64)).collect();
        let desc: Vec<[u8; 32]> = (0..n).map(|i| [i as u8; 32]).collect();
        let mut f = Frame::of_keypoints(keypoints.clone(), desc);
        f.octave = (0..n as i32).collect();
        f.angle = (0..n).map(|i| i as f32).collect();
        // keypoints 1, 2, 4 and 5 have stereo points (in that order), their depth 10 + keypoint index
        for i in [1usize, 2, 4, 5] {
            f.of_keypoint[i] = Some(f.points.len());
            f.points.push(Vector3::new(0.0, 0.0, 10.0 + i as f64));
            f.desc.push([i as u8; 32]);
            f.obs.push([keypoints[i].0, keypoints[i].1, keypoints[i].0 - 3.0]);
        }
        let keep = [true, false, true, true, false, true];
        let r = f.retain_keypoints(&keep);
        let kept: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
        assert_eq!(r.keypoints.len(), kept.len());
        assert_eq!(r.points.len(), 2, "the stereo points of keypoints 2 and 5");
        for (new, &old) in kept.iter().enumerate() {
            assert_eq!(r.keypoints[new], keypoints[old]);
            assert_eq!(r.keypoint_desc[new], [old as u8; 32]);
            assert_eq!((r.octave[new], r.angle[new]), (old as i32, old as f32));
            match r.of_keypoint[new] {
                Some(q) => {
                    assert_eq!(r.points[q].z, 10.0 + old as f64);
                    assert_eq!((r.desc[q], r.obs[q][0]), ([old as u8; 32], keypoints[old].0));
                }
                None => assert!(f.of_keypoint[old].is_none(), "keypoint {old} lost its stereo point"),
            }
        }
        assert_eq!(r.point_keypoints(), vec![1, 3], "each point knows its keypoint");
    }
}
