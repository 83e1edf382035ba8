//! Composition of the SLAM parts: the threaded system ([`system`]: detection, tracking and local
//! mapping threads talking through channels; the tracking thread owns the live map), the saved map
//! ([`saved_map`]: the file form of a run's map, written once the run ends), local bundle adjustment
//! ([`mapping`]), the object mapper ([`objects`]: association, ellipsoid initialisation and
//! optimisation) and the objects' texture planes ([`texture`]).
//!
//! OpenCV stays out: the visual front end comes in through `slam_core::StereoTracker`, detections
//! through `slam_core::DetectionSource`.

#![warn(missing_docs)]

pub mod mapping;
pub mod objects;
pub mod saved_map;
pub mod serde_forms;
pub mod settings;
pub mod system;
pub mod texture;
pub mod tracking_states;
pub mod yaw_cue;
