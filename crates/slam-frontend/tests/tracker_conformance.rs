//! The stereo tracker passes the `StereoTracker` conformance suite on the first frames of the shipped
//! KITTI odometry 06 sequence (the pipeline's tests run it on a scripted tracker too).

use std::{path::PathBuf, sync::Arc};

use slam_core::{
    tracker_conformance::{check_all, Subject},
    Image,
};
use slam_frontend::{odometry::MIN_NEW_POINTS, read_image, StereoRig, StereoVo, VoConfig};
use slam_map::{Map, ScalePyramid};
use slam_quadric::Intrinsics;

fn kitti_frame(i: usize) -> (Image, Image) {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_odom_06/sequences/06"));
    let read = |cam: &str| read_image(root.join(cam).join(format!("{i:06}.png")), false).expect("fixture image");
    (read("image_0"), read("image_1"))
}

#[test]
fn the_stereo_tracker_conforms() {
    // P0 / P1 of the sequence's calib.txt
    let rig = StereoRig { k: Intrinsics::new(707.0912, 707.0912, 601.8873, 183.1104), baseline: 379.8145 / 707.0912 };
    let frames: Vec<(Image, Image)> = (0..8).map(kitti_frame).collect();
    let mut make = || {
        let vo =
            StereoVo::new(rig, VoConfig::default(), Arc::new(slam_lm::LevenbergMarquardt::default())).expect("ORB");
        let policy = vo.creation_policy(MIN_NEW_POINTS);
        Subject { tracker: Box::new(vo), map: Map::new(rig, ScalePyramid::default()), policy }
    };
    check_all(&mut make, &frames).expect("the stereo tracker conforms");
}
