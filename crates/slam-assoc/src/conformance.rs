//! Checks every [`Associator`] must pass. Another association crate can run them from its own tests:
//! `slam_assoc::conformance::check_all(&mut || Box::new(MyAssociator::default()))`.
//!
//! Each check returns `Err(description)` on the first violation. These are test helpers, for a
//! test to assert on and print: the description is for a person, not a typed error a program would
//! handle (the seam itself, [`Associator::associate`], cannot fail).

use slam_core::{
    geometry::BBox, Assignment, AssociationInput, Associator, ClassId, Detection, PointPair, Region, TrackId, TrackView,
};

use slam_core::rng::SimRng;

/// A factory of fresh associators (associators may keep state between frames).
pub type Factory<'a> = &'a mut dyn FnMut() -> Box<dyn Associator>;

/// Run every check.
pub fn check_all(make: Factory<'_>) -> Result<(), String> {
    check_invariants(make)?;
    check_permutation_invariance(make)?;
    check_class_gating(make)?;
    check_deterministic_ties(make)?;
    check_degenerate_input(make)?;
    Ok(())
}

/// Random scene: tracks and detections near them (some moved, some new), two classes.
fn scene(rng: &mut SimRng, n_tracks: usize, n_dets: usize) -> (Vec<Detection>, Vec<(TrackId, ClassId, BBox)>) {
    let tracks: Vec<(TrackId, ClassId, BBox)> = (0..n_tracks)
        .map(|k| {
            let x = rng.uniform(0.0, 1100.0);
            let y = rng.uniform(0.0, 300.0);
            let w = rng.uniform(20.0, 150.0);
            (
                TrackId(1000 + 7 * k as u64),
                ClassId((k % 2) as u16),
                BBox::new(x, y, x + w, y + w * rng.uniform(0.4, 1.2)),
            )
        })
        .collect();
    let dets = (0..n_dets)
        .map(|k| {
            if k < n_tracks && rng.unit() < 0.8 {
                let (_, c, b) = tracks[k];
                let dx = rng.uniform(-8.0, 8.0);
                let dy = rng.uniform(-5.0, 5.0);
                Detection::new(c, rng.uniform(0.3, 1.0), BBox::new(b.xmin + dx, b.ymin + dy, b.xmax + dx, b.ymax + dy))
            } else {
                let x = rng.uniform(0.0, 1100.0);
                let y = rng.uniform(0.0, 300.0);
                let w = rng.uniform(20.0, 150.0);
                Detection::new(ClassId(rng.below(2) as u16), rng.uniform(0.3, 1.0), BBox::new(x, y, x + w, y + 0.7 * w))
            }
        })
        .collect();
    (dets, tracks)
}

fn views(tracks: &[(TrackId, ClassId, BBox)]) -> Vec<TrackView<'static>> {
    tracks
        .iter()
        .map(|&(id, class, b)| TrackView {
            id,
            class,
            projected: Some(BBox::new(b.xmin - 2.0, b.ymin, b.xmax + 1.0, b.ymax + 2.0)),
            predicted: Some(b),
            last: b,
            reference_region: Some(Region::Box(b)),
        })
        .collect()
}

fn flow_for(dets: &[Detection], rng: &mut SimRng) -> Vec<PointPair> {
    let mut out = Vec::new();
    for d in dets {
        for _ in 0..8 {
            let x = rng.uniform(d.bbox.xmin, d.bbox.xmax);
            let y = rng.uniform(d.bbox.ymin, d.bbox.ymax);
            out.push(PointPair {
                reference: [x + rng.uniform(-3.0, 3.0), y + rng.uniform(-3.0, 3.0)],
                current: [x, y],
            });
        }
    }
    out
}

fn validate(a: &Assignment, dets: &[Detection], tracks: &[TrackView<'_>]) -> Result<(), String> {
    let mut seen = vec![0usize; dets.len()];
    for &(d, _) in &a.matches {
        *seen.get_mut(d).ok_or(format!("match names detection {d} of {}", dets.len()))? += 1;
    }
    for &d in &a.unmatched {
        *seen.get_mut(d).ok_or(format!("unmatched names detection {d} of {}", dets.len()))? += 1;
    }
    if let Some(d) = seen.iter().position(|&c| c != 1) {
        return Err(format!("detection {d} appears {} times", seen[d]));
    }
    let mut ids: Vec<TrackId> = a.matches.iter().map(|m| m.1).collect();
    ids.sort();
    if ids.windows(2).any(|w| w[0] == w[1]) {
        return Err("a track is matched twice".into());
    }
    for &(d, id) in &a.matches {
        let t = tracks.iter().find(|t| t.id == id).ok_or(format!("unknown track {id}"))?;
        if t.class.group() != dets[d].class.group() {
            return Err(format!("detection {d} matched across class groups"));
        }
    }
    if !a.matches.windows(2).all(|w| w[0].0 < w[1].0) || !a.unmatched.windows(2).all(|w| w[0] < w[1]) {
        return Err("output not sorted".into());
    }
    Ok(())
}

/// Assignment invariants on 200 random scenes of up to 30 × 30.
pub fn check_invariants(make: Factory<'_>) -> Result<(), String> {
    let mut rng = SimRng::new(1);
    for trial in 0..200 {
        let (n_t, n_d) = (rng.below(30), rng.below(30));
        let (dets, tracks) = scene(&mut rng, n_t, n_d);
        let v = views(&tracks);
        let flow = flow_for(&dets, &mut rng);
        let a = make().associate(&AssociationInput { detections: &dets, tracks: &v, flow: &flow });
        validate(&a, &dets, &v).map_err(|e| format!("trial {trial}: {e}"))?;
    }
    Ok(())
}

/// Shuffling detections and tracks shuffles the answer accordingly.
pub fn check_permutation_invariance(make: Factory<'_>) -> Result<(), String> {
    let mut rng = SimRng::new(2);
    for trial in 0..100 {
        let (n_t, n_d) = (1 + rng.below(20), 1 + rng.below(20));
        let (dets, tracks) = scene(&mut rng, n_t, n_d);
        let flow = flow_for(&dets, &mut rng);
        let a = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &flow });
        let dp = rng.permutation(dets.len());
        let tp = rng.permutation(tracks.len());
        let dets2: Vec<Detection> = dp.iter().map(|&i| dets[i].clone()).collect();
        let tracks2: Vec<_> = tp.iter().map(|&i| tracks[i]).collect();
        let b = make().associate(&AssociationInput { detections: &dets2, tracks: &views(&tracks2), flow: &flow });
        let mut mapped: Vec<(usize, TrackId)> = b.matches.iter().map(|&(d, t)| (dp[d], t)).collect();
        mapped.sort();
        if mapped != a.matches {
            return Err(format!("trial {trial}: permuted input gave a different assignment"));
        }
    }
    Ok(())
}

/// A detection never matches a track of another class group ([`ClassId::group`]), even when the boxes
/// coincide, and does match one of its group.
pub fn check_class_gating(make: Factory<'_>) -> Result<(), String> {
    let b = BBox::new(100.0, 100.0, 200.0, 180.0);
    let tracks = [(TrackId(1), ClassId(3), b)];
    let dets = vec![Detection::new(ClassId(4), 0.9, b)];
    let a = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &[] });
    if !a.matches.is_empty() || a.unmatched != vec![0] {
        return Err("matched across classes".into());
    }
    let dets = vec![Detection::new(ClassId(3), 0.9, b)];
    let a = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &[] });
    if a.matches != vec![(0, TrackId(1))] {
        return Err("did not match an identical box of the same class".into());
    }
    // a class group (`ClassId::group`) is one: the detector calls one vehicle car, then truck
    let tracks = [(TrackId(1), ClassId(2), b)];
    let dets = vec![Detection::new(ClassId(7), 0.9, b)];
    let a = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &[] });
    if a.matches != vec![(0, TrackId(1))] {
        return Err("did not match a truck box to the identical box of a car track".into());
    }
    Ok(())
}

/// Exact ties are broken the same way every time: identical detections go to identical tracks in
/// ascending order (lowest detection index to lowest track id).
pub fn check_deterministic_ties(make: Factory<'_>) -> Result<(), String> {
    let b = BBox::new(300.0, 120.0, 380.0, 170.0);
    let tracks = [(TrackId(9), ClassId(0), b), (TrackId(4), ClassId(0), b)];
    let dets = vec![Detection::new(ClassId(0), 0.8, b), Detection::new(ClassId(0), 0.8, b)];
    let first = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &[] });
    for _ in 0..5 {
        let again = make().associate(&AssociationInput { detections: &dets, tracks: &views(&tracks), flow: &[] });
        if again != first {
            return Err("tie broken differently on a repeated call".into());
        }
    }
    if first.matches != vec![(0, TrackId(4)), (1, TrackId(9))] {
        return Err(format!("tie rule violated: {:?}", first.matches));
    }
    Ok(())
}

/// Empty input, NaN boxes and NaN flow give valid answers without panicking; NaN boxes stay unmatched.
pub fn check_degenerate_input(make: Factory<'_>) -> Result<(), String> {
    let a = make().associate(&AssociationInput { detections: &[], tracks: &[], flow: &[] });
    if a != Assignment::default() {
        return Err("empty input gave a non-empty answer".into());
    }
    let b = BBox::new(10.0, 10.0, 50.0, 40.0);
    let tracks = [(TrackId(1), ClassId(0), b), (TrackId(2), ClassId(0), BBox::new(f64::NAN, 0.0, 1.0, 1.0))];
    let dets = vec![
        Detection::new(ClassId(0), 1.0, BBox::new(f64::NAN, 10.0, 50.0, 40.0)),
        Detection::new(ClassId(0), 1.0, b),
    ];
    let flow = [PointPair { reference: [f64::NAN, 1.0], current: [20.0, 20.0] }];
    let v = views(&tracks);
    let a = make().associate(&AssociationInput { detections: &dets, tracks: &v, flow: &flow });
    validate(&a, &dets, &v)?;
    if a.matches.iter().any(|&(d, _)| d == 0) {
        return Err("a NaN detection was matched".into());
    }
    let a = make().associate(&AssociationInput { detections: &[], tracks: &v, flow: &[] });
    if a != Assignment::default() {
        return Err("no detections gave a non-empty answer".into());
    }
    Ok(())
}
