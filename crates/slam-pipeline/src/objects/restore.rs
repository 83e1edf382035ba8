//! Objects of a map loaded from an earlier run ([`ObjectMapper::restore`]): each keeps its id, class,
//! ellipsoid, flags, map points and the detections it was fitted from, so that a later run's
//! detections of it join the same object (it re-enters association as a track whenever its ellipsoid
//! projects into the view, [`ObjectMapper::associate`]) and its next fit uses both runs' boxes.

use slam_core::{geometry::BBox, ClassId, TrackId};
use slam_quadric::{Camera, Ellipsoid, Intrinsics};

use super::{MappedObject, ObjectMapper, Observation};
use crate::saved_map::{pose_from_array, pose_to_array, ObjectView, SavedObject};

impl ObjectMapper {
    /// Take the objects of a loaded map (`k`: the run's left camera, for their views); new objects
    /// get ids after the highest loaded one. Returns how many were restored with an ellipsoid.
    pub fn restore(&mut self, objects: &[SavedObject], k: Intrinsics) -> usize {
        let mut restored = 0;
        for o in objects {
            let id = TrackId(o.id);
            let mut obj = MappedObject::new(id, ClassId(o.class));
            let r = nalgebra::Matrix3::from_row_slice(&o.rotation);
            let rotation = nalgebra::UnitQuaternion::from_matrix(&r);
            let pose = nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::from(nalgebra::Vector3::from(o.center)),
                rotation,
            );
            obj.ellipsoid = Some(Ellipsoid::new(pose, nalgebra::Vector3::from(o.semi_axes)));
            obj.dynamic = o.dynamic;
            obj.moving = o.moving;
            obj.points = o.points.iter().copied().collect();
            obj.observations = o
                .views
                .iter()
                .enumerate()
                .map(|(detection, v)| Observation {
                    frame: v.frame,
                    camera: Camera::new(k, pose_from_array(&v.pose)),
                    bbox: BBox::new(v.bbox[0], v.bbox[1], v.bbox[2], v.bbox[3]),
                    class: ClassId(v.class),
                    detection,
                    centroid: None,
                    depth_sigma: 0.0,
                    reference: v.reference.map(|(kf, rel)| (kf, pose_from_array(&rel))),
                })
                .collect();
            obj.earlier = obj.observations.len();
            // fitted from these already: the next fit waits for the new run's boxes (counted as the
            // fits count them: the boxes clear of the image border)
            let (image, margin) = (self.config.image, self.config.border_margin_px);
            obj.fitted_at = obj.observations.iter().filter(|x| !x.bbox.touches_border(&image, margin)).count();
            restored += 1;
            self.loaded.insert(id);
            self.objects.insert(id, obj);
        }
        if let Some(max) = objects.iter().map(|o| o.id).max() {
            self.tracker.reserve_ids(max + 1);
        }
        restored
    }
}

impl Observation {
    /// The stored form of an observation.
    pub fn to_view(&self) -> ObjectView {
        let b = self.bbox;
        ObjectView {
            frame: self.frame,
            pose: pose_to_array(&self.camera.world_from_camera),
            bbox: [b.xmin, b.ymin, b.xmax, b.ymax],
            class: self.class.0,
            reference: self.reference.map(|(kf, rel)| (kf, pose_to_array(&rel))),
        }
    }
}
