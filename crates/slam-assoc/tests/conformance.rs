//! Both associators pass the conformance suite (ODA against IoU-only on simulated crossings is in
//! `slam-studies`' tests).

use slam_assoc::{conformance, IouAssociator, Oda};

#[test]
fn oda_conforms() {
    conformance::check_all(&mut || Box::new(Oda::default())).expect("ODA conformance");
}

#[test]
fn iou_conforms() {
    conformance::check_all(&mut || Box::new(IouAssociator::default())).expect("IoU conformance");
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
