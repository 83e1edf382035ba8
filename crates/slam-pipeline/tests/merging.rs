//! Object merging in the mapper: one parked car boxed twice in every frame (two tracks of one object)
//! ends as one ellipsoid; two parked cars a car length apart stay two.

mod common;

use common::{lm, K};
use nalgebra::Isometry3;
use slam_assoc::Oda;
use slam_core::{geometry::BBox, ClassId, Detection};
use slam_pipeline::objects::{MapperConfig, ObjectMapper};
use slam_quadric::{metrics, Camera, Ellipsoid};

const FRAMES: usize = 24;

fn car(x: f64, z: f64) -> Ellipsoid {
    common::car(x, z, 0.05)
}

/// Drive 1 m per frame past `cars`; `boxes` turns each car's exact box into the frame's detections.
fn drive(cars: &[Ellipsoid], boxes: impl Fn(BBox) -> Vec<BBox>) -> ObjectMapper {
    let mut mapper = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
    for f in 0..FRAMES {
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, f as f64));
        let dets: Vec<Detection> = cars
            .iter()
            .filter_map(|e| common::detected_box(e, &cam))
            .flat_map(&boxes)
            .map(|b| Detection::new(ClassId(2), 1.0, b))
            .collect();
        let ids = mapper.step(f, &cam, &dets);
        assert_eq!(ids.len(), dets.len());
    }
    mapper
}

#[test]
fn a_car_boxed_twice_becomes_one_ellipsoid() {
    let parked = car(5.0, 30.0);
    // a detector that boxes the car twice: the whole car, and its front three quarters
    let twice = |b: BBox| vec![b, BBox::new(b.xmin + 0.25 * b.width(), b.ymin, b.xmax, b.ymax)];
    let mapper = drive(&[parked], twice);
    let mapped: Vec<_> = mapper.objects().filter(|o| o.ellipsoid.is_some()).collect();
    let ids: Vec<_> = mapped.iter().map(|o| o.id).collect();
    assert_eq!(mapped.len(), 1, "one ellipsoid, got objects {ids:?}");
    assert_eq!(mapper.merged().len(), 1, "the second track merged into the first: {:?}", mapper.merged());
    let (dropped, kept) = mapper.merged().iter().next().map(|(d, k)| (*d, *k)).expect("a merge");
    assert_eq!(mapped[0].id, kept);
    assert!(mapper.object(dropped).is_none(), "the dropped track's object is gone");
    // the kept ellipsoid is the car (the whole-car boxes dominate its fit)
    let e = mapped[0].ellipsoid.as_ref().expect("ellipsoid");
    assert!(metrics::e_trans(e, &parked) < 1.0, "centre off by {:.2} m", metrics::e_trans(e, &parked));
}

#[test]
fn two_cars_a_car_length_apart_stay_two() {
    // parked one behind the other, 6 m between centres (merge distance 2.5 m)
    let cars = [car(5.0, 30.0), car(5.0, 36.0)];
    let mapper = drive(&cars, |b| vec![b]);
    assert!(mapper.merged().is_empty(), "merged: {:?}", mapper.merged());
    let mapped: Vec<_> = mapper.objects().filter(|o| o.ellipsoid.is_some()).collect();
    let ids: Vec<_> = mapped.iter().map(|o| o.id).collect();
    assert_eq!(mapped.len(), 2, "objects {ids:?}");
    for truth in &cars {
        let best = mapped
            .iter()
            .filter_map(|o| o.ellipsoid.as_ref())
            .map(|e| metrics::e_trans(e, truth))
            .fold(f64::INFINITY, f64::min);
        assert!(best < 0.5, "no ellipsoid within 0.5 m of the car at {:?}: {best:.2}", truth.centre());
    }
}
