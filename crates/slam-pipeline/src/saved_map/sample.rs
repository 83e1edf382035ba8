//! A small consistent saved map for the tests of this module.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::{pose_to_array, FramePose, SavedKeyframe, SavedMap, SavedMapPoint};

/// Two keyframes (the second culled), one point observed by the first, two frames.
pub(super) fn sample() -> SavedMap {
    let mut m = SavedMap::default();
    let pose =
        Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3));
    m.keyframes.insert(
        0,
        SavedKeyframe {
            frame: 0,
            pose: pose_to_array(&Isometry3::identity()),
            parent: None,
            observations: vec![(7, [1.0, 2.0, 0.5])],
            culled: false,
        },
    );
    m.keyframes.insert(
        1,
        SavedKeyframe { frame: 3, pose: pose_to_array(&pose), parent: Some(0), observations: vec![], culled: true },
    );
    m.points.insert(7, SavedMapPoint { position: [0.5, 0.1, 9.0], observed_by: vec![0] });
    m.trajectory.push(FramePose {
        frame: 0,
        keyframe: Some(0),
        relative: pose_to_array(&Isometry3::identity()),
        state: "initialised".into(),
    });
    m.trajectory.push(FramePose {
        frame: 1,
        keyframe: Some(1),
        relative: pose_to_array(&pose.inverse()),
        state: "tracked".into(),
    });
    m
}
