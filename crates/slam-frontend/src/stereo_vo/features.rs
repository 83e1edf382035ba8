//! ORB features of one image, spread over it. OpenCV's ORB keeps, at each pyramid level, the keypoints
//! with the highest corner scores, wherever they are: on a street that is foliage, fences and a few
//! façades, while the road, the walls and the far field get few. A pose from such points is pulled by
//! whatever those few structures' stereo errors have in common. ORB-SLAM spreads its keypoints over a
//! grid for that reason (Mur-Artal et al., 2015); here the same idea in our own form, each level of the
//! pyramid on its own ([`detect_level`]):
//! 1. FAST corners (threshold 20) over the level; in each cell of [`DETECTION_CELL`] pixels that has none,
//!    FAST again at a lower threshold (7), so that low-contrast parts of the view (road, walls) still
//!    offer a corner;
//! 2. the level's share of the keypoints taken from a grid of cells of about one keypoint each, the best
//!    corner score of every cell first, then the second best, and so on ([`spread_per_level`]);
//! 3. the orientation (intensity centroid of the 31-pixel patch, [`orientation`]) and the descriptor
//!    (OpenCV's ORB on the given keypoints) of the kept keypoints only.

use opencv::{core, features2d, imgproc, prelude::*};

use crate::image_io::FrontendError;

/// Pyramid levels of the ORB extractor.
pub(crate) const LEVELS: usize = 8;
/// Scale between pyramid levels.
pub(crate) const SCALE: f64 = 1.2;
/// FAST threshold of a corner (grey levels): ORB's, and ORB-SLAM's first pass.
const FAST_THRESHOLD: i32 = 20;
/// FAST threshold in a cell where the first pass found no corner: low enough for the road's and a
/// wall's texture (a few grey levels of contrast under KITTI's sensor noise of about 2), high enough
/// that flat sky yields nothing.
const FAST_THRESHOLD_LOW: i32 = 7;
/// Side of the cells of the low-threshold pass, pixels of the level: about one keypoint's worth of
/// image at ORB's quota (2000 keypoints over a KITTI image give cells of 15–30 px at level 0).
pub(crate) const DETECTION_CELL: i32 = 30;
/// Margin a keypoint keeps from the level's border, pixels: the descriptor's rotated 31-pixel patch
/// (OpenCV's ORB drops keypoints nearer than its edge threshold, 31, on the full image).
const BORDER: i32 = 31;
/// Half the side of the patch a keypoint's orientation is measured over (ORB's 31-pixel patch).
const PATCH_RADIUS: i32 = 15;

/// Keypoints: positions, 256-bit ORB descriptors, pyramid levels, orientations (degrees).
pub(crate) struct Features {
    pub(crate) points: Vec<(f64, f64)>,
    pub(crate) desc: Vec<[u8; 32]>,
    pub(crate) octave: Vec<i32>,
    pub(crate) angle: Vec<f32>,
}

/// An ORB extractor: `features` keypoints per image, [`LEVELS`] levels [`SCALE`] apart, 31-pixel
/// patches; with `spread`, detected and spread over the image level by level (the module's doc),
/// without, OpenCV's ORB as it is (Harris score, FAST threshold 20).
pub(crate) struct Extractor {
    orb: core::Ptr<features2d::ORB>,
    features: usize,
    spread: bool,
}

impl Extractor {
    /// The extractor of `features` keypoints per image, spread over the image or not.
    pub(crate) fn new(features: i32, spread: bool) -> Result<Self, FrontendError> {
        let orb = features2d::ORB::create(
            features,
            SCALE as f32,
            LEVELS as i32,
            BORDER,
            0,
            2,
            features2d::ORB_ScoreType::HARRIS_SCORE,
            31,
            FAST_THRESHOLD,
        )?;
        Ok(Self { orb, features: features.max(0) as usize, spread })
    }

    /// The keypoints of a grey image and their descriptors.
    pub(crate) fn extract(&mut self, img: &Mat) -> Result<Features, FrontendError> {
        let mut kps = core::Vector::<core::KeyPoint>::new();
        let mut desc = Mat::default();
        if self.spread {
            let mut kept = self.detect(img)?;
            // descriptors of the kept keypoints only (ORB drops those too near the border)
            self.orb.compute(img, &mut kept, &mut desc)?;
            kps = kept;
        } else {
            self.orb.detect_and_compute(img, &core::no_array(), &mut kps, &mut desc, false)?;
        }
        let mut f = Features {
            points: Vec::with_capacity(kps.len()),
            desc: Vec::with_capacity(kps.len()),
            octave: Vec::with_capacity(kps.len()),
            angle: Vec::with_capacity(kps.len()),
        };
        for (i, kp) in kps.iter().enumerate() {
            let row = desc.at_row::<u8>(i as i32)?;
            if row.len() != 32 {
                continue;
            }
            let mut d = [0u8; 32];
            d.copy_from_slice(row);
            f.points.push((kp.pt().x as f64, kp.pt().y as f64));
            f.desc.push(d);
            f.octave.push(kp.octave());
            f.angle.push(kp.angle());
        }
        Ok(f)
    }

    /// The spread keypoints of every level, with their orientation, in level-0 pixels.
    fn detect(&self, img: &Mat) -> Result<core::Vector<core::KeyPoint>, FrontendError> {
        let quotas = level_quotas(self.features);
        let mut level_img = img.clone();
        let mut out = core::Vector::<core::KeyPoint>::new();
        for (level, &quota) in quotas.iter().enumerate() {
            if level > 0 {
                let scale = SCALE.powi(level as i32);
                let size = core::Size::new(
                    (img.cols() as f64 / scale).round() as i32,
                    (img.rows() as f64 / scale).round() as i32,
                );
                if size.width <= 2 * BORDER || size.height <= 2 * BORDER {
                    break;
                }
                let mut next = Mat::default();
                imgproc::resize(&level_img, &mut next, size, 0.0, 0.0, imgproc::INTER_LINEAR)?;
                level_img = next;
            }
            if quota == 0 {
                continue;
            }
            let candidates = detect_level(&level_img)?;
            let (w, h) = (level_img.cols() as f64, level_img.rows() as f64);
            let all: Vec<Candidate> =
                candidates.iter().map(|&(at, score)| Candidate { at, level: level as i32, score }).collect();
            let mut quota_here = [0usize; LEVELS];
            quota_here[level] = quota;
            let grey = super::grey::GreyView::of(&level_img)?;
            let scale = SCALE.powi(level as i32);
            for i in spread_per_level(&all, quota_here, (w, h)) {
                let (x, y) = all[i].at;
                let angle = orientation(&grey, x.round() as i64, y.round() as i64);
                out.push(core::KeyPoint::new_coords(
                    (x * scale) as f32,
                    (y * scale) as f32,
                    (31.0 * scale) as f32,
                    angle,
                    all[i].score,
                    level as i32,
                    -1,
                )?);
            }
        }
        Ok(out)
    }
}

/// A FAST corner: its position (level pixels) and score.
type Corner = ((f64, f64), f32);

/// The FAST corners of one pyramid level away from its border (level pixels, corner score): threshold
/// [`FAST_THRESHOLD`] over the level, then [`FAST_THRESHOLD_LOW`] in each [`DETECTION_CELL`] without a
/// corner.
fn detect_level(img: &Mat) -> Result<Vec<Corner>, FrontendError> {
    let (w, h) = (img.cols(), img.rows());
    let inner = core::Rect::new(BORDER - 3, BORDER - 3, w - 2 * (BORDER - 3), h - 2 * (BORDER - 3));
    let roi = Mat::roi(img, inner)?;
    let mut kps = core::Vector::<core::KeyPoint>::new();
    features2d::fast(&roi, &mut kps, FAST_THRESHOLD, true)?;
    let keep =
        |x: f64, y: f64| x >= BORDER as f64 && y >= BORDER as f64 && x < (w - BORDER) as f64 && y < (h - BORDER) as f64;
    let (ox, oy) = (inner.x as f64, inner.y as f64);
    let mut out: Vec<Corner> = kps
        .iter()
        .map(|k| ((k.pt().x as f64 + ox, k.pt().y as f64 + oy), k.response()))
        .filter(|((x, y), _)| keep(*x, *y))
        .collect();
    let cols = ((w - 2 * BORDER) / DETECTION_CELL).max(1);
    let rows = ((h - 2 * BORDER) / DETECTION_CELL).max(1);
    let mut occupied = vec![false; (cols * rows) as usize];
    let cell_of = |x: f64, y: f64| {
        let c = (((x as i32) - BORDER) / DETECTION_CELL).clamp(0, cols - 1);
        let r = (((y as i32) - BORDER) / DETECTION_CELL).clamp(0, rows - 1);
        (r * cols + c) as usize
    };
    for ((x, y), _) in &out {
        occupied[cell_of(*x, *y)] = true;
    }
    for r in 0..rows {
        for c in 0..cols {
            if occupied[(r * cols + c) as usize] {
                continue;
            }
            // the cell with the 3-pixel ring FAST reads around each candidate
            let x0 = BORDER + c * DETECTION_CELL - 3;
            let y0 = BORDER + r * DETECTION_CELL - 3;
            let x1 = if c == cols - 1 { w - BORDER + 3 } else { x0 + DETECTION_CELL + 6 };
            let y1 = if r == rows - 1 { h - BORDER + 3 } else { y0 + DETECTION_CELL + 6 };
            let cell = Mat::roi(img, core::Rect::new(x0, y0, x1 - x0, y1 - y0))?;
            let mut low = core::Vector::<core::KeyPoint>::new();
            features2d::fast(&cell, &mut low, FAST_THRESHOLD_LOW, true)?;
            out.extend(
                low.iter()
                    .map(|k| ((k.pt().x as f64 + x0 as f64, k.pt().y as f64 + y0 as f64), k.response()))
                    .filter(|((x, y), _)| keep(*x, *y) && cell_of(*x, *y) == (r * cols + c) as usize),
            );
        }
    }
    Ok(out)
}

/// Orientation of the keypoint at `(x, y)` (level pixels), degrees in `[0, 360)`: the direction from
/// the keypoint to the intensity centroid of the disc of radius [`PATCH_RADIUS`] around it (Rosin's
/// moments, as ORB measures it), so that the descriptor can be taken in a frame that turns with the
/// image.
pub(crate) fn orientation(grey: &super::grey::GreyView<'_>, x: i64, y: i64) -> f32 {
    let (mut m10, mut m01) = (0i64, 0i64);
    let r = PATCH_RADIUS as i64;
    let (width, height) = grey.size();
    let inside = x >= r && y >= r && x + r < width as i64 && y + r < height as i64;
    for dy in -r..=r {
        let half = DISC_HALF_WIDTH[(dy + r) as usize] as i64;
        if inside {
            // the whole row of the disc lies in the image: summed over the row's slice
            let start = (y + dy) as usize * width + (x - half) as usize;
            let row = &grey.data()[start..start + (2 * half + 1) as usize];
            let (mut sum, mut moment) = (0i64, 0i64);
            for (i, &v) in row.iter().enumerate() {
                sum += v as i64;
                moment += (i as i64 - half) * v as i64;
            }
            m10 += moment;
            m01 += dy * sum;
        } else {
            for dx in -half..=half {
                if let Some(v) = grey.at(x + dx, y + dy) {
                    m10 += dx * v as i64;
                    m01 += dy * v as i64;
                }
            }
        }
    }
    let a = (m01 as f64).atan2(m10 as f64).to_degrees();
    (if a < 0.0 { a + 360.0 } else { a }) as f32
}

/// Half the width of each row of the disc of radius [`PATCH_RADIUS`] (row `dy + radius`).
const DISC_HALF_WIDTH: [u8; (2 * PATCH_RADIUS + 1) as usize] = {
    let mut out = [0u8; (2 * PATCH_RADIUS + 1) as usize];
    let r = PATCH_RADIUS;
    let mut dy = -r;
    while dy <= r {
        // the largest dx with dx² + dy² ≤ r²
        let mut half = 0;
        while (half + 1) * (half + 1) + dy * dy <= r * r {
            half += 1;
        }
        out[(dy + r) as usize] = half as u8;
        dy += 1;
    }
    out
};

/// A detected keypoint: position (level-0 pixels), pyramid level, corner score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Candidate {
    pub(crate) at: (f64, f64),
    pub(crate) level: i32,
    pub(crate) score: f32,
}

/// How many of `features` keypoints each pyramid level gets: in proportion to the level's image area's
/// side (a geometric series of ratio 1/[`SCALE`], as OpenCV's ORB shares them), the last level taking
/// what remains.
pub(crate) fn level_quotas(features: usize) -> [usize; LEVELS] {
    let factor = 1.0 / SCALE;
    let mut desired = features as f64 * (1.0 - factor) / (1.0 - factor.powi(LEVELS as i32));
    let mut quotas = [0usize; LEVELS];
    let mut sum = 0;
    for q in quotas.iter_mut().take(LEVELS - 1) {
        *q = desired.round() as usize;
        sum += *q;
        desired *= factor;
    }
    quotas[LEVELS - 1] = features.saturating_sub(sum);
    quotas
}

/// Indices of the candidates kept: at each level, its quota taken from a grid over the `size` image
/// whose cells would hold one keypoint each (side √(area / quota)), every cell's best candidate
/// first (by score), then every cell's second best, and so on until the quota is reached.
pub(crate) fn spread_per_level(candidates: &[Candidate], quotas: [usize; LEVELS], (w, h): (f64, f64)) -> Vec<usize> {
    let mut kept = Vec::new();
    for (level, &quota) in quotas.iter().enumerate() {
        if quota == 0 {
            continue;
        }
        let side = (w * h / quota as f64).sqrt().max(1.0);
        let (cols, rows) = ((w / side).ceil().max(1.0) as usize, (h / side).ceil().max(1.0) as usize);
        let cell = |(x, y): (f64, f64)| {
            let (c, r) =
                ((x / side).floor().clamp(0.0, cols as f64 - 1.0), (y / side).floor().clamp(0.0, rows as f64 - 1.0));
            r as usize * cols + c as usize
        };
        let mut at_level: Vec<usize> = (0..candidates.len()).filter(|&i| candidates[i].level == level as i32).collect();
        // best first, ties by index, so the order is deterministic
        at_level.sort_by(|&a, &b| candidates[b].score.total_cmp(&candidates[a].score).then(a.cmp(&b)));
        let mut seen = vec![0usize; cols * rows];
        let mut ranked: Vec<(usize, usize)> = at_level
            .into_iter()
            .map(|i| {
                let c = cell(candidates[i].at);
                seen[c] += 1;
                (seen[c] - 1, i)
            })
            .collect();
        // rank within the cell first; within a rank the order of scores is kept (stable sort)
        ranked.sort_by_key(|&(rank, _)| rank);
        kept.extend(ranked.into_iter().take(quota).map(|(_, i)| i));
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotas_share_the_features_geometrically_and_add_up() {
        let q = level_quotas(2000);
        assert_eq!(q.iter().sum::<usize>(), 2000);
        assert_eq!(q[0], 434, "{q:?}");
        for l in 1..LEVELS - 1 {
            let ratio = q[l - 1] as f64 / q[l] as f64;
            assert!((ratio - SCALE).abs() < 0.02, "{q:?}");
        }
    }

    /// Candidates crowded in one corner of the image (high scores) and spread thinly elsewhere (low
    /// scores): the spread keeps one per cell over the whole image before a second one of the crowd,
    /// and keeps the best of each cell.
    #[test]
    fn spreading_takes_every_cell_before_the_crowd() {
        let (w, h) = (400.0, 100.0);
        let mut c = Vec::new();
        // 100 strong candidates in the 40 × 40 top-left corner
        for i in 0..100 {
            c.push(Candidate { at: (4.0 * (i % 10) as f64, 4.0 * (i / 10) as f64), level: 0, score: 100.0 + i as f32 });
        }
        // two weak candidates in every 20 × 20 cell elsewhere
        for gx in 0..20 {
            for gy in 0..5 {
                if gx < 2 && gy < 2 {
                    continue;
                }
                for k in 0..2 {
                    let at = (20.0 * gx as f64 + 5.0 + 8.0 * k as f64, 20.0 * gy as f64 + 10.0);
                    c.push(Candidate { at, level: 0, score: 1.0 + k as f32 });
                }
            }
        }
        let mut quotas = [0; LEVELS];
        quotas[0] = 100; // cells of √(400·100/100) = 20 px
        let kept = spread_per_level(&c, quotas, (w, h));
        assert_eq!(kept.len(), 100);
        // 96 cells outside the crowd get one each (the better of their two), the crowd's 4 cells one each
        let crowd = kept.iter().filter(|&&i| i < 100).count();
        assert_eq!(crowd, 4, "one per crowded cell");
        assert!(kept.iter().filter(|&&i| i >= 100).all(|&i| c[i].score == 2.0), "the best of each cell");
        // without spreading the crowd alone would have filled the quota
        let mut by_score: Vec<usize> = (0..c.len()).collect();
        by_score.sort_by(|&a, &b| c[b].score.total_cmp(&c[a].score));
        assert!(by_score[..100].iter().all(|&i| i < 100));
    }

    /// A grey image of `w` × `h` pixels whose value at (x, y) is `f(x, y)`.
    fn image(w: i32, h: i32, f: impl Fn(i32, i32) -> u8) -> Mat {
        let data: Vec<u8> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| f(x, y)).collect();
        Mat::new_rows_cols_with_data(h, w, &data).expect("image").try_clone().expect("owned")
    }

    /// The orientation points from the keypoint to the brighter side of its patch: along +x for a
    /// brightness that grows with x, +y (down the image) for one that grows with y, and so on round.
    #[test]
    fn orientation_points_to_the_brighter_side() {
        for (want, f) in [
            (0.0, (|x, _| 60 + x) as fn(i32, i32) -> i32),
            (90.0, |_, y| 60 + y),
            (180.0, |x, _| 200 - x),
            (270.0, |_, y| 200 - y),
            (45.0, |x, y| 60 + (x + y) / 2),
        ] {
            let img = image(100, 100, |x, y| f(x, y).clamp(0, 255) as u8);
            let grey = super::super::grey::GreyView::of(&img).expect("view");
            let a = orientation(&grey, 50, 50) as f64;
            let off = (a - want + 540.0).rem_euclid(360.0) - 180.0;
            assert!(off.abs() < 1.0, "want {want}°, got {a}°");
        }
    }

    /// Dots of 12 grey levels of contrast (below ORB's FAST threshold of 20, above the low one of 7) on
    /// the right half of a flat image, dots of 100 on the left half: the low-contrast dots are still
    /// found, by the second pass in their empty cells, and the flat grey between them gives no corner.
    /// (Single-pixel dots: each is a FAST corner of its own, with no equal-scored neighbour for the
    /// non-maximum suppression to cancel it against.)
    #[test]
    fn a_low_contrast_cell_still_offers_corners() {
        let dots: Vec<(i32, i32, u8)> = (0..6)
            .flat_map(|i| (0..3).map(move |j| (50 + 40 * i, 50 + 40 * j)))
            .map(|(x, y)| (x, y, if x < 150 { 228 } else { 140 }))
            .collect();
        let img = image(300, 200, |x, y| dots.iter().find(|d| d.0 == x && d.1 == y).map_or(128, |d| d.2));
        let corners = detect_level(&img).expect("FAST");
        for &(x, y, v) in &dots {
            let found = corners.iter().any(|((cx, cy), _)| (cx - x as f64).hypot(cy - y as f64) < 1.0);
            assert!(found, "dot of contrast {} at ({x}, {y}) not found: {corners:?}", v - 128);
        }
        assert_eq!(corners.len(), dots.len(), "corners on flat grey: {corners:?}");
        // ORB's threshold alone finds the high-contrast dots only
        let mut high = core::Vector::<core::KeyPoint>::new();
        features2d::fast(&img, &mut high, FAST_THRESHOLD, true).expect("FAST");
        assert_eq!(high.len(), 9, "threshold 20: {:?}", high.iter().map(|k| k.pt()).collect::<Vec<_>>());
        assert!(high.iter().all(|k| k.pt().x < 150.0));
    }

    /// Levels are spread separately, each within its quota, and a level without candidates takes none.
    #[test]
    fn each_level_keeps_its_own_quota() {
        let c: Vec<Candidate> = (0..60)
            .map(|i| Candidate { at: (10.0 * (i % 30) as f64, 50.0), level: (i / 30) * 2, score: i as f32 })
            .collect();
        let mut quotas = [0; LEVELS];
        (quotas[0], quotas[1], quotas[2]) = (10, 5, 40);
        let kept = spread_per_level(&c, quotas, (300.0, 100.0));
        assert_eq!(kept.iter().filter(|&&i| c[i].level == 0).count(), 10);
        assert_eq!(kept.iter().filter(|&&i| c[i].level == 2).count(), 30, "all 30 of level 2");
        assert_eq!(kept.len(), 40);
    }
}
