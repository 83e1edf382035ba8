//! Association glue: one box per object ([`suppress_duplicate_boxes`]), and a frame's detections
//! given to the associator with the objects' projected ellipsoids and recorded as observations
//! ([`ObjectMapper::associate`], [`ObjectMapper::step`]).

use std::collections::BTreeMap;

use slam_assoc::TrackerInput;
use slam_core::{geometry::BBox, Detection, KeyframeId, PointPair, TrackId};
use slam_quadric::{project, Camera};

use super::{MappedObject, ObjectMapper, Observation};

/// IoU above which two boxes of one class group are one object (the detector's own class-wise NMS
/// threshold).
const DUPLICATE_IOU: f64 = 0.45;

/// Share of a box's area inside a larger box of its class group above which it is a part of that
/// object (a tile's cut of a car, its front or its wheels boxed again).
const NESTED_SHARE: f64 = 0.8;

/// One box per object: boxes of one class group (car / bus / truck; bicycle / motorcycle) that overlap
/// a larger kept box by IoU above 0.45 (the same object boxed twice: across tiles, or as two classes)
/// or lie inside it by 80 % of their area (a part of it) are dropped. Larger boxes are kept first (the
/// whole object, not its part); ties by score, then by position, so the result is deterministic.
/// Returns the kept boxes in their input order and how many were dropped.
pub fn suppress_duplicate_boxes(detections: Vec<Detection>) -> (Vec<Detection>, usize) {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    let key = |d: &Detection| (d.bbox.area(), d.score, d.bbox.xmin, d.bbox.ymin);
    order.sort_by(|&a, &b| {
        let (ka, kb) = (key(&detections[a]), key(&detections[b]));
        kb.0.total_cmp(&ka.0).then(kb.1.total_cmp(&ka.1)).then(ka.2.total_cmp(&kb.2)).then(ka.3.total_cmp(&kb.3))
    });
    let mut keep = vec![false; detections.len()];
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        let d = &detections[i];
        let duplicate = kept.iter().any(|&j| {
            let o = &detections[j];
            o.class.group() == d.class.group()
                && (o.bbox.iou(&d.bbox) > DUPLICATE_IOU
                    || o.bbox.intersection(&d.bbox).is_some_and(|x| x.area() >= NESTED_SHARE * d.bbox.area()))
        });
        if !duplicate {
            keep[i] = true;
            kept.push(i);
        }
    }
    let dropped = keep.iter().filter(|k| !**k).count();
    (detections.into_iter().zip(keep).filter_map(|(d, k)| k.then_some(d)).collect(), dropped)
}

impl ObjectMapper {
    /// Process one frame and fit the touched objects that are due, on this thread (image-free mode);
    /// returns each detection's object.
    pub fn step(&mut self, frame: usize, camera: &Camera, detections: &[Detection]) -> Vec<Option<TrackId>> {
        let tracks = self.associate(frame, camera, None, detections, &[]);
        let mut touched: Vec<TrackId> = tracks.iter().flatten().copied().collect();
        touched.sort();
        touched.dedup();
        for id in touched {
            if let Some(job) = self.job_for(id) {
                let result = job.run(&[]);
                self.apply(result);
            }
        }
        tracks
    }

    /// Associate one frame's detections with the objects (ODA with the projected ellipsoids and, when
    /// given, keypoints tracked from the previous frame by optical flow) and record the observations;
    /// returns each detection's object. No fitting: see [`ObjectMapper::fit_jobs`].
    pub fn associate(
        &mut self,
        frame: usize,
        camera: &Camera,
        reference: Option<(KeyframeId, nalgebra::Isometry3<f64>)>,
        detections: &[Detection],
        flow: &[PointPair],
    ) -> Vec<Option<TrackId>> {
        let projected: BTreeMap<TrackId, BBox> = self
            .objects
            .values()
            .filter_map(|o| {
                let e = o.ellipsoid.as_ref()?;
                let b = project(e, camera).and_then(|c| c.clipped_bounds(&self.config.image)).ok()?;
                Some((o.id, b))
            })
            .collect();
        // a loaded map's objects in view come back as tracks (their projected box as the prediction)
        for id in &self.loaded {
            let (Some(b), Some(o)) = (projected.get(id), self.objects.get(id)) else { continue };
            if !o.moving && !self.tracker.tracks().iter().any(|t| t.id == *id) {
                self.tracker.recall(*id, o.class, b);
            }
        }
        let out = self.tracker.step(&TrackerInput { detections, projected: &projected, flow, keyframe: true });
        self.count_misses(camera, &projected, detections, &out.tracks);
        for (k, (t, d)) in out.tracks.iter().zip(detections).enumerate() {
            let Some(id) = *t else { continue };
            if self.merged.contains_key(&id) {
                continue;
            }
            let obj = self.objects.entry(id).or_insert_with(|| MappedObject::new(id, d.class));
            obj.observations.push(Observation {
                frame,
                camera: *camera,
                bbox: d.bbox,
                class: d.class,
                detection: k,
                centroid: None,
                depth_sigma: 0.0,
                reference,
            });
            obj.class = obj.majority_class();
        }
        out.tracks
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::ClassId;

    #[test]
    fn one_box_per_object_across_tiles_parts_and_class_groups() {
        let d = |class: u16, score: f64, b: [f64; 4]| {
            Detection::new(ClassId(class), score, BBox::new(b[0], b[1], b[2], b[3]))
        };
        let input = vec![
            d(2, 0.6, [100.0, 100.0, 200.0, 180.0]), // a car
            d(2, 0.9, [105.0, 102.0, 196.0, 178.0]), // the same car from another tile (IoU 0.86)
            d(7, 0.5, [98.0, 95.0, 203.0, 182.0]),   // the same car called a truck: same class group
            d(2, 0.8, [150.0, 120.0, 198.0, 178.0]), // its front half: a part
            d(0, 0.7, [150.0, 110.0, 170.0, 170.0]), // a person in front of it: another group, kept
            d(2, 0.7, [400.0, 100.0, 480.0, 160.0]), // another car
            d(2, 0.7, [470.0, 100.0, 560.0, 160.0]), // its neighbour, overlapping a little: kept
        ];
        let (kept, dropped) = suppress_duplicate_boxes(input.clone());
        assert_eq!(dropped, 3);
        // the largest box of the first car (the "truck") stands for it; input order is kept
        let boxes: Vec<[f64; 2]> = kept.iter().map(|k| [k.bbox.xmin, k.bbox.ymin]).collect();
        assert_eq!(boxes, vec![[98.0, 95.0], [150.0, 110.0], [400.0, 100.0], [470.0, 100.0]]);
        // deterministic whatever the input order
        let mut reversed = input;
        reversed.reverse();
        let (again, n) = suppress_duplicate_boxes(reversed);
        assert_eq!(n, 3);
        let mut a: Vec<[f64; 2]> = again.iter().map(|k| [k.bbox.xmin, k.bbox.ymin]).collect();
        a.reverse();
        assert_eq!(a, boxes);
    }
}
