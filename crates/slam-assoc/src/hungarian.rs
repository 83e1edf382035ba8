//! Gated minimum-cost assignment with deterministic, order-independent results.

use pathfinding::{kuhn_munkres::kuhn_munkres_min, matrix::Matrix};
use slam_core::{Assignment, Detection, TrackId};

/// Cost of pairing a detection with a track: `Some(c)` with finite `c ≥ 0`, or `None` when gated out.
pub type Cost = Option<f64>;

/// Integer scale of costs (costs are rounded to 1e-9, far below any meaningful difference).
const SCALE: f64 = 1e9;
/// Integer cost of a forbidden pair: above any sum of allowed costs, so the assignment first maximises
/// the number of allowed pairs, then minimises their total cost.
const FORBIDDEN: i64 = 1 << 50;

/// Assign detections to tracks by minimum total cost over allowed pairs.
///
/// `cost(d, t)` is evaluated once per pair; NaN, infinite or negative costs count as gated out. The
/// problem is solved in a canonical order (tracks by id; detections by class, box and score, then
/// index), so the answer does not depend on the order of the inputs, and exact ties are broken the same
/// way every time.
pub fn assign(detections: &[Detection], tracks: &[TrackId], cost: impl Fn(usize, usize) -> Cost) -> Assignment {
    let n_det = detections.len();
    let mut det_order: Vec<usize> = (0..n_det).collect();
    det_order.sort_by(|&a, &b| {
        let (da, db) = (&detections[a], &detections[b]);
        da.class
            .cmp(&db.class)
            .then(da.bbox.xmin.total_cmp(&db.bbox.xmin))
            .then(da.bbox.ymin.total_cmp(&db.bbox.ymin))
            .then(da.bbox.xmax.total_cmp(&db.bbox.xmax))
            .then(da.bbox.ymax.total_cmp(&db.bbox.ymax))
            .then(da.score.total_cmp(&db.score))
            .then(a.cmp(&b))
    });
    let mut trk_order: Vec<usize> = (0..tracks.len()).collect();
    trk_order.sort_by_key(|&t| (tracks[t], t));

    let mut matches = Vec::new();
    if n_det > 0 && !tracks.is_empty() {
        let costs: Vec<Vec<i64>> = det_order
            .iter()
            .map(|&d| {
                trk_order
                    .iter()
                    .map(|&t| match cost(d, t) {
                        Some(c) if c.is_finite() && c >= 0.0 => ((c * SCALE).round() as i64).min(FORBIDDEN - 1),
                        _ => FORBIDDEN,
                    })
                    .collect()
            })
            .collect();
        // Kuhn–Munkres needs rows <= columns.
        let transpose = n_det > tracks.len();
        let rows: Vec<Vec<i64>> = if transpose {
            (0..tracks.len()).map(|t| costs.iter().map(|r| r[t]).collect()).collect()
        } else {
            costs.clone()
        };
        if let Ok(m) = Matrix::from_rows(rows) {
            let (_, cols) = kuhn_munkres_min(&m);
            for (r, &c) in cols.iter().enumerate() {
                let (di, ti) = if transpose { (c, r) } else { (r, c) };
                if costs[di][ti] < FORBIDDEN {
                    matches.push((det_order[di], tracks[trk_order[ti]]));
                }
            }
        }
    }
    matches.sort();
    let mut used = vec![false; n_det];
    for &(d, _) in &matches {
        used[d] = true;
    }
    let unmatched = (0..n_det).filter(|&d| !used[d]).collect();
    Assignment { matches, unmatched }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::{geometry::BBox, ClassId};

    fn det(x: f64) -> Detection {
        Detection::new(ClassId(1), 1.0, BBox::new(x, 0.0, x + 10.0, 10.0))
    }

    #[test]
    fn rectangular_both_ways_and_gating() {
        let dets = vec![det(0.0), det(100.0), det(200.0)];
        let tracks = vec![TrackId(7), TrackId(3)];
        // det 0 ↔ track 3 cheap, det 2 ↔ track 7 cheap, det 1 gated everywhere
        let table = [[Some(0.9), Some(0.1)], [None, None], [Some(0.2), Some(f64::NAN)]];
        let a = assign(&dets, &tracks, |d, t| table[d][t]);
        assert_eq!(a.matches, vec![(0, TrackId(3)), (2, TrackId(7))]);
        assert_eq!(a.unmatched, vec![1]);
        // more tracks than detections
        let a = assign(&dets[..1], &tracks, |d, t| table[d][t]);
        assert_eq!(a.matches, vec![(0, TrackId(3))]);
        // no tracks
        let a = assign(&dets, &[], |_, _| Some(0.0));
        assert_eq!(a.unmatched, vec![0, 1, 2]);
    }

    #[test]
    fn maximises_matches_then_cost() {
        let dets = vec![det(0.0), det(50.0)];
        let tracks = vec![TrackId(1), TrackId(2)];
        let table = [[Some(0.1), Some(0.5)], [Some(0.2), None]];
        let a = assign(&dets, &tracks, |d, t| table[d][t]);
        assert_eq!(a.matches, vec![(0, TrackId(2)), (1, TrackId(1))]);
    }
}
