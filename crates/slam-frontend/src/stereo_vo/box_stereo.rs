//! Dense stereo inside detection boxes: an object's own stereo points.
//!
//! Tracking's ORB features are spread over the image (one or a few per grid cell, for a well-posed
//! pose), so a car 40 m away, a box of 70 × 50 pixels, holds a handful of them and its central part
//! two or three: too few to say where the car is in a frame (the object mapper needs five). Semi-global
//! block matching (OpenCV's `StereoSGBM`, Hirschmüller 2008) inside the box gives a disparity at most
//! of its textured pixels; the search covers only the disparities the object's possible depths allow
//! (from the class's heights and the box's height), so a box costs a few hundred thousand cost
//! evaluations. The matcher's own checks keep a disparity only when it is unique (the best cost beats
//! the second by `UNIQUENESS_PERCENT`), left-right consistent (within a pixel) and part of a smooth
//! patch (speckle filter); a disparity is refined to 1/16 px by the matcher's sub-pixel fit.

use opencv::{
    calib3d::{StereoSGBM, StereoSGBM_MODE_SGBM_3WAY},
    core::{self, Mat, Rect},
    prelude::*,
};
use slam_core::{BoxQuery, FramePoint};

use super::config::StereoRig;
use crate::image_io::FrontendError;

/// Block size of the matcher, pixels: 5 × 5, the smallest window whose sum of absolute differences is
/// still robust to the grey-level noise of an 8-bit camera; larger windows blur a car's edges.
const BLOCK: i32 = 5;
/// Smoothness penalties of SGBM (OpenCV's recommended `8·n·B²` and `32·n·B²` for `n = 1` channel and
/// block size `B`): a disparity change of one pixel costs `P1`, a larger jump `P2`.
const P1: i32 = 8 * BLOCK * BLOCK;
const P2: i32 = 32 * BLOCK * BLOCK;
/// The best match must beat the second best by this many percent (OpenCV suggests 5-15).
const UNIQUENESS_PERCENT: i32 = 10;
/// Left-right check: the right image's match of a pixel must come back within a pixel.
const LR_MAX_DIFF: i32 = 1;
/// Speckle filter: patches of fewer than this many pixels whose disparities differ from their
/// surroundings by more than `SPECKLE_RANGE` pixels are dropped (small patches are mismatches on
/// texture-less paint or glass; OpenCV suggests 50-200).
const SPECKLE_WINDOW: i32 = 50;
const SPECKLE_RANGE: i32 = 2;
/// Smallest box side matched, pixels: a box narrower than a few blocks holds no surface to measure.
const MIN_SIDE: i32 = 3 * BLOCK;
/// Most points kept per box: the box is sampled on a grid coarse enough for this many (a 70 × 50 box
/// keeps every other pixel; a near car's 400 × 200 box every 11th), enough for a depth cluster, a
/// median and faces, and a bounded cost downstream.
pub(crate) const MAX_POINTS: usize = 800;
/// Most pixels a box is matched at: a larger box is matched at a coarser scale (see [`box_points`]);
/// four times `MAX_POINTS`, a distant car's box at full resolution.
const MATCHED_PIXELS: usize = 4 * MAX_POINTS;
/// Largest disparity searched, pixels (a depth of `fb / 256`, 1.5 m on KITTI: nearer than any box the
/// detector gives of a whole object).
const MAX_DISPARITY: f64 = 256.0;

/// The dense stereo points of each query's box in a rectified grey pair (see the module).
pub(crate) fn box_points(
    left: &Mat,
    right: &Mat,
    rig: &StereoRig,
    disparity_offset: f64,
    queries: &[BoxQuery],
) -> Result<Vec<Vec<FramePoint>>, FrontendError> {
    queries.iter().map(|q| one_box(left, right, rig, disparity_offset, q)).collect()
}

fn one_box(
    left: &Mat,
    right: &Mat,
    rig: &StereoRig,
    offset: f64,
    q: &BoxQuery,
) -> Result<Vec<FramePoint>, FrontendError> {
    let (w, h) = (left.cols(), left.rows());
    let b = &q.bbox;
    if ![b.xmin, b.ymin, b.xmax, b.ymax, q.depth.0, q.depth.1].iter().all(|v| v.is_finite()) {
        return Ok(Vec::new());
    }
    let (x0, y0) = (b.xmin.floor().max(0.0) as i32, b.ymin.floor().max(0.0) as i32);
    let (x1, y1) = ((b.xmax.ceil() as i32).min(w), (b.ymax.ceil() as i32).min(h));
    if x1 - x0 < MIN_SIDE || y1 - y0 < MIN_SIDE {
        return Ok(Vec::new());
    }
    let fb = rig.focal_baseline();
    // the disparities the object's depths allow (the measured disparity is the true one less the
    // rig's offset), a pixel of margin each side
    let (near, far) = q.depth;
    let d_max = if near > 0.0 { fb / near } else { MAX_DISPARITY }.min(MAX_DISPARITY) - offset + 1.0;
    let d_min = (if far > 0.0 { fb / far } else { 0.0 } - offset - 1.0).max(0.0);
    if d_max <= d_min {
        return Ok(Vec::new());
    }
    let d_min = d_min.floor() as i32;
    // a large (near) box is matched at a coarser scale `s` (a power of two), at which it holds at most
    // `MATCHED_PIXELS`: it keeps `MAX_POINTS` samples either way, its disparities are large, and the
    // cost (pixels × disparities) stays that of a distant car's box
    let rows = y1 - y0;
    let area = ((x1 - x0) * rows) as f64;
    let s = (area / MATCHED_PIXELS as f64).sqrt().log2().ceil().clamp(0.0, 3.0).exp2() as i32;
    // SGBM searches `num` disparities (at scale s) from 0 in the shifted pair below: a multiple of 16
    let span = (d_max.ceil() as i32 - d_min + 1 + s - 1) / s;
    let num = ((span + 15) / 16 * 16).max(16);
    // the left crop starts `num` (scaled) columns before the box (SGBM leaves its first `num` columns
    // without a disparity); the right crop is the left one shifted by `d_min`, so that a disparity d'
    // found there is `d_min + s·d'` in the images
    let xs = (x0 - num * s).max(d_min).max(0);
    // columns with a disparity: from `xs + num·s` (a box at the left border, where the crop cannot
    // start that early, keeps fewer); too few and there is nothing to match (OpenCV 4.6's SGBM also
    // fails an assertion on a crop without any such column)
    if x1 - (xs + num * s) < MIN_SIDE {
        return Ok(Vec::new());
    }
    let crop = |m: &Mat, x: i32| -> Result<Mat, FrontendError> {
        let roi = Mat::roi(m, Rect::new(x, y0, x1 - xs, rows))?;
        let mut out = Mat::default();
        if s > 1 {
            let size = core::Size::new((x1 - xs) / s, rows / s);
            opencv::imgproc::resize(&roi, &mut out, size, 0.0, 0.0, opencv::imgproc::INTER_AREA)?;
        } else {
            out = roi.try_clone()?;
        }
        Ok(out)
    };
    let (l, r) = (crop(left, xs)?, crop(right, xs - d_min)?);
    let mut sgbm = StereoSGBM::create(
        0,
        num,
        BLOCK,
        P1,
        P2,
        LR_MAX_DIFF,
        63,
        UNIQUENESS_PERCENT,
        SPECKLE_WINDOW,
        SPECKLE_RANGE,
        StereoSGBM_MODE_SGBM_3WAY,
    )?;
    let mut disparity = Mat::default();
    sgbm.compute(&l, &r, &mut disparity)?;
    let (cols_s, rows_s) = (disparity.cols(), disparity.rows());
    let step = (((cols_s * rows_s) as f64 / MAX_POINTS as f64).sqrt().ceil() as i32).max(1);
    let k = &rig.k;
    let mut out = Vec::new();
    for cy in (0..rows_s).step_by(step as usize) {
        for cx in (num..cols_s).step_by(step as usize) {
            let raw = *disparity.at_2d::<i16>(cy, cx)?;
            if raw < 0 {
                continue;
            }
            // the scaled pixel's centre in the image
            let (u, v) =
                (xs as f64 + (cx as f64 + 0.5) * s as f64 - 0.5, y0 as f64 + (cy as f64 + 0.5) * s as f64 - 0.5);
            if u < x0 as f64 || u >= x1 as f64 {
                continue;
            }
            let measured = d_min as f64 + s as f64 * raw as f64 / 16.0;
            let d = measured + offset;
            if d <= 0.0 {
                continue;
            }
            let z = fb / d;
            if (near > 0.0 && z < near) || (far > 0.0 && z > far) {
                continue;
            }
            out.push(FramePoint {
                camera_point: nalgebra::Vector3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z),
                observation: [u, v, u - measured],
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_quadric::{BBox, Intrinsics};

    /// A rectified pair of a textured plane at depth `z` (a fronto-parallel board) over a farther
    /// textured background at `z_back`: the right image is the left shifted by each surface's disparity.
    fn pair(z: f64, z_back: f64, rig: &StereoRig, board: (i32, i32, i32, i32)) -> (Mat, Mat) {
        let (w, h) = (400, 200);
        let fb = rig.focal_baseline();
        let (d_board, d_back) = (fb / z, fb / z_back);
        // a deterministic texture of blobs: value from a hash of the (surface) coordinate
        let tex = |x: f64, y: f64, seed: u32| -> u8 {
            let (xi, yi) = ((x / 3.0).floor() as i64, (y / 3.0).floor() as i64);
            let mut v = (xi.wrapping_mul(73856093) ^ yi.wrapping_mul(19349663) ^ seed as i64) as u64;
            v ^= v >> 13;
            v = v.wrapping_mul(0x5bd1e995);
            (v >> 24) as u8
        };
        let mut left =
            Mat::new_rows_cols_with_default(h, w, opencv::core::CV_8UC1, opencv::core::Scalar::all(0.0)).unwrap();
        let mut right = left.clone();
        let inside = |x: i32, y: i32| x >= board.0 && x < board.2 && y >= board.1 && y < board.3;
        for y in 0..h {
            for x in 0..w {
                // left pixel: the board where it covers the pixel, else the background
                let lv = if inside(x, y) { tex(x as f64, y as f64, 1) } else { tex(x as f64, y as f64, 2) };
                *left.at_2d_mut::<u8>(y, x).unwrap() = lv;
                // right pixel x_r sees the board at left column x_r + d_board when that lies on it
                let xb = x as f64 + d_board;
                let rv = if inside(xb.round() as i32, y) {
                    tex(xb, y as f64, 1)
                } else {
                    tex(x as f64 + d_back, y as f64, 2)
                };
                *right.at_2d_mut::<u8>(y, x).unwrap() = rv;
            }
        }
        (left, right)
    }

    #[test]
    fn a_board_in_its_box_is_found_at_its_depth() {
        let rig = StereoRig { k: Intrinsics::new(700.0, 700.0, 200.0, 100.0), baseline: 0.54 };
        // board at 15 m (disparity 25.2 px) over a background at 60 m (6.3 px)
        let board = (180, 60, 300, 150);
        let (left, right) = pair(15.0, 60.0, &rig, board);
        let bbox = BBox::new(board.0 as f64, board.1 as f64, board.2 as f64, board.3 as f64);
        let q = BoxQuery { bbox, depth: (5.0, 40.0) };
        let pts = box_points(&left, &right, &rig, 0.0, &[q]).expect("matches").remove(0);
        let found = pts.len();
        assert!(found > 200, "{found} points");
        let mut z: Vec<f64> = pts.iter().map(|p| p.camera_point.z).collect();
        z.sort_by(f64::total_cmp);
        let median = z[z.len() / 2];
        assert!((median - 15.0).abs() < 0.3, "median depth {median}");
        // most points on the board: within the depth noise of a pixel of disparity
        let near = z.iter().filter(|&&d| (d - 15.0).abs() < 15.0 * 15.0 / rig.focal_baseline()).count();
        assert!(near as f64 > 0.9 * z.len() as f64, "{near} of {}", z.len());
        for p in &pts {
            let [u, v, ur] = p.observation;
            assert!(bbox.contains_point(u, v) && ur < u, "{:?}", p.observation);
            assert!((5.0..=40.0).contains(&p.camera_point.z));
        }
        // the depth range limits the search: a query that excludes the board's depth reports only
        // depths inside it, and the uniqueness and consistency checks leave most of the board without one
        // (what remains are matches of the random texture to itself at another shift)
        let far_only = BoxQuery { bbox, depth: (30.0, 100.0) };
        let pts = box_points(&left, &right, &rig, 0.0, &[far_only]).expect("matches").remove(0);
        assert!(pts.iter().all(|p| (30.0..=100.0).contains(&p.camera_point.z)), "only far points");
        assert!(2 * pts.len() < found, "{} points found on a board outside the searched depths", pts.len());
        // a box too small, outside the image or not finite gives nothing, never an error
        let tiny = BoxQuery { bbox: BBox::new(10.0, 10.0, 15.0, 40.0), depth: (1.0, 80.0) };
        let outside = BoxQuery { bbox: BBox::new(500.0, 10.0, 600.0, 80.0), depth: (1.0, 80.0) };
        let nan = BoxQuery { bbox: BBox::new(f64::NAN, 10.0, 100.0, 80.0), depth: (1.0, 80.0) };
        let out = box_points(&left, &right, &rig, 0.0, &[tiny, outside, nan]).expect("no error");
        assert!(out.iter().all(Vec::is_empty));
    }
}
