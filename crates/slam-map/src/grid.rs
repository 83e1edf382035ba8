//! Keypoints bucketed in square cells: a spatial index of an image's keypoints, built once per image
//! and read by every projection search into it.

/// Keypoints bucketed in square cells (compressed rows: the keypoints of cell `c` are
/// `items[start[c]..start[c + 1]]`, in ascending index), built once per frame and queried by every
/// projection search of that frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct KeypointGrid {
    cell: f64,
    cols: usize,
    rows: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl KeypointGrid {
    /// Side of a cell, pixels: about the smallest search window (a few pixels at the coarse pyramid
    /// levels) times ten, so a typical window touches a handful of cells.
    pub const CELL: f64 = 32.0;

    /// The grid of `points` (pixels; negative coordinates count in the first cell).
    pub fn new(points: &[(f64, f64)]) -> Self {
        Self::with_cell(points, Self::CELL)
    }

    /// The grid of `points` in cells of `cell` pixels (a narrow search, such as an epipolar band, reads
    /// fewer keypoints from smaller cells).
    pub fn with_cell(points: &[(f64, f64)], cell: f64) -> Self {
        // below a pixel a cell holds no more than one keypoint and the grid's size grows without bound
        let cell = if cell.is_finite() && cell >= 1.0 { cell } else { Self::CELL };
        let cols = points.iter().map(|p| Self::coord(p.0, cell)).max().unwrap_or(0) + 1;
        let rows = points.iter().map(|p| Self::coord(p.1, cell)).max().unwrap_or(0) + 1;
        let mut start = vec![0u32; cols * rows + 1];
        for p in points {
            start[Self::coord(p.1, cell) * cols + Self::coord(p.0, cell) + 1] += 1;
        }
        for c in 1..start.len() {
            start[c] += start[c - 1];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let c = Self::coord(p.1, cell) * cols + Self::coord(p.0, cell);
            items[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        Self { cell, cols, rows, start, items }
    }

    /// A coordinate's cell; beyond 65 535 cells (an image a thousand times KITTI's width) the last.
    fn coord(x: f64, cell: f64) -> usize {
        (x / cell).floor().clamp(0.0, 65_535.0) as usize
    }

    /// Calls `visit` with every keypoint index in the cells that a disc of `radius` around `(u, v)`
    /// touches, column by column (left to right), each column top to bottom, each cell in ascending
    /// index. The caller tests the exact distance.
    pub fn for_each_near(&self, (u, v): (f64, f64), radius: f64, mut visit: impl FnMut(usize)) {
        if self.items.is_empty() || !(u.is_finite() && v.is_finite() && radius.is_finite()) {
            return;
        }
        let r = (radius / self.cell).ceil() as i64;
        let (gx, gy) = ((u / self.cell).floor() as i64, (v / self.cell).floor() as i64);
        let clamp = |x: i64, n: usize| x.clamp(0, n as i64 - 1) as usize;
        if gx + r < 0 || gy + r < 0 || gx - r >= self.cols as i64 || gy - r >= self.rows as i64 {
            return;
        }
        let (x0, x1) = (clamp(gx - r, self.cols), clamp(gx + r, self.cols));
        let (y0, y1) = (clamp(gy - r, self.rows), clamp(gy + r, self.rows));
        for x in x0..=x1 {
            for y in y0..=y1 {
                let c = y * self.cols + x;
                for &i in &self.items[self.start[c] as usize..self.start[c + 1] as usize] {
                    visit(i as usize);
                }
            }
        }
    }

    /// Calls `visit` once with every keypoint index in the cells near the segment from `a` to `b`: a
    /// superset of the keypoints whose offsets in u and in v from some point of the segment are both at
    /// most `radius` (a square neighbourhood, which holds the round one; the caller tests its own
    /// bound), row of cells by row of cells. The segment is clipped to the grid's extent widened by
    /// `radius` (an epipolar segment may start far outside the image); in each row of cells, the cells
    /// visited are those within `radius` across of the part of the segment within `radius` of the row,
    /// so that no cell is met twice. Nothing is visited for a negative or non-finite input.
    pub fn for_each_near_segment(&self, a: (f64, f64), b: (f64, f64), radius: f64, mut visit: impl FnMut(usize)) {
        if self.items.is_empty() || ![a.0, a.1, b.0, b.1, radius].iter().all(|x| x.is_finite()) || radius < 0.0 {
            return;
        }
        let (w, h) = (self.cols as f64 * self.cell, self.rows as f64 * self.cell);
        let Some((a, b)) = clip_segment(a, b, (-radius, -radius), (w + radius, h + radius)) else { return };
        let cell_of = |x: f64, n: usize| ((x / self.cell).floor().max(0.0) as usize).min(n - 1);
        let (lo_v, hi_v) = (a.1.min(b.1), a.1.max(b.1));
        for y in cell_of(lo_v - radius, self.rows)..=cell_of(hi_v + radius, self.rows) {
            // the part of the segment whose v lies within `radius` of this row of cells
            let (band_lo, band_hi) = (y as f64 * self.cell - radius, (y + 1) as f64 * self.cell + radius);
            let dv = b.1 - a.1;
            let (t0, t1) = if dv == 0.0 {
                if a.1 < band_lo || a.1 > band_hi {
                    continue;
                }
                (0.0, 1.0)
            } else {
                let (ta, tb) = ((band_lo - a.1) / dv, (band_hi - a.1) / dv);
                (ta.min(tb).max(0.0), ta.max(tb).min(1.0))
            };
            if t0 > t1 {
                continue;
            }
            let (u0, u1) = (a.0 + t0 * (b.0 - a.0), a.0 + t1 * (b.0 - a.0));
            let (lo_u, hi_u) = (u0.min(u1) - radius, u0.max(u1) + radius);
            if hi_u < 0.0 || lo_u >= w {
                continue;
            }
            let row = y * self.cols;
            let (x0, x1) = (cell_of(lo_u, self.cols), cell_of(hi_u, self.cols));
            for &i in &self.items[self.start[row + x0] as usize..self.start[row + x1 + 1] as usize] {
                visit(i as usize);
            }
        }
    }
}

/// The part of the segment `a`–`b` inside the box from `lo` to `hi` (Liang–Barsky), if any.
fn clip_segment(a: (f64, f64), b: (f64, f64), lo: (f64, f64), hi: (f64, f64)) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 - lo.0), (dx, hi.0 - a.0), (-dy, a.1 - lo.1), (dy, hi.1 - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
            continue;
        }
        let r = q / p;
        if p < 0.0 {
            t0 = t0.max(r);
        } else {
            t1 = t1.min(r);
        }
        if t0 > t1 {
            return None;
        }
    }
    Some(((a.0 + t0 * dx, a.1 + t0 * dy), (a.0 + t1 * dx, a.1 + t1 * dy)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::ChaCha8Rng, RngExt, SeedableRng};

    /// The grid visits exactly the keypoints a scan of all keypoints finds within the window (and
    /// maybe a few more, which the caller's exact test drops), near the image border and outside it.
    #[test]
    fn grid_finds_every_keypoint_a_full_scan_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let points: Vec<(f64, f64)> =
            (0..800).map(|_| (rng.random_range(0.0..1241.0), rng.random_range(0.0..376.0))).collect();
        let grid = KeypointGrid::new(&points);
        for _ in 0..300 {
            let q = (rng.random_range(-80.0..1320.0), rng.random_range(-80.0..450.0));
            let radius = rng.random_range(1.0..170.0);
            let near = |p: &(f64, f64)| (p.0 - q.0).powi(2) + (p.1 - q.1).powi(2) <= radius * radius;
            let scan: Vec<usize> = (0..points.len()).filter(|&i| near(&points[i])).collect();
            let mut found = Vec::new();
            grid.for_each_near(q, radius, |i| found.push(i));
            let mut within: Vec<usize> = found.iter().copied().filter(|&i| near(&points[i])).collect();
            within.sort_unstable();
            assert_eq!(within, scan, "query {q:?} radius {radius}");
            let unique: std::collections::HashSet<usize> = found.iter().copied().collect();
            assert_eq!(unique.len(), found.len(), "a keypoint visited twice");
        }
        let mut none = 0;
        KeypointGrid::new(&[]).for_each_near((10.0, 10.0), 50.0, |_| none += 1);
        KeypointGrid::new(&[]).for_each_near_segment((0.0, 0.0), (100.0, 100.0), 5.0, |_| none += 1);
        assert_eq!(none, 0);
    }

    /// The segment query finds every keypoint a full scan finds within the radius of the segment, for
    /// segments inside the image, crossing it, starting thousands of pixels outside it (an epipolar
    /// segment's near end) and missing it.
    #[test]
    fn segment_query_finds_every_keypoint_a_full_scan_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let points: Vec<(f64, f64)> =
            (0..1500).map(|_| (rng.random_range(0.0..1241.0), rng.random_range(0.0..376.0))).collect();
        let grid = KeypointGrid::with_cell(&points, 16.0);
        let distance = |p: (f64, f64), a: (f64, f64), b: (f64, f64)| {
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let t = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / (dx * dx + dy * dy).max(1e-12)).clamp(0.0, 1.0);
            (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
        };
        for n in 0..500 {
            let spread = if n % 4 == 0 { 20000.0 } else { 1500.0 };
            let a: (f64, f64) = (rng.random_range(-spread..spread), rng.random_range(-spread..spread));
            let b: (f64, f64) = (rng.random_range(-100.0..1340.0), rng.random_range(-100.0..480.0));
            // every tenth a row (the epipolar line of a rectified pair), a column or a single point
            let a = match n % 10 {
                1 => (a.0, b.1),
                2 => (b.0, a.1),
                3 => b,
                _ => a,
            };
            let radius = if n % 25 == 0 { 0.0 } else { rng.random_range(0.5..12.0) };
            let scan: Vec<usize> = (0..points.len()).filter(|&i| distance(points[i], a, b) <= radius).collect();
            let mut found = Vec::new();
            grid.for_each_near_segment(a, b, radius, |i| found.push(i));
            found.sort_unstable();
            assert!(found.windows(2).all(|w| w[0] < w[1]), "each keypoint visited once");
            let within: Vec<usize> = found.iter().copied().filter(|&i| distance(points[i], a, b) <= radius).collect();
            assert_eq!(within, scan, "segment {a:?}-{b:?} radius {radius}");
            // the square neighbourhood too: offsets in u and v from the segment's nearest point in that
            // sense (a convex function of the position along the segment, minimised by ternary search)
            let square = |p: (f64, f64)| {
                let at = |t: f64| (p.0 - a.0 - t * (b.0 - a.0)).abs().max((p.1 - a.1 - t * (b.1 - a.1)).abs());
                let (mut lo, mut hi) = (0.0f64, 1.0f64);
                for _ in 0..100 {
                    let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
                    if at(m1) <= at(m2) {
                        hi = m2;
                    } else {
                        lo = m1;
                    }
                }
                at(0.5 * (lo + hi))
            };
            let in_square: Vec<usize> = (0..points.len()).filter(|&i| square(points[i]) <= radius - 1e-9).collect();
            assert!(in_square.iter().all(|i| found.binary_search(i).is_ok()), "square: {a:?}-{b:?} radius {radius}");
        }
        let mut none = 0;
        grid.for_each_near_segment((0.0, 0.0), (1000.0, 300.0), -20.0, |_| none += 1);
        grid.for_each_near_segment((0.0, f64::NAN), (1000.0, 300.0), 5.0, |_| none += 1);
        assert_eq!(none, 0, "a negative radius or a NaN end visits nothing");
        // a cell below a pixel falls back to the default size
        assert_eq!(KeypointGrid::with_cell(&points, 1e-9).cell, KeypointGrid::CELL);
    }
}
