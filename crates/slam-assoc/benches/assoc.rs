//! Association of 50 tracks × 50 detections with all three ODA cues, and with IoU only.
//! Run: `cargo bench -p slam-assoc`.

#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use slam_assoc::{IouAssociator, Oda};
use slam_core::{
    geometry::BBox, rng::SimRng, AssociationInput, Associator, ClassId, Detection, PointPair, Region, TrackId,
    TrackView,
};

fn scene(n: usize) -> (Vec<Detection>, Vec<TrackView<'static>>, Vec<PointPair>) {
    let mut rng = SimRng::new(5);
    let mut dets = Vec::new();
    let mut tracks = Vec::new();
    let mut flow = Vec::new();
    for k in 0..n {
        let x = rng.uniform(0.0, 1150.0);
        let y = rng.uniform(100.0, 300.0);
        let w = rng.uniform(30.0, 90.0);
        let b = BBox::new(x, y, x + w, y + 0.6 * w);
        let class = ClassId((k % 3) as u16);
        tracks.push(TrackView {
            id: TrackId(k as u64),
            class,
            projected: Some(b),
            predicted: Some(b),
            last: b,
            reference_region: Some(Region::Box(b)),
        });
        let d = BBox::new(b.xmin + 3.0, b.ymin - 2.0, b.xmax + 3.0, b.ymax - 2.0);
        dets.push(Detection::new(class, 0.8, d));
        for _ in 0..20 {
            let px = rng.uniform(d.xmin, d.xmax);
            let py = rng.uniform(d.ymin, d.ymax);
            flow.push(PointPair { reference: [px - 3.0, py + 2.0], current: [px, py] });
        }
    }
    (dets, tracks, flow)
}

fn benches(c: &mut Criterion) {
    let (dets, tracks, flow) = scene(50);
    let input = AssociationInput { detections: &dets, tracks: &tracks, flow: &flow };
    let mut oda = Oda::default();
    c.bench_function("ODA 50x50 (3 cues, 1000 flow points)", |b| b.iter(|| oda.associate(black_box(&input))));
    let mut iou = IouAssociator::default();
    c.bench_function("IoU 50x50", |b| b.iter(|| iou.associate(black_box(&input))));
}

criterion_group!(assoc, benches);
criterion_main!(assoc);
