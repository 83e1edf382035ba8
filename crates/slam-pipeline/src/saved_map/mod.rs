//! The saved map: the file form of a run's map (`map.json` and the keyframes' features file beside
//! it), as opposed to the live map ([`slam_core::Map`], the map crate's `Map`) a run tracks against.
//!
//! Who owns what: the tracking thread owns the live map (`TrackingThread::map`): its tracker reads
//! it, keyframes go into it, and it applies the edits local mapping sends back; the local-mapping
//! thread only works on snapshots of a keyframe's window and never holds the map. A [`SavedMap`] is
//! made from the live map once, when the run ends ([`crate::system::System::finish`] through
//! [`SavedMap::from_live`]), and the caller writes it ([`SavedMap::save`]: slam-runner's output
//! folder). A later run reads one back ([`SavedMap::load`]) and turns it into the live map it starts
//! from ([`SavedMap::to_live`], handed to [`crate::system::SystemBuilder::map`]).
//!
//! - `format`: the serde structs of the file and the versions they read;
//! - `contents`: what a saved map holds, read back (poses, counts);
//! - `file`: saving and loading, atomically, with the features file beside it;
//! - `check`: the checks of a map read from a file;
//! - [`features`]: the binary features file (keypoints, descriptors, observations);
//! - `live`: live map to file and back.

mod check;
mod contents;
pub mod features;
mod file;
mod format;
mod live;
#[cfg(test)]
mod sample;

pub use check::{MAX_COORDINATE_M, MAX_ID};
pub use contents::SavedMapStats;
pub use features::{FeaturesRef, SavedFeatures};
pub use file::{features_path, features_places, SavedMapError};
pub use format::{
    pose_from_array, pose_to_array, FramePose, GroundTruthWorld, MapCamera, ObjectView, PoseArray, SavedKeyframe,
    SavedMap, SavedMapPoint, SavedObject, MAP_FORMAT, MAP_VERSION, MAP_WORLD,
};
pub use live::{CameraMismatch, LoadedMap, ToLiveError};
