//! ODA beats IoU-only on simulated crossing objects, and the simulation is deterministic.

use slam_assoc::{IouAssociator, ObjectTracker, Oda, TrackerConfig};
use slam_studies::assoc_sim::{run, simulate, SimConfig};

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
