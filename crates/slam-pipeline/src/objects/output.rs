//! The object map on disk (`objects.json`, version 1) and the saved map's form of an object.

use std::path::Path;

use serde::Serialize;

use super::{MappedObject, Observation};

/// Version of the object-map JSON.
pub const OBJECT_MAP_VERSION: u32 = 1;

/// An object as the object-map JSON stores it (the map file adds its map points).
#[derive(Serialize)]
struct ObjectJson {
    id: u64,
    class: u16,
    class_name: String,
    center: [f64; 3],
    semi_axes: [f64; 3],
    rotation: [f64; 9],
    frames: Vec<usize>,
    dynamic: bool,
    moving: bool,
}

#[derive(Serialize)]
struct MapJson<'a> {
    version: u32,
    frame: &'a str,
    objects: Vec<ObjectJson>,
}

impl MappedObject {
    /// The stored form (`None` without an ellipsoid): centre, semi-axes, rotation (3×3 row-major, world
    /// from object), frames, dynamic flag and map points.
    pub fn to_saved_object(&self) -> Option<crate::saved_map::SavedObject> {
        let e = self.ellipsoid.as_ref()?;
        let r = e.rotation();
        let kept = views_to_keep(&self.observations);
        Some(crate::saved_map::SavedObject {
            id: self.id.0,
            class: self.class.0,
            class_name: self.class.name().to_string(),
            center: [e.centre().x, e.centre().y, e.centre().z],
            semi_axes: [e.semi_axes.x, e.semi_axes.y, e.semi_axes.z],
            rotation: std::array::from_fn(|k| r[(k / 3, k % 3)]),
            frames: self.observations[self.earlier.min(self.observations.len())..].iter().map(|x| x.frame).collect(),
            dynamic: self.dynamic,
            moving: self.moving,
            points: self.points.iter().copied().collect(),
            views: kept.iter().map(|&k| self.observations[k].to_view()).collect(),
            earlier_views: kept.iter().filter(|&&k| k < self.earlier).count(),
        })
    }
}

/// The observations of an object a map keeps ([`MappedObject::to_saved_object`]), by index, in order: one
/// per reference keyframe, the one taken nearest that keyframe (the latest on a tie), and every one
/// without a reference. The frames between two keyframes see the object from about the same place; a
/// map used day after day over one road would otherwise keep each run's boxes of it (18, 28, 38, 48, 58
/// views over chained runs of the same frames), while its keyframes, and so its views, stop growing
/// once the road is mapped.
fn views_to_keep(observations: &[Observation]) -> Vec<usize> {
    let mut best: std::collections::BTreeMap<slam_core::KeyframeId, (f64, usize)> = Default::default();
    let mut kept = Vec::new();
    for (k, o) in observations.iter().enumerate() {
        match o.reference {
            Some((kf, rel)) => {
                let d = rel.translation.vector.norm();
                let e = best.entry(kf).or_insert((d, k));
                if d <= e.0 {
                    *e = (d, k);
                }
            }
            None => kept.push(k),
        }
    }
    kept.extend(best.values().map(|&(_, k)| k));
    kept.sort_unstable();
    kept
}

/// Write the object map (objects with an ellipsoid) as JSON, atomically, naming the world frame of the
/// poses the objects were mapped with "world of the input poses" ([`write_object_map_in`]).
pub fn write_object_map(path: &Path, objects: &[&MappedObject]) -> std::io::Result<()> {
    write_object_map_in(path, objects, INPUT_POSES_WORLD)
}

/// The world frame of an object map made from given poses ([`write_object_map`]), in words.
pub const INPUT_POSES_WORLD: &str = "world of the input poses (camera to world of the left camera)";

/// Write the object map (objects with an ellipsoid) as JSON, atomically. Schema (version 1): `frame`
/// (the world frame, in words), `objects` with `id`, `class` (COCO index), `class_name`, `center`
/// `[x, y, z]` and `rotation` (3×3 row-major, world from object) in that world frame, `semi_axes` metres
/// along the object's x (length), y (height), z (width), `frames` (frames of its detections), `dynamic`
/// (flagged dynamic by any test) and `moving` (its map points moved: not a mapped object).
pub fn write_object_map_in(path: &Path, objects: &[&MappedObject], frame: &str) -> std::io::Result<()> {
    slam_core::files::write_atomic(path, object_map_text(objects, frame)?.as_bytes()).map_err(std::io::Error::other)
}

/// The object map's JSON text ([`write_object_map_in`]), for writers that put it in place themselves.
pub fn object_map_text(objects: &[&MappedObject], frame: &str) -> std::io::Result<String> {
    let objects = objects
        .iter()
        .filter_map(|o| o.to_saved_object())
        .map(|m| ObjectJson {
            id: m.id,
            class: m.class,
            class_name: m.class_name,
            center: m.center,
            semi_axes: m.semi_axes,
            rotation: m.rotation,
            frames: m.frames,
            dynamic: m.dynamic,
            moving: m.moving,
        })
        .collect();
    serde_json::to_string_pretty(&MapJson { version: OBJECT_MAP_VERSION, frame, objects })
        .map_err(std::io::Error::other)
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;
    use slam_core::{geometry::BBox, ClassId, TrackId};
    use slam_quadric::{Camera, Ellipsoid, Intrinsics};

    use super::*;

    /// An object seen from frames 0-5 of an earlier run and 10-15 of this one: the map keeps one view per
    /// reference keyframe (the one nearest it, the latest on a tie) and each view without a keyframe, in
    /// order, and counts the earlier runs' among them; driving the same keyframes again adds no view.
    #[test]
    fn an_object_keeps_one_view_per_keyframe_that_saw_it() {
        let k = Intrinsics::new(707.0, 707.0, 601.9, 183.1);
        let seen = |frame: usize, reference: Option<(u64, f64)>| Observation {
            frame,
            camera: Camera::new(k, Isometry3::translation(0.0, 0.0, frame as f64)),
            bbox: BBox::new(100.0, 100.0, 200.0, 160.0),
            class: ClassId(2),
            detection: 0,
            centroid: None,
            depth_sigma: 0.0,
            reference: reference.map(|(kf, d)| (kf, Isometry3::translation(0.0, 0.0, d))),
        };
        let mut o = MappedObject::new(TrackId(4), ClassId(2));
        o.ellipsoid =
            Some(Ellipsoid::new(Isometry3::translation(0.0, 0.0, 20.0), nalgebra::Vector3::new(2.0, 0.8, 0.9)));
        // an earlier run: keyframe 1 from frames 0-2, keyframe 2 from 3-4, frame 5 without a keyframe
        o.observations = vec![
            seen(0, Some((1, 0.0))),
            seen(1, Some((1, 1.2))),
            seen(2, Some((1, 2.4))),
            seen(3, Some((2, 0.0))),
            seen(4, Some((2, 1.2))),
            seen(5, None),
        ];
        o.earlier = o.observations.len();
        // this run over the same keyframes: frame 10 as near keyframe 1 as frame 0 was, frame 11 farther
        o.observations.extend([seen(10, Some((1, 0.0))), seen(11, Some((2, 0.6))), seen(12, Some((3, 0.0)))]);
        let m = o.to_saved_object().expect("an ellipsoid");
        let frames: Vec<usize> = m.views.iter().map(|v| v.frame).collect();
        assert_eq!(frames, [3, 5, 10, 12], "keyframe 1: frame 10 (a tie with 0, the latest), keyframe 2: frame 3");
        assert_eq!(m.earlier_views, 2, "frames 3 and 5 come from the earlier run");
        assert_eq!(m.frames, [10, 11, 12], "this run's detections");
        // the same run again over the same keyframes keeps as many views
        let mut again = o.clone();
        again.observations.extend([seen(20, Some((1, 0.5))), seen(21, Some((2, 0.9))), seen(22, Some((3, 0.2)))]);
        assert_eq!(again.to_saved_object().expect("an ellipsoid").views.len(), 4);
    }
}
