//! Track management around any [`Associator`]: prediction, creation, retirement.

use std::collections::BTreeMap;

use slam_core::{geometry::BBox, Associator, ClassId, Detection, Mask, PointPair, Region, TrackId, TrackView};

use crate::kalman::KalmanBoxFilter;

/// Settings of [`ObjectTracker`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// A track is retired after this many consecutive frames without a match. Default 10.
    pub max_missed: u32,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self { max_missed: 10 }
    }
}

/// A track's region in its reference frame, owned.
#[derive(Debug, Clone, PartialEq)]
pub enum OwnedRegion {
    /// Box.
    Box(BBox),
    /// Instance mask.
    Mask(Mask),
}

impl OwnedRegion {
    fn view(&self) -> Region<'_> {
        match self {
            OwnedRegion::Box(b) => Region::Box(*b),
            OwnedRegion::Mask(m) => Region::Mask(m),
        }
    }
}

/// One object track.
#[derive(Debug, Clone)]
pub struct Track {
    /// Identity, increasing in creation order.
    pub id: TrackId,
    /// Class of the detection that created it.
    pub class: ClassId,
    /// Box filter.
    pub filter: KalmanBoxFilter,
    /// Last matched box.
    pub last: BBox,
    /// Consecutive frames without a match.
    pub missed: u32,
    /// Number of matched frames.
    pub hits: u32,
    /// Its region in the last reference frame, when it was matched there.
    pub reference: Option<OwnedRegion>,
}

/// Input of one tracker step.
#[derive(Debug, Clone, Copy)]
pub struct TrackerInput<'a> {
    /// Detections of this frame.
    pub detections: &'a [Detection],
    /// Boxes of the projected ellipsoids of tracks that have one.
    pub projected: &'a BTreeMap<TrackId, BBox>,
    /// Where a track's object is expected in this frame from its 3-D position and the camera's motion
    /// (the caller knows both): it replaces the Kalman filter's image-space prediction of those tracks,
    /// which assumes a constant velocity in the image and fails when frames are far apart (the camera's
    /// own motion moves and grows a box in ways no constant image velocity follows).
    pub predicted: &'a BTreeMap<TrackId, BBox>,
    /// Keypoints tracked from the last reference frame to this frame.
    pub flow: &'a [PointPair],
    /// This frame becomes the new reference frame (the flow of later frames starts here; the running
    /// system sets it on every frame).
    pub keyframe: bool,
}

/// Output of one tracker step.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TrackerOutput {
    /// The track of every detection, in detection order: existing (matched) or new; `None` for a
    /// detection with a non-finite box (skipped and logged).
    pub tracks: Vec<Option<TrackId>>,
    /// Tracks created this step.
    pub created: Vec<TrackId>,
    /// Tracks retired this step.
    pub retired: Vec<TrackId>,
}

/// Keeps object tracks and associates each frame's detections with them.
pub struct ObjectTracker {
    associator: Box<dyn Associator>,
    config: TrackerConfig,
    tracks: Vec<Track>,
    next_id: u64,
}

impl ObjectTracker {
    /// A tracker around an associator.
    pub fn new(associator: Box<dyn Associator>, config: TrackerConfig) -> Self {
        Self { associator, config, tracks: Vec::new(), next_id: 0 }
    }

    /// Name of the associator in use.
    pub fn associator_name(&self) -> &'static str {
        self.associator.name()
    }

    /// Live tracks, by increasing id.
    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// New tracks take ids from `next` on at least (ids below it belong to objects made before, e.g.
    /// of a map loaded from an earlier run).
    pub fn reserve_ids(&mut self, next: u64) {
        self.next_id = self.next_id.max(next);
    }

    /// Bring back a known object as a live track with its id (no-op when a live track has it), its
    /// box filter started at `bbox` (where its map ellipsoid projects) and no match yet: an object
    /// mapped before that comes into view again is associated like a tracked one.
    pub fn recall(&mut self, id: TrackId, class: ClassId, bbox: &BBox) {
        if self.tracks.iter().any(|t| t.id == id) || !bbox.to_array().iter().all(|v| v.is_finite()) {
            return;
        }
        self.next_id = self.next_id.max(id.0 + 1);
        let at = self.tracks.partition_point(|t| t.id < id);
        let track =
            Track { id, class, filter: KalmanBoxFilter::new(bbox), last: *bbox, missed: 0, hits: 0, reference: None };
        self.tracks.insert(at, track);
    }

    /// Process one frame.
    pub fn step(&mut self, input: &TrackerInput<'_>) -> TrackerOutput {
        let predicted: Vec<BBox> = self.tracks.iter_mut().map(|t| t.filter.predict()).collect();
        let assignment = {
            let views: Vec<TrackView<'_>> = self
                .tracks
                .iter()
                .zip(&predicted)
                .map(|(t, p)| TrackView {
                    id: t.id,
                    class: t.class,
                    projected: input.projected.get(&t.id).copied(),
                    predicted: Some(input.predicted.get(&t.id).copied().unwrap_or(*p)),
                    last: t.last,
                    reference_region: t.reference.as_ref().map(|r| r.view()),
                })
                .collect();
            self.associator.associate(&slam_core::AssociationInput {
                detections: input.detections,
                tracks: &views,
                flow: input.flow,
            })
        };
        let mut out = TrackerOutput { tracks: vec![None; input.detections.len()], ..Default::default() };
        let mut matched = vec![false; self.tracks.len()];
        for &(d, id) in &assignment.matches {
            let Some(k) = self.tracks.iter().position(|t| t.id == id) else { continue };
            let Some(det) = input.detections.get(d) else { continue };
            let t = &mut self.tracks[k];
            t.filter.update(&det.bbox);
            t.last = det.bbox;
            t.missed = 0;
            t.hits += 1;
            if input.keyframe {
                t.reference = Some(region_of(det));
            }
            matched[k] = true;
            out.tracks[d] = Some(id);
        }
        for (k, t) in self.tracks.iter_mut().enumerate() {
            if !matched[k] {
                t.missed += 1;
                if input.keyframe {
                    t.reference = None;
                }
            }
        }
        let max_missed = self.config.max_missed;
        out.retired = self.tracks.iter().filter(|t| t.missed > max_missed).map(|t| t.id).collect();
        self.tracks.retain(|t| t.missed <= max_missed);
        for &d in &assignment.unmatched {
            let Some(det) = input.detections.get(d) else { continue };
            if !det.bbox.to_array().iter().all(|v| v.is_finite()) {
                tracing::debug!(detection = d, "skipping non-finite detection box");
                continue;
            }
            let id = TrackId(self.next_id);
            self.next_id += 1;
            self.tracks.push(Track {
                id,
                class: det.class,
                filter: KalmanBoxFilter::new(&det.bbox),
                last: det.bbox,
                missed: 0,
                hits: 1,
                reference: input.keyframe.then(|| region_of(det)),
            });
            out.created.push(id);
            out.tracks[d] = Some(id);
        }
        out
    }
}

fn region_of(d: &Detection) -> OwnedRegion {
    match &d.mask {
        Some(m) => OwnedRegion::Mask(m.clone()),
        None => OwnedRegion::Box(d.bbox),
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::IouAssociator;

    /// A known object recalled at its projected box is matched by the detection there and keeps its
    /// id; recalling it again while it lives changes nothing; new tracks take ids past the reserved
    /// ones; a recalled track that is never matched retires like any other.
    #[test]
    fn a_recalled_object_keeps_its_id_and_new_ones_come_after_the_reserved_ids() {
        let mut t = ObjectTracker::new(Box::new(IouAssociator::default()), TrackerConfig { max_missed: 2 });
        t.reserve_ids(10);
        let at = BBox::new(100.0, 100.0, 200.0, 160.0);
        t.recall(TrackId(4), ClassId(2), &at);
        t.recall(TrackId(4), ClassId(2), &at);
        t.recall(TrackId(2), ClassId(2), &BBox::new(500.0, 100.0, 560.0, 140.0));
        t.recall(TrackId(3), ClassId(2), &BBox::new(f64::NAN, 0.0, 1.0, 1.0));
        assert_eq!(t.tracks().iter().map(|x| x.id.0).collect::<Vec<_>>(), [2, 4], "in id order, once each, finite");
        let dets = [
            Detection::new(ClassId(2), 0.9, BBox::new(104.0, 102.0, 203.0, 161.0)),
            Detection::new(ClassId(2), 0.9, BBox::new(800.0, 100.0, 900.0, 170.0)),
        ];
        let projected = BTreeMap::new();
        let input =
            TrackerInput { detections: &dets, projected: &projected, predicted: &projected, flow: &[], keyframe: true };
        let out = t.step(&input);
        assert_eq!(out.tracks, [Some(TrackId(4)), Some(TrackId(10))]);
        for _ in 0..3 {
            t.step(&TrackerInput { detections: &dets[..1], ..input });
        }
        assert!(t.tracks().iter().all(|x| x.id != TrackId(2)), "never matched: retired");
    }
}
