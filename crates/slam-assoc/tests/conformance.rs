//! Both associators pass the conformance suite; ODA beats IoU-only on crossing objects.

use slam_assoc::{
    conformance,
    eval::{run, simulate, SimConfig},
    IouAssociator, ObjectTracker, Oda, TrackerConfig,
};

#[test]
fn oda_conforms() {
    conformance::check_all(&mut || Box::new(Oda::default())).expect("ODA conformance");
}

#[test]
fn iou_conforms() {
    conformance::check_all(&mut || Box::new(IouAssociator::default())).expect("IoU conformance");
}

#[test]
fn oda_has_fewer_id_switches_on_crossing_objects() {
    let cfg = SimConfig::default();
    let (mut oda_sw, mut iou_sw) = (0, 0);
    for seed in 0..5 {
        let frames = simulate(&cfg, seed);
        let mut a = ObjectTracker::new(Box::new(Oda::default()), TrackerConfig::default());
        let mut b = ObjectTracker::new(Box::new(IouAssociator::default()), TrackerConfig::default());
        let ra = run(&mut a, &frames);
        let rb = run(&mut b, &frames);
        assert_eq!(ra.misses, rb.misses);
        assert_eq!(ra.false_positives, rb.false_positives);
        oda_sw += ra.id_switches;
        iou_sw += rb.id_switches;
    }
    eprintln!("ID switches over 5 seeds: ODA {oda_sw}, IoU-only {iou_sw}");
    assert!(oda_sw * 3 < iou_sw * 2, "ODA {oda_sw} vs IoU {iou_sw} ID switches");
}

#[test]
fn simulation_is_deterministic() {
    let cfg = SimConfig { frames: 50, ..SimConfig::default() };
    let a = simulate(&cfg, 3);
    let b = simulate(&cfg, 3);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.detections, y.detections);
        assert_eq!(x.flow, y.flow);
    }
}

/// The projected-ellipsoid gate: a track whose ellipsoid projects far from a detection does not take it,
/// even when its predicted box (the other cues) agrees; without the gate it does (the paper's cost).
#[test]
fn projected_gate_stops_a_fitted_object_taking_another_box() {
    use slam_assoc::{Oda, OdaConfig};
    use slam_core::{geometry::BBox, AssociationInput, Associator, ClassId, Detection, TrackId, TrackView};
    let det = [Detection::new(ClassId(2), 0.9, BBox::new(700.0, 170.0, 760.0, 215.0))];
    let track = [TrackView {
        id: TrackId(7),
        class: ClassId(2),
        // its ellipsoid is elsewhere (the car it was fitted to, farther right) ...
        projected: Some(BBox::new(820.0, 180.0, 900.0, 240.0)),
        // ... but the motion model predicts a box on the detection
        predicted: Some(BBox::new(702.0, 171.0, 761.0, 216.0)),
        last: BBox::new(700.0, 170.0, 758.0, 214.0),
        reference_region: None,
    }];
    let input = AssociationInput { detections: &det, tracks: &track, flow: &[] };
    let mut plain = Oda::default();
    assert_eq!(plain.associate(&input).matches, vec![(0, TrackId(7))], "the paper's cost accepts it");
    let mut gated = Oda::new(OdaConfig { min_projected_iou: Some(0.1), ..OdaConfig::default() });
    let a = gated.associate(&input);
    assert!(a.matches.is_empty() && a.unmatched == vec![0], "{a:?}");
}
