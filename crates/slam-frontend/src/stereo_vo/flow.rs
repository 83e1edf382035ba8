//! Optical flow of the last two frames' keypoints inside detection boxes: the association's flow cue
//! and the scene flow of stereo points that tells moving objects apart.

use opencv::{core, prelude::*};
use slam_core::{geometry::BBox, PointPair};

use crate::image_io::FrontendError;

/// The grey left images and keypoints of the previous and the current frame, and the current frame's
/// right image (dense stereo in boxes).
#[derive(Default)]
pub(crate) struct FlowHistory {
    grey: [Option<Mat>; 2],
    right: Option<Mat>,
    keypoints: [Vec<(f64, f64)>; 2],
    /// The stereo keypoints of the last two frames, those on moving regions included (the scene flow's).
    flow_keypoints: [Vec<(f64, f64)>; 2],
}

impl FlowHistory {
    /// A new frame: its grey left image, its keypoints (those tracking uses) and its stereo keypoints
    /// (those on moving regions too).
    pub(crate) fn push(
        &mut self,
        (grey, right): (Mat, Mat),
        keypoints: Vec<(f64, f64)>,
        flow_keypoints: Vec<(f64, f64)>,
    ) {
        self.grey.swap(0, 1);
        self.grey[1] = Some(grey);
        self.right = Some(right);
        self.keypoints.swap(0, 1);
        self.keypoints[1] = keypoints;
        self.flow_keypoints.swap(0, 1);
        self.flow_keypoints[1] = flow_keypoints;
    }

    /// The current frame's grey pair (left, right), once a frame was pushed.
    pub(crate) fn current_pair(&self) -> Option<(&Mat, &Mat)> {
        Some((self.grey[1].as_ref()?, self.right.as_ref()?))
    }

    /// More start points of the scene flow in the current frame (pixels with a stereo point: an
    /// object's dense points), followed into the next frame with its stereo keypoints.
    pub(crate) fn add_flow_keypoints(&mut self, points: impl IntoIterator<Item = (f64, f64)>) {
        self.flow_keypoints[1].extend(points);
    }

    /// Forward-backward Lucas-Kanade flow of the previous frame's keypoints inside `regions` into the
    /// current frame (with `stereo_only`, the keypoints with a stereo point, those the frame's moving
    /// regions kept out of tracking included), up to `per_region` per region evenly spaced;
    /// pairs whose round trip misses by more than a pixel are dropped.
    pub(crate) fn optical_flow(
        &self,
        regions: &[BBox],
        stereo_only: bool,
        per_region: usize,
    ) -> Result<Vec<PointPair>, FrontendError> {
        let [Some(prev), Some(curr)] = &self.grey else {
            return Ok(Vec::new());
        };
        // the stereo points' flow starts from every stereo keypoint of the frame before, those on
        // moving regions too (the scene flow measures the objects the tracking leaves out)
        let kp = if stereo_only { &self.flow_keypoints[0] } else { &self.keypoints[0] };
        let mut pts = core::Vector::<core::Point2f>::new();
        for b in regions {
            let inside: Vec<usize> = (0..kp.len()).filter(|&i| b.contains_point(kp[i].0, kp[i].1)).collect();
            let step = inside.len().div_ceil(per_region.max(1)).max(1);
            for &i in inside.iter().step_by(step) {
                pts.push(core::Point2f::new(kp[i].0 as f32, kp[i].1 as f32));
            }
        }
        if pts.is_empty() {
            return Ok(Vec::new());
        }
        let lk = |a: &Mat, b: &Mat, from: &core::Vector<core::Point2f>| -> Result<_, FrontendError> {
            let mut to = core::Vector::<core::Point2f>::new();
            let mut status = core::Vector::<u8>::new();
            let mut err = core::Vector::<f32>::new();
            opencv::video::calc_optical_flow_pyr_lk(
                a,
                b,
                from,
                &mut to,
                &mut status,
                &mut err,
                core::Size::new(15, 15),
                2,
                core::TermCriteria::new(core::TermCriteria_COUNT + core::TermCriteria_EPS, 30, 0.01)?,
                0,
                1e-4,
            )?;
            Ok((to, status))
        };
        let (fwd, s1) = lk(prev, curr, &pts)?;
        let (back, s2) = lk(curr, prev, &fwd)?;
        let mut out = Vec::new();
        for i in 0..pts.len() {
            let (p, q, r) = (pts.get(i)?, fwd.get(i)?, back.get(i)?);
            if s1.get(i)? == 1 && s2.get(i)? == 1 && ((p.x - r.x).powi(2) + (p.y - r.y).powi(2)) < 1.0 {
                out.push(PointPair { reference: [p.x as f64, p.y as f64], current: [q.x as f64, q.y as f64] });
            }
        }
        Ok(out)
    }
}
