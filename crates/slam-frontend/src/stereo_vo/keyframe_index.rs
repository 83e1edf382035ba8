//! Keyframe retrieval for relocalisation: a descriptor index over every keyframe of the run by
//! multi-index hashing. Each 256-bit ORB descriptor is cut into [`CHUNKS`] substrings of 16 bits, and
//! each substring keys a hash table of the stored descriptors holding it. Two descriptors within
//! Hamming distance `d` share at least one substring exactly with probability
//! `1 − (1 − (1 − d/256)^16)^16`: 0.90 at `d` = 30 (a typical distance between views of one ORB
//! corner), 0.66 at 40. A query looks its descriptors up in the tables, checks the full distance of
//! each candidate, and every keyframe holding a descriptor within [`MAX_HAMMING`] of a query descriptor
//! gets that descriptor's vote; keyframes are ranked by their votes.
//!
//! No vocabulary is trained, so nothing depends on the scenes seen first. The ranking only decides
//! which keyframes are tried; a candidate is accepted by the pose verification in
//! [`crate::stereo_vo`], never by its votes.

use slam_map::hamming;

/// A binary descriptor (ORB: 256 bits).
pub(crate) type Descriptor = [u8; 32];

/// Substrings per descriptor (16 bits each).
const CHUNKS: usize = 16;

/// Largest Hamming distance of a vote: ten standard deviations below the 128 bits that unrelated
/// ORB descriptors differ by (σ ≈ 8), and under the 60 of a tracking match, so chance votes are rare.
const MAX_HAMMING: u32 = 50;

/// Keyframes' descriptors with one table per 16-bit substring, addressed directly by the substring's
/// value: each of its 65 536 slots heads a chain of the stored descriptors holding that value, linked
/// through `next`. An insert is two writes per substring and allocates nothing per value (a hash map
/// of small vectors cost ~10 ms per keyframe); the tables take 16 × 256 KiB.
#[derive(Debug, Default)]
pub(crate) struct KeyframeIndex {
    /// Each keyframe's key (the caller's) and its number of descriptors.
    entries: Vec<(u64, usize)>,
    /// Every stored descriptor and its keyframe (slot in `entries`).
    descriptors: Vec<(Descriptor, u32)>,
    /// Per substring: the newest stored descriptor holding each value (`NONE`: none).
    heads: Vec<Vec<u32>>,
    /// Per stored descriptor and substring: the next older descriptor holding the same value.
    next: Vec<[u32; CHUNKS]>,
}

/// The end of a chain.
const NONE: u32 = u32::MAX;

/// Most entries of one chain a query follows (from the newest). A 16-bit substring value is shared by
/// chance by one in 65 536 unrelated descriptors, so a keyframe of 2000 descriptors lengthens a chain
/// by 0.03 on average, while a feature seen again from every keyframe of a place (a car standing
/// still, a road driven again) lengthens the chains of its substrings by one per keyframe. Following at
/// most 64 entries reaches the 64 newest keyframes that saw such a feature, and by chance alone some
/// 2000 keyframes back; a query costs at most descriptors × 16 × 64 distance checks however long the
/// run, instead of growing with it.
const CHAIN_LIMIT: usize = 64;

fn chunk(d: &Descriptor, c: usize) -> u16 {
    u16::from_le_bytes([d[2 * c], d[2 * c + 1]])
}

impl KeyframeIndex {
    /// Number of keyframes indexed.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no keyframe is indexed.
    pub(crate) fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Add a keyframe under `key` with its descriptors.
    pub(crate) fn insert(&mut self, key: u64, descriptors: &[Descriptor]) {
        if self.heads.is_empty() {
            self.heads = vec![vec![NONE; 1 << 16]; CHUNKS];
        }
        let slot = self.entries.len() as u32;
        self.entries.push((key, descriptors.len()));
        for d in descriptors {
            let id = self.descriptors.len() as u32;
            self.descriptors.push((*d, slot));
            let mut links = [NONE; CHUNKS];
            for (c, (head, link)) in self.heads.iter_mut().zip(links.iter_mut()).enumerate() {
                let h = &mut head[chunk(d, c) as usize];
                *link = *h;
                *h = id;
            }
            self.next.push(links);
        }
    }

    /// The keys of the `n` best keyframes for a frame's descriptors, best first, with their scores:
    /// the votes (query descriptors with a stored descriptor of that keyframe within [`MAX_HAMMING`])
    /// over √(query descriptors × keyframe descriptors), so a keyframe with more keypoints is not
    /// favoured for its size. Ties go to the lower key.
    #[cfg(test)]
    pub(crate) fn query(&self, descriptors: &[Descriptor], n: usize) -> Vec<(u64, f64)> {
        self.query_counted(descriptors, n, &|_| true).0
    }

    /// [`KeyframeIndex::query`] among the keyframes whose keys `keep` takes (those of one map segment,
    /// or of every segment but one): ranked among themselves, so that the keyframes left out do not
    /// take the `n` places.
    pub(crate) fn query_among(
        &self,
        descriptors: &[Descriptor],
        n: usize,
        keep: &dyn Fn(u64) -> bool,
    ) -> Vec<(u64, f64)> {
        self.query_counted(descriptors, n, keep).0
    }

    /// [`KeyframeIndex::query`] and the number of chain entries it visited (at most descriptors × 16 ×
    /// [`CHAIN_LIMIT`]). The chains are walked by two threads, each for half of the descriptors (a
    /// query is bound by memory reads: 2 000 descriptors walk some 250 000 chain entries in a map with
    /// a keyframe a frame), and their votes added: the same result as one walk.
    fn query_counted(
        &self,
        descriptors: &[Descriptor],
        n: usize,
        keep: &dyn Fn(u64) -> bool,
    ) -> (Vec<(u64, f64)>, usize) {
        let (votes, visited) = if descriptors.len() >= 256 {
            let (a, b) = descriptors.split_at(descriptors.len() / 2);
            let (mut mine, other) = std::thread::scope(|s| {
                let other = std::thread::Builder::new().spawn_scoped(s, || self.votes(b)).ok();
                let mine = self.votes(a);
                (mine, other.and_then(|h| h.join().ok()))
            });
            // walked here when the second thread could not be started
            let (more, walked) = other.unwrap_or_else(|| self.votes(b));
            for (v, m) in mine.0.iter_mut().zip(&more) {
                *v += m;
            }
            mine.1 += walked;
            mine
        } else {
            self.votes(descriptors)
        };
        let votes: Vec<(u32, u32)> =
            votes.into_iter().enumerate().filter(|(_, v)| *v > 0).map(|(slot, v)| (slot as u32, v)).collect();
        let mut scored: Vec<(u64, f64)> = votes
            .into_iter()
            .map(|(slot, v)| {
                let (key, size) = self.entries[slot as usize];
                (key, v as f64 / ((descriptors.len() * size).max(1) as f64).sqrt())
            })
            .filter(|(key, _)| keep(*key))
            .collect();
        scored.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        scored.truncate(n);
        (scored, visited)
    }

    /// Each keyframe's votes from `descriptors` (one per query descriptor with a stored descriptor of
    /// that keyframe within [`MAX_HAMMING`]), by slot, and the chain entries visited.
    fn votes(&self, descriptors: &[Descriptor]) -> (Vec<u32>, usize) {
        let mut votes = vec![0u32; self.entries.len()];
        // the query descriptor (its number + 1) that last voted for each keyframe: one vote per
        // keyframe and query descriptor, checked in constant time however many keyframes it meets
        let mut last_vote = vec![0u32; self.entries.len()];
        let mut visited = 0;
        for (n, q) in descriptors.iter().enumerate() {
            let mark = n as u32 + 1;
            for (c, head) in self.heads.iter().enumerate() {
                let mut id = head[chunk(q, c) as usize];
                let mut walked = 0;
                while id != NONE && walked < CHAIN_LIMIT {
                    let (d, slot) = &self.descriptors[id as usize];
                    let s = *slot as usize;
                    if last_vote[s] != mark && hamming(q, d) <= MAX_HAMMING {
                        last_vote[s] = mark;
                        votes[s] += 1;
                    }
                    id = self.next[id as usize][c];
                    walked += 1;
                }
                visited += walked;
            }
        }
        (votes, visited)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::rng::SimRng;

    fn random(rng: &mut SimRng, n: usize) -> Vec<Descriptor> {
        (0..n).map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8)).collect()
    }

    /// A descriptor with `bits` distinct bits flipped (chosen by the generator).
    fn noisy(rng: &mut SimRng, d: &Descriptor, bits: usize) -> Descriptor {
        let mut out = *d;
        let mut flipped = Vec::new();
        while flipped.len() < bits {
            let b = (rng.uniform(0.0, 256.0) as usize).min(255);
            if !flipped.contains(&b) {
                flipped.push(b);
                out[b / 8] ^= 1 << (b % 8);
            }
        }
        out
    }

    #[test]
    fn the_index_retrieves_the_keyframe_of_a_noisy_view_first() {
        let mut rng = SimRng::new(5);
        let places: Vec<Vec<Descriptor>> = (0..6).map(|_| random(&mut rng, 600)).collect();
        let mut index = KeyframeIndex::default();
        assert!(index.query(&places[0], 3).is_empty(), "nothing indexed yet");
        for (i, p) in places.iter().enumerate() {
            index.insert(10 + i as u64, p);
        }
        assert_eq!(index.len(), 6);
        for (i, p) in places.iter().enumerate() {
            // a later view: 40 % of the descriptors seen again 30 bits off, the rest new
            let mut view: Vec<Descriptor> = p.iter().take(240).map(|d| noisy(&mut rng, d, 30)).collect();
            view.extend(random(&mut rng, 360));
            let best = index.query(&view, 3);
            assert_eq!(best[0].0, 10 + i as u64, "place {i}: {best:?}");
            // most of the re-seen descriptors vote (the hashing's recall at 30 bits is ~0.9), and
            // unrelated random descriptors (~128 bits away) give the others next to nothing
            assert!(best[0].1 > 0.3, "{best:?}");
            assert!(best.get(1).map_or(0.0, |b| b.1) < 0.02, "{best:?}");
        }
    }

    #[test]
    fn a_query_visits_a_bounded_number_of_entries_however_long_the_run() {
        let mut rng = SimRng::new(11);
        let place = random(&mut rng, 200);
        let mut index = KeyframeIndex::default();
        // the same place indexed again and again (a car standing still): every chain of its substrings
        // grows by one per keyframe
        let mut visited = Vec::new();
        for k in 0..300u64 {
            index.insert(k, &place);
            if k == 99 || k == 299 {
                let (best, n) = index.query_counted(&place, 3, &|_| true);
                assert_eq!(best.len(), 3, "the newest keyframes of the place are found: {best:?}");
                assert!(best.iter().all(|b| b.0 >= k + 1 - CHAIN_LIMIT as u64), "{best:?}");
                visited.push(n);
            }
        }
        assert_eq!(visited[0], 200 * CHUNKS * CHAIN_LIMIT, "at the limit after 100 keyframes");
        assert_eq!(visited[1], visited[0], "and no more after 300");
    }

    #[test]
    fn a_descriptor_beyond_the_vote_distance_does_not_vote() {
        let mut rng = SimRng::new(9);
        let stored = random(&mut rng, 1);
        let mut index = KeyframeIndex::default();
        index.insert(1, &stored);
        // 8 bits off: some 16-bit substring is untouched (8 flips touch at most 8 of 16)
        assert_eq!(index.query(&[noisy(&mut rng, &stored[0], 8)], 1).len(), 1);
        // 60 bits off: beyond the vote distance whatever the substrings say
        for _ in 0..20 {
            assert!(index.query(&[noisy(&mut rng, &stored[0], 60)], 1).is_empty());
        }
    }

    /// A query of many descriptors, walked by two threads, ranks and scores exactly as one walk of all
    /// of them does.
    #[test]
    fn two_threads_vote_as_one_walk() {
        let mut rng = SimRng::new(21);
        let mut index = KeyframeIndex::default();
        let places: Vec<Vec<Descriptor>> = (0..12).map(|_| random(&mut rng, 400)).collect();
        for (k, p) in places.iter().enumerate() {
            index.insert(k as u64, p);
        }
        // a view sharing half of place 3 and a quarter of place 7
        let mut view: Vec<Descriptor> = places[3][..200].iter().map(|d| noisy(&mut rng, d, 20)).collect();
        view.extend(places[7][..100].iter().map(|d| noisy(&mut rng, d, 20)));
        view.extend(random(&mut rng, 300));
        assert!(view.len() >= 256, "the two-thread path");
        let (ranked, visited) = index.query_counted(&view, 12, &|_| true);
        let (votes, walked) = index.votes(&view);
        assert_eq!(visited, walked);
        let mut one: Vec<(u64, f64)> = votes
            .iter()
            .enumerate()
            .filter(|(_, v)| **v > 0)
            .map(|(slot, &v)| (index.entries[slot].0, f64::from(v) / ((view.len() * 400) as f64).sqrt()))
            .collect();
        one.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        one.truncate(12);
        assert_eq!(ranked, one);
        assert_eq!((ranked[0].0, ranked[1].0), (3, 7));
        // ranked among the keyframes kept: place 3 left out, place 7 comes first, as it does among all
        // but place 3
        let among = index.query_among(&view, 3, &|k| k != 3);
        assert_eq!(among.first().map(|a| a.0), Some(7));
        assert!(among.iter().all(|(k, _)| *k != 3));
        assert_eq!(among, ranked.iter().filter(|r| r.0 != 3).take(3).copied().collect::<Vec<_>>());
    }
}
