//! The scripted tracker the system tests drive the pipeline with passes the `StereoTracker`
//! conformance suite: the minimal second implementation beside the stereo tracker (`slam-frontend`'s
//! tests run the suite on that one).

mod common;

use common::{car, field, Scene, ScriptedTracker, B, IMAGE, K};
use nalgebra::{Isometry3, Vector3};
use slam_core::{
    map::{CreationPolicy, ScalePyramid, StereoCamera},
    tracker_conformance::{check_all, Subject},
    Image, Map,
};
use slam_quadric::Ellipsoid;

/// Driving straight ahead at 1 m a frame.
fn truth(i: usize) -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, i as f64)
}

/// One parked car beside the road.
fn cars(_: usize) -> Vec<Ellipsoid> {
    vec![car(5.0, 30.0, 0.0)]
}

fn no_texture(_: usize) -> Vec<(u64, Vector3<f64>)> {
    Vec::new()
}

#[test]
fn the_scripted_tracker_conforms() {
    let blank = Image::new(IMAGE.width as u32, IMAGE.height as u32, 1, vec![0; (IMAGE.width * IMAGE.height) as usize])
        .expect("size matches");
    let frames = vec![(blank.clone(), blank); 10];
    let mut make = || Subject {
        tracker: Box::new(ScriptedTracker::new(Scene {
            truth,
            believed: truth,
            cars,
            field: field(3, 400),
            texture: no_texture,
        })),
        map: Map::new(StereoCamera { k: K, baseline: B }, ScalePyramid::default()),
        policy: CreationPolicy::default(),
    };
    check_all(&mut make, &frames).expect("the scripted tracker conforms");
}
