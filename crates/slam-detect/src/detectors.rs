//! Wrappers around any detection source (the network, a file, labels), used by `slam-app run`:
//! - [`ClassFilter`]: keeps the classes the system maps as objects ([`OBJECT_CLASSES`]);
//! - [`DetectionGuard`]: bounds on what a source hands the system: the mapped classes only, boxes
//!   clipped to the image (refused when nothing of them is inside), at most `max` per frame (the highest
//!   scores), every change counted;
//! - [`unused_frames`]: reports of detections that no frame of the run will use.

use std::sync::{
    atomic::{AtomicUsize, Ordering},
    Arc,
};

use slam_core::{geometry::BBox, DetectError, Detection, DetectionSource, Image};

/// What the guard changed, over a run.
#[derive(Debug, Default)]
pub struct DetectionCounts {
    /// Boxes of classes the system does not map as objects ([`OBJECT_CLASSES`]), skipped.
    pub other_classes: AtomicUsize,
    /// Boxes reaching past the image border, clipped to it.
    pub clipped: AtomicUsize,
    /// Boxes with nothing inside the image (or non-finite), refused.
    pub outside: AtomicUsize,
    /// Boxes over the per-frame limit, dropped (lowest scores first).
    pub over_limit: AtomicUsize,
    /// Frames that hit the limit.
    pub frames_limited: AtomicUsize,
}

impl DetectionCounts {
    /// One line for the run's summary.
    pub fn summary(&self, max: usize) -> String {
        let get = |a: &AtomicUsize| a.load(Ordering::Relaxed);
        format!(
            "detection bounds: {} boxes clipped to the image, {} refused (outside the image), {} dropped over the \
             limit of {max} per frame (in {} frames), {} of classes not mapped as objects skipped (mapped: person, \
             bicycle, car, motorcycle, bus, truck)",
            get(&self.clipped),
            get(&self.outside),
            get(&self.over_limit),
            get(&self.frames_limited),
            get(&self.other_classes)
        )
    }
}

/// Clip `b` to a `w × h` image: `None` when less than a pixel of it is inside (or it is not finite), else
/// the clipped box and whether it changed.
pub fn clip(b: BBox, w: f64, h: f64) -> Option<(BBox, bool)> {
    let a = b.to_array();
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let c = BBox::new(b.xmin.clamp(0.0, w), b.ymin.clamp(0.0, h), b.xmax.clamp(0.0, w), b.ymax.clamp(0.0, h));
    if c.width() < 1.0 || c.height() < 1.0 {
        return None;
    }
    Some((c, c != b))
}

/// Keep the `max` highest-scored detections (ties: the earlier one), in their original order; returns how
/// many were dropped.
pub fn limit(dets: &mut Vec<Detection>, max: usize) -> usize {
    if dets.len() <= max {
        return 0;
    }
    let mut order: Vec<usize> = (0..dets.len()).collect();
    order.sort_by(|&i, &j| dets[j].score.total_cmp(&dets[i].score).then(i.cmp(&j)));
    let mut keep = vec![false; dets.len()];
    for &i in &order[..max] {
        keep[i] = true;
    }
    let dropped = dets.len() - max;
    let mut k = keep.into_iter();
    dets.retain(|_| k.next().unwrap_or(false));
    dropped
}

/// COCO classes mapped as objects: person, bicycle, car, motorcycle, bus, truck.
pub const OBJECT_CLASSES: [u16; 6] = [0, 1, 2, 3, 5, 7];

/// Whether a detection is of a class mapped as objects ([`OBJECT_CLASSES`]).
fn mapped(d: &Detection) -> bool {
    OBJECT_CLASSES.contains(&d.class.0)
}

/// Keeps the detections of the mapped classes ([`OBJECT_CLASSES`]) only.
pub struct ClassFilter(pub Box<dyn DetectionSource>);

impl DetectionSource for ClassFilter {
    fn name(&self) -> &str {
        self.0.name()
    }
    fn needs_image(&self) -> bool {
        self.0.needs_image()
    }
    fn detect(&mut self, frame: usize, image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let mut d = self.0.detect(frame, image)?;
        d.retain(mapped);
        Ok(d)
    }
    fn forward_ms(&self) -> Option<f64> {
        self.0.forward_ms()
    }
    fn clipped(&self) -> usize {
        self.0.clipped()
    }
}

/// A detection source with its output bounded (see the module).
pub struct DetectionGuard {
    inner: Box<dyn DetectionSource>,
    size: [f64; 2],
    max: usize,
    counts: Arc<DetectionCounts>,
}

impl DetectionGuard {
    /// Wrap `inner` for images of `size = [width, height]`, at most `max` detections per frame.
    pub fn new(inner: Box<dyn DetectionSource>, size: [f64; 2], max: usize) -> (Self, Arc<DetectionCounts>) {
        let counts = Arc::new(DetectionCounts::default());
        (Self { inner, size, max, counts: counts.clone() }, counts)
    }
}

impl DetectionSource for DetectionGuard {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn needs_image(&self) -> bool {
        self.inner.needs_image()
    }
    fn detect(&mut self, frame: usize, image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let mut raw = self.inner.detect(frame, image)?;
        let all = raw.len();
        raw.retain(mapped);
        self.counts.other_classes.fetch_add(all - raw.len(), Ordering::Relaxed);
        let [w, h] = self.size;
        let (mut clipped, mut outside) = (0, 0);
        let mut dets = Vec::with_capacity(raw.len());
        for mut d in raw {
            match clip(d.bbox, w, h) {
                None => outside += 1,
                Some((b, changed)) => {
                    clipped += changed as usize;
                    d.bbox = b;
                    dets.push(d);
                }
            }
        }
        // boxes the source clipped itself reached past the image as much as those clipped here
        clipped += self.inner.clipped();
        let dropped = limit(&mut dets, self.max);
        if clipped + outside + dropped > 0 {
            tracing::debug!(frame, clipped, outside, dropped, "detections bounded");
        }
        self.counts.clipped.fetch_add(clipped, Ordering::Relaxed);
        self.counts.outside.fetch_add(outside, Ordering::Relaxed);
        self.counts.over_limit.fetch_add(dropped, Ordering::Relaxed);
        self.counts.frames_limited.fetch_add((dropped > 0) as usize, Ordering::Relaxed);
        Ok(dets)
    }
    fn forward_ms(&self) -> Option<f64> {
        self.inner.forward_ms()
    }
    fn clipped(&self) -> usize {
        self.inner.clipped()
    }
}

/// Detections of frames the run does not play: `per_frame` is (frame id, boxes) of a source, `played` the
/// frame ids played (increasing). `None` when every frame with boxes is played.
pub fn unused_frames(
    source: &str,
    per_frame: impl Iterator<Item = (usize, usize)>,
    played: &[usize],
) -> Option<String> {
    let (Some(&first), Some(&last)) = (played.first(), played.last()) else { return None };
    let (mut after, mut after_boxes, mut other, mut other_boxes) = (Vec::new(), 0, 0, 0);
    let (mut before, mut before_boxes) = (Vec::new(), 0);
    for (f, n) in per_frame {
        if f > last {
            after.push(f);
            after_boxes += n;
        } else if f < first {
            before.push(f);
            before_boxes += n;
        } else if played.binary_search(&f).is_err() {
            other += 1;
            other_boxes += n;
        }
    }
    let mut parts = Vec::new();
    if !before.is_empty() {
        before.sort_unstable();
        parts.push(format!(
            "{} frames ({before_boxes} boxes) lie before the first frame played, {first} (last: frame {}), not used",
            before.len(),
            before[before.len() - 1]
        ));
    }
    if !after.is_empty() {
        after.sort_unstable();
        parts.push(format!(
            "{} frames ({after_boxes} boxes) lie after the last frame played, {last} (first: frame {}), not used",
            after.len(),
            after[0]
        ));
    }
    if other > 0 {
        parts.push(format!(
            "{other} frames ({other_boxes} boxes) within ids {first}..={last} are not played (missing images or \
             --frames/--stride), not used"
        ));
    }
    (!parts.is_empty()).then(|| format!("{source}: {}", parts.join("; ")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::ClassId;

    fn det(score: f64, b: [f64; 4]) -> Detection {
        Detection::new(ClassId(2), score, BBox::from_array(b))
    }

    #[test]
    fn boxes_are_clipped_or_refused() {
        let inside = BBox::new(10.0, 10.0, 50.0, 40.0);
        assert_eq!(clip(inside, 100.0, 50.0), Some((inside, false)));
        let (c, changed) = clip(BBox::new(-20.0, 10.0, 50.0, 80.0), 100.0, 50.0).expect("overlaps");
        assert!(changed && c == BBox::new(0.0, 10.0, 50.0, 50.0), "{c:?}");
        assert_eq!(clip(BBox::new(5000.0, 10.0, 5100.0, 40.0), 100.0, 50.0), None);
        assert_eq!(clip(BBox::new(-100.0, -90.0, -50.0, -40.0), 100.0, 50.0), None);
        assert_eq!(clip(BBox::new(99.5, 10.0, 300.0, 40.0), 100.0, 50.0), None, "half a pixel inside");
        assert_eq!(clip(BBox::new(f64::NAN, 10.0, 30.0, 40.0), 100.0, 50.0), None);
    }

    #[test]
    fn the_limit_keeps_the_best_scores_in_their_order() {
        let mut d: Vec<Detection> =
            [0.3, 0.9, 0.5, 0.9, 0.1].iter().enumerate().map(|(i, &s)| det(s, [i as f64, 0.0, 10.0, 10.0])).collect();
        assert_eq!(limit(&mut d, 3), 2);
        let kept: Vec<(f64, f64)> = d.iter().map(|d| (d.score, d.bbox.xmin)).collect();
        assert_eq!(kept, [(0.9, 1.0), (0.5, 2.0), (0.9, 3.0)]);
        let before = d.clone();
        assert_eq!(limit(&mut d, 3), 0);
        assert_eq!(d, before, "under the limit nothing changes");
    }

    struct Fixed(Vec<Detection>);
    impl DetectionSource for Fixed {
        fn name(&self) -> &str {
            "fixed"
        }
        fn needs_image(&self) -> bool {
            false
        }
        fn detect(&mut self, _: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
            Ok(self.0.clone())
        }
    }

    #[test]
    fn the_guard_counts_what_it_changed() {
        let mut boxes = vec![det(0.8, [10.0, 10.0, 50.0, 40.0]), det(0.7, [-5.0, 0.0, 20.0, 20.0])];
        boxes.push(det(0.9, [2000.0, 10.0, 2100.0, 40.0]));
        boxes.extend((0..5).map(|i| det(0.1, [i as f64, 0.0, 30.0, 30.0])));
        // a traffic light and a bench: classes not mapped as objects, skipped first and counted
        boxes.push(Detection::new(ClassId(9), 0.95, BBox::new(1.0, 1.0, 9.0, 20.0)));
        boxes.push(Detection::new(ClassId(13), 0.95, BBox::new(30.0, 1.0, 90.0, 20.0)));
        let (mut g, counts) = DetectionGuard::new(Box::new(Fixed(boxes)), [1242.0, 375.0], 4);
        let out = g.detect(0, None).expect("detects");
        assert_eq!(out.len(), 4);
        assert_eq!(out[0].score, 0.8);
        assert_eq!(out[1].bbox.xmin, 0.0);
        assert!(out.iter().all(|d| d.class == ClassId(2)));
        let s = counts.summary(4);
        assert!(
            s.contains("1 boxes clipped")
                && s.contains("1 refused")
                && s.contains("3 dropped")
                && s.contains("in 1 frames")
                && s.contains("2 of classes not mapped as objects skipped"),
            "{s}"
        );
    }

    /// A source that clipped boxes itself (a network's boxes reaching past its input) has them counted
    /// with the guard's own, through the class filter too.
    #[test]
    fn boxes_the_source_clipped_itself_are_counted() {
        struct ClippedTwo;
        impl DetectionSource for ClippedTwo {
            fn name(&self) -> &str {
                "clipped"
            }
            fn needs_image(&self) -> bool {
                false
            }
            fn detect(&mut self, _: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
                Ok(vec![det(0.9, [0.0, 0.0, 1242.0, 375.0]), det(0.8, [-3.0, 5.0, 30.0, 30.0])])
            }
            fn clipped(&self) -> usize {
                2
            }
        }
        let filtered = ClassFilter(Box::new(ClippedTwo));
        assert_eq!(filtered.clipped(), 2);
        let (mut g, counts) = DetectionGuard::new(Box::new(filtered), [1242.0, 375.0], 100);
        assert_eq!(g.detect(0, None).expect("detects").len(), 2);
        assert!(counts.summary(100).contains("3 boxes clipped to the image"), "{}", counts.summary(100));
    }

    #[test]
    fn the_class_filter_keeps_mapped_classes_only() {
        let boxes: Vec<Detection> = [0u16, 2, 9, 7, 56]
            .iter()
            .map(|&c| Detection::new(ClassId(c), 0.5, BBox::new(0.0, 0.0, 10.0, 10.0)))
            .collect();
        let mut f = ClassFilter(Box::new(Fixed(boxes)));
        let kept: Vec<u16> = f.detect(0, None).expect("detects").iter().map(|d| d.class.0).collect();
        assert_eq!(kept, [0, 2, 7], "person, car, truck kept; traffic light (9) and chair (56) dropped");
        assert_eq!(f.name(), "fixed");
    }

    /// A source that says its network took 7.5 ms.
    struct Timed;
    impl DetectionSource for Timed {
        fn name(&self) -> &str {
            "timed"
        }
        fn needs_image(&self) -> bool {
            false
        }
        fn detect(&mut self, _: usize, _: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
            Ok(vec![det(0.9, [0.0, 0.0, 10.0, 10.0])])
        }
        fn forward_ms(&self) -> Option<f64> {
            Some(7.5)
        }
    }

    #[test]
    fn the_wrappers_pass_the_forward_time_on() {
        let mut filter = ClassFilter(Box::new(Timed));
        filter.detect(0, None).expect("detects");
        assert_eq!(filter.forward_ms(), Some(7.5));
        let (guard, _) = DetectionGuard::new(Box::new(filter), [100.0, 100.0], 10);
        assert_eq!(guard.forward_ms(), Some(7.5));
        assert_eq!(ClassFilter(Box::new(Fixed(Vec::new()))).forward_ms(), None, "no network, no time");
    }

    #[test]
    fn unused_frames_are_reported() {
        assert_eq!(unused_frames("f", [(0, 3), (4, 1)].into_iter(), &[0, 1, 2, 3, 4]), None);
        assert_eq!(unused_frames("f", [(0, 3)].into_iter(), &[]), None);
        let m =
            unused_frames("f.json", [(0, 3), (7, 2), (9, 1), (2, 5)].into_iter(), &[0, 1, 3, 4, 5]).expect("reported");
        assert!(m.contains("2 frames (3 boxes) lie after the last frame played, 5 (first: frame 7)"), "{m}");
        assert!(m.contains("1 frames (5 boxes) within ids 0..=5 are not played"), "{m}");
        // a run starting at frame 20 (`--frames 20..`): frames 0..=19 are before it, not "within" it
        let m =
            unused_frames("l.txt", [(3, 2), (19, 1), (20, 4), (22, 1)].into_iter(), &[20, 21, 23]).expect("reported");
        assert!(m.contains("2 frames (3 boxes) lie before the first frame played, 20 (last: frame 19)"), "{m}");
        assert!(m.contains("1 frames (1 boxes) within ids 20..=23 are not played"), "{m}");
        assert!(!m.contains("after"), "{m}");
    }
}
