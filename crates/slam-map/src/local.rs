//! The keyframes around a view. Tracking's local map: the keyframes that observe the points a frame
//! sees, ranked by how many of them each observes, and their best covisible neighbours (the parts of
//! the map the frame is likely to see next; the reference keyframe is the one sharing the most).
//! Local mapping's window: a new keyframe, its covisible keyframes (optimised together), the other
//! keyframes that observe their points (held fixed), and the neighbours that new points are
//! triangulated and fused with.

use std::collections::{BTreeMap, BTreeSet};

use crate::{map::Map, KeyframeId, PointId};

/// Tracking's local keyframes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LocalKeyframes {
    /// The keyframes, the reference first, then by how many of the view's points they observe, then
    /// the neighbours added.
    pub keyframes: Vec<KeyframeId>,
    /// The keyframe observing the most of the view's points (ties: the newest).
    pub reference: Option<KeyframeId>,
}

impl Map {
    /// The keyframes observing `points` (a view's matched points), ranked by how many each observes,
    /// then for each of them its `neighbours` best covisible keyframes and its parent; at most `max` in
    /// all.
    pub fn local_keyframes(&self, points: &[PointId], neighbours: usize, max: usize) -> LocalKeyframes {
        let mut votes: BTreeMap<KeyframeId, usize> = BTreeMap::new();
        for p in points.iter().filter_map(|id| self.point(*id)) {
            for o in &p.observations {
                if self.keyframe(o.keyframe).is_some() {
                    *votes.entry(o.keyframe).or_default() += 1;
                }
            }
        }
        let mut ranked: Vec<(KeyframeId, usize)> = votes.into_iter().collect();
        ranked.sort_by(|a, b| b.1.cmp(&a.1).then(b.0.cmp(&a.0)));
        let reference = ranked.first().map(|r| r.0);
        let mut chosen: Vec<KeyframeId> = ranked.iter().map(|r| r.0).take(max).collect();
        let mut seen: BTreeSet<KeyframeId> = chosen.iter().copied().collect();
        let first = chosen.clone();
        'outer: for k in first {
            let parent = self.keyframe(k).and_then(|kf| kf.parent);
            for n in self.covisibility().best(k, neighbours).into_iter().chain(parent) {
                if chosen.len() >= max {
                    break 'outer;
                }
                if self.keyframe(n).is_some() && seen.insert(n) {
                    chosen.push(n);
                }
            }
        }
        LocalKeyframes { keyframes: chosen, reference }
    }
}

/// How local mapping's window around a new keyframe is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowConfig {
    /// Least shared points for a covisible keyframe to be optimised with the new one: a link of fewer
    /// shared points constrains the relative pose of the two poorly (ORB-SLAM's threshold, 15: more
    /// than the 3 points a pose needs by a wide margin, for outliers and for spread).
    pub min_weight: u32,
    /// Most keyframes optimised (the new one and its heaviest links).
    pub max_free: usize,
    /// Most keyframes held fixed, per keyframe optimised.
    pub fixed_per_free: usize,
    /// The new keyframe's neighbours that new points are triangulated with.
    pub neighbours: usize,
    /// Each of those neighbours' own best neighbours that points are fused with too.
    pub second_neighbours: usize,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self { min_weight: 15, max_free: 20, fixed_per_free: 4, neighbours: 10, second_neighbours: 5 }
    }
}

/// Local mapping's window around a new keyframe.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Window {
    /// The new keyframe.
    pub keyframe: KeyframeId,
    /// Optimised: the new keyframe and its covisible keyframes (heaviest first).
    pub free: Vec<KeyframeId>,
    /// Held fixed: the other keyframes that observe the free keyframes' points, those sharing the most
    /// first.
    pub fixed: Vec<KeyframeId>,
    /// The neighbours new points are triangulated with (heaviest first).
    pub neighbours: Vec<KeyframeId>,
    /// The keyframes points are fused with: the neighbours and their own best neighbours.
    pub fusion: Vec<KeyframeId>,
}

impl Window {
    /// Every keyframe of the window.
    pub fn all(&self) -> BTreeSet<KeyframeId> {
        std::iter::once(self.keyframe)
            .chain(self.free.iter().copied())
            .chain(self.fixed.iter().copied())
            .chain(self.neighbours.iter().copied())
            .chain(self.fusion.iter().copied())
            .collect()
    }
}

impl Map {
    /// The window of local mapping around keyframe `kf` ([`WindowConfig`]).
    pub fn window_of(&self, kf: KeyframeId, config: &WindowConfig) -> Window {
        let cov = self.covisibility();
        let mut linked = cov.neighbours(kf, config.min_weight);
        if linked.is_empty() {
            // a keyframe sharing fewer points with every other is still adjusted with its best link
            linked = cov.neighbours(kf, 1).into_iter().take(1).collect();
        }
        let free: Vec<KeyframeId> = std::iter::once(kf)
            .chain(linked.iter().map(|l| l.0))
            .filter(|k| self.keyframe(*k).is_some())
            .take(config.max_free.max(1))
            .collect();
        let fixed = self.fixed_ring(&free, config.fixed_per_free * free.len());
        let neighbours = cov.best(kf, config.neighbours);
        let mut fusion = neighbours.clone();
        let mut seen: BTreeSet<KeyframeId> = fusion.iter().copied().chain([kf]).collect();
        for n in &neighbours {
            for m in cov.best(*n, config.second_neighbours) {
                if seen.insert(m) {
                    fusion.push(m);
                }
            }
        }
        Window { keyframe: kf, free, fixed, neighbours, fusion }
    }

    /// The keyframes outside `free` that observe points of `free`'s keyframes, those sharing the most
    /// points first (ties: the newest), at most `max`.
    pub fn fixed_ring(&self, free: &[KeyframeId], max: usize) -> Vec<KeyframeId> {
        let free_set: BTreeSet<KeyframeId> = free.iter().copied().collect();
        let mut shared: BTreeMap<KeyframeId, usize> = BTreeMap::new();
        let mut points = BTreeSet::new();
        for k in free.iter().filter_map(|k| self.keyframe(*k)) {
            points.extend(k.observations().map(|(_, p)| p));
        }
        for p in points.iter().filter_map(|p| self.point(*p)) {
            for o in &p.observations {
                if !free_set.contains(&o.keyframe) && self.keyframe(o.keyframe).is_some() {
                    *shared.entry(o.keyframe).or_default() += 1;
                }
            }
        }
        let mut ranked: Vec<(KeyframeId, usize)> = shared.into_iter().collect();
        ranked.sort_by(|a, b| b.1.cmp(&a.1).then(b.0.cmp(&a.0)));
        ranked.into_iter().take(max).map(|r| r.0).collect()
    }
}
