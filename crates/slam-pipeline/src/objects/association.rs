//! Association glue: one box per object ([`suppress_duplicate_boxes`]), and a frame's detections
//! given to the associator with the objects' projected ellipsoids and recorded as observations
//! ([`ObjectMapper::associate`], [`ObjectMapper::step`]).

use std::collections::BTreeMap;

use nalgebra::{Point3, Vector3};
use slam_assoc::TrackerInput;
use slam_core::{geometry::BBox, Detection, KeyframeId, PointPair, TrackId};
use slam_quadric::{project, Camera, ImageSize};

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

/// Where an object is expected in the view of `camera` at `frame` (a frame id), from its 3-D position
/// and the camera's motion: its latest box, placed at the depth of its latest stereo centroid in that
/// box's camera (a rectangle facing that camera), moved by the object's own motion since (a moving
/// object's rate now, [`super::motion::current_rate`]; none for a static one) and projected into `camera`, clipped to the
/// image. The camera's motion between the two frames is what moves and grows a box when frames are far
/// apart; a constant image velocity (the Kalman filter's) does not follow it. `None` without a
/// centroid, for a moving object without a measured rate, or when the box does not lie in front of
/// the camera.
pub fn predict_box(o: &MappedObject, frame: usize, camera: &Camera, image: &ImageSize) -> Option<BBox> {
    let last = o.observations.last()?;
    let (seen, centroid) = o.observations.iter().rev().find_map(|x| x.centroid.map(|c| (x.frame, c)))?;
    let rate = if o.moving { super::motion::current_rate(o)? } else { Vector3::zeros() };
    let at_last = centroid + rate * last.frame.saturating_sub(seen) as f64;
    let from_last = last.camera.camera_from_world();
    let depth = (from_last * Point3::from(at_last)).z;
    // a box nearer than a metre is no object the detector boxes whole (and the division blows up)
    if depth.is_nan() || depth < 1.0 {
        return None;
    }
    let k = &last.camera.intrinsics;
    let moved = rate * frame.saturating_sub(last.frame) as f64;
    let b = &last.bbox;
    let mut bounds = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for (u, v) in [(b.xmin, b.ymin), (b.xmax, b.ymin), (b.xmin, b.ymax), (b.xmax, b.ymax)] {
        let y = (v - k.cy) / k.fy;
        let x = (u - k.cx - k.skew * y) / k.fx;
        let world = last.camera.world_from_camera * Point3::new(x * depth, y * depth, depth) + moved;
        let p = camera.project_point(&world)?;
        bounds = [bounds[0].min(p.x), bounds[1].min(p.y), bounds[2].max(p.x), bounds[3].max(p.y)];
    }
    let clipped =
        BBox::new(bounds[0].max(0.0), bounds[1].max(0.0), bounds[2].min(image.width), bounds[3].min(image.height));
    (clipped.xmax > clipped.xmin && clipped.ymax > clipped.ymin).then_some(clipped)
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
        // where each object's stereo points say it is, carried into this camera
        let predicted: BTreeMap<TrackId, BBox> = self
            .objects
            .values()
            .filter(|o| !self.merged.contains_key(&o.id))
            .filter_map(|o| Some((o.id, predict_box(o, frame, camera, &self.config.image)?)))
            .collect();
        let out = self.tracker.step(&TrackerInput {
            detections,
            projected: &projected,
            predicted: &predicted,
            flow,
            keyframe: true,
        });
        if tracing::enabled!(tracing::Level::TRACE) {
            for (d, t) in detections.iter().zip(&out.tracks) {
                let p = t.and_then(|t| predicted.get(&t));
                tracing::trace!(frame, class = d.class.0, bbox = ?d.bbox.to_array(), track = ?t.map(|t| t.0), predicted = ?p.map(|b| b.to_array()), "associated");
            }
            for (id, b) in &predicted {
                tracing::trace!(frame, track = id.0, predicted = ?b.to_array(), "predicted box");
            }
        }
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
    use slam_core::TrackId;

    #[test]
    fn a_box_is_predicted_from_the_object_s_depth_and_the_camera_s_motion() {
        use slam_quadric::Intrinsics;
        let k = Intrinsics::new(721.5, 721.5, 609.6, 172.9);
        let image = ImageSize::new(1242.0, 375.0);
        // a car-sized rectangle facing the camera, 4 m to the left, 15 m ahead
        let corners = [(-5.0, -0.5, 15.0), (-3.0, -0.5, 15.0), (-5.0, 1.0, 15.0), (-3.0, 1.0, 15.0)];
        let seen_from = |pose: nalgebra::Isometry3<f64>| {
            let cam = Camera::new(k, pose);
            let px: Vec<_> =
                corners.iter().map(|&(x, y, z)| cam.project_point(&Point3::new(x, y, z)).unwrap()).collect();
            let xs = px.iter().map(|p| p.x);
            let ys = px.iter().map(|p| p.y);
            BBox::new(
                xs.clone().fold(f64::INFINITY, f64::min),
                ys.clone().fold(f64::INFINITY, f64::min),
                xs.fold(f64::NEG_INFINITY, f64::max),
                ys.fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let first = nalgebra::Isometry3::identity();
        let mut car = MappedObject::new(TrackId(1), ClassId(2));
        car.observations.push(Observation {
            frame: 10,
            camera: Camera::new(k, first),
            bbox: seen_from(first),
            class: ClassId(2),
            detection: 0,
            centroid: Some(Vector3::new(-4.0, 0.25, 15.0)),
            depth_sigma: 0.3,
            reference: None,
        });
        // three frames on, the camera drove 6 m forward and turned 5° to the left: the box has moved
        // out and grown in ways a constant image velocity cannot know
        let now = nalgebra::Isometry3::new(Vector3::new(0.0, 0.0, 6.0), Vector3::new(0.0, -5f64.to_radians(), 0.0));
        let truth = seen_from(now);
        let predicted = predict_box(&car, 13, &Camera::new(k, now), &image).expect("in view");
        assert!(predicted.iou(&truth) > 0.95, "{predicted:?} vs {truth:?}");
        let stale = car.observations[0].bbox.iou(&truth);
        assert!(stale < 0.5, "the last box alone is far off: IoU {stale}");
        // no centroid: no prediction; a moving object without a measured rate: none either
        let mut without = car.clone();
        without.observations[0].centroid = None;
        assert!(predict_box(&without, 13, &Camera::new(k, now), &image).is_none());
        let mut moving = car.clone();
        moving.moving = true;
        assert!(predict_box(&moving, 13, &Camera::new(k, now), &image).is_none());
        // with its rate it is carried along: 1 m per frame id towards +x for 3 frame ids
        moving.flows.push((
            10,
            1,
            crate::objects::SceneFlow::new(Vector3::new(1.0, 0.0, 0.0), Vector3::z(), (0.1, 0.1), 20),
        ));
        let ahead = predict_box(&moving, 13, &Camera::new(k, now), &image).expect("in view");
        let shifted = {
            let cam = Camera::new(k, now);
            let p: Vec<_> =
                corners.iter().map(|&(x, y, z)| cam.project_point(&Point3::new(x + 3.0, y, z)).unwrap()).collect();
            BBox::new(p[0].x.min(p[2].x), p[0].y.min(p[1].y), p[1].x.max(p[3].x), p[2].y.max(p[3].y))
        };
        assert!(ahead.iou(&shifted) > 0.9, "{ahead:?} vs {shifted:?}");
        // behind the camera: nothing
        let behind = nalgebra::Isometry3::new(Vector3::new(0.0, 0.0, 30.0), Vector3::zeros());
        assert!(predict_box(&car, 20, &Camera::new(k, behind), &image).is_none());
    }

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
