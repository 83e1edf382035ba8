//! What a saved map holds, read back: the poses of keyframes, points and frames, and its counts.

use nalgebra::{Isometry3, Vector3};
use slam_core::{KeyframeId, PointId};

use super::{pose_from_array, SavedKeyframe, SavedMap};

/// Counts describing a map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SavedMapStats {
    /// Keyframes.
    pub keyframes: usize,
    /// Map segments (keyframes without a parent).
    pub segments: usize,
    /// Map points.
    pub points: usize,
    /// Stereo observations.
    pub observations: usize,
    /// Objects (with an ellipsoid).
    pub objects: usize,
    /// Objects flagged dynamic.
    pub dynamic_objects: usize,
    /// Frames.
    pub frames: usize,
    /// Length of the keyframe path (the spanning tree: each keyframe's distance from its parent),
    /// metres.
    pub keyframe_path_m: f64,
}

impl SavedMap {
    /// The frame whose camera is the map's world: its first keyframe's (the lowest id; a map's first
    /// keyframe sits at the origin), `None` for a map without keyframes.
    pub fn first_frame(&self) -> Option<usize> {
        self.keyframes.values().next().map(|k| k.frame)
    }

    /// Pose of a keyframe.
    pub fn keyframe_pose(&self, id: KeyframeId) -> Option<Isometry3<f64>> {
        self.keyframes.get(&id).map(|k| pose_from_array(&k.pose))
    }

    /// World position of a point.
    pub fn point(&self, id: PointId) -> Option<Vector3<f64>> {
        self.points.get(&id).map(|p| Vector3::from(p.position))
    }

    /// Pose of every frame (keyframe pose composed with the frame's relative pose); `None` for a frame
    /// whose keyframe is missing.
    pub fn frame_poses(&self) -> Vec<Option<Isometry3<f64>>> {
        self.trajectory
            .iter()
            .map(|f| f.keyframe.and_then(|k| self.keyframe_pose(k)).map(|k| k * pose_from_array(&f.relative)))
            .collect()
    }

    /// Counts. The keyframe path is the length of the keyframes' spanning tree: each keyframe's
    /// distance from its parent (the keyframe it was tracked from), summed, so that keyframes a later
    /// run added over the same road count by where they were tracked from, not by their ids (ids follow
    /// the runs, and summing in id order hopped back across the road at each run).
    pub fn stats(&self) -> SavedMapStats {
        let live = |id: &KeyframeId| self.keyframes.get(id).filter(|k| !k.culled);
        let centre = |k: &SavedKeyframe| Vector3::new(k.pose[4], k.pose[5], k.pose[6]);
        let keyframe_path_m = self
            .keyframes
            .values()
            .filter(|k| !k.culled)
            .filter_map(|k| Some((centre(k) - centre(live(&k.parent?)?)).norm()))
            .fold(0.0, |a, d| a + d);
        SavedMapStats {
            keyframes: self.keyframes.values().filter(|k| !k.culled).count(),
            segments: self.keyframes.values().filter(|k| k.parent.is_none()).count(),
            points: self.points.len(),
            observations: self.keyframes.values().map(|k| k.observations.len()).sum(),
            objects: self.objects.len(),
            dynamic_objects: self.objects.iter().filter(|o| o.dynamic).count(),
            frames: self.trajectory.len(),
            keyframe_path_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The keyframe path follows the spanning tree: a second run's keyframes over the same road add
    /// their distance from the keyframe each was tracked from, not the hop back from the first run's
    /// last keyframe (24 m here, 48 m in id order); a map of one keyframe has a path of 0 m, not -0.
    #[test]
    fn the_keyframe_path_follows_the_spanning_tree() {
        let kf = |z: f64, parent: Option<KeyframeId>| SavedKeyframe {
            frame: 0,
            pose: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, z],
            parent,
            observations: vec![],
            culled: false,
        };
        let mut m = SavedMap::default();
        m.keyframes.insert(0, kf(0.0, None));
        assert_eq!(format!("{:.1}", m.stats().keyframe_path_m), "0.0");
        m.keyframes.insert(1, kf(10.0, Some(0)));
        m.keyframes.insert(2, kf(20.0, Some(1)));
        assert_eq!(m.stats().keyframe_path_m, 20.0);
        m.keyframes.insert(3, kf(2.0, Some(0)));
        m.keyframes.insert(4, kf(12.0, Some(1)));
        assert_eq!(m.stats().keyframe_path_m, 24.0);
    }
}
