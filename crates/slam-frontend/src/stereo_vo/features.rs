//! ORB features of one image, spread over it. OpenCV's ORB keeps, at each pyramid level, the keypoints
//! with the highest corner scores, wherever they are: on a street that is foliage, fences and a few
//! façades, while the road, the walls and the far field get few. A pose from such points is pulled by
//! whatever those few structures' stereo errors have in common. ORB-SLAM spreads its keypoints over a
//! grid for that reason (Mur-Artal et al., 2015); here the same idea in our own form: more candidates
//! than wanted are detected at each level, and each level's share is taken from a grid of cells of
//! about one keypoint each, the best of every cell first, then the second best, and so on.

use opencv::{core, features2d, prelude::*};

use crate::image_io::FrontendError;

/// Pyramid levels of the ORB extractor.
pub(crate) const LEVELS: usize = 8;
/// Scale between pyramid levels.
pub(crate) const SCALE: f64 = 1.2;
/// Candidates detected per keypoint kept when spreading: a cell of a level's grid holds one keypoint
/// on average, so four candidates per keypoint leave most cells of textured areas a choice and fill
/// the sparse ones.
const CANDIDATES_PER_KEPT: i32 = 4;

/// Keypoints: positions, 256-bit ORB descriptors, pyramid levels, orientations (degrees).
pub(crate) struct Features {
    pub(crate) points: Vec<(f64, f64)>,
    pub(crate) desc: Vec<[u8; 32]>,
    pub(crate) octave: Vec<i32>,
    pub(crate) angle: Vec<f32>,
}

/// An ORB extractor: `features` keypoints per image, [`LEVELS`] levels [`SCALE`] apart, Harris
/// score, FAST threshold 20, 31-pixel patches; with `spread`, spread over the image
/// ([`spread_per_level`]).
pub(crate) struct Extractor {
    orb: core::Ptr<features2d::ORB>,
    features: usize,
    spread: bool,
}

impl Extractor {
    /// The extractor of `features` keypoints per image, spread over the image or not.
    pub(crate) fn new(features: i32, spread: bool) -> Result<Self, FrontendError> {
        let detected = if spread { features.saturating_mul(CANDIDATES_PER_KEPT) } else { features };
        let orb = features2d::ORB::create(
            detected,
            SCALE as f32,
            LEVELS as i32,
            31,
            0,
            2,
            features2d::ORB_ScoreType::HARRIS_SCORE,
            31,
            20,
        )?;
        Ok(Self { orb, features: features.max(0) as usize, spread })
    }

    /// The keypoints of a grey image and their descriptors.
    pub(crate) fn extract(&mut self, img: &Mat) -> Result<Features, FrontendError> {
        let mut kps = core::Vector::<core::KeyPoint>::new();
        let mut desc = Mat::default();
        if self.spread {
            self.orb.detect(img, &mut kps, &core::no_array())?;
            let (w, h) = (img.cols() as f64, img.rows() as f64);
            let all: Vec<Candidate> = kps
                .iter()
                .map(|k| Candidate { at: (k.pt().x as f64, k.pt().y as f64), level: k.octave(), score: k.response() })
                .collect();
            let mut kept: core::Vector<core::KeyPoint> = spread_per_level(&all, level_quotas(self.features), (w, h))
                .into_iter()
                .filter_map(|i| kps.get(i).ok())
                .collect();
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
}

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
