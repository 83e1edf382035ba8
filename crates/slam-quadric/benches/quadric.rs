//! Micro-benchmarks: projection + bounds, clipped bounds, box prediction with Jacobians, and each
//! initialiser with five views (the paper's arc geometry). Run: `cargo bench -p slam-quadric`.

#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_quadric::{
    init::{all_methods, BoxView, Dqp},
    predict_box, project, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics,
};

fn kitti() -> (Intrinsics, ImageSize) {
    (Intrinsics::new(721.5377, 721.5377, 609.5593, 172.854), ImageSize::new(1242.0, 375.0))
}

fn car() -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(Translation3::new(0.0, 0.9, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.05, 0.0)),
        Vector3::new(2.1, 0.8, 0.85),
    )
}

/// Five level cameras on an 18° arc of radius 15 m around the object, each looking at its centre.
fn arc_views() -> Vec<BoxView> {
    let (k, img) = kitti();
    let e = car();
    (0..5)
        .map(|i| {
            let phi = (-9.0 + 4.5 * i as f64).to_radians();
            let c = Point3::new(15.0 * phi.sin(), 0.0, -15.0 * phi.cos());
            let target = Point3::new(0.0, 0.0, 0.0);
            // camera y (down) is world +y
            let pose = Isometry3::face_towards(&c, &target, &Vector3::y());
            let cam = Camera::new(k, pose);
            let b = project(&e, &cam).and_then(|c| c.clipped_bounds(&img)).expect("visible");
            BoxView::new(cam, b)
        })
        .collect()
}

fn benches(c: &mut Criterion) {
    let (k, img) = kitti();
    let cam = Camera::new(k, Isometry3::translation(0.5, 0.0, -15.0));
    let e = car();
    c.bench_function("project+bounds", |b| b.iter(|| project(black_box(&e), black_box(&cam)).and_then(|c| c.bounds())));
    c.bench_function("project+clipped_bounds", |b| {
        b.iter(|| project(black_box(&e), black_box(&cam)).and_then(|c| c.clipped_bounds(&img)))
    });
    c.bench_function("predict_box+jacobians(full)", |b| {
        b.iter(|| predict_box(black_box(&e), black_box(&cam), &BoundsModel::Full))
    });
    let views = arc_views();
    let mut methods = all_methods();
    methods.push(Box::new(Dqp::with_centre_correction()));
    for m in methods {
        c.bench_function(&format!("init/{}/5 views", m.name()), |b| b.iter(|| m.initialize(black_box(&views))));
    }
}

criterion_group!(quadric, benches);
criterion_main!(quadric);
