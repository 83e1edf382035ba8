//! Shared vocabulary and trait seams of the quadric-SLAM workspace.
//!
//! Implementation crates meet here instead of depending on each other: `slam-assoc` implements
//! [`assoc::Associator`], `slam-frontend` implements [`tracking::StereoTracker`] (with what the objects
//! ask of it, [`tracking::object_inputs`]) and [`source::DetectionSource`], and the pipeline holds `Box<dyn …>` values chosen from configuration.
//! The crate is deliberately small: typed ids, object classes, detections with optional instance masks,
//! images, the association, detection and tracking contracts (the tracking one with its conformance
//! suite, [`tracker_conformance`]), and the rules every file reader and writer
//! follows ([`files`]: regular files only, a size cap, atomic writes), figures of sets that may be empty
//! ([`figure`]: a dash, never NaN) and the memory a command may still take ([`memory`]). Geometry comes from `slam-quadric`, re-exported as [`geometry`].

#![warn(missing_docs)]

pub mod assoc;
pub mod check;
pub mod detection;
pub mod figure;
pub mod files;
pub mod memory;
pub mod rig;
pub mod rng;
pub mod source;
pub mod tracker_conformance;
pub mod tracking;

/// The geometry crate, re-exported so that users of the seams need one dependency.
pub use slam_quadric as geometry;

pub use assoc::{Assignment, AssociationInput, Associator, PointPair, TrackView};
pub use detection::{ClassId, Detection, Mask, Region, TrackId, COCO_NAMES};
pub use source::{DetectError, DetectionSource, Image};
pub use tracking::{
    BoxQuery, FramePoint, KeyframeId, KeyframePoint, Map, MovingRegion, NewKeyframe, ObjectInputs, ObjectMeasurements,
    PointId, SegmentJoin, Sightings, StageTimes, StereoTracker, TrackError, TrackState, TrackedFrame,
};

/// The map crate, re-exported so that users of the tracking seam need one dependency.
pub use slam_map as map;

/// Common types, meant to be glob-imported: `use slam_core::prelude::*;`.
pub mod prelude {
    pub use crate::{
        assoc::{Assignment, AssociationInput, Associator, PointPair, TrackView},
        detection::{ClassId, Detection, Mask, Region, TrackId},
        geometry::{BBox, Camera, Ellipsoid, ImageSize, Intrinsics},
    };
}
