//! Stereo odometry on its own: a [`StereoVo`] and the map it tracks against, each keyframe it hands over
//! inserted at once and no local mapping (`slam-app stereo-check`, tests, a quick look at a sequence).
//! The whole system (`slam-pipeline`) owns the map itself and adds local mapping.

use std::sync::Arc;

use slam_core::{Image, MovingRegion, TrackedFrame};
use slam_map::{CreationPolicy, Map, ScalePyramid};
use slam_optim::SharedOptimizer;

use crate::{image_io::FrontendError, StereoRig, StereoVo, VoConfig};

/// Least new map points made at a keyframe from its nearest stereo keypoints (the pipeline's
/// `mapping.min_new_points` default; see `slam_map::CreationPolicy`).
pub const MIN_NEW_POINTS: usize = 100;

/// A tracker and its map.
pub struct Odometry {
    /// The tracker.
    pub vo: StereoVo,
    /// The map: keyframes and their points, no local mapping.
    pub map: Map,
    policy: CreationPolicy,
}

impl Odometry {
    /// Odometry for a rig with an empty map.
    pub fn new(rig: StereoRig, config: VoConfig, optimizer: SharedOptimizer) -> Result<Self, FrontendError> {
        let vo = StereoVo::new(rig, config, optimizer)?;
        let policy = vo.creation_policy(MIN_NEW_POINTS);
        Ok(Self { vo, map: Map::new(rig, ScalePyramid::default()), policy })
    }

    /// Track a stereo pair; a keyframe it hands over is inserted, and the frame's sightings counted.
    pub fn track(
        &mut self,
        frame: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
    ) -> Result<TrackedFrame, FrontendError> {
        let tf = self.vo.process(frame, left, right, exclude, &self.map)?;
        self.map.count_sightings(&tf.sightings.visible, &tf.sightings.found);
        if let Some(kf) = &tf.keyframe {
            if let Err(e) = self.map.insert_keyframe(kf.clone(), &self.policy) {
                tracing::warn!(frame, "keyframe not inserted: {e}");
            }
        }
        Ok(tf)
    }

    /// The features of the keyframes, shared (for tests of retrieval).
    pub fn keyframe_features(&self) -> Vec<(u64, Arc<slam_map::Features>)> {
        self.map.keyframes().map(|k| (k.id, k.features.clone())).collect()
    }
}
