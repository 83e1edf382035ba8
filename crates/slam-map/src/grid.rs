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
        let cell = Self::CELL;
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

    fn coord(x: f64, cell: f64) -> usize {
        (x / cell).floor().max(0.0) as usize
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
        assert_eq!(none, 0);
    }
}
