//! Binary descriptors: 256-bit ORB descriptors, their Hamming distance, the best-two ratio test of
//! descriptor matching, and the representative descriptor of a point seen several times.

/// A 256-bit binary descriptor (ORB).
pub type Descriptor = [u8; 32];

/// Hamming distance of two descriptors, on 64-bit words (four population counts instead of 32).
#[inline]
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    let mut sum = 0;
    for w in 0..4 {
        let x = u64::from_ne_bytes(a[8 * w..8 * w + 8].try_into().unwrap_or([0; 8]));
        let y = u64::from_ne_bytes(b[8 * w..8 * w + 8].try_into().unwrap_or([0; 8]));
        sum += (x ^ y).count_ones();
    }
    sum
}

/// The two smallest Hamming distances among the candidates offered, and the best candidate.
#[derive(Debug, Clone, Copy)]
pub struct BestTwo {
    /// The smallest distance offered (`u32::MAX` before any).
    pub best: u32,
    second: u32,
    arg: usize,
}

impl Default for BestTwo {
    fn default() -> Self {
        Self::new()
    }
}

impl BestTwo {
    /// Nothing offered yet.
    pub fn new() -> Self {
        Self { best: u32::MAX, second: u32::MAX, arg: usize::MAX }
    }

    /// Offer candidate `j` at distance `h`.
    pub fn offer(&mut self, h: u32, j: usize) {
        if h < self.best {
            (self.second, self.best, self.arg) = (self.best, h, j);
        } else if h < self.second {
            self.second = h;
        }
    }

    /// The best candidate when its distance is at most `max_hamming` and below 0.9 × the second best
    /// (at or below with `tie_ok`); a lone candidate passes the ratio test. A match much better than
    /// the next candidate is unambiguous; two near-equal candidates are repeated texture.
    pub fn winner(&self, max_hamming: u32, tie_ok: bool) -> Option<usize> {
        let limit = 0.9 * self.second as f64;
        let ratio = self.second == u32::MAX || (self.best as f64) < limit || (tie_ok && self.best as f64 == limit);
        (self.arg != usize::MAX && self.best <= max_hamming && ratio).then_some(self.arg)
    }
}

/// The representative of several descriptors of one point: the one whose median distance to the
/// others is smallest (a medoid, robust to a few views that saw something else at that pixel). Ties go
/// to the earlier descriptor; `None` without descriptors.
pub fn representative(descriptors: &[Descriptor]) -> Option<Descriptor> {
    match descriptors.len() {
        0 => None,
        1 | 2 => Some(descriptors[0]),
        n => {
            let mut best = (u32::MAX, 0);
            let mut row = Vec::with_capacity(n);
            for (i, a) in descriptors.iter().enumerate() {
                row.clear();
                row.extend(descriptors.iter().map(|b| hamming(a, b)));
                row.sort_unstable();
                // the median of the distances to the others (row[0] is the distance to itself)
                let median = row[1 + (n - 2) / 2];
                if median < best.0 {
                    best = (median, i);
                }
            }
            Some(descriptors[best.1])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flip(d: &Descriptor, bits: &[usize]) -> Descriptor {
        let mut out = *d;
        for &b in bits {
            out[b / 8] ^= 1 << (b % 8);
        }
        out
    }

    #[test]
    fn hamming_counts_differing_bits() {
        let a = [0u8; 32];
        assert_eq!(hamming(&a, &a), 0);
        assert_eq!(hamming(&a, &[0xff; 32]), 256);
        assert_eq!(hamming(&a, &flip(&a, &[0, 9, 255])), 3);
    }

    #[test]
    fn the_ratio_test_refuses_ambiguous_matches() {
        let mut two = BestTwo::new();
        two.offer(30, 4);
        assert_eq!(two.winner(50, false), Some(4), "a lone candidate");
        two.offer(32, 7);
        assert_eq!(two.winner(50, false), None, "30 is not below 0.9 × 32");
        let mut clear = BestTwo::new();
        clear.offer(60, 1);
        clear.offer(20, 2);
        assert_eq!(clear.winner(50, false), Some(2));
        assert_eq!(clear.winner(10, false), None, "too far");
    }

    #[test]
    fn the_representative_is_the_medoid_and_ignores_an_odd_view() {
        let base = [0x5au8; 32];
        // four views of one corner (a few bits each) and one view of something else
        let views = vec![
            flip(&base, &[1, 2]),
            flip(&base, &[3]),
            flip(&base, &[100, 101, 102]),
            base,
            flip(&base, &(0..120).collect::<Vec<_>>()),
        ];
        assert_eq!(representative(&views), Some(base));
        assert_eq!(representative(&[]), None);
        assert_eq!(representative(&views[..1]), Some(views[0]));
    }
}
