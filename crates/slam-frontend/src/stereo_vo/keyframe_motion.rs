//! Whether a frame sees the scene from somewhere new: the image motion of its tracked map points since
//! the keyframe saw them. A keyframe must bring new information; a frame standing where its keyframe
//! stands (a car waiting at a light, the same stereo pair recorded again) brings none, however many
//! frames have passed, so the keyframe policy's frame-count and weak-frame rules ask for motion first
//! (`stereo_vo`'s keyframe decision).

/// Median image motion, pixels, below which a frame stands where its keyframe stands. ORB finds its
/// keypoints on whole pixels of a pyramid level, so a point that did not move is found again within
/// about a pixel; a median motion below one pixel cannot be told from that jitter. Any real motion
/// moves the image by far more over a few frames: 0.1 m sideways moves a point 20 m away by 3.5 px
/// at KITTI's focal length (707 px).
pub(crate) const STILL_PX: f64 = 1.0;

/// The median distance, pixels, between where each tracked point was seen in the keyframe and where
/// it is seen now (`(keyframe, frame)` pairs of image positions); `None` without pairs.
pub(crate) fn median_motion(pairs: impl IntoIterator<Item = ((f64, f64), (f64, f64))>) -> Option<f64> {
    let mut d: Vec<f64> = pairs.into_iter().map(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1)).collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// Whether a frame has moved from its keyframe ([`STILL_PX`]); a frame with no tracked point of the
/// keyframe cannot be shown to stand still and counts as moved.
pub(crate) fn moved(pairs: impl IntoIterator<Item = ((f64, f64), (f64, f64))>) -> bool {
    median_motion(pairs).is_none_or(|m| m >= STILL_PX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_moved_when_its_points_moved_by_a_pixel_or_more() {
        let grid: Vec<(f64, f64)> = (0..50).map(|i| (10.0 * i as f64, 5.0 + (i % 7) as f64)).collect();
        let shifted = |dx: f64| grid.iter().map(move |&(u, v)| ((u, v), (u + dx, v)));
        assert_eq!(median_motion(shifted(0.0)), Some(0.0));
        assert!(!moved(shifted(0.0)), "the same image again");
        assert!(!moved(shifted(0.6)), "jitter below a pixel");
        assert!(moved(shifted(1.5)));
        // a few points that moved (a passing car) do not make a standing camera move: the median
        let mostly_still =
            grid.iter().enumerate().map(|(i, &(u, v))| ((u, v), (u + if i < 20 { 30.0 } else { 0.2 }, v)));
        assert!(!moved(mostly_still));
        assert!(moved(std::iter::empty()), "nothing tracked: not shown to stand still");
        assert_eq!(median_motion([((0.0, 0.0), (3.0, 4.0))]), Some(5.0));
    }
}
