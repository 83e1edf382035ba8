//! The map of the visual front end, in parts a reader finds by name:
//!
//! - [`camera`]: the stereo camera and the ORB scale pyramid; [`descriptor`]: binary descriptors, their
//!   distance and the representative of several; [`grid`]: keypoints in cells for projection searches;
//! - [`keyframe`]: keyframes and their features; [`point`]: map points; [`covisibility`]: the graph
//!   linking keyframes that share points;
//! - [`Map`] (`map.rs`): the three kept consistent by a few primitives, snapshots of part of the map that
//!   record their changes as [`Edit`]s, and the replay of those edits on the live map;
//! - the life of keyframes and points: [`insert`] (a new keyframe, its observations and its near
//!   stereo points), [`local`] (the keyframes around a view: tracking's local map, local mapping's
//!   window), [`triangulation`] (new points between covisible keyframes), [`fusion`] (a point found
//!   twice made one), [`point_culling`] (young points that are not found again), [`keyframe_culling`]
//!   (keyframes whose points others see); [`restore`]: a map rebuilt from what a map file keeps.
//!
//! No OpenCV and no optimiser: local bundle adjustment works on a snapshot elsewhere
//! (`slam-pipeline`) and hands its result back as edits.

#![warn(missing_docs)]

pub mod camera;
pub mod covisibility;
pub mod descriptor;
pub mod edit;
pub mod fusion;
pub mod grid;
pub mod insert;
pub mod keyframe;
pub mod keyframe_culling;
pub mod local;
mod map;
pub mod point;
pub mod point_culling;
pub mod restore;
pub mod triangulation;

#[cfg(test)]
mod synthetic;

/// Identity of a map point, unique within a map (never reused).
pub type PointId = u64;

/// Identity of a keyframe, unique within a map (0, 1, 2, … in creation order, never reused).
pub type KeyframeId = u64;

pub use camera::{ScalePyramid, StereoCamera};
pub use covisibility::Covisibility;
pub use descriptor::{hamming, BestTwo, Descriptor};
pub use edit::Edit;
pub use grid::KeypointGrid;
pub use insert::{CreationPolicy, Inserted, NewKeyframe};
pub use keyframe::{Features, Keyframe, Keypoint};
pub use map::{Map, MapError, Retired};
pub use point::{MapPoint, Observation};
pub use restore::{RestoreError, SavedPoint};
