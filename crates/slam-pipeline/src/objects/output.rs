//! The object map on disk (`objects.json`, version 1) and the map database's form of an object.

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
    pub fn to_map_object(&self) -> Option<crate::map::MapObject> {
        let e = self.ellipsoid.as_ref()?;
        let r = e.rotation();
        Some(crate::map::MapObject {
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
            views: self.observations.iter().map(Observation::to_view).collect(),
            earlier_views: self.earlier,
        })
    }
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
        .filter_map(|o| o.to_map_object())
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
